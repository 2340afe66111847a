//! Amanatides-Woo 3D DDA: the voxels a segment crosses, in order, one face at a time.
//!
//! Coordinates are in cells (cell `(i, j, k)` spans `[i, i+1) x [j, j+1) x [k, k+1)`).
//! The walk moves along exactly one axis per step and only toward the end voxel, so it
//! reaches the end voxel in exactly `|di| + |dj| + |dk|` steps whatever the rounding
//! (an axis that has reached the end voxel's coordinate is never stepped again): a
//! ray can neither overshoot nor loop.

/// One step of the walk: the voxel entered, which axis moved in which direction, and
/// what that step adds to a linear cell index (so a caller updates its index with one
/// add).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Step {
    /// The voxel entered.
    pub voxel: [i32; 3],
    /// The axis that moved (0 = x, 1 = y, 2 = z).
    pub axis: usize,
    /// +1 or -1.
    pub dir: i32,
    /// `dir` times the stride of `axis` given to [`Dda::with_strides`] (0 without).
    pub offset: isize,
}

/// One axis of the walk. Scalar fields (no arrays indexed by a run-time axis) let the
/// compiler keep the whole walk in registers.
#[derive(Debug, Clone, Copy)]
struct Axis {
    voxel: i32,
    step: i32,
    /// Steps left along this axis.
    left: u32,
    /// Ray parameter at the next boundary; infinity once the axis is done.
    t_max: f32,
    t_delta: f32,
    offset: isize,
}

impl Axis {
    #[inline(always)]
    fn new(from: f32, to: f32, stride: isize) -> Self {
        let voxel = floor_i32(from);
        let target = floor_i32(to);
        if voxel == target {
            return Self {
                voxel,
                step: 0,
                left: 0,
                t_max: f32::INFINITY,
                t_delta: f32::INFINITY,
                offset: 0,
            };
        }
        // The voxels differ; keep the sign of their difference (not of the rounded
        // delta), which is what termination relies on.
        let step = if target > voxel { 1 } else { -1 };
        let ad = (to - from).abs().max(f32::MIN_POSITIVE);
        let boundary = if step > 0 {
            voxel as f32 + 1.0
        } else {
            voxel as f32
        };
        Self {
            voxel,
            step,
            left: target.abs_diff(voxel),
            t_max: ((boundary - from) / ad * step as f32).max(0.0),
            t_delta: 1.0 / ad,
            offset: step as isize * stride,
        }
    }

    #[inline(always)]
    fn advance(&mut self) {
        self.voxel += self.step;
        self.left -= 1;
        self.t_max = if self.left == 0 {
            f32::INFINITY
        } else {
            self.t_max + self.t_delta
        };
    }
}

/// The walk from the voxel containing `from` to the voxel containing `to`. The start
/// voxel is [`Dda::start`]; iterating yields every following voxel up to and including
/// the end voxel.
#[derive(Debug, Clone)]
pub struct Dda {
    x: Axis,
    y: Axis,
    z: Axis,
}

impl Dda {
    /// A walk between two points in cell coordinates; both must be finite (the caller
    /// checks: the mapper only casts rays it has clipped to its window).
    #[inline(always)]
    pub fn new(from: [f32; 3], to: [f32; 3]) -> Self {
        Self::with_strides(from, to, [0, 0, 0])
    }

    /// As [`Dda::new`], each step also giving the change of a linear index whose axes
    /// have these strides.
    #[inline(always)]
    pub fn with_strides(from: [f32; 3], to: [f32; 3], strides: [isize; 3]) -> Self {
        Self {
            x: Axis::new(from[0], to[0], strides[0]),
            y: Axis::new(from[1], to[1], strides[1]),
            z: Axis::new(from[2], to[2], strides[2]),
        }
    }

    /// The voxel the walk is in (the one containing `from` before the first step).
    pub fn start(&self) -> [i32; 3] {
        [self.x.voxel, self.y.voxel, self.z.voxel]
    }

    /// Steps left before the end voxel is reached.
    pub fn remaining(&self) -> u32 {
        self.x.left + self.y.left + self.z.left
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

    #[inline(always)]
    fn next(&mut self) -> Option<Step> {
        // Axes already at the end voxel have t_max = infinity; all three at infinity
        // means the end voxel has been reached.
        let (axis, a) = if self.x.t_max <= self.y.t_max && self.x.t_max <= self.z.t_max {
            (0, &mut self.x)
        } else if self.y.t_max <= self.z.t_max {
            (1, &mut self.y)
        } else {
            (2, &mut self.z)
        };
        if a.t_max == f32::INFINITY {
            return None;
        }
        a.advance();
        let (dir, offset) = (a.step, a.offset);
        Some(Step {
            voxel: [self.x.voxel, self.y.voxel, self.z.voxel],
            axis,
            dir,
            offset,
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
