//! Amanatides-Woo 3D DDA: the voxels a segment crosses, in order, one face at a time.
//!
//! Coordinates are in cells (cell `(i, j, k)` spans `[i, i+1) x [j, j+1) x [k, k+1)`).
//! The walk moves along exactly one axis per step and only toward the end voxel, so it
//! reaches the end voxel in exactly `|di| + |dj| + |dk|` steps whatever the rounding
//! (an axis that has reached the end voxel's coordinate is never stepped again): a
//! ray can neither overshoot nor loop.

/// One step of the walk: the voxel entered, and which axis moved in which direction
/// (so a caller can update a linear index with one add).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Step {
    /// The voxel entered.
    pub voxel: [i32; 3],
    /// The axis that moved (0 = x, 1 = y, 2 = z).
    pub axis: usize,
    /// +1 or -1.
    pub dir: i32,
}

/// The walk from the voxel containing `from` to the voxel containing `to`. The start
/// voxel is [`Dda::start`]; iterating yields every following voxel up to and including
/// the end voxel.
#[derive(Debug, Clone)]
pub struct Dda {
    voxel: [i32; 3],
    target: [i32; 3],
    step: [i32; 3],
    t_max: [f32; 3],
    t_delta: [f32; 3],
}

impl Dda {
    /// A walk between two points in cell coordinates; both must be finite (the caller
    /// checks: the mapper only casts rays it has clipped to its window).
    #[inline(always)]
    pub fn new(from: [f32; 3], to: [f32; 3]) -> Self {
        let mut voxel = [0i32; 3];
        let mut target = [0i32; 3];
        let mut step = [0i32; 3];
        let mut t_max = [f32::INFINITY; 3];
        let mut t_delta = [f32::INFINITY; 3];
        for i in 0..3 {
            voxel[i] = floor_i32(from[i]);
            target[i] = floor_i32(to[i]);
            let d = to[i] - from[i];
            if voxel[i] == target[i] {
                continue;
            }
            // The voxels differ, so d is not 0 (up to rounding: keep the sign of the
            // voxel difference, which is what termination relies on).
            step[i] = if target[i] > voxel[i] { 1 } else { -1 };
            let ad = d.abs().max(f32::MIN_POSITIVE);
            t_delta[i] = 1.0 / ad;
            let boundary = if step[i] > 0 {
                voxel[i] as f32 + 1.0
            } else {
                voxel[i] as f32
            };
            t_max[i] = ((boundary - from[i]) / ad * step[i] as f32).max(0.0);
        }
        Self {
            voxel,
            target,
            step,
            t_max,
            t_delta,
        }
    }

    /// The voxel the walk starts in (the one containing `from`).
    pub fn start(&self) -> [i32; 3] {
        self.voxel
    }

    /// The voxel the walk ends in (the one containing `to`).
    pub fn end(&self) -> [i32; 3] {
        self.target
    }

    /// Steps left before the end voxel is reached.
    pub fn remaining(&self) -> u32 {
        (0..3).map(|i| self.target[i].abs_diff(self.voxel[i])).sum()
    }
}

/// `floor` without a libm call (x86-64 without SSE4.1 has no rounding instruction, and
/// this runs twice per ray per axis).
#[inline(always)]
pub fn floor_i32(x: f32) -> i32 {
    let i = x as i32;
    if (i as f32) > x { i - 1 } else { i }
}

impl Iterator for Dda {
    type Item = Step;

    #[inline]
    fn next(&mut self) -> Option<Step> {
        // Axes already at the end voxel have t_max = infinity; all three at infinity
        // means the end voxel has been reached.
        let [a, b, c] = self.t_max;
        let axis = if a <= b && a <= c {
            0
        } else if b <= c {
            1
        } else {
            2
        };
        if self.t_max[axis] == f32::INFINITY {
            return None;
        }
        self.voxel[axis] += self.step[axis];
        self.t_max[axis] = if self.voxel[axis] == self.target[axis] {
            f32::INFINITY
        } else {
            self.t_max[axis] + self.t_delta[axis]
        };
        Some(Step {
            voxel: self.voxel,
            axis,
            dir: self.step[axis],
        })
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        let n = self.remaining() as usize;
        (n, Some(n))
    }
}

#[cfg(test)]
#[path = "raycast_test.rs"]
mod tests;
