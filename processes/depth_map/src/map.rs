//! The occupancy window: log-odds per cell, updated by ray casting from depth frames,
//! re-centred on the vehicle, inflated for the planner.
//!
//! Every buffer is allocated in [`OccupancyMap::new`] and never again: integrating a
//! frame, moving the window, inflating and writing the wire form only write into them.

use ipc_types::msg::{CellState, Header, Intrinsics, OccupancyMapHeader};
use nalgebra::{Isometry3, Point3};

use crate::DepthError;
use crate::frame::{DepthPixels, DepthView};
use crate::inflate::{BitGrid, Inflater};
use crate::raycast::Dda;

/// Log-odds are kept as fixed point, this many units per 1.0: exact, deterministic
/// arithmetic in 2 bytes per cell.
const LOG_ODDS_SCALE: f64 = 1000.0;
/// A cell never observed.
const UNKNOWN: i16 = i16::MIN;

/// Per-frame cell flags (all zero between frames).
const TOUCHED: u8 = 1;
const HIT: u8 = 2;
const END: u8 = 4;
const TRAV: u8 = 8;

/// Keeps clipped ray ends this far (cells) inside the window.
const EDGE_EPS: f32 = 1e-3;

/// The log-odds model: what one observation adds, and the bounds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LogOdds {
    /// Added when a ray ends in the cell (EGO-Planner: logit(0.65) = +0.62).
    pub hit: f64,
    /// Added when a ray passes through the cell (logit(0.35) = -0.62).
    pub miss: f64,
    /// Lower clamp, so that a cell seen free for a long time still turns occupied after
    /// a few hits (logit(0.12) = -2.0).
    pub min: f64,
    /// Upper clamp, so that a removed obstacle clears after a few misses
    /// (logit(0.90) = +2.2).
    pub max: f64,
    /// A cell is occupied above this (logit(0.80) = +1.39).
    pub occupied: f64,
}

impl Default for LogOdds {
    fn default() -> Self {
        Self {
            hit: 0.62,
            miss: -0.62,
            min: -2.0,
            max: 2.2,
            occupied: 1.39,
        }
    }
}

/// How depth pixels become rays.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RaySettings {
    /// Frame width the map accepts, px (the ray table is sized for it).
    pub width: u32,
    /// Frame height the map accepts, px.
    pub height: u32,
    /// Cast a ray through every k-th pixel of every k-th row.
    pub pixel_step: u32,
    /// Rays are cut at this length, m: a farther return only frees the ray up to it.
    pub max_ray_m: f64,
    /// Returns nearer than this are ignored, m (stereo artefacts, the airframe).
    pub min_depth_m: f64,
    /// A pixel with no return (0) frees its ray up to `max_ray_m`, as EGO-Planner does.
    /// Off: such pixels are ignored (safer with cameras that return 0 on textureless
    /// surfaces).
    pub no_return_as_free: bool,
    /// A ray cast back from its end stops after walking through this many consecutive
    /// cells that another ray of the frame already walked through. EGO-Planner stops at
    /// the first, which leaves about 30 % of the free cells a frame could see unvisited;
    /// 8 visits 99.4 % or more of them for about 0.4 ms more; 0 never stops (exact,
    /// slower). See `docs/mapping.md`.
    pub shared_run_to_stop: u32,
}

impl Default for RaySettings {
    fn default() -> Self {
        Self {
            width: 640,
            height: 480,
            pixel_step: 2,
            max_ray_m: 5.0,
            min_depth_m: 0.1,
            no_return_as_free: true,
            shared_run_to_stop: 8,
        }
    }
}

/// Geometry and model of the window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapSettings {
    /// Cell edge, m (EGO-Planner: 0.15).
    pub resolution_m: f64,
    /// Window size along x, y, z, m; rounded to whole cells.
    pub size_m: [f64; 3],
    /// The window's bottom never goes below this height, m (so that a vehicle near the
    /// ground does not spend half its window under it); `f64::NEG_INFINITY` for none.
    pub floor_z_m: f64,
    /// The window moves when the vehicle is farther than this from its centre along an
    /// axis, m (moving copies the window, so not on every cell crossed).
    pub recenter_threshold_m: f64,
    /// Inflation radius for the planner, m (EGO-Planner: 0.299).
    pub inflation_m: f64,
    /// The log-odds model.
    pub log_odds: LogOdds,
    /// How depth pixels become rays.
    pub rays: RaySettings,
}

impl Default for MapSettings {
    fn default() -> Self {
        Self {
            resolution_m: 0.15,
            size_m: [10.2, 10.2, 4.8],
            floor_z_m: -0.45,
            recenter_threshold_m: 0.6,
            inflation_m: 0.299,
            log_odds: LogOdds::default(),
            rays: RaySettings::default(),
        }
    }
}

/// The most cells a window may have (3 bytes each plus bits: about 30 MB).
pub const MAX_CELLS: usize = 8 << 20;

impl MapSettings {
    /// Cells along x, y, z.
    pub fn dims(&self) -> [usize; 3] {
        self.size_m
            .map(|s| (s / self.resolution_m).round().max(1.0) as usize)
    }

    /// Checks every value; the error names it.
    pub fn validate(&self) -> Result<(), DepthError> {
        let bad = |m: String| Err(DepthError::Settings(m));
        let r = self.resolution_m;
        if !(r.is_finite() && (0.01..=2.0).contains(&r)) {
            return bad(format!("resolution_m {r} (allowed: 0.01 to 2)"));
        }
        for (i, s) in self.size_m.iter().enumerate() {
            if !(s.is_finite() && *s >= 4.0 * r && *s <= 200.0) {
                return bad(format!(
                    "size_m[{i}] {s} (allowed: 4 cells ({}) to 200 m)",
                    4.0 * r
                ));
            }
        }
        let cells: usize = self.dims().iter().product();
        if cells > MAX_CELLS {
            return bad(format!(
                "size_m / resolution_m gives {cells} cells (allowed: at most {MAX_CELLS})"
            ));
        }
        if self.floor_z_m.is_nan() || self.floor_z_m == f64::INFINITY {
            return bad("floor_z_m must be a number or -inf".into());
        }
        let t = self.recenter_threshold_m;
        let half_min = self.size_m.iter().fold(f64::INFINITY, |a, b| a.min(*b)) / 2.0;
        if !(t.is_finite() && t >= 0.0 && t < half_min) {
            return bad(format!(
                "recenter_threshold_m {t} (allowed: 0 to below half the smallest window size, {half_min})"
            ));
        }
        let inf = self.inflation_m;
        if !(inf.is_finite() && (0.0..=8.0 * r).contains(&inf) && inf <= 2.0) {
            return bad(format!(
                "inflation_m {inf} (allowed: 0 to 8 cells and at most 2 m)"
            ));
        }
        let l = &self.log_odds;
        let all = [l.hit, l.miss, l.min, l.max, l.occupied];
        if !all.iter().all(|v| v.is_finite() && v.abs() <= 30.0) {
            return bad("log-odds values must be finite, within +-30".into());
        }
        if !(l.hit > 0.0 && l.miss < 0.0) {
            return bad("log-odds hit must be > 0 and miss < 0".into());
        }
        if !(l.min < 0.0 && l.min < l.occupied && l.occupied < l.max) {
            return bad("log-odds must satisfy min < 0, min < occupied < max".into());
        }
        let rs = &self.rays;
        if !(16..=4096).contains(&rs.width) || !(16..=4096).contains(&rs.height) {
            return bad(format!(
                "frame size {}x{} (allowed: 16 to 4096 each)",
                rs.width, rs.height
            ));
        }
        if rs.shared_run_to_stop > 64 {
            return bad(format!(
                "shared_run_to_stop {} (allowed: 0 to 64)",
                rs.shared_run_to_stop
            ));
        }
        if !(1..=16).contains(&rs.pixel_step) {
            return bad(format!("pixel_step {} (allowed: 1 to 16)", rs.pixel_step));
        }
        if !(rs.max_ray_m.is_finite() && rs.max_ray_m > r && rs.max_ray_m <= 50.0) {
            return bad(format!(
                "max_ray_m {} (allowed: above one cell, at most 50)",
                rs.max_ray_m
            ));
        }
        if !(rs.min_depth_m.is_finite() && rs.min_depth_m >= 0.0 && rs.min_depth_m < rs.max_ray_m) {
            return bad(format!(
                "min_depth_m {} (allowed: 0 to below max_ray_m)",
                rs.min_depth_m
            ));
        }
        Ok(())
    }
}

/// What one frame did to the map (all counts are per frame).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct IntegrateStats {
    /// Pixels sampled (every `pixel_step`-th).
    pub pixels: u32,
    /// Rays that ended on a surface within `max_ray_m`: one hit.
    pub hits: u32,
    /// Rays with a return beyond `max_ray_m`: free up to it, no hit.
    pub beyond_range: u32,
    /// Pixels with no return (0): freed up to `max_ray_m` or ignored, by setting.
    pub no_return: u32,
    /// Pixels ignored as invalid: NaN, infinite, negative, saturated (`u16::MAX`).
    pub invalid: u32,
    /// Returns nearer than `min_depth_m`, ignored.
    pub too_near: u32,
    /// Rays cut at the window's edge (their end counts as free).
    pub clipped: u32,
    /// Rays not cast because another ray of the frame already ended in the same cell.
    pub shared_ends: u32,
    /// Cells a ray ended in or passed through (each updated once).
    pub cells_touched: u32,
    /// Cells whose log-odds changed (not already at a clamp).
    pub cells_updated: u32,
    /// Cells that became occupied.
    pub became_occupied: u32,
    /// Cells that stopped being occupied.
    pub became_free: u32,
}

/// How many cells are in each state (for logs, tests and figures; scans the window).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Census {
    /// Never observed, not inflated.
    pub unknown: usize,
    /// Observed free, not inflated.
    pub free: usize,
    /// Occupied.
    pub occupied: usize,
    /// Within the inflation radius of an occupied cell, not occupied.
    pub inflated: usize,
}

/// The local occupancy window. See the crate documentation for the model.
#[derive(Debug, Clone)]
pub struct OccupancyMap {
    s: MapSettings,
    dims: [usize; 3],
    strides: [isize; 3],
    /// Cell index (world cells, `floor(p / resolution)`) of the window's minimum corner.
    origin: [i64; 3],
    placed: bool,
    log_odds: Vec<i16>,
    flags: Vec<u8>,
    touched: Vec<u32>,
    occupied: BitGrid,
    inflater: Inflater,
    /// Per sampled pixel: normalized x, y (z = 1) and the ray length per metre of depth.
    rays: Vec<[f32; 3]>,
    rays_for: Option<Intrinsics>,
    q: Fixed,
    capture_ns: u64,
    inflation_current: bool,
}

/// The log-odds model in fixed point.
#[derive(Debug, Clone, Copy)]
struct Fixed {
    hit: i16,
    miss: i16,
    min: i16,
    max: i16,
    occupied: i16,
}

/// A depth pixel, read.
#[derive(Clone, Copy)]
enum Reading {
    Depth(f32),
    NoReturn,
    Invalid,
}

impl OccupancyMap {
    /// Allocates every buffer the map will ever use; the window starts centred on the
    /// world origin (the take-off point) with every cell unknown.
    pub fn new(settings: MapSettings) -> Result<Self, DepthError> {
        settings.validate()?;
        let dims = settings.dims();
        let n: usize = dims.iter().product();
        let fx = |v: f64| (v * LOG_ODDS_SCALE).round() as i16;
        let l = settings.log_odds;
        let rs = settings.rays;
        let k = rs.pixel_step as usize;
        let ray_count = (rs.width as usize).div_ceil(k) * (rs.height as usize).div_ceil(k);
        let mut map = Self {
            s: settings,
            dims,
            strides: [1, dims[0] as isize, (dims[0] * dims[1]) as isize],
            origin: [0; 3],
            placed: false,
            log_odds: vec![UNKNOWN; n],
            flags: vec![0; n],
            touched: Vec::with_capacity(n),
            occupied: BitGrid::new(dims),
            inflater: Inflater::new(dims, settings.inflation_m / settings.resolution_m),
            rays: Vec::with_capacity(ray_count),
            rays_for: None,
            q: Fixed {
                hit: fx(l.hit),
                miss: fx(l.miss),
                min: fx(l.min),
                max: fx(l.max),
                occupied: fx(l.occupied),
            },
            capture_ns: 0,
            inflation_current: true,
        };
        map.origin = map.origin_for([0, 0, 0]);
        Ok(map)
    }

    /// The settings in use.
    pub fn settings(&self) -> &MapSettings {
        &self.s
    }

    /// Cells along x, y, z.
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Cell edge, m.
    pub fn resolution(&self) -> f64 {
        self.s.resolution_m
    }

    /// World position of the window's minimum corner, m.
    pub fn origin(&self) -> Point3<f64> {
        let r = self.s.resolution_m;
        Point3::new(
            self.origin[0] as f64 * r,
            self.origin[1] as f64 * r,
            self.origin[2] as f64 * r,
        )
    }

    /// Capture time of the newest frame integrated (0 before the first).
    pub fn last_capture_ns(&self) -> u64 {
        self.capture_ns
    }

    /// World cell containing `p` (`floor(p / resolution)`), if finite and representable.
    fn world_cell(&self, p: [f64; 3]) -> Option<[i64; 3]> {
        let r = self.s.resolution_m;
        let mut c = [0i64; 3];
        for i in 0..3 {
            let v = (p[i] / r).floor();
            if !(v.is_finite() && v.abs() < 1e15) {
                return None;
            }
            c[i] = v as i64;
        }
        Some(c)
    }

    /// The window origin that centres the window on world cell `c` (respecting the floor).
    fn origin_for(&self, c: [i64; 3]) -> [i64; 3] {
        let mut o = [0i64; 3];
        for i in 0..3 {
            o[i] = c[i] - (self.dims[i] / 2) as i64;
        }
        if self.s.floor_z_m.is_finite() {
            let floor = (self.s.floor_z_m / self.s.resolution_m).floor() as i64;
            o[2] = o[2].max(floor);
        }
        o
    }

    /// Window index of world point `p`, if inside.
    fn index_of(&self, p: &Point3<f64>) -> Option<[usize; 3]> {
        let c = self.world_cell([p.x, p.y, p.z])?;
        let mut ix = [0usize; 3];
        for i in 0..3 {
            let d = c[i] - self.origin[i];
            if d < 0 || d >= self.dims[i] as i64 {
                return None;
            }
            ix[i] = d as usize;
        }
        Some(ix)
    }

    #[inline]
    fn linear(&self, ix: [usize; 3]) -> usize {
        ix[0] + self.dims[0] * (ix[1] + self.dims[1] * ix[2])
    }

    /// Moves the window so that it follows the vehicle: along each axis where
    /// `vehicle` is farther than `recenter_threshold_m` from the window's centre, the
    /// window is re-centred on it (never below the floor). Cells that stay inside keep
    /// what they know; cells that enter are unknown. The first call places the window.
    /// Returns whether the window moved. Allocates nothing.
    pub fn recenter(&mut self, vehicle: &Point3<f64>) -> Result<bool, DepthError> {
        let c = self
            .world_cell([vehicle.x, vehicle.y, vehicle.z])
            .ok_or(DepthError::NonFinitePose)?;
        let want = self.origin_for(c);
        let mut new = self.origin;
        let limit = self.s.recenter_threshold_m / self.s.resolution_m;
        for i in 0..3 {
            let centre = self.origin[i] + (self.dims[i] / 2) as i64;
            if !self.placed || (c[i] - centre).abs() as f64 > limit {
                new[i] = want[i];
            }
        }
        let first = !self.placed;
        self.placed = true;
        if new == self.origin && !first {
            return Ok(false);
        }
        let shift = [
            new[0] - self.origin[0],
            new[1] - self.origin[1],
            new[2] - self.origin[2],
        ];
        self.origin = new;
        self.shift_cells(shift);
        self.rebuild_occupied();
        self.inflate();
        Ok(true)
    }

    /// `new[x, y, z] = old[x + sx, y + sy, z + sz]`, unknown where that is outside.
    fn shift_cells(&mut self, s: [i64; 3]) {
        let d = self.dims.map(|v| v as i64);
        let n = self.log_odds.len();
        if (0..3).any(|i| s[i].abs() >= d[i]) {
            self.log_odds.fill(UNKNOWN);
            return;
        }
        let lin = s[0] + s[1] * d[0] + s[2] * d[0] * d[1];
        let a = lin.unsigned_abs() as usize;
        if lin > 0 {
            self.log_odds.copy_within(a..n, 0);
        } else if lin < 0 {
            self.log_odds.copy_within(0..n - a, a);
        }
        let (nx, ny, nz) = (self.dims[0], self.dims[1], self.dims[2]);
        for z in 0..nz {
            for y in 0..ny {
                let row = nx * (y + ny * z);
                let sy = y as i64 + s[1];
                let sz = z as i64 + s[2];
                let cells = &mut self.log_odds[row..row + nx];
                if !(0..d[1]).contains(&sy) || !(0..d[2]).contains(&sz) {
                    cells.fill(UNKNOWN);
                } else if s[0] > 0 {
                    cells[nx - s[0] as usize..].fill(UNKNOWN);
                } else if s[0] < 0 {
                    cells[..(-s[0]) as usize].fill(UNKNOWN);
                }
            }
        }
    }

    fn rebuild_occupied(&mut self) {
        self.occupied.clear();
        let (nx, ny) = (self.dims[0], self.dims[1]);
        let occ = self.q.occupied;
        for (i, &v) in self.log_odds.iter().enumerate() {
            if v != UNKNOWN && v > occ {
                self.occupied
                    .set(i % nx, (i / nx) % ny, i / (nx * ny), true);
            }
        }
    }

    /// Recomputes the inflated cells from the occupied ones (tens of microseconds; see
    /// `docs/mapping.md`). [`OccupancyMap::integrate`] does not inflate: call this before
    /// publishing or planning. Allocates nothing.
    pub fn inflate(&mut self) {
        self.inflater.run(&self.occupied);
        self.inflation_current = true;
    }

    /// False after a frame was integrated and before [`OccupancyMap::inflate`]: the
    /// inflated cells then lag the occupied ones by that frame.
    pub fn inflation_is_current(&self) -> bool {
        self.inflation_current
    }

    /// Updates the map with one depth frame seen from `world_from_camera` (optical
    /// frame: x right, y down, z forward) at `capture_ns`: one ray per sampled pixel
    /// from the camera, cast back from its end (EGO-Planner's order), each cell updated
    /// at most once per frame (hit wins over miss). The camera must be inside the
    /// window ([`OccupancyMap::recenter`] first). On an error the map is unchanged.
    /// Allocates nothing.
    pub fn integrate(
        &mut self,
        frame: &DepthView<'_>,
        world_from_camera: &Isometry3<f64>,
        capture_ns: u64,
    ) -> Result<IntegrateStats, DepthError> {
        let rs = self.s.rays;
        if frame.width() != rs.width || frame.height() != rs.height {
            return Err(DepthError::FrameSize {
                got_w: frame.width(),
                got_h: frame.height(),
                want_w: rs.width,
                want_h: rs.height,
            });
        }
        let q = world_from_camera.rotation.coords;
        let t = world_from_camera.translation.vector;
        if !(q.iter().chain(t.iter()).all(|v| v.is_finite()) && (q.norm() - 1.0).abs() < 1e-6) {
            return Err(DepthError::NonFinitePose);
        }
        let res = self.s.resolution_m;
        let origin = self.origin();
        let cam = [
            ((t.x - origin.x) / res) as f32,
            ((t.y - origin.y) / res) as f32,
            ((t.z - origin.z) / res) as f32,
        ];
        if !(0..3).all(|i| cam[i] >= EDGE_EPS && cam[i] <= self.dims[i] as f32 - EDGE_EPS) {
            return Err(DepthError::OutsideWindow);
        }
        if self.rays_for != Some(frame.intrinsics()) {
            self.build_rays(frame.intrinsics());
        }
        let m = world_from_camera.rotation.to_rotation_matrix();
        let m = m.matrix();
        let rot = [0, 1, 2].map(|r| [0, 1, 2].map(|c| (m[(r, c)] / res) as f32));
        let mut stats = IntegrateStats::default();
        let min_depth = rs.min_depth_m as f32;
        match frame.pixels() {
            DepthPixels::U16 { data, scale_m } => self.cast_all(
                |i| match data.get(i).copied() {
                    Some(0) => Reading::NoReturn,
                    Some(u16::MAX) | None => Reading::Invalid,
                    Some(v) => Reading::Depth(f32::from(v) * scale_m),
                },
                cam,
                &rot,
                min_depth,
                &mut stats,
            ),
            DepthPixels::F32(data) => self.cast_all(
                |i| match data.get(i).copied() {
                    Some(0.0) => Reading::NoReturn,
                    Some(v) if v.is_finite() && v > 0.0 => Reading::Depth(v),
                    _ => Reading::Invalid,
                },
                cam,
                &rot,
                min_depth,
                &mut stats,
            ),
        }
        self.apply(&mut stats);
        self.capture_ns = capture_ns;
        if stats.became_occupied + stats.became_free > 0 {
            self.inflation_current = false;
        }
        Ok(stats)
    }

    fn build_rays(&mut self, k: Intrinsics) {
        let rs = self.s.rays;
        let step = rs.pixel_step as usize;
        self.rays.clear();
        for v in (0..rs.height as usize).step_by(step) {
            for u in (0..rs.width as usize).step_by(step) {
                let x = ((u as f64 - k.cx) / k.fx) as f32;
                let y = ((v as f64 - k.cy) / k.fy) as f32;
                // Never past the capacity reserved in new(): same loop bounds.
                if self.rays.len() < self.rays.capacity() {
                    self.rays.push([x, y, (x * x + y * y + 1.0).sqrt()]);
                }
            }
        }
        self.rays_for = Some(k);
    }

    #[inline(always)]
    fn cast_all(
        &mut self,
        read: impl Fn(usize) -> Reading,
        cam: [f32; 3],
        rot: &[[f32; 3]; 3],
        min_depth: f32,
        stats: &mut IntegrateStats,
    ) {
        let rs = self.s.rays;
        let (w, h, step) = (
            rs.width as usize,
            rs.height as usize,
            rs.pixel_step as usize,
        );
        let max_ray = rs.max_ray_m as f32;
        let free_no_return = rs.no_return_as_free;
        let hi = self.dims.map(|d| d as f32 - EDGE_EPS);
        let mut ri = 0;
        // Neighbouring pixels mostly end in the same cell: the last ray's end cell and
        // whether it was a hit, checked before touching the flags.
        let mut last_end = usize::MAX;
        let mut last_hit = false;
        for v in (0..h).step_by(step) {
            for u in (0..w).step_by(step) {
                let Some(&[x, y, len]) = self.rays.get(ri) else {
                    return;
                };
                ri += 1;
                stats.pixels += 1;
                // Depth along the optical axis to the ray's end, and whether it is a hit.
                let (depth, hit) = match read(v * w + u) {
                    Reading::Depth(d) if d < min_depth => {
                        stats.too_near += 1;
                        continue;
                    }
                    Reading::Depth(d) if d * len <= max_ray => {
                        stats.hits += 1;
                        (d, true)
                    }
                    Reading::Depth(_) => {
                        stats.beyond_range += 1;
                        (max_ray / len, false)
                    }
                    Reading::NoReturn => {
                        stats.no_return += 1;
                        if !free_no_return {
                            continue;
                        }
                        (max_ray / len, false)
                    }
                    Reading::Invalid => {
                        stats.invalid += 1;
                        continue;
                    }
                };
                let dir = [
                    (rot[0][0] * x + rot[0][1] * y + rot[0][2]) * depth,
                    (rot[1][0] * x + rot[1][1] * y + rot[1][2]) * depth,
                    (rot[2][0] * x + rot[2][1] * y + rot[2][2]) * depth,
                ];
                let mut end = [cam[0] + dir[0], cam[1] + dir[1], cam[2] + dir[2]];
                let mut hit = hit;
                if !(0..3).all(|i| end[i] >= EDGE_EPS && end[i] <= hi[i]) {
                    // Liang-Barsky against the window (the camera is inside): the
                    // ray's end becomes the point where it leaves, free.
                    let mut s = 1.0f32;
                    for i in 0..3 {
                        if end[i] > hi[i] {
                            s = s.min((hi[i] - cam[i]) / dir[i]);
                        } else if end[i] < EDGE_EPS {
                            s = s.min((EDGE_EPS - cam[i]) / dir[i]);
                        }
                    }
                    let s = s.clamp(0.0, 1.0);
                    end = [0, 1, 2].map(|i| (cam[i] + dir[i] * s).clamp(EDGE_EPS, hi[i]));
                    hit = false;
                    stats.clipped += 1;
                }
                // `end` is inside the window (clipped), so truncation is floor.
                let e = end.map(|v| v as usize);
                let idx = e[0] + self.dims[0] * (e[1] + self.dims[1] * e[2]);
                if idx == last_end && (last_hit || !hit) {
                    stats.shared_ends += 1;
                    continue;
                }
                last_end = idx;
                last_hit = hit;
                self.mark_ray(cam, end, e, hit, stats);
            }
        }
    }

    /// Marks the end cell (hit or miss) and walks back to the camera, marking misses,
    /// until it meets a cell another ray of this frame already walked through.
    #[inline(always)]
    fn mark_ray(
        &mut self,
        cam: [f32; 3],
        end: [f32; 3],
        e: [usize; 3],
        hit: bool,
        stats: &mut IntegrateStats,
    ) {
        if !(0..3).all(|i| e[i] < self.dims[i]) {
            return;
        }
        let mut idx = self.linear(e);
        let Some(f) = self.flags.get_mut(idx) else {
            return;
        };
        let old = *f;
        if old & END != 0 {
            if hit {
                *f |= HIT;
            }
            stats.shared_ends += 1;
            return;
        }
        *f = old | END | TOUCHED | if hit { HIT } else { 0 };
        if old & TOUCHED == 0 {
            self.touched.push(idx as u32);
        }
        let dda = Dda::with_strides(end, cam, self.strides);
        let stop = self.s.rays.shared_run_to_stop;
        let mut run = 0;
        for step in dda {
            idx = idx.wrapping_add_signed(step.offset);
            let Some(f) = self.flags.get_mut(idx) else {
                break;
            };
            let old = *f;
            if old & TRAV != 0 {
                run += 1;
                if run == stop {
                    break;
                }
                continue;
            }
            run = 0;
            *f = old | TRAV | TOUCHED;
            if old & TOUCHED == 0 {
                self.touched.push(idx as u32);
            }
        }
    }

    /// Applies the frame's marks to the log-odds and clears them.
    fn apply(&mut self, stats: &mut IntegrateStats) {
        let q = self.q;
        stats.cells_touched = self.touched.len() as u32;
        let (nx, ny) = (self.dims[0], self.dims[1]);
        for &i in &self.touched {
            let i = i as usize;
            let (Some(f), Some(lo)) = (self.flags.get_mut(i), self.log_odds.get_mut(i)) else {
                continue;
            };
            let was = *lo;
            let base = if was == UNKNOWN { 0 } else { was };
            let now = if *f & HIT != 0 {
                base.saturating_add(q.hit).min(q.max)
            } else {
                base.saturating_add(q.miss).max(q.min)
            };
            *f = 0;
            *lo = now;
            if now != was {
                stats.cells_updated += 1;
            }
            let was_occ = was != UNKNOWN && was > q.occupied;
            let now_occ = now > q.occupied;
            if was_occ != now_occ {
                self.occupied
                    .set(i % nx, (i / nx) % ny, i / (nx * ny), now_occ);
                if now_occ {
                    stats.became_occupied += 1;
                } else {
                    stats.became_free += 1;
                }
            }
        }
        self.touched.clear();
    }

    /// State of window cell `ix` (x, y, z indices); `Unknown` outside the window.
    pub fn state_at_index(&self, ix: [usize; 3]) -> CellState {
        if (0..3).any(|i| ix[i] >= self.dims[i]) {
            return CellState::Unknown;
        }
        let (x, y, z) = (ix[0], ix[1], ix[2]);
        if self.occupied.get(x, y, z) {
            CellState::Occupied
        } else if self.inflater.inflated.get(x, y, z) {
            CellState::Inflated
        } else if self
            .log_odds
            .get(self.linear(ix))
            .is_none_or(|&v| v == UNKNOWN)
        {
            CellState::Unknown
        } else {
            CellState::Free
        }
    }

    /// State of the cell containing world point `p`. Outside the window, or for a
    /// non-finite point: `Unknown`, never free and never occupied. Inflation is as of
    /// the last [`OccupancyMap::inflate`].
    pub fn state_at(&self, p: &Point3<f64>) -> CellState {
        match self.index_of(p) {
            Some(ix) => self.state_at_index(ix),
            None => CellState::Unknown,
        }
    }

    /// True when `p` was observed free and is clear of every inflated obstacle: where
    /// the planner may put the vehicle's centre. Unknown space is not free.
    pub fn is_free_inflated(&self, p: &Point3<f64>) -> bool {
        self.state_at(p) == CellState::Free
    }

    /// Log-odds of the cell containing `p`; `None` outside the window or never observed.
    pub fn log_odds_at(&self, p: &Point3<f64>) -> Option<f64> {
        let ix = self.index_of(p)?;
        let v = *self.log_odds.get(self.linear(ix))?;
        (v != UNKNOWN).then(|| f64::from(v) / LOG_ODDS_SCALE)
    }

    /// World centre of window cell `ix`.
    pub fn cell_centre(&self, ix: [usize; 3]) -> Point3<f64> {
        let r = self.s.resolution_m;
        let o = self.origin();
        Point3::new(
            o.x + (ix[0] as f64 + 0.5) * r,
            o.y + (ix[1] as f64 + 0.5) * r,
            o.z + (ix[2] as f64 + 0.5) * r,
        )
    }

    /// Cells of the window (the wire payload's length).
    pub fn cell_count(&self) -> usize {
        self.log_odds.len()
    }

    /// Writes every cell as a [`CellState`] byte, x fastest, then y, then z, straight
    /// into `out` (a loaned shared-memory slice), and returns the header describing it
    /// (`msg` carries only the capture time; the caller adds sequence and stages).
    /// Occupied wins over inflated, inflated over free and unknown.
    pub fn write_wire(&self, out: &mut [u8]) -> Result<OccupancyMapHeader, DepthError> {
        if out.len() != self.cell_count() {
            return Err(DepthError::WireSize {
                got: out.len(),
                want: self.cell_count(),
            });
        }
        // Known or not for every cell (a compare the compiler vectorizes), then the
        // inflated and occupied cells, visited bit by bit (a few thousand).
        for (o, &lo) in out.iter_mut().zip(&self.log_odds) {
            *o = if lo == UNKNOWN {
                CellState::Unknown as u8
            } else {
                CellState::Free as u8
            };
        }
        let (nx, ny) = (self.dims[0], self.dims[1]);
        let put = |state: CellState| {
            move |out: &mut [u8], x: usize, y: usize, z: usize| {
                if let Some(o) = out.get_mut(x + nx * (y + ny * z)) {
                    *o = state as u8;
                }
            }
        };
        let inflated = put(CellState::Inflated);
        self.inflater
            .for_each_inflated(|x, y, z| inflated(out, x, y, z));
        let occupied = put(CellState::Occupied);
        self.occupied
            .for_each_set(&mut |x, y, z| occupied(out, x, y, z));
        Ok(self.wire_header())
    }

    /// The header [`OccupancyMap::write_wire`] returns.
    pub fn wire_header(&self) -> OccupancyMapHeader {
        let o = self.origin();
        OccupancyMapHeader {
            msg: Header::captured_at(self.capture_ns),
            origin: [o.x, o.y, o.z],
            resolution: self.s.resolution_m,
            inflation: self.s.inflation_m,
            dims: self.dims.map(|d| d as u32),
            reserved: 0,
            state_ns: 0,
        }
    }

    /// Counts the cells in each state.
    pub fn census(&self) -> Census {
        let mut c = Census::default();
        for z in 0..self.dims[2] {
            for y in 0..self.dims[1] {
                for x in 0..self.dims[0] {
                    match self.state_at_index([x, y, z]) {
                        CellState::Unknown => c.unknown += 1,
                        CellState::Free => c.free += 1,
                        CellState::Occupied => c.occupied += 1,
                        CellState::Inflated => c.inflated += 1,
                    }
                }
            }
        }
        c
    }

    /// Cells in the inflation kernel (81 with the paper's 0.15 m and 0.299 m).
    pub fn inflation_kernel_cells(&self) -> usize {
        self.inflater.kernel_cells()
    }

    /// Bytes held by the map's buffers (fixed for its lifetime).
    pub fn memory_bytes(&self) -> usize {
        self.log_odds.capacity() * 2
            + self.flags.capacity()
            + self.touched.capacity() * 4
            + self.rays.capacity() * 12
            + self.occupied_bytes()
            + self.inflater.bytes()
    }

    fn occupied_bytes(&self) -> usize {
        self.occupied.storage().1 * 8
    }

    /// Address and capacity of every buffer: equal before and after any amount of use
    /// shows that nothing was reallocated.
    pub fn storage(&self) -> Vec<(usize, usize)> {
        let mut v = vec![
            (self.log_odds.as_ptr() as usize, self.log_odds.capacity()),
            (self.flags.as_ptr() as usize, self.flags.capacity()),
            (self.touched.as_ptr() as usize, self.touched.capacity()),
            (self.rays.as_ptr() as usize, self.rays.capacity()),
            self.occupied.storage(),
        ];
        self.inflater.storage(&mut v);
        v
    }
}

#[cfg(test)]
#[path = "map_test.rs"]
mod tests;
