//! The downward camera: renders what the quadrotor's pad camera sees.
//!
//! Pinhole + OpenCV distortion (the calibration the detector will use), the
//! pad board textured with OpenCV's own ArUco markers, a procedural asphalt
//! ground, motion blur over the exposure, and seeded Gaussian sensor noise.
//!
//! Speed comes from doing the expensive part once: the undistorted ray of every
//! pixel is fixed by the calibration, so it is computed at construction. Per
//! frame each ray is intersected with the pad plane (kept if it lands on the
//! board) or else the ground plane z = 0, and the texture is sampled
//! bilinearly from a mip level chosen by the distance, so far markers do not
//! alias. Only the ground and the pad board are drawn (no vehicle body, no
//! shadows, no sky model).

use nalgebra::{Isometry3, Point2, Point3, Translation3, UnitQuaternion, Vector3};
use opencv::core::{CV_8UC1, CV_8UC3, Mat, Scalar};
use opencv::prelude::*;
use optics::{CameraCalibration, PadModel};
use serde::Deserialize;
use thiserror::Error;

use crate::bilinear::{self, Image};
use crate::ground_vehicle::PadState;
use crate::noise::{MAX_SLICE, PixelNoise};
use crate::params::{self, ParamError};
use crate::rng::Pcg32;

/// Calls `$generic` through an AVX2 build when the CPU has AVX2 (checked at
/// run time). Only the vector width changes, so results are bit-identical.
macro_rules! avx2_dispatch {
    ($(#[$doc:meta])* fn $name:ident => $avx2:ident, $generic:ident ($($arg:ident: $ty:ty),*) -> $ret:ty) => {
        $(#[$doc])*
        fn $name($($arg: $ty),*) -> $ret {
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU supports AVX2 (checked just above), which
                // is all the target_feature function requires.
                return unsafe { $avx2($($arg),*) };
            }
            $generic($($arg),*)
        }

        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2")]
        fn $avx2($($arg: $ty),*) -> $ret {
            $generic($($arg),*)
        }
    };
}

/// Why a camera could not be built or used.
#[derive(Debug, Error)]
pub enum CameraError {
    /// A configuration value is out of range.
    #[error("camera: {0}")]
    Param(#[from] ParamError),
    /// The pad could not be drawn.
    #[error("camera: {0}")]
    Pad(#[from] optics::PadError),
    /// OpenCV failed (building the texture atlas, sampling, converting).
    #[error("camera: {0}")]
    OpenCv(#[from] opencv::Error),
    /// The image is wider than the renderer's bands allow.
    #[error("camera: image width {0} px is above the supported 4096 px")]
    TooWide(u32),
    /// The pad texture is too fine for the sampler's 16-bit coordinates.
    #[error(
        "camera: texture atlas {0} x {1} px is above 32767 px a side (lower pad_texture_px_per_m)"
    )]
    AtlasTooLarge(usize, usize),
    /// A drawn calibration is not a valid camera.
    #[error("camera: {0}")]
    Calibration(#[from] optics::CalibrationError),
    /// The output buffer does not hold exactly one frame.
    #[error("camera: output buffer holds {got} bytes, a frame is {want}")]
    BufferSize {
        /// Bytes given.
        got: usize,
        /// Bytes a frame needs.
        want: usize,
    },
}

/// Pixel layout of a rendered frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum PixelFormat {
    /// One byte per pixel, grey (what the detector consumes).
    #[default]
    Mono8,
    /// Three bytes per pixel, OpenCV's B, G, R order (grey replicated).
    Bgr8,
}

/// Configuration of the downward camera (the `[camera_down]` section).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DownCameraParams {
    /// Position of the camera's optical centre in the body frame (FLU), m.
    /// The camera looks straight down: optical z = -body z, image up = body
    /// forward (optical x = -body y, optical y = -body x).
    pub position_in_body_m: [f64; 3],
    /// Exposure time, s: the motion during it blurs the image.
    pub exposure_time_s: f64,
    /// Time from the middle of the exposure to the frame being published, s.
    /// Metadata only: the caller applies it when timestamping and publishing.
    pub latency_s: f64,
    /// Standard deviation of the additive Gaussian sensor noise, grey levels.
    pub noise_sigma: f64,
    /// Most sub-exposure renders blended for motion blur (1 disables blur).
    pub max_blur_samples: u32,
    /// Output pixel layout.
    pub format: PixelFormat,
    /// Seed of the noise and of the ground texture.
    pub seed: u64,
    /// Resolution of the pad texture, px per metre (2000 = 0.5 mm texels,
    /// fine enough for the 2.5 cm marker at 0.1 m on a 1280x720 camera).
    pub pad_texture_px_per_m: f64,
    /// Grey level of the markers' black.
    pub black_level: u8,
    /// Grey level of the board's white.
    pub white_level: u8,
}

impl Default for DownCameraParams {
    fn default() -> Self {
        Self {
            position_in_body_m: [0.05, 0.0, -0.05],
            exposure_time_s: 0.004,
            latency_s: 0.030,
            noise_sigma: 2.0,
            max_blur_samples: 8,
            format: PixelFormat::Mono8,
            seed: 1,
            pad_texture_px_per_m: 2000.0,
            black_level: 25,
            white_level: 230,
        }
    }
}

impl DownCameraParams {
    /// Checks every field; the error names the field.
    pub fn validate(&self) -> Result<(), ParamError> {
        for (i, v) in self.position_in_body_m.iter().enumerate() {
            params::in_range(&format!("position_in_body_m[{i}]"), *v, -2.0, 2.0)?;
        }
        params::in_range("exposure_time_s", self.exposure_time_s, 0.0, 0.1)?;
        params::in_range("latency_s", self.latency_s, 0.0, 1.0)?;
        params::in_range("noise_sigma", self.noise_sigma, 0.0, 64.0)?;
        if !(1..=64).contains(&self.max_blur_samples) {
            return Err(ParamError::new(
                "max_blur_samples",
                self.max_blur_samples,
                "must be in [1, 64]",
            ));
        }
        params::in_range(
            "pad_texture_px_per_m",
            self.pad_texture_px_per_m,
            200.0,
            8000.0,
        )?;
        if self.black_level >= self.white_level {
            return Err(ParamError::new(
                "black_level",
                self.black_level,
                format!("must be < white_level ({})", self.white_level),
            ));
        }
        Ok(())
    }

    /// The mount: maps body-frame points into the optical frame.
    pub fn camera_from_body(&self) -> Isometry3<f64> {
        optics::down_camera_from_body(self.position_in_body_m)
    }
}

/// How far a real camera is from its calibration and its drawing, per seed: the
/// simulator renders with the perturbed intrinsics and mount while the pipeline reads
/// the nominal calibration file and mount (standard deviations).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CameraErrors {
    /// Focal lengths, relative (0.01 = 1 %).
    pub focal_fraction: f64,
    /// Principal point, px.
    pub principal_point_px: f64,
    /// Distortion coefficients k1, k2, p1, p2, k3 (absolute).
    pub distortion: [f64; 5],
    /// Mount rotation about each optical axis, deg.
    pub mount_rotation_deg: f64,
    /// Mount translation along each axis, m.
    pub mount_translation_m: f64,
    /// Offset of the frames' capture timestamps from the true mid-exposure time, drawn
    /// once per seed (a driver stamping at readout, a clock not quite shared), ms.
    pub clock_offset_ms: f64,
    /// Jitter of each frame's timestamp around that offset, ms.
    pub clock_jitter_ms: f64,
}

impl Default for CameraErrors {
    /// A calibrated camera on a real airframe: 1 % focal length, 3 px principal point,
    /// k1 0.01, k2 0.005, tangential 0.0005, 1 deg and 1 cm of mount, timestamps off
    /// by 3 ms with 1 ms of jitter.
    fn default() -> Self {
        Self {
            focal_fraction: 0.01,
            principal_point_px: 3.0,
            distortion: [0.01, 0.005, 0.0005, 0.0005, 0.0],
            mount_rotation_deg: 1.0,
            mount_translation_m: 0.01,
            clock_offset_ms: 3.0,
            clock_jitter_ms: 1.0,
        }
    }
}

impl CameraErrors {
    /// None at all: the renderer's camera is the calibration (tests of the detector).
    pub fn none() -> Self {
        Self {
            focal_fraction: 0.0,
            principal_point_px: 0.0,
            distortion: [0.0; 5],
            mount_rotation_deg: 0.0,
            mount_translation_m: 0.0,
            clock_offset_ms: 0.0,
            clock_jitter_ms: 0.0,
        }
    }

    /// Checks every field.
    pub fn validate(&self) -> Result<(), ParamError> {
        params::in_range("focal_fraction", self.focal_fraction, 0.0, 0.1)?;
        params::in_range("principal_point_px", self.principal_point_px, 0.0, 50.0)?;
        for (i, d) in self.distortion.iter().enumerate() {
            params::in_range(&format!("distortion[{i}]"), *d, 0.0, 0.2)?;
        }
        params::in_range("mount_rotation_deg", self.mount_rotation_deg, 0.0, 10.0)?;
        params::in_range("mount_translation_m", self.mount_translation_m, 0.0, 0.1)?;
        params::in_range("clock_offset_ms", self.clock_offset_ms, 0.0, 50.0)?;
        params::in_range("clock_jitter_ms", self.clock_jitter_ms, 0.0, 10.0)
    }

    /// The clock offset drawn for `seed`, ns (signed).
    pub fn draw_clock_offset_ns(&self, seed: u64) -> i64 {
        let mut rng = Pcg32::with_stream(seed, 22);
        (self.clock_offset_ms * rng.normal() * 1e6) as i64
    }

    /// The true calibration and mount error drawn for `seed` around `nominal`.
    pub fn draw(
        &self,
        nominal: &CameraCalibration,
        seed: u64,
    ) -> Result<(CameraCalibration, Isometry3<f64>), CameraError> {
        let mut rng = Pcg32::with_stream(seed, 21);
        let mut n = |std: f64| std * rng.normal();
        let fx = nominal.fx * (1.0 + n(self.focal_fraction));
        let fy = nominal.fy * (1.0 + n(self.focal_fraction));
        let cx = nominal.cx + n(self.principal_point_px);
        let cy = nominal.cy + n(self.principal_point_px);
        let mut distortion = nominal.distortion;
        for (d, std) in distortion.iter_mut().zip(self.distortion) {
            *d += n(std);
        }
        let truth =
            CameraCalibration::new(nominal.width, nominal.height, fx, fy, cx, cy, distortion)?;
        let mount = MountErrors {
            rotation_deg: self.mount_rotation_deg,
            translation_m: self.mount_translation_m,
        };
        Ok((truth, mount.draw_with(n)))
    }
}

/// How far a sensor's true mount is from the drawing the pipeline reads (standard
/// deviations, drawn per seed).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MountErrors {
    /// Rotation about each optical axis, deg.
    pub rotation_deg: f64,
    /// Translation along each axis, m.
    pub translation_m: f64,
}

impl Default for MountErrors {
    /// A sensor bolted to a real airframe: 1 deg and 1 cm.
    fn default() -> Self {
        Self {
            rotation_deg: 1.0,
            translation_m: 0.01,
        }
    }
}

impl MountErrors {
    /// Checks every field.
    pub fn validate(&self) -> Result<(), ParamError> {
        params::in_range("mount_errors.rotation_deg", self.rotation_deg, 0.0, 10.0)?;
        params::in_range("mount_errors.translation_m", self.translation_m, 0.0, 0.1)
    }

    /// The mount error drawn for `seed`: maps the true optical frame into the nominal one.
    pub fn draw(&self, seed: u64) -> Isometry3<f64> {
        let mut rng = Pcg32::with_stream(seed, 24);
        self.draw_with(|std| std * rng.normal())
    }

    fn draw_with(&self, mut n: impl FnMut(f64) -> f64) -> Isometry3<f64> {
        let r = self.rotation_deg.to_radians();
        let rotation = UnitQuaternion::from_euler_angles(n(r), n(r), n(r));
        let t = self.translation_m;
        let translation = Translation3::new(n(t), n(t), n(t));
        Isometry3::from_parts(translation, rotation)
    }
}

/// The body's true motion at the middle of the exposure.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyMotion {
    /// Body pose in world ENU.
    pub world_from_body: Isometry3<f64>,
    /// Velocity of the body origin in world ENU, m/s.
    pub linear_velocity: Vector3<f64>,
    /// Angular rates in the body frame, rad/s.
    pub angular_velocity_body: Vector3<f64>,
}

impl BodyMotion {
    /// A body at rest at `world_from_body` (no blur).
    pub fn at_rest(world_from_body: Isometry3<f64>) -> Self {
        Self {
            world_from_body,
            linear_velocity: Vector3::zeros(),
            angular_velocity_body: Vector3::zeros(),
        }
    }

    fn at(&self, dt: f64) -> Isometry3<f64> {
        let rot = self.world_from_body.rotation
            * UnitQuaternion::from_scaled_axis(self.angular_velocity_body * dt);
        Isometry3::from_parts(
            Translation3::from(self.world_from_body.translation.vector + self.linear_velocity * dt),
            rot,
        )
    }
}

fn pad_at(pad: &PadState, dt: f64) -> Isometry3<f64> {
    let rot =
        UnitQuaternion::from_scaled_axis(pad.angular_velocity * dt) * pad.world_from_pad.rotation;
    Isometry3::from_parts(
        Translation3::from(pad.world_from_pad.translation.vector + pad.linear_velocity * dt),
        rot,
    )
}

/// One rendered image.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
    /// Pixel layout of `data`.
    pub format: PixelFormat,
    /// Row-major pixels, no padding.
    pub data: Vec<u8>,
    /// Exposure-to-publish latency the caller should apply, s.
    pub latency_s: f64,
    /// Sub-exposures blended for motion blur (1 = no visible motion).
    pub blur_samples: u32,
}

impl Frame {
    /// Copies the frame into an OpenCV `Mat` (CV_8UC1 or CV_8UC3), e.g. for the detector.
    pub fn to_mat(&self) -> Result<Mat, CameraError> {
        let typ = match self.format {
            PixelFormat::Mono8 => CV_8UC1,
            PixelFormat::Bgr8 => CV_8UC3,
        };
        let mut m = Mat::new_rows_cols_with_default(
            self.height as i32,
            self.width as i32,
            typ,
            Scalar::all(0.0),
        )?;
        m.data_bytes_mut()?.copy_from_slice(&self.data);
        Ok(m)
    }
}

/// A mono texture level, stored with one extra column and row
/// (edge-replicated, or wrapped for a tiled texture) so a bilinear sample at
/// the last texel, or across the tile seam, reads the right neighbour.
#[derive(Debug, Clone)]
struct Texture {
    w: usize,
    h: usize,
    stride: usize,
    wrap: bool,
    data: Vec<u8>,
}

impl Texture {
    /// From `w x h` row-major pixels; `wrap` for a texture tiled over the plane
    /// (then `w` and `h` must be powers of two).
    fn new(w: usize, h: usize, pixels: &[u8], wrap: bool) -> Texture {
        let stride = w + 1;
        let mut data = Vec::with_capacity(stride * (h + 1));
        for r in 0..=h {
            let src = if r < h {
                r
            } else if wrap {
                0
            } else {
                h - 1
            };
            let row = &pixels[src * w..(src + 1) * w];
            data.extend_from_slice(row);
            data.push(if wrap { row[0] } else { row[w - 1] });
        }
        Texture {
            w,
            h,
            stride,
            wrap,
            data,
        }
    }

    fn at(&self, c: usize, r: usize) -> u8 {
        self.data[r * self.stride + c]
    }

    fn downsample(&self) -> Texture {
        let (w, h) = (self.w / 2, self.h / 2);
        let mut px = Vec::with_capacity(w * h);
        for r in 0..h {
            for c in 0..w {
                let s = u16::from(self.at(2 * c, 2 * r))
                    + u16::from(self.at(2 * c + 1, 2 * r))
                    + u16::from(self.at(2 * c, 2 * r + 1))
                    + u16::from(self.at(2 * c + 1, 2 * r + 1));
                px.push(((s + 2) / 4) as u8);
            }
        }
        Texture::new(w, h, &px, self.wrap)
    }

    fn mip_chain(self) -> Vec<Texture> {
        let mut levels = vec![self];
        while let Some(last) = levels.last() {
            if last.w < 16 || last.h < 16 {
                break;
            }
            let next = last.downsample();
            levels.push(next);
        }
        levels
    }
}

/// Ground texture: 1024 x 1024 texels of 2 cm, tiled (20.48 m period).
const GROUND_SIZE: usize = 1024;
const GROUND_PX_PER_M: f64 = 50.0;
/// Grey level where a ray misses both planes (looking above the horizon).
const SKY_LEVEL: f32 = 200.0;

/// Procedural asphalt: multi-octave value noise, speckle, expansion joints
/// every 2.56 m and a few dark stains, so the ground has texture a detector
/// must reject (and optical flow could track) without looking like a marker.
fn ground_texture(seed: u64) -> Texture {
    let n = GROUND_SIZE;
    let mut rng = Pcg32::with_stream(seed, 0x6772_6f75_6e64);
    let mut acc = vec![0.0f32; n * n];
    for (cell, amp) in [(128usize, 14.0f32), (32, 10.0), (8, 8.0), (2, 6.0)] {
        let g = n / cell;
        let lattice: Vec<f32> = (0..g * g)
            .map(|_| rng.uniform() as f32 * 2.0 - 1.0)
            .collect();
        for r in 0..n {
            let (gr, fr) = (r / cell, (r % cell) as f32 / cell as f32);
            let sr = fr * fr * (3.0 - 2.0 * fr);
            for c in 0..n {
                let (gc, fc) = (c / cell, (c % cell) as f32 / cell as f32);
                let sc = fc * fc * (3.0 - 2.0 * fc);
                let l = |a: usize, b: usize| lattice[(a % g) * g + (b % g)];
                let top = l(gr, gc) + (l(gr, gc + 1) - l(gr, gc)) * sc;
                let bot = l(gr + 1, gc) + (l(gr + 1, gc + 1) - l(gr + 1, gc)) * sc;
                acc[r * n + c] += amp * (top + (bot - top) * sr);
            }
        }
    }
    let stains: Vec<(f32, f32, f32)> = (0..12)
        .map(|_| {
            (
                rng.uniform() as f32 * n as f32,
                rng.uniform() as f32 * n as f32,
                10.0 + rng.uniform() as f32 * 30.0,
            )
        })
        .collect();
    let mut data = Vec::with_capacity(n * n);
    for r in 0..n {
        for c in 0..n {
            let mut v = 105.0 + acc[r * n + c] + (rng.uniform() as f32 - 0.5) * 16.0;
            if r % 128 < 2 || c % 128 < 2 {
                v -= 35.0;
            }
            for &(sx, sy, rad) in &stains {
                let dx = (c as f32 - sx).abs().min(n as f32 - (c as f32 - sx).abs());
                let dy = (r as f32 - sy).abs().min(n as f32 - (r as f32 - sy).abs());
                if dx * dx + dy * dy < rad * rad {
                    v -= 25.0;
                }
            }
            data.push(v.clamp(0.0, 255.0) as u8);
        }
    }
    Texture::new(n, n, &data, true)
}

/// Mip level of detail at `depth_m` along the optical axis: the finer level
/// whose texels are at most one pixel wide, and how far (0..1) the pixel
/// footprint is toward the next coarser level, for trilinear blending.
fn mip_level(depth_m: f64, focal_px: f64, texels_per_m: f64, levels: usize) -> (usize, f32) {
    let texels_per_px = depth_m / focal_px * texels_per_m;
    if !(texels_per_px.is_finite() && texels_per_px > 1.0) {
        return (0, 0.0);
    }
    let lod = texels_per_px.log2();
    let top = levels.saturating_sub(1);
    let level = lod.floor() as usize;
    if level >= top {
        (top, 0.0)
    } else {
        (level, lod.fract() as f32)
    }
}

/// A rigid transform in f32 for the per-pixel loop.
#[derive(Debug, Clone, Copy)]
struct PlaneMap {
    r: [[f32; 3]; 3],
    t: [f32; 3],
}

impl PlaneMap {
    fn new(plane_from_camera: &Isometry3<f64>) -> Self {
        let m = plane_from_camera.rotation.to_rotation_matrix();
        let m = m.matrix();
        let t = plane_from_camera.translation.vector;
        let mut r = [[0.0f32; 3]; 3];
        for (i, row) in r.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = m[(i, j)] as f32;
            }
        }
        Self {
            r,
            t: [t.x as f32, t.y as f32, t.z as f32],
        }
    }
}

/// The downward camera renderer. Build once (rays, textures), render per frame.
#[derive(Debug, Clone)]
pub struct DownCamera {
    params: DownCameraParams,
    calibration: CameraCalibration,
    camera_from_body: Isometry3<f64>,
    rays: Vec<[f32; 2]>,
    /// Smallest and largest normalized ray coordinates (x, y) of any pixel:
    /// the field of view, for deciding what is in view.
    ray_bounds: [[f64; 2]; 2],
    /// The same per strip of [`STRIP_ROWS`] rows, to skip the pad where it cannot be.
    band_bounds: Vec<[[f32; 2]; 2]>,
    atlas: Atlas,
    pad_min: [f64; 2],
    pad_max: [f64; 2],
    noise: PixelNoise,
    /// Sub-exposure sum of the current band.
    accum: Vec<f32>,
    tile: Tile,
}

/// Where one mip level sits in the atlas.
#[derive(Debug, Clone, Copy)]
struct Block {
    x0: f32,
    y0: f32,
    w: usize,
    h: usize,
}

/// Every texture level in one image, so one sampling pass covers the pad, the
/// ground and the sky for all pixels at once.
#[derive(Debug, Clone)]
struct Atlas {
    image: Image,
    pad: Vec<Block>,
    ground: Vec<Block>,
    /// Centre of a 2x2 block of sky grey.
    sky: (f32, f32),
}

impl Atlas {
    /// Packs the pad levels in one column and the ground levels in the next
    /// (each with its extra border row and column), plus a sky block.
    fn new(pad: &[Texture], ground: &[Texture]) -> Result<Self, CameraError> {
        let column = |levels: &[Texture]| -> (usize, usize) {
            let w = levels.iter().map(|t| t.stride).max().unwrap_or(0);
            let h = levels.iter().map(|t| t.h + 2).sum();
            (w, h)
        };
        let (pw, ph) = column(pad);
        let (gw, gh) = column(ground);
        let width = pw + gw + 4;
        let height = ph.max(gh + 4);
        if width > i16::MAX as usize || height > i16::MAX as usize {
            return Err(CameraError::AtlasTooLarge(width, height));
        }
        let mut texels = vec![0u8; width * height];
        let data = texels.as_mut_slice();
        let place = |levels: &[Texture], x0: usize, y_start: usize, data: &mut [u8]| {
            let mut y = y_start;
            let mut blocks = Vec::new();
            for t in levels {
                for r in 0..=t.h {
                    let dst = (y + r) * width + x0;
                    data[dst..dst + t.stride]
                        .copy_from_slice(&t.data[r * t.stride..(r + 1) * t.stride]);
                }
                blocks.push(Block {
                    x0: x0 as f32,
                    y0: y as f32,
                    w: t.w,
                    h: t.h,
                });
                y += t.h + 2;
            }
            blocks
        };
        let pad_blocks = place(pad, 0, 0, data);
        let ground_blocks = place(ground, pw + 1, 0, data);
        let (sx, sy) = (pw + gw + 1, 0);
        for (r, c) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
            data[(sy + r) * width + sx + c] = SKY_LEVEL as u8;
        }
        Ok(Self {
            image: Image::new(&texels, width, height),
            pad: pad_blocks,
            ground: ground_blocks,
            sky: (sx as f32 + 0.5, sy as f32 + 0.5),
        })
    }
}

impl DownCamera {
    /// Precomputes the per-pixel rays from the calibration, draws the pad
    /// texture from the pad model and generates the ground from the seed.
    pub fn new(
        params: DownCameraParams,
        calibration: CameraCalibration,
        pad: &PadModel,
    ) -> Result<Self, CameraError> {
        params.validate()?;
        let (w, h) = (calibration.width as usize, calibration.height as usize);
        if w > MAX_WIDTH {
            return Err(CameraError::TooWide(calibration.width));
        }
        let mut rays = Vec::with_capacity(w * h);
        for v in 0..h {
            for u in 0..w {
                let n = calibration.undistort_pixel(&Point2::new(u as f64, v as f64));
                rays.push([n.x as f32, n.y as f32]);
            }
        }
        let band_bounds: Vec<[[f32; 2]; 2]> = rays
            .chunks(STRIP_ROWS * w)
            .map(|band| {
                band.iter().fold(
                    [[f32::INFINITY; 2], [f32::NEG_INFINITY; 2]],
                    |[lo, hi], r| {
                        [
                            [lo[0].min(r[0]), lo[1].min(r[1])],
                            [hi[0].max(r[0]), hi[1].max(r[1])],
                        ]
                    },
                )
            })
            .collect();
        let mut ray_bounds = [[f64::INFINITY; 2], [f64::NEG_INFINITY; 2]];
        for r in &rays {
            for k in 0..2 {
                ray_bounds[0][k] = ray_bounds[0][k].min(f64::from(r[k]));
                ray_bounds[1][k] = ray_bounds[1][k].max(f64::from(r[k]));
            }
        }
        let mat = pad.render_texture(params.pad_texture_px_per_m)?;
        let bytes = mat.data_bytes()?;
        let (black, white) = (f32::from(params.black_level), f32::from(params.white_level));
        let pixels: Vec<u8> = bytes
            .iter()
            .map(|&b| (black + (white - black) * f32::from(b) / 255.0).round() as u8)
            .collect();
        let texture = Texture::new(mat.cols() as usize, mat.rows() as usize, &pixels, false);
        let atlas = Atlas::new(
            &texture.mip_chain(),
            &ground_texture(params.seed).mip_chain(),
        )?;
        Ok(Self {
            camera_from_body: params.camera_from_body(),
            noise: PixelNoise::new(params.seed),
            atlas,
            tile: Tile::new(),
            pad_min: pad.board.min_m,
            pad_max: pad.board.max_m,
            accum: Vec::new(),
            rays,
            ray_bounds,
            band_bounds,
            calibration,
            params,
        })
    }

    /// The configuration in use.
    pub fn params(&self) -> &DownCameraParams {
        &self.params
    }

    /// The calibration images are rendered with (what the detector should load).
    pub fn calibration(&self) -> &CameraCalibration {
        &self.calibration
    }

    /// The camera mount (body to optical frame).
    pub fn camera_from_body(&self) -> Isometry3<f64> {
        self.camera_from_body
    }

    /// Moves the true mount by `error` (in the optical frame): the camera as built,
    /// against the nominal mount the pipeline is configured with.
    pub fn set_mount_error(&mut self, error: Isometry3<f64>) {
        self.camera_from_body = error.inverse() * self.params.camera_from_body();
    }

    /// Renders one frame. `body` is the true motion at the middle of the
    /// exposure, `pad` the pad at the same instant (`None`: no pad in the world).
    ///
    /// The image is produced in bands of [`TILE_ROWS`] rows so that the
    /// coordinate maps, the sampled band and the accumulator stay in cache;
    /// each band blends every sub-exposure before moving on.
    pub fn render(
        &mut self,
        body: &BodyMotion,
        pad: Option<&PadState>,
    ) -> Result<Frame, CameraError> {
        let mut data = vec![0u8; self.frame_len()];
        let blur_samples = self.render_into(body, pad, &mut data)?;
        Ok(Frame {
            width: self.calibration.width,
            height: self.calibration.height,
            format: self.params.format,
            data,
            latency_s: self.params.latency_s,
            blur_samples,
        })
    }

    /// Bytes of one frame (row-major, no padding).
    pub fn frame_len(&self) -> usize {
        let channels = match self.params.format {
            PixelFormat::Mono8 => 1,
            PixelFormat::Bgr8 => 3,
        };
        self.calibration.width as usize * self.calibration.height as usize * channels
    }

    /// Renders straight into `data` (a loaned shared-memory sample in the `sim` process,
    /// so the frame is never copied); returns the sub-exposures blended.
    pub fn render_into(
        &mut self,
        body: &BodyMotion,
        pad: Option<&PadState>,
        data: &mut [u8],
    ) -> Result<u32, CameraError> {
        if data.len() != self.frame_len() {
            return Err(CameraError::BufferSize {
                got: data.len(),
                want: self.frame_len(),
            });
        }
        let half = self.params.exposure_time_s / 2.0;
        let samples = self.blur_samples(body, pad);
        let body_from_camera = self.camera_from_body.inverse();
        let passes: Vec<Pass> = (0..samples)
            .map(|k| {
                let dt = if samples == 1 {
                    0.0
                } else {
                    2.0 * half * ((f64::from(k) + 0.5) / f64::from(samples) - 0.5)
                };
                let world_from_camera = body.at(dt) * body_from_camera;
                let pad_from_camera = pad.map(|p| pad_at(p, dt).inverse() * world_from_camera);
                self.pass(&world_from_camera, pad_from_camera.as_ref())
            })
            .collect();
        let weight = 1.0 / samples as f32;
        let (w, h) = (
            self.calibration.width as usize,
            self.calibration.height as usize,
        );
        let channels = match self.params.format {
            PixelFormat::Mono8 => 1,
            PixelFormat::Bgr8 => 3,
        };
        self.noise.new_frame();
        let mut row = 0;
        while row < h {
            let rows = TILE_ROWS.min(h - row);
            let range = row * w..(row + rows) * w;
            self.tile.resize(rows, w);
            let rays = self.rays.get(range.clone()).unwrap_or(&[]);
            let strips = row / STRIP_ROWS..(row + rows).div_ceil(STRIP_ROWS);
            let band = self.band_bounds.get(strips).unwrap_or(&[]);
            let out = data
                .get_mut(range.start * channels..range.end * channels)
                .unwrap_or(&mut []);
            if let [pass] = passes.as_slice() {
                // One sub-exposure (the common case): noise and quantize straight
                // from the sampled band, no f32 accumulator round trip.
                let blend = self.tile.sample(&self.atlas, pass, rays, band);
                let sigma = self.params.noise_sigma as f32;
                let noise = self.noise.slice(rows * w);
                let (fine, coarse) = self.tile.sampled();
                quantize_sampled(out, channels, fine, coarse, blend, noise, sigma);
            } else {
                self.accum.clear();
                self.accum.resize(rows * w, 0.0);
                for pass in &passes {
                    let blend = self.tile.sample(&self.atlas, pass, rays, band);
                    let (fine, coarse) = self.tile.sampled();
                    accumulate(&mut self.accum, fine, coarse, weight, blend);
                }
                self.finish_tile(out, channels);
            }
            row += rows;
        }
        Ok(samples)
    }

    /// How many sub-exposures keep the blur smooth: about one per pixel of
    /// image motion of the pad centre or the ground under the camera.
    fn blur_samples(&self, body: &BodyMotion, pad: Option<&PadState>) -> u32 {
        let half = self.params.exposure_time_s / 2.0;
        if self.params.max_blur_samples <= 1 || half <= 0.0 {
            return 1;
        }
        let body_from_camera = self.camera_from_body.inverse();
        let cam = |dt: f64| body.at(dt) * body_from_camera;
        let (c0, c1) = (cam(-half), cam(half));
        let mut motion: f64 = 0.0;
        // Only a point in view counts: outside the calibrated field the
        // distortion polynomial swings wildly, so a pad far outside the image
        // would otherwise ask for the most sub-exposures while the visible
        // ground barely moves (the 120 deg paper-sim camera hovering at 2 m).
        let [lo, hi] = self.ray_bounds;
        let in_view = |p: &Point3<f64>| {
            p.z > 0.0 && {
                let (x, y) = (p.x / p.z, p.y / p.z);
                (lo[0]..=hi[0]).contains(&x) && (lo[1]..=hi[1]).contains(&y)
            }
        };
        let mut track = |p0: Point3<f64>, p1: Point3<f64>| {
            let (q0, q1) = (
                c0.inverse_transform_point(&p0),
                c1.inverse_transform_point(&p1),
            );
            if !(in_view(&q0) || in_view(&q1)) {
                return;
            }
            let a = self.calibration.project(&q0);
            let b = self.calibration.project(&q1);
            if let (Some(a), Some(b)) = (a, b) {
                motion = motion.max((a - b).norm());
            }
        };
        if let Some(p) = pad {
            track(
                pad_at(p, -half).transform_point(&Point3::origin()),
                pad_at(p, half).transform_point(&Point3::origin()),
            );
        }
        let mid = body.at(0.0) * body_from_camera;
        let axis = mid.rotation * Vector3::z();
        if axis.z < -1e-6 {
            let s = -mid.translation.vector.z / axis.z;
            let g = Point3::from(mid.translation.vector + axis * s);
            track(g, g);
        }
        (motion.ceil() as u32).clamp(1, self.params.max_blur_samples)
    }

    /// Per-sub-exposure constants: the plane maps and the mip levels to use.
    fn pass(
        &self,
        world_from_camera: &Isometry3<f64>,
        pad_from_camera: Option<&Isometry3<f64>>,
    ) -> Pass {
        let focal = self.calibration.fx.max(self.calibration.fy);
        let depth_to = |plane_from_camera: &Isometry3<f64>| {
            let axis = plane_from_camera.rotation * Vector3::z();
            let tz = plane_from_camera.translation.vector.z;
            if axis.z < -1e-6 {
                -tz / axis.z
            } else {
                tz.abs()
            }
        };
        let atlas = &self.atlas;
        let ppm = self.params.pad_texture_px_per_m;
        let pad = pad_from_camera
            .filter(|p| p.translation.vector.z > 0.0)
            .and_then(|p| {
                let (level, blend) = mip_level(depth_to(p), focal, ppm, atlas.pad.len());
                let fine = *atlas.pad.get(level)?;
                let (view_min, view_max) = self.pad_view(p);
                let coarse = *atlas.pad.get(level + 1).unwrap_or(&fine);
                Some(PadPass {
                    map: PlaneMap::new(p),
                    fine,
                    coarse,
                    scale: (ppm / f64::from(1u32 << level)) as f32,
                    blend,
                    min: [self.pad_min[0] as f32, self.pad_min[1] as f32],
                    max: [self.pad_max[0] as f32, self.pad_max[1] as f32],
                    view_min,
                    view_max,
                })
            });
        let ground = (world_from_camera.translation.vector.z > 0.0)
            .then(|| {
                let (level, _) = mip_level(
                    depth_to(world_from_camera),
                    focal,
                    GROUND_PX_PER_M,
                    atlas.ground.len(),
                );
                let block = *atlas.ground.get(level)?;
                Some((
                    PlaneMap::new(world_from_camera),
                    block,
                    (GROUND_PX_PER_M / f64::from(1u32 << level)) as f32,
                ))
            })
            .flatten();
        Pass { pad, ground }
    }

    /// Bounding box of the board's corners in normalized ray coordinates,
    /// widened by 1e-3 (a fraction of a pixel, far above the f32 error of the
    /// per-pixel test); unbounded when a corner is not in front of the camera.
    fn pad_view(&self, pad_from_camera: &Isometry3<f64>) -> ([f32; 2], [f32; 2]) {
        const MARGIN: f64 = 1e-3;
        let camera_from_pad = pad_from_camera.inverse();
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for (x, y) in [
            (self.pad_min[0], self.pad_min[1]),
            (self.pad_max[0], self.pad_min[1]),
            (self.pad_min[0], self.pad_max[1]),
            (self.pad_max[0], self.pad_max[1]),
        ] {
            let c = camera_from_pad.transform_point(&Point3::new(x, y, 0.0));
            if c.z.is_nan() || c.z <= 1e-6 {
                return ([f32::NEG_INFINITY; 2], [f32::INFINITY; 2]);
            }
            for (k, v) in [c.x / c.z, c.y / c.z].into_iter().enumerate() {
                lo[k] = lo[k].min(v);
                hi[k] = hi[k].max(v);
            }
        }
        (
            [(lo[0] - MARGIN) as f32, (lo[1] - MARGIN) as f32],
            [(hi[0] + MARGIN) as f32, (hi[1] + MARGIN) as f32],
        )
    }

    /// Adds sensor noise and quantizes one band into `out`.
    fn finish_tile(&mut self, out: &mut [u8], channels: usize) {
        let sigma = self.params.noise_sigma as f32;
        let noise = self.noise.slice(self.accum.len());
        if channels == 1 {
            quantize(out, &self.accum, noise, sigma);
        } else {
            for ((o, &a), &n) in out.chunks_exact_mut(channels).zip(&self.accum).zip(noise) {
                o.fill(to_u8(a + sigma * n));
            }
        }
    }
}

/// Rows rendered together: a band blends every sub-exposure before the next band,
/// its coordinates filled and sampled strip by strip ([`STRIP_ROWS`]). Divides 480
/// and 720 (sized when OpenCV's `remap` sampled whole bands on both cores; the
/// strip sampler runs on the caller's core, as a campaign's worker does).
pub const TILE_ROWS: usize = 240;

/// Rows whose maps are filled together, each strip tested on its own for
/// whether it can see the pad. Divides [`TILE_ROWS`].
const STRIP_ROWS: usize = 16;
const _: () = assert!(TILE_ROWS.is_multiple_of(STRIP_ROWS));
/// Pixels of a strip checked together for whether their coarse points are their fine
/// ones (a multiple of the sampler's 8 lanes).
const SAME_RUN: usize = 64;
const STRIPS_PER_TILE: usize = TILE_ROWS / STRIP_ROWS;
/// Widest image: a band of it must fit in one noise slice.
const MAX_WIDTH: usize = 4096;
const _: () = assert!(MAX_WIDTH * TILE_ROWS <= MAX_SLICE);

/// What one sub-exposure needs to map a pixel's ray to atlas coordinates.
#[derive(Debug, Clone, Copy)]
struct Pass {
    pad: Option<PadPass>,
    ground: Option<(PlaneMap, Block, f32)>,
}

#[derive(Debug, Clone, Copy)]
struct PadPass {
    map: PlaneMap,
    fine: Block,
    coarse: Block,
    /// Texels per metre at the fine level.
    scale: f32,
    /// Weight of the coarse level (trilinear filtering).
    blend: f32,
    min: [f32; 2],
    max: [f32; 2],
    /// Bounding box of the board in normalized ray coordinates (x/z, y/z),
    /// widened a little, or unbounded when the board reaches behind the
    /// camera: a band whose rays all fall outside it cannot see the pad.
    view_min: [f32; 2],
    view_max: [f32; 2],
}

/// Scratch for one band: the atlas coordinates of one strip at the fine and the
/// coarse pad level (filled and sampled strip by strip, so they stay in cache), and
/// what was sampled there for the whole band.
#[derive(Debug, Clone)]
struct Tile {
    rows: usize,
    cols: usize,
    /// Integer texel and fraction index of each pixel of a strip: fine, coarse.
    xy: [Vec<u32>; 2],
    fxy: [Vec<u32>; 2],
    /// The band sampled at the fine and the coarse level.
    sampled: [Vec<u8>; 2],
    /// Whether `sampled[1]` holds the coarse level of the last band.
    coarse_valid: bool,
}

impl Tile {
    fn new() -> Self {
        Self {
            rows: 0,
            cols: 0,
            xy: [Vec::new(), Vec::new()],
            fxy: [Vec::new(), Vec::new()],
            sampled: [Vec::new(), Vec::new()],
            coarse_valid: false,
        }
    }

    fn resize(&mut self, rows: usize, cols: usize) {
        if (rows, cols) != (self.rows, self.cols) {
            for k in 0..2 {
                self.xy[k] = vec![0; STRIP_ROWS * cols];
                self.fxy[k] = vec![0; STRIP_ROWS * cols];
                self.sampled[k] = vec![0; rows * cols];
            }
            (self.rows, self.cols) = (rows, cols);
        }
    }

    /// Maps every ray of the band into the atlas and samples it at each pad
    /// level the band needs; returns the weight of the coarse level (0: only the
    /// fine level was sampled, and [`Tile::sampled`] returns it twice). `band`
    /// holds the smallest and largest ray (x, y) of each [`STRIP_ROWS`]-row
    /// strip of the band (a missing strip is taken to see the pad).
    fn sample(
        &mut self,
        atlas: &Atlas,
        pass: &Pass,
        rays: &[[f32; 2]],
        band: &[[[f32; 2]; 2]],
    ) -> f32 {
        let strip = STRIP_ROWS * self.cols.max(1);
        let strips = rays.len().div_ceil(strip).min(STRIPS_PER_TILE);
        // Which strips can see the board; the coarse level is needed only
        // from the first to the last of them (the pad is usually a small part
        // of the frame, and sampling every pixel twice was a third of the render).
        let mut pad_in = [false; STRIPS_PER_TILE];
        for (k, seen) in pad_in.iter_mut().enumerate().take(strips) {
            *seen = pass.pad.is_some_and(|p| {
                band.get(k).is_none_or(|[lo, hi]| {
                    (0..2).all(|k| p.view_min[k] <= hi[k] && lo[k] <= p.view_max[k])
                })
            });
        }
        let first = pad_in.iter().position(|&b| b).unwrap_or(strips);
        let last = pad_in.iter().rposition(|&b| b).map_or(first, |k| k + 1);
        let blended = pass.pad.is_some_and(|p| p.blend > 0.0);
        let [fxy, cxy] = &mut self.xy;
        let [ff, cf] = &mut self.fxy;
        let [fine, coarse] = &mut self.sampled;
        // Strip by strip, so the pad arithmetic is skipped where it cannot be
        // and the strip's coordinates are still in cache when it is sampled.
        let mut any_pad = false;
        for (k, ((rays, fine), coarse)) in rays
            .chunks(strip)
            .zip(fine.chunks_mut(strip))
            .zip(coarse.chunks_mut(strip))
            .enumerate()
        {
            let n = rays.len();
            let pad_in_strip = pad_in.get(k).copied().unwrap_or(true);
            let two_levels = blended && (first..last).contains(&k);
            any_pad |= fill_maps(
                atlas,
                pass,
                rays,
                Maps {
                    fx: &mut fxy[..n],
                    fy: &mut ff[..n],
                    cx: &mut cxy[..n],
                    cy: &mut cf[..n],
                },
                pad_in_strip,
                two_levels,
            );
            bilinear::sample(&atlas.image, &fxy[..n], &ff[..n], fine);
            if two_levels {
                // Off the board the coarse point is the fine one, so is its sample:
                // runs of such pixels are copied (the board is often a small part of
                // the strips that can see it).
                let runs = cxy[..n]
                    .chunks(SAME_RUN)
                    .zip(cf[..n].chunks(SAME_RUN))
                    .zip(fxy[..n].chunks(SAME_RUN).zip(ff[..n].chunks(SAME_RUN)))
                    .zip(coarse.chunks_mut(SAME_RUN).zip(fine.chunks(SAME_RUN)));
                for (((cxy, cf), (fxy, ff)), (coarse, fine)) in runs {
                    if cxy == fxy && cf == ff {
                        coarse.copy_from_slice(fine);
                    } else {
                        bilinear::sample(&atlas.image, cxy, cf, coarse);
                    }
                }
            } else if blended {
                // The ground has one level: coarse = fine off the pad's strips.
                coarse.copy_from_slice(fine);
            }
        }
        self.coarse_valid = any_pad && blended;
        if self.coarse_valid {
            pass.pad.map_or(0.0, |p| p.blend)
        } else {
            0.0
        }
    }

    /// The band sampled at the fine and the coarse level by the last
    /// [`Tile::sample`] (the fine one twice when the coarse was not needed).
    fn sampled(&self) -> (&[u8], &[u8]) {
        let fine = self.sampled[0].as_slice();
        let coarse = if self.coarse_valid {
            self.sampled[1].as_slice()
        } else {
            fine
        };
        (fine, coarse)
    }
}

/// [`fill_maps_generic`] specialized to what the band needs: rays that
/// cannot reach the board skip the pad arithmetic, and the coarse maps are
/// written only when the pad level is blended (about half the arithmetic and
/// stores of the full loop, which the 120 deg camera's mostly-ground frames
/// paid for every pixel).
fn fill_maps(
    atlas: &Atlas,
    pass: &Pass,
    rays: &[[f32; 2]],
    maps: Maps<'_>,
    pad_in_band: bool,
    coarse: bool,
) -> bool {
    // The coarse maps are sampled over every strip from the first to the last
    // that can see the pad, so such strips write them even without the pad (= fine).
    match (pass.pad.is_some() && pad_in_band, coarse) {
        (false, false) => fill_maps_ground(atlas, pass, rays, maps),
        (false, true) => fill_maps_ground_coarse(atlas, pass, rays, maps),
        (true, false) => fill_maps_fine(atlas, pass, rays, maps),
        (true, true) => fill_maps_trilinear(atlas, pass, rays, maps),
    }
}

avx2_dispatch!(
    /// Ground and sky only (fine maps).
    fn fill_maps_ground => fill_maps_ground_avx2, fill_maps_ground_generic(atlas: &Atlas, pass: &Pass, rays: &[[f32; 2]], maps: Maps<'_>) -> bool
);
avx2_dispatch!(
    /// Ground and sky only (fine and coarse maps).
    fn fill_maps_ground_coarse => fill_maps_ground_coarse_avx2, fill_maps_ground_coarse_generic(atlas: &Atlas, pass: &Pass, rays: &[[f32; 2]], maps: Maps<'_>) -> bool
);
avx2_dispatch!(
    /// Pad at one level, ground, sky (fine maps).
    fn fill_maps_fine => fill_maps_fine_avx2, fill_maps_fine_generic(atlas: &Atlas, pass: &Pass, rays: &[[f32; 2]], maps: Maps<'_>) -> bool
);
avx2_dispatch!(
    /// Pad at two levels, ground, sky (fine and coarse maps).
    fn fill_maps_trilinear => fill_maps_trilinear_avx2, fill_maps_trilinear_generic(atlas: &Atlas, pass: &Pass, rays: &[[f32; 2]], maps: Maps<'_>) -> bool
);

#[inline(always)]
fn fill_maps_ground_generic(atlas: &Atlas, pass: &Pass, rays: &[[f32; 2]], maps: Maps<'_>) -> bool {
    fill_maps_generic::<false, false>(atlas, pass, rays, maps)
}

#[inline(always)]
fn fill_maps_ground_coarse_generic(
    atlas: &Atlas,
    pass: &Pass,
    rays: &[[f32; 2]],
    maps: Maps<'_>,
) -> bool {
    fill_maps_generic::<false, true>(atlas, pass, rays, maps)
}

#[inline(always)]
fn fill_maps_fine_generic(atlas: &Atlas, pass: &Pass, rays: &[[f32; 2]], maps: Maps<'_>) -> bool {
    fill_maps_generic::<true, false>(atlas, pass, rays, maps)
}

#[inline(always)]
fn fill_maps_trilinear_generic(
    atlas: &Atlas,
    pass: &Pass,
    rays: &[[f32; 2]],
    maps: Maps<'_>,
) -> bool {
    fill_maps_generic::<true, true>(atlas, pass, rays, maps)
}

/// Atlas coordinates of every ray of a band, written branch-free so the
/// compiler can vectorize it: both planes are intersected for every pixel and
/// the result selected (pad if the ray lands on the board, else ground, else
/// sky). Outputs: fine-level x, y and coarse-level x, y (equal off the pad;
/// written only with `COARSE`). Without `PAD` every ray is taken to miss the
/// board. Returns whether any ray of the band landed on the pad.
#[inline(always)]
fn fill_maps_generic<const PAD: bool, const COARSE: bool>(
    atlas: &Atlas,
    pass: &Pass,
    rays: &[[f32; 2]],
    maps: Maps<'_>,
) -> bool {
    let Maps { fx, fy, cx, cy } = maps;
    let n = rays
        .len()
        .min(fx.len())
        .min(fy.len())
        .min(cx.len())
        .min(cy.len());
    let (rays, fx, fy, cx, cy) = (
        &rays[..n],
        &mut fx[..n],
        &mut fy[..n],
        &mut cx[..n],
        &mut cy[..n],
    );
    // A plane the rays never hit stands in for an absent pad or ground: the
    // camera 1 m above it, looking straight up (every ray has s < 0).
    let never = PlaneMap {
        r: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        t: [0.0, 0.0, 1.0],
    };
    let no_block = Block {
        x0: atlas.sky.0,
        y0: atlas.sky.1,
        w: 1,
        h: 1,
    };
    let p = pass.pad.unwrap_or(PadPass {
        map: never,
        fine: no_block,
        coarse: no_block,
        scale: 1.0,
        blend: 0.0,
        min: [1.0, 1.0],
        max: [-1.0, -1.0],
        view_min: [1.0, 1.0],
        view_max: [-1.0, -1.0],
    });
    let (gmap, gblock, gscale) = pass.ground.unwrap_or((never, no_block, 1.0));
    let (pr, pt) = (p.map.r, p.map.t);
    let (gr, gt) = (gmap.r, gmap.t);
    let (fw, fh) = ((p.fine.w - 1) as f32, (p.fine.h - 1) as f32);
    let (cw, ch) = ((p.coarse.w - 1) as f32, (p.coarse.h - 1) as f32);
    let size = gblock.w as f32;
    let inv = 1.0 / size;
    let (skyx, skyy) = atlas.sky;
    // floor(q) by the 1.5 * 2^23 rounding trick (no libm call, no float to
    // int conversion, so the loop vectorizes); exact for |q| < 2^22 tiles.
    const ROUND: f32 = 12_582_912.0;
    let wrap = |t: f32| {
        let q = (t * inv).clamp(-4.0e6, 4.0e6);
        let k = (q + ROUND) - ROUND;
        let k = if k > q { k - 1.0 } else { k };
        (t - k * size).max(0.0).min(size)
    };
    let mut any_pad = false;
    for i in 0..n {
        let [rx, ry] = rays[i];
        // Pad plane.
        let az = pr[2][0] * rx + pr[2][1] * ry + pr[2][2];
        let s = -pt[2] / az;
        let x = pt[0] + s * (pr[0][0] * rx + pr[0][1] * ry + pr[0][2]);
        let y = pt[1] + s * (pr[1][0] * rx + pr[1][1] * ry + pr[1][2]);
        let on_pad =
            PAD & (s > 0.0) & (x >= p.min[0]) & (x <= p.max[0]) & (y >= p.min[1]) & (y <= p.max[1]);
        let u = (x - p.min[0]) * p.scale;
        let v = (p.max[1] - y) * p.scale;
        let ufine = p.fine.x0 + (u - 0.5).max(0.0).min(fw);
        let vfine = p.fine.y0 + (v - 0.5).max(0.0).min(fh);
        let ucoarse = p.coarse.x0 + (u * 0.5 - 0.5).max(0.0).min(cw);
        let vcoarse = p.coarse.y0 + (v * 0.5 - 0.5).max(0.0).min(ch);
        // Ground plane.
        let gaz = gr[2][0] * rx + gr[2][1] * ry + gr[2][2];
        let gs = -gt[2] / gaz;
        let gx = gt[0] + gs * (gr[0][0] * rx + gr[0][1] * ry + gr[0][2]);
        let gy = gt[1] + gs * (gr[1][0] * rx + gr[1][1] * ry + gr[1][2]);
        let on_ground = gs > 0.0;
        let ug = if on_ground {
            gblock.x0 + wrap(gx * gscale - 0.5)
        } else {
            skyx
        };
        let vg = if on_ground {
            gblock.y0 + wrap(-gy * gscale - 0.5)
        } else {
            skyy
        };
        (fx[i], fy[i]) = bilinear::point(
            if on_pad { ufine } else { ug },
            if on_pad { vfine } else { vg },
        );
        if COARSE {
            (cx[i], cy[i]) = bilinear::point(
                if on_pad { ucoarse } else { ug },
                if on_pad { vcoarse } else { vg },
            );
        }
        any_pad |= on_pad;
    }
    any_pad
}

/// Atlas coordinates of every pixel of a strip, in the fixed-point form OpenCV's
/// `remap` samples (and [`bilinear::sample`] with it, made by [`bilinear::point`]): integer (x, y) and the
/// 1/32-pixel fraction index; fine and coarse pad level.
struct Maps<'a> {
    fx: &'a mut [u32],
    fy: &'a mut [u32],
    cx: &'a mut [u32],
    cy: &'a mut [u32],
}

/// Rounds (half to even) and saturates a grey level to a byte. Adding
/// 1.5 * 2^23 puts the rounded value in the low mantissa bits, so this is
/// float min/max/add and a bit mask: it vectorizes fully, where a float to
/// int cast kept a scalar NaN check per pixel in the loops below.
#[inline(always)]
#[allow(
    clippy::manual_clamp,
    reason = "max/min map NaN to 0; clamp would pass NaN through to the bit trick"
)]
fn to_u8(v: f32) -> u8 {
    const ROUND: f32 = 12_582_912.0;
    (v.max(0.0).min(255.0) + ROUND).to_bits() as u8
}

avx2_dispatch!(
    /// `accum += weight * lerp(fine, coarse, blend)` over a band.
    fn accumulate => accumulate_avx2, accumulate_generic(accum: &mut [f32], fine: &[u8], coarse: &[u8], weight: f32, blend: f32) -> ()
);

#[inline(always)]
fn accumulate_generic(accum: &mut [f32], fine: &[u8], coarse: &[u8], weight: f32, blend: f32) {
    for ((acc, &a), &b) in accum.iter_mut().zip(fine).zip(coarse) {
        let (a, b) = (f32::from(a), f32::from(b));
        *acc += weight * (a + (b - a) * blend);
    }
}

avx2_dispatch!(
    /// `out = to_u8(accum + sigma * noise)` over a band (mono).
    fn quantize => quantize_avx2, quantize_generic(out: &mut [u8], accum: &[f32], noise: &[f32], sigma: f32) -> ()
);

#[inline(always)]
fn quantize_generic(out: &mut [u8], accum: &[f32], noise: &[f32], sigma: f32) {
    for ((o, &a), &n) in out.iter_mut().zip(accum).zip(noise) {
        *o = to_u8(a + sigma * n);
    }
}

/// `out = to_u8(lerp(fine, coarse, blend) + sigma * noise)` over a band, each
/// grey written `channels` times: the single-sub-exposure path, same
/// arithmetic as accumulating with weight 1 and then quantizing.
fn quantize_sampled(
    out: &mut [u8],
    channels: usize,
    fine: &[u8],
    coarse: &[u8],
    blend: f32,
    noise: &[f32],
    sigma: f32,
) {
    if channels == 1 {
        quantize_mono(out, fine, coarse, blend, noise, sigma);
    } else {
        for (((o, &a), &b), &n) in out
            .chunks_exact_mut(channels)
            .zip(fine)
            .zip(coarse)
            .zip(noise)
        {
            let (a, b) = (f32::from(a), f32::from(b));
            o.fill(to_u8(a + (b - a) * blend + sigma * n));
        }
    }
}

avx2_dispatch!(
    /// Mono [`quantize_sampled`].
    fn quantize_mono => quantize_mono_avx2, quantize_mono_generic(out: &mut [u8], fine: &[u8], coarse: &[u8], blend: f32, noise: &[f32], sigma: f32) -> ()
);

#[inline(always)]
fn quantize_mono_generic(
    out: &mut [u8],
    fine: &[u8],
    coarse: &[u8],
    blend: f32,
    noise: &[f32],
    sigma: f32,
) {
    // Indexed over slices cut to one length: the four-way zip did not vectorize.
    let n = out.len().min(fine.len()).min(coarse.len()).min(noise.len());
    let (out, fine, coarse, noise) = (&mut out[..n], &fine[..n], &coarse[..n], &noise[..n]);
    for i in 0..n {
        let (a, b) = (f32::from(fine[i]), f32::from(coarse[i]));
        out[i] = to_u8(a + (b - a) * blend + sigma * noise[i]);
    }
}
