//! A forward-looking depth camera like the Intel RealSense D435: 640x480,
//! about 87 x 58 deg field of view, 0.2 - 10 m valid range, depth (along the
//! optical axis) in u16 millimetres, 0 where there is no valid measurement,
//! and noise growing with the square of the range as stereo noise does.
//!
//! Rays are cast against the ground plane z = 0 analytically and against the
//! boxes (obstacles, the ground vehicle's body) by the slab test (parry's
//! `Cuboid::cast_local_ray`, operation for operation, in a loop the compiler
//! vectorizes: one parry call per pixel was a tenth of a mission's time); a box
//! is only tested for the pixels inside its projected screen rectangle, so a
//! box costs in proportion to its size on screen.

use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use serde::Deserialize;

/// Metres per unit of a depth frame's pixels (u16 millimetres), for readers of the frames.
pub const DEPTH_SCALE_M: f64 = 0.001;

use crate::geometry::Obb;
use crate::noise::{MAX_SLICE, PixelNoise};
use crate::params::{self, ParamError};

/// Configuration of the forward depth camera (the `[camera_depth]` section).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DepthCameraParams {
    /// Image width, px.
    pub width: u32,
    /// Image height, px.
    pub height: u32,
    /// Horizontal field of view, deg.
    pub hfov_deg: f64,
    /// Vertical field of view, deg (pixels need not be square).
    pub vfov_deg: f64,
    /// Nearest valid depth, m (closer reads 0).
    pub min_depth_m: f64,
    /// Farthest valid depth, m (farther reads 0).
    pub max_depth_m: f64,
    /// Depth noise sigma = k * z^2; k in 1/m (D435: about 0.002 - 0.004).
    pub noise_k_per_m: f64,
    /// Position of the optical centre in the body frame (FLU), m. The camera
    /// looks forward: optical z = body x, optical x = -body y, optical y = -body z.
    pub position_in_body_m: [f64; 3],
    /// Time from capture to publish, s (metadata the caller applies).
    pub latency_s: f64,
    /// Seed of the noise.
    pub seed: u64,
}

impl Default for DepthCameraParams {
    fn default() -> Self {
        Self {
            width: 640,
            height: 480,
            hfov_deg: 87.0,
            vfov_deg: 58.0,
            min_depth_m: 0.2,
            max_depth_m: 10.0,
            noise_k_per_m: 0.003,
            position_in_body_m: [0.1, 0.0, 0.1],
            latency_s: 0.033,
            seed: 2,
        }
    }
}

impl DepthCameraParams {
    /// Checks every field; the error names the field.
    pub fn validate(&self) -> Result<(), ParamError> {
        for (name, v) in [("width", self.width), ("height", self.height)] {
            if !(16..=4096).contains(&v) {
                return Err(ParamError::new(name, v, "must be in [16, 4096]"));
            }
        }
        params::in_range("hfov_deg", self.hfov_deg, 10.0, 170.0)?;
        params::in_range("vfov_deg", self.vfov_deg, 10.0, 170.0)?;
        params::in_range("min_depth_m", self.min_depth_m, 0.0, 100.0)?;
        if !(self.max_depth_m.is_finite()
            && self.max_depth_m > self.min_depth_m
            && self.max_depth_m <= 65.0)
        {
            return Err(ParamError::new(
                "max_depth_m",
                self.max_depth_m,
                format!(
                    "must be > min_depth_m ({}) and <= 65 (u16 mm)",
                    self.min_depth_m
                ),
            ));
        }
        params::in_range("noise_k_per_m", self.noise_k_per_m, 0.0, 0.1)?;
        for (i, v) in self.position_in_body_m.iter().enumerate() {
            params::in_range(&format!("position_in_body_m[{i}]"), *v, -2.0, 2.0)?;
        }
        params::in_range("latency_s", self.latency_s, 0.0, 1.0)?;
        Ok(())
    }

    /// Focal lengths (fx, fy), px, from the fields of view.
    pub fn focal_px(&self) -> (f64, f64) {
        (
            f64::from(self.width) / 2.0 / (self.hfov_deg.to_radians() / 2.0).tan(),
            f64::from(self.height) / 2.0 / (self.vfov_deg.to_radians() / 2.0).tan(),
        )
    }

    /// Principal point (cx, cy), px: the image centre (OpenCV pixel-centre convention).
    pub fn principal_point_px(&self) -> (f64, f64) {
        (
            (f64::from(self.width) - 1.0) / 2.0,
            (f64::from(self.height) - 1.0) / 2.0,
        )
    }

    /// The mount: maps body-frame points into the optical frame.
    pub fn camera_from_body(&self) -> Isometry3<f64> {
        let r = nalgebra::Rotation3::from_matrix_unchecked(nalgebra::Matrix3::new(
            0.0, 0.0, 1.0, //
            -1.0, 0.0, 0.0, //
            0.0, -1.0, 0.0,
        ));
        let p = self.position_in_body_m;
        Isometry3::from_parts(
            Translation3::new(p[0], p[1], p[2]),
            UnitQuaternion::from_rotation_matrix(&r),
        )
        .inverse()
    }
}

/// One depth image.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthFrame {
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
    /// Row-major depth along the optical axis, mm; 0 = no valid measurement.
    pub depth_mm: Vec<u16>,
    /// Capture-to-publish latency the caller should apply, s.
    pub latency_s: f64,
}

impl DepthFrame {
    /// Depth of pixel (u, v) in metres, `None` where invalid or outside.
    pub fn depth_m(&self, u: u32, v: u32) -> Option<f64> {
        if u >= self.width || v >= self.height {
            return None;
        }
        let d = *self.depth_mm.get((v * self.width + u) as usize)?;
        (d > 0).then(|| f64::from(d) / 1000.0)
    }
}

/// The depth camera renderer.
#[derive(Debug, Clone)]
pub struct DepthCamera {
    params: DepthCameraParams,
    camera_from_body: Isometry3<f64>,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    rays: Vec<[f32; 2]>,
    depth: Vec<f32>,
    noise: PixelNoise,
}

impl DepthCamera {
    /// Precomputes the per-pixel rays (an ideal pinhole: depth cameras are
    /// rectified before they output depth).
    pub fn new(params: DepthCameraParams) -> Result<Self, ParamError> {
        params.validate()?;
        let (fx, fy) = params.focal_px();
        let (cx, cy) = params.principal_point_px();
        let (w, h) = (params.width as usize, params.height as usize);
        let mut rays = Vec::with_capacity(w * h);
        for v in 0..h {
            for u in 0..w {
                rays.push([((u as f64 - cx) / fx) as f32, ((v as f64 - cy) / fy) as f32]);
            }
        }
        Ok(Self {
            camera_from_body: params.camera_from_body(),
            noise: PixelNoise::new(params.seed),
            depth: vec![0.0; w * h],
            rays,
            fx,
            fy,
            cx,
            cy,
            params,
        })
    }

    /// The configuration in use.
    pub fn params(&self) -> &DepthCameraParams {
        &self.params
    }

    /// The camera mount (body to optical frame).
    pub fn camera_from_body(&self) -> Isometry3<f64> {
        self.camera_from_body
    }

    /// Renders from a mount off the drawing by `error` (the true optical frame into the
    /// nominal one, as [`crate::camera::MountErrors::draw`] gives it): the pipeline reads
    /// the drawing.
    pub fn set_mount_error(&mut self, error: Isometry3<f64>) {
        self.camera_from_body = error.inverse() * self.params.camera_from_body();
    }

    /// Renders the depth image seen from `world_from_body` with these boxes.
    pub fn render(&mut self, world_from_body: &Isometry3<f64>, obstacles: &[Obb]) -> DepthFrame {
        let mut out = vec![0u16; self.frame_len()];
        self.render_into(world_from_body, obstacles, &mut out);
        DepthFrame {
            width: self.params.width,
            height: self.params.height,
            depth_mm: out,
            latency_s: self.params.latency_s,
        }
    }

    /// Pixels of one frame.
    pub fn frame_len(&self) -> usize {
        self.depth.len()
    }

    /// Renders straight into `out` (a loaned shared-memory sample in the `sim` process);
    /// pixels beyond `out` are not written, missing ones stay as they were.
    pub fn render_into(
        &mut self,
        world_from_body: &Isometry3<f64>,
        obstacles: &[Obb],
        out: &mut [u16],
    ) {
        let world_from_camera = world_from_body * self.camera_from_body.inverse();
        let rot = world_from_camera.rotation.to_rotation_matrix();
        let m = rot.matrix();
        let r: [[f32; 3]; 3] = [
            [m[(0, 0)] as f32, m[(0, 1)] as f32, m[(0, 2)] as f32],
            [m[(1, 0)] as f32, m[(1, 1)] as f32, m[(1, 2)] as f32],
            [m[(2, 0)] as f32, m[(2, 1)] as f32, m[(2, 2)] as f32],
        ];
        let o = world_from_camera.translation.vector;
        let oz = o.z as f32;
        // Ground: depth t along (rx, ry, 1) where the ray meets z = 0.
        for (d, &[rx, ry]) in self.depth.iter_mut().zip(&self.rays) {
            let dz = r[2][0] * rx + r[2][1] * ry + r[2][2];
            let t = -oz / dz;
            *d = if t > 0.0 { t } else { f32::INFINITY };
        }
        let w = self.params.width as usize;
        let far = self.params.max_depth_m as f32 * 1.5;
        for b in obstacles {
            let Some((u0, u1, v0, v1)) = self.screen_rect(&world_from_camera, b) else {
                continue;
            };
            let half = [b.half_m[0] as f32, b.half_m[1] as f32, b.half_m[2] as f32];
            // The ray in the box's frame: origin and the rotation of the directions.
            let local = b.world_from_box.inverse_transform_point(&o.into());
            let origin = [local.x as f32, local.y as f32, local.z as f32];
            let box_from_world = b.world_from_box.rotation.inverse().to_rotation_matrix();
            let bm = box_from_world.matrix() * rot.matrix();
            let rb: [[f32; 3]; 3] =
                std::array::from_fn(|i| std::array::from_fn(|j| bm[(i, j)] as f32));
            let slab = Slab {
                half,
                origin,
                rb,
                far,
            };
            for v in v0..=v1 {
                let row = v * w + u0..v * w + u1 + 1;
                if let (Some(rays), Some(depth)) =
                    (self.rays.get(row.clone()), self.depth.get_mut(row))
                {
                    slab.cast_row(rays, depth);
                }
            }
        }
        let (lo, hi) = (
            self.params.min_depth_m as f32,
            self.params.max_depth_m as f32,
        );
        let k = self.params.noise_k_per_m as f32;
        // (z + noise) mm rounded half up, 1 to 65535, or 0 out of range: `floor` and
        // the integer taken by the 1.5 * 2^23 trick (exact below 2^22), so the
        // loop vectorizes where a float to int cast kept it scalar.
        let to_mm = |z: f32, n: f32| {
            const ROUND: f32 = 12_582_912.0;
            #[allow(
                clippy::manual_clamp,
                reason = "max/min: NaN, never in range, reads 1 mm instead of passing through"
            )]
            let y = ((z + k * z * z * n) * 1000.0 + 0.5).max(1.0).min(65535.0);
            let r = (y + ROUND) - ROUND;
            let floor = if r > y { r - 1.0 } else { r };
            let mm = ((floor + ROUND).to_bits() & 0xffff) as u16;
            if (z >= lo) & (z <= hi) { mm } else { 0 }
        };
        self.noise.new_frame();
        for (o, d) in out.chunks_mut(MAX_SLICE).zip(self.depth.chunks(MAX_SLICE)) {
            let noise = self.noise.slice(d.len());
            // Indexed over slices cut to one length: the three-way zip stayed scalar.
            let n = o.len().min(d.len()).min(noise.len());
            let (o, d, noise) = (&mut o[..n], &d[..n], &noise[..n]);
            for i in 0..n {
                o[i] = to_mm(d[i], noise[i]);
            }
        }
    }

    /// Inclusive pixel rectangle (u0, u1, v0, v1) that contains the box's
    /// projection; the whole image if the box reaches behind the camera's near
    /// plane, `None` if it is entirely behind or off screen.
    fn screen_rect(
        &self,
        world_from_camera: &Isometry3<f64>,
        b: &Obb,
    ) -> Option<(usize, usize, usize, usize)> {
        let (w, h) = (f64::from(self.params.width), f64::from(self.params.height));
        let near = 1e-3;
        let mut behind = 0;
        let (mut umin, mut umax, mut vmin, mut vmax) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        let mut straddles = false;
        for p in b.corners() {
            let c = world_from_camera.inverse_transform_point(&p);
            if c.z <= near {
                behind += 1;
                straddles = true;
                continue;
            }
            let u = self.cx + self.fx * c.x / c.z;
            let v = self.cy + self.fy * c.y / c.z;
            umin = umin.min(u);
            umax = umax.max(u);
            vmin = vmin.min(v);
            vmax = vmax.max(v);
        }
        if behind == 8 {
            return None;
        }
        if straddles {
            return Some((0, w as usize - 1, 0, h as usize - 1));
        }
        let u0 = (umin.floor() - 1.0).max(0.0);
        let u1 = (umax.ceil() + 1.0).min(w - 1.0);
        let v0 = (vmin.floor() - 1.0).max(0.0);
        let v1 = (vmax.ceil() + 1.0).min(h - 1.0);
        if u0 > u1 || v0 > v1 {
            return None;
        }
        Some((u0 as usize, u1 as usize, v0 as usize, v1 as usize))
    }
}

/// One box seen from one camera pose: the slab test of every pixel's ray.
struct Slab {
    /// Half extents of the box, m.
    half: [f32; 3],
    /// The camera's centre in the box's frame.
    origin: [f32; 3],
    /// Rotation of the camera's rays into the box's frame.
    rb: [[f32; 3]; 3],
    /// Farthest depth worth testing, m.
    far: f32,
}

impl Slab {
    /// Lowers each `depth` to where its ray (x/z, y/z, 1) enters the box (0 inside
    /// it). The arithmetic is parry's `Aabb::cast_local_ray` with `solid`, operation
    /// for operation, so depths are bit-identical to it; written without early exits
    /// so the row vectorizes.
    #[inline]
    fn cast_row(&self, rays: &[[f32; 2]], depth: &mut [f32]) {
        let Self {
            half,
            origin,
            rb,
            far,
        } = self;
        for (d, &[rx, ry]) in depth.iter_mut().zip(rays) {
            let dir = [
                rb[0][0] * rx + rb[0][1] * ry + rb[0][2],
                rb[1][0] * rx + rb[1][1] * ry + rb[1][2],
                rb[2][0] * rx + rb[2][1] * ry + rb[2][2],
            ];
            let mut tmin = 0.0f32;
            let mut tmax = d.min(*far);
            let mut miss = false;
            for k in 0..3 {
                let (lo, hi, o) = (-half[k], half[k], origin[k]);
                // Both branches computed and one kept, so the loop has no jumps.
                let along = dir[k] != 0.0;
                let denom = 1.0 / dir[k];
                let a = (lo - o) * denom;
                let b = (hi - o) * denom;
                let (near, far) = if a > b { (b, a) } else { (a, b) };
                tmin = if along { tmin.max(near) } else { tmin };
                tmax = if along { tmax.min(far) } else { tmax };
                // Once tmin passes tmax it stays past: parry returns there.
                miss |= if along { tmin > tmax } else { o < lo || o > hi };
            }
            *d = if miss { *d } else { d.min(tmin) };
        }
    }
}

#[cfg(test)]
#[path = "depth_test.rs"]
mod tests;
