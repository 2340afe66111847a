//! What the planner asks of a map, and two maps that answer it.
//!
//! The planner never depends on the depth-mapping crate: it reads any
//! [`OccupancyQuery`]. [`GridMap`] is a dense inflated voxel grid built from boxes (tests,
//! benchmarks, `landing plan`); [`CellView`] reads the depth-map's wire format
//! (`OccupancyMapHeader` + one `CellState` byte per cell) in place.

use ipc_types::msg::{CellState, OccupancyMapHeader};
use nalgebra::Vector3;

/// The occupancy a planner needs: an inflated map on a regular lattice.
///
/// `is_occupied` answers for the *inflated* map (obstacles grown by the drone's radius
/// plus margin), so a point reported free is a point the drone's centre may occupy.
/// Points outside `bounds` read as free (EGO-Planner treats unknown space as free); the
/// planner separately refuses trajectories that leave the bounds.
pub trait OccupancyQuery {
    /// Edge of one cell, m; the A* lattice uses it.
    fn resolution(&self) -> f64;
    /// True when `p` lies in an occupied or inflated cell.
    fn is_occupied(&self, p: &Vector3<f64>) -> bool;
    /// Minimum and maximum corners of the mapped volume, m.
    fn bounds(&self) -> (Vector3<f64>, Vector3<f64>);
}

/// An axis-aligned box obstacle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    /// Minimum corner, m.
    pub min: Vector3<f64>,
    /// Maximum corner, m.
    pub max: Vector3<f64>,
}

impl Aabb {
    /// Euclidean distance from `p` to the box (0 inside); used by independent checks.
    pub fn distance(&self, p: &Vector3<f64>) -> f64 {
        let mut d2 = 0.0;
        for i in 0..3 {
            let e = (self.min[i] - p[i]).max(p[i] - self.max[i]).max(0.0);
            d2 += e * e;
        }
        d2.sqrt()
    }
}

/// Why a grid could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MapError {
    /// Resolution, inflation or bounds are not finite and positive.
    #[error("map: {0}")]
    Invalid(&'static str),
    /// The grid would exceed the cell budget.
    #[error("map: {cells} cells exceed the limit of {limit}")]
    TooLarge {
        /// Cells requested.
        cells: usize,
        /// The limit.
        limit: usize,
    },
}

/// The most cells a [`GridMap`] may hold (64 M: 64 MB), so a typo cannot eat the memory.
pub const MAX_CELLS: usize = 64 << 20;

/// A dense inflated voxel grid: one byte per cell (0 free, 1 inflated, 2 occupied).
#[derive(Debug, Clone)]
pub struct GridMap {
    origin: Vector3<f64>,
    resolution: f64,
    inv_resolution: f64,
    inflation: f64,
    dims: [usize; 3],
    cells: Vec<u8>,
    boxes: Vec<Aabb>,
}

impl GridMap {
    /// An empty grid covering `min..max` with cells of `resolution` m; boxes added later are
    /// grown by `inflation` m (rounded up to whole cells, per axis, as EGO-Planner does).
    pub fn new(
        min: Vector3<f64>,
        max: Vector3<f64>,
        resolution: f64,
        inflation: f64,
    ) -> Result<Self, MapError> {
        if !(resolution.is_finite() && resolution > 1e-3) {
            return Err(MapError::Invalid("resolution must be finite and > 1 mm"));
        }
        if !(inflation.is_finite() && inflation >= 0.0) {
            return Err(MapError::Invalid("inflation must be finite and >= 0"));
        }
        if !(min.iter().chain(max.iter()).all(|v| v.is_finite())) {
            return Err(MapError::Invalid("bounds must be finite"));
        }
        let mut dims = [0usize; 3];
        for i in 0..3 {
            let n = ((max[i] - min[i]) / resolution).ceil();
            if !(n >= 1.0) {
                return Err(MapError::Invalid(
                    "bounds: max must exceed min on every axis",
                ));
            }
            dims[i] = n.min(1e9) as usize;
        }
        let cells = dims[0].saturating_mul(dims[1]).saturating_mul(dims[2]);
        if cells > MAX_CELLS {
            return Err(MapError::TooLarge {
                cells,
                limit: MAX_CELLS,
            });
        }
        Ok(Self {
            origin: min,
            resolution,
            inv_resolution: 1.0 / resolution,
            inflation,
            dims,
            cells: vec![0; cells],
            boxes: Vec::new(),
        })
    }

    /// A grid with `boxes` already added.
    pub fn from_boxes(
        min: Vector3<f64>,
        max: Vector3<f64>,
        resolution: f64,
        inflation: f64,
        boxes: &[Aabb],
    ) -> Result<Self, MapError> {
        let mut m = Self::new(min, max, resolution, inflation)?;
        for b in boxes {
            m.add_box(b);
        }
        Ok(m)
    }

    /// Marks the cells a box overlaps as occupied and those within the inflation as
    /// inflated. A non-finite box is ignored.
    pub fn add_box(&mut self, b: &Aabb) {
        if !(b.min.iter().chain(b.max.iter()).all(|v| v.is_finite())) {
            return;
        }
        self.boxes.push(*b);
        let k = (self.inflation / self.resolution - 1e-9).ceil().max(0.0) as i64;
        let mut lo = [0i64; 3];
        let mut hi = [0i64; 3];
        for i in 0..3 {
            lo[i] = ((b.min[i] - self.origin[i]) / self.resolution).floor() as i64;
            hi[i] = ((b.max[i] - self.origin[i]) / self.resolution).ceil() as i64 - 1;
            hi[i] = hi[i].max(lo[i]);
        }
        self.mark(lo, hi, k, 1);
        self.mark(lo, hi, 0, 2);
    }

    fn mark(&mut self, lo: [i64; 3], hi: [i64; 3], grow: i64, value: u8) {
        let d = self.dims.map(|v| v as i64);
        let r = |i: usize| ((lo[i] - grow).max(0), (hi[i] + grow).min(d[i] - 1));
        let (x0, x1) = r(0);
        let (y0, y1) = r(1);
        let (z0, z1) = r(2);
        for z in z0..=z1 {
            for y in y0..=y1 {
                for x in x0..=x1 {
                    let idx = ((z * d[1] + y) * d[0] + x) as usize;
                    if self.cells[idx] < value {
                        self.cells[idx] = value;
                    }
                }
            }
        }
    }

    /// The boxes added, for independent checks.
    pub fn boxes(&self) -> &[Aabb] {
        &self.boxes
    }

    /// Inflation radius applied, m.
    pub fn inflation(&self) -> f64 {
        self.inflation
    }

    /// Cells along x, y, z.
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    #[inline]
    fn index(&self, p: &Vector3<f64>) -> Option<usize> {
        cell_index(&self.origin, self.inv_resolution, self.dims, p)
    }
}

/// Linear index (x fastest) of the cell holding `p`, or `None` outside or for NaN;
/// `inv_resolution` is 1 / the cell edge (a multiplication, not three divisions).
#[inline]
fn cell_index(
    origin: &Vector3<f64>,
    inv_resolution: f64,
    dims: [usize; 3],
    p: &Vector3<f64>,
) -> Option<usize> {
    let mut ix = [0usize; 3];
    for i in 0..3 {
        // Truncation is the floor for f >= 0 and, unlike `floor`, is inlined on the
        // baseline x86-64 target; `!(f >= 0)` also rejects NaN. A dimension fits in u32
        // (MAX_CELLS), and f64 -> u32 is one instruction where f64 -> usize is a branchy
        // sequence.
        let f = (p[i] - origin[i]) * inv_resolution;
        if !(f >= 0.0) || f >= dims[i] as f64 {
            return None;
        }
        ix[i] = (f as u32 as usize).min(dims[i] - 1);
    }
    Some((ix[2] * dims[1] + ix[1]) * dims[0] + ix[0])
}

impl OccupancyQuery for GridMap {
    fn resolution(&self) -> f64 {
        self.resolution
    }

    #[inline]
    fn is_occupied(&self, p: &Vector3<f64>) -> bool {
        self.index(p).is_some_and(|i| self.cells[i] != 0)
    }

    fn bounds(&self) -> (Vector3<f64>, Vector3<f64>) {
        let ext = Vector3::new(
            self.dims[0] as f64,
            self.dims[1] as f64,
            self.dims[2] as f64,
        ) * self.resolution;
        (self.origin, self.origin + ext)
    }
}

/// The depth-map's occupancy window read in place: the received header and cell bytes.
///
/// `Occupied` and `Inflated` cells are occupied; `Free` and `Unknown` cells are free for
/// planning (EGO-Planner's choice: the depth camera sees ahead, and a planner that
/// refuses unknown space cannot leave a half-mapped start). Outside the window is free
/// too, as every [`OccupancyQuery`]; the planner keeps its trajectories inside it.
#[derive(Debug, Clone, Copy)]
pub struct CellView<'a> {
    origin: Vector3<f64>,
    resolution: f64,
    inv_resolution: f64,
    dims: [usize; 3],
    cells: &'a [u8],
}

impl<'a> CellView<'a> {
    /// A view of `cells` laid out as `header` says; `None` when the header is not finite,
    /// has no cells, or promises more cells than the payload holds.
    pub fn new(header: &OccupancyMapHeader, cells: &'a [u8]) -> Option<Self> {
        let origin = Vector3::from(header.origin);
        let finite = origin.iter().all(|v| v.is_finite()) && header.resolution.is_finite();
        if !(finite && header.resolution > 1e-3) {
            return None;
        }
        let dims = header.dims.map(|d| d as usize);
        let n = dims[0].checked_mul(dims[1])?.checked_mul(dims[2])?;
        if n == 0 || cells.len() < n {
            return None;
        }
        Some(Self {
            origin,
            resolution: header.resolution,
            inv_resolution: 1.0 / header.resolution,
            dims,
            cells: &cells[..n],
        })
    }
}

impl OccupancyQuery for CellView<'_> {
    fn resolution(&self) -> f64 {
        self.resolution
    }

    fn is_occupied(&self, p: &Vector3<f64>) -> bool {
        cell_index(&self.origin, self.inv_resolution, self.dims, p).is_some_and(|i| {
            matches!(
                CellState::from_raw(self.cells[i]),
                CellState::Occupied | CellState::Inflated
            )
        })
    }

    fn bounds(&self) -> (Vector3<f64>, Vector3<f64>) {
        let ext = Vector3::new(
            self.dims[0] as f64,
            self.dims[1] as f64,
            self.dims[2] as f64,
        ) * self.resolution;
        (self.origin, self.origin + ext)
    }
}

#[cfg(test)]
#[path = "map_test.rs"]
mod tests;
