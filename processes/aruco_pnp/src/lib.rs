//! aruco-pnp: where the landing pad is, from one camera frame.
//!
//! [`PadEstimator::process`] takes a frame, its capture time and the vehicle pose at
//! that time, and returns the pad pose: markers detected (in the region where the pad
//! was last seen, else the whole frame), those whose active range fits the distance
//! kept, one PnP over all their corners refined on the total reprojection error,
//! outlier markers dropped, a covariance. No IPC, no clock, no sleeping: the `aruco-pnp`
//! binary binds it to iceoryx2 and `landing run` calls it in lockstep.

pub mod config;
pub mod detect;
pub mod edges;
pub mod pose;
pub mod stage;

use ipc_types::msg::{Header, MAX_MARKERS, PadObservation, PixelEncoding, Pose};
use nalgebra::{Isometry3, Matrix6, Point3, UnitQuaternion};
use opencv::core::{Mat, Rect};
use opencv::imgproc;
use opencv::prelude::*;
use optics::{CameraCalibration, PadModel};
use thiserror::Error;

pub use config::ArucoConfig;
pub use detect::{DetectSettings, Detector, Marker};
pub use pose::{LevelPrior, MarkerCorners, PoseSettings, PoseSolution};
pub use stage::ArucoStage;

/// Why a frame gave no answer (as opposed to "no pad in view", which is `Ok(None)`).
#[derive(Debug, Error)]
pub enum EstimateError {
    /// The frame's size is not the calibration's.
    #[error("frame is {got_w}x{got_h}, the calibration is {want_w}x{want_h}")]
    FrameSize {
        /// Frame width.
        got_w: u32,
        /// Frame height.
        got_h: u32,
        /// Calibrated width.
        want_w: u32,
        /// Calibrated height.
        want_h: u32,
    },
    /// The pixel encoding is not one the detector reads, or the header is inconsistent
    /// with the bytes (stride, length).
    #[error("frame layout: {0}")]
    Layout(&'static str),
    /// Detection failed inside OpenCV.
    #[error(transparent)]
    Detect(#[from] detect::DetectError),
    /// OpenCV failed converting the frame.
    #[error("frame: {0}")]
    OpenCv(#[from] opencv::Error),
}

/// A camera frame as the detector reads it: borrowed pixels and their layout.
#[derive(Debug, Clone, Copy)]
pub struct Frame<'a> {
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
    /// Bytes from one row to the next.
    pub stride: u32,
    /// Pixel encoding.
    pub encoding: PixelEncoding,
    /// The pixels.
    pub data: &'a [u8],
    /// True when camera-ingest already undistorted the frame (ideal pinhole with the
    /// calibration's camera matrix): the lens model must not be applied again.
    pub undistorted: bool,
}

/// Where the detector looked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Search {
    /// Only the region around the pad's last pose.
    Region,
    /// The whole frame (no track, or the region had no pad marker).
    Full,
}

/// The pad pose from one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Estimate {
    /// Pad in the camera's optical frame.
    pub camera_from_pad: Isometry3<f64>,
    /// Pad in the world, when the vehicle pose at capture time was known.
    pub world_from_pad: Option<Isometry3<f64>>,
    /// Covariance of (x, y, z, roll, pitch, yaw): of `world_from_pad` when it is known,
    /// else of `camera_from_pad` in camera axes.
    pub covariance: Matrix6<f64>,
    /// RMS reprojection error over the corners used, px.
    pub rms_px: f64,
    /// Markers that went into the pose.
    pub used: Vec<u32>,
    /// Markers detected but dropped as outliers.
    pub rejected: Vec<u32>,
    /// Every pad marker decoded in the frame (before the active-range choice).
    pub detected: Vec<u32>,
    /// Where the detector looked to find them.
    pub search: Search,
}

impl Estimate {
    /// The wire message, stamped by `header`; `None` when any number is not finite
    /// (never published).
    pub fn observation(&self, header: Header) -> Option<PadObservation> {
        let mut obs = PadObservation {
            msg: header,
            camera_from_pad: pose_of(&self.camera_from_pad),
            reprojection_error_px: self.rms_px,
            ..PadObservation::default()
        };
        if let Some(w) = &self.world_from_pad {
            obs.world_from_pad = pose_of(w);
            obs.world_valid = 1;
        }
        for (k, v) in obs.covariance.iter_mut().enumerate() {
            *v = self.covariance[(k / 6, k % 6)];
        }
        for (slot, id) in obs.marker_ids.iter_mut().zip(&self.used) {
            *slot = *id;
        }
        obs.marker_count = self.used.len().min(MAX_MARKERS) as u32;
        let finite = obs.camera_from_pad.is_finite()
            && obs.world_from_pad.is_finite()
            && obs.reprojection_error_px.is_finite()
            && obs.covariance.iter().all(|v| v.is_finite());
        finite.then_some(obs)
    }
}

/// The wire form of a transform.
pub fn pose_of(iso: &Isometry3<f64>) -> Pose {
    let q = iso.rotation.coords;
    let t = iso.translation.vector;
    Pose {
        translation: [t.x, t.y, t.z],
        rotation_xyzw: [q.x, q.y, q.z, q.w],
    }
}

/// What the last good frame said, for the next frame's search region and range choice.
#[derive(Debug, Clone, Copy)]
struct Track {
    camera_from_pad: Isometry3<f64>,
    capture_ns: u64,
    /// The camera's attitude then, when the vehicle state gave it.
    world_from_camera: Option<UnitQuaternion<f64>>,
}

impl Track {
    /// The pad as the camera should see it now: the last pose turned by how the camera
    /// has turned since (the vehicle's attitude, known for both frames). A few degrees of
    /// roll move the pad tens of pixels, out of its search region; the pad's offset from
    /// the camera changes little between frames while the vehicle follows it.
    fn predicted(&self, world_from_camera: Option<&Isometry3<f64>>) -> Track {
        let (Some(then), Some(now)) = (self.world_from_camera, world_from_camera) else {
            return *self;
        };
        let now_from_then = now.rotation.inverse() * then;
        Track {
            camera_from_pad: Isometry3::from_parts(
                (now_from_then * self.camera_from_pad.translation.vector).into(),
                now_from_then * self.camera_from_pad.rotation,
            ),
            ..*self
        }
    }
}

/// Counters a process reports (and tests read).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counters {
    /// Frames searched.
    pub frames: u64,
    /// Frames that gave a pose.
    pub poses: u64,
    /// Frames searched in the tracked region only.
    pub region_searches: u64,
    /// Frames where the region missed and the whole frame was searched again.
    pub fallbacks: u64,
}

/// Tuning of the estimator (from the `[aruco_pnp]` config section).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EstimatorSettings {
    /// Detector settings.
    pub detect: DetectSettings,
    /// Pose solver settings.
    pub pose: PoseSettings,
    /// The search region around the last pose grows by this fraction of its size on
    /// every side (room for the motion between frames).
    pub region_margin: f64,
    /// Least margin, px.
    pub region_margin_min_px: f64,
    /// A track older than this is forgotten (the whole frame is searched), ns.
    pub track_timeout_ns: u64,
    /// Markers are kept when the distance is within their active range widened by
    /// this fraction (so that two ranges overlap instead of flickering).
    pub range_slack: f64,
    /// How far from level the pad may be (1 sigma, rad) when the vehicle attitude is
    /// known; 0 turns the level prior off. See [`pose::LevelPrior`].
    pub level_sigma_rad: f64,
    /// Place corners from the markers' edges ([`edges`]) instead of cornerSubPix alone.
    pub edge_refinement: bool,
}

impl Default for EstimatorSettings {
    fn default() -> Self {
        Self {
            detect: DetectSettings::default(),
            pose: PoseSettings::default(),
            region_margin: 0.35,
            region_margin_min_px: 24.0,
            track_timeout_ns: 300_000_000,
            range_slack: 0.15,
            level_sigma_rad: 2f64.to_radians(),
            edge_refinement: true,
        }
    }
}

/// Frame in, pad pose out.
#[derive(Debug)]
pub struct PadEstimator {
    calibration: CameraCalibration,
    /// The same camera matrix without distortion, for undistorted frames.
    pinhole: CameraCalibration,
    /// Which of the two the current frame uses.
    undistorted: bool,
    pad: PadModel,
    camera_from_body: Isometry3<f64>,
    settings: EstimatorSettings,
    detector: Detector,
    track: Option<Track>,
    gray: Mat,
    counters: Counters,
}

impl PadEstimator {
    /// An estimator for this camera, pad and camera mount.
    pub fn new(
        calibration: CameraCalibration,
        pad: PadModel,
        camera_from_body: Isometry3<f64>,
        settings: EstimatorSettings,
    ) -> Result<Self, EstimateError> {
        let mut pinhole = calibration;
        pinhole.distortion = [0.0; 5];
        Ok(Self {
            detector: Detector::new(settings.detect)?,
            calibration,
            pinhole,
            undistorted: false,
            pad,
            camera_from_body,
            settings,
            track: None,
            gray: Mat::default(),
            counters: Counters::default(),
        })
    }

    /// The camera mount: maps body-frame points into the optical frame.
    pub fn camera_from_body(&self) -> Isometry3<f64> {
        self.camera_from_body
    }

    /// The calibration frames must match.
    pub fn calibration(&self) -> &CameraCalibration {
        &self.calibration
    }

    /// What happened so far.
    pub fn counters(&self) -> Counters {
        self.counters
    }

    /// Forgets the track: the next frame is searched whole.
    pub fn reset(&mut self) {
        self.track = None;
    }

    /// Finds the pad in `frame`, captured at `capture_ns`; `world_from_body` is the
    /// vehicle pose at that time, if known. `Ok(None)`: no pad marker in view.
    pub fn process(
        &mut self,
        frame: &Frame<'_>,
        capture_ns: u64,
        world_from_body: Option<&Isometry3<f64>>,
    ) -> Result<Option<Estimate>, EstimateError> {
        self.check(frame)?;
        self.counters.frames += 1;
        self.undistorted = frame.undistorted;
        if self.track.is_some_and(|t| {
            capture_ns.saturating_sub(t.capture_ns) > self.settings.track_timeout_ns
        }) {
            self.track = None;
        }
        let world_from_camera = world_from_body.map(|w| w * self.camera_from_body.inverse());
        let predicted = self.track.map(|t| t.predicted(world_from_camera.as_ref()));
        let region = predicted.as_ref().and_then(|t| self.region(t));
        // The frame's bytes as a Mat header (no copy): `stride` bytes a row, of which
        // the first `width * bpp` are pixels. Colour frames are converted to grey.
        let (w, h) = (frame.width as i32, frame.height as i32);
        let bytes = frame
            .data
            .get(..frame.stride as usize * frame.height as usize)
            .unwrap_or(&[]);
        let rows = Mat::new_rows_cols_with_data(h, frame.stride as i32, bytes)?;
        let bpp = frame.encoding.bytes_per_pixel() as i32;
        let pixels = Mat::roi(&rows, Rect::new(0, 0, w * bpp, h))?;
        let code = match frame.encoding {
            PixelEncoding::Mono8 => None,
            PixelEncoding::Bgr8 => Some(imgproc::COLOR_BGR2GRAY),
            PixelEncoding::Rgb8 => Some(imgproc::COLOR_RGB2GRAY),
        };
        if let Some(code) = code {
            let colour = pixels.reshape(3, h)?;
            imgproc::cvt_color_def(&colour, &mut self.gray, code)?;
        }
        let gray = &self.gray;
        let smallest = predicted.as_ref().and_then(|t| self.smallest_active_px(t));
        let look = |detector: &mut Detector, region: Option<Rect>| {
            let hint = region.and(smallest);
            match code {
                None => detector.detect(&pixels, region, hint),
                Some(_) => detector.detect(gray, region, hint),
            }
        };
        let mut search = Search::Full;
        let mut found = Vec::new();
        if let Some(r) = region {
            self.counters.region_searches += 1;
            let markers = look(&mut self.detector, Some(r))?;
            found = self.pad_markers(markers);
            if found.is_empty() {
                self.counters.fallbacks += 1;
            } else {
                search = Search::Region;
            }
        }
        if found.is_empty() {
            let markers = look(&mut self.detector, None)?;
            found = self.pad_markers(markers);
        }
        if found.is_empty() {
            self.track = None;
            return Ok(None);
        }
        let gray = match code {
            None => edges::Gray {
                data: frame.data,
                width: frame.width as usize,
                height: frame.height as usize,
                stride: frame.stride as usize,
            },
            Some(_) => edges::Gray {
                data: self.gray.data_bytes()?,
                width: frame.width as usize,
                height: frame.height as usize,
                stride: frame.width as usize,
            },
        };
        if self.settings.edge_refinement {
            for m in &mut found {
                if let Some(c) = edges::refine(&gray, self.lens(), &m.corners) {
                    m.corners = c;
                }
            }
        }
        let detected: Vec<u32> = found.iter().map(|m| m.id).collect();
        let chosen = self.active(&found);
        let corners: Vec<MarkerCorners> = chosen
            .iter()
            .filter_map(|m| {
                let object = self.pad.marker_corners_pad(m.id).ok()?;
                Some(MarkerCorners {
                    id: m.id,
                    object,
                    image: m.corners,
                })
            })
            .collect();
        let level = world_from_camera
            .filter(|_| self.settings.level_sigma_rad > 0.0)
            .map(|w| pose::LevelPrior {
                world_from_camera: w.rotation.to_rotation_matrix(),
                sigma_rad: self.settings.level_sigma_rad,
            });
        let solution = match pose::solve(self.lens(), &corners, &self.settings.pose, level.as_ref())
        {
            Ok(s) => s,
            Err(e) => {
                tracing::debug!(error = %e, "no pose from the detected markers");
                self.track = None;
                return Ok(None);
            }
        };
        self.track = Some(Track {
            camera_from_pad: solution.camera_from_pad,
            capture_ns,
            world_from_camera: world_from_camera.map(|w| w.rotation),
        });
        self.counters.poses += 1;
        let world_from_pad = world_from_camera.map(|w| w * solution.camera_from_pad);
        let covariance = match &world_from_camera {
            Some(w) => {
                pose::world_covariance(&solution.covariance, &w.rotation.to_rotation_matrix())
            }
            None => pose::world_covariance(&solution.covariance, &nalgebra::Rotation3::identity()),
        };
        Ok(Some(Estimate {
            camera_from_pad: solution.camera_from_pad,
            world_from_pad,
            covariance,
            rms_px: solution.rms_px,
            used: solution.used,
            rejected: solution.rejected,
            detected,
            search,
        }))
    }

    fn check(&self, frame: &Frame<'_>) -> Result<(), EstimateError> {
        if (frame.width, frame.height) != (self.calibration.width, self.calibration.height) {
            return Err(EstimateError::FrameSize {
                got_w: frame.width,
                got_h: frame.height,
                want_w: self.calibration.width,
                want_h: self.calibration.height,
            });
        }
        let bpp = frame.encoding.bytes_per_pixel();
        let row = frame.width as usize * bpp;
        if (frame.stride as usize) < row {
            return Err(EstimateError::Layout("stride shorter than a row"));
        }
        let need = frame.stride as usize * frame.height as usize;
        if frame.data.len() < need {
            return Err(EstimateError::Layout("fewer bytes than the header says"));
        }
        Ok(())
    }

    /// The lens model of the current frame.
    fn lens(&self) -> &CameraCalibration {
        if self.undistorted {
            &self.pinhole
        } else {
            &self.calibration
        }
    }

    /// Only markers of this pad.
    fn pad_markers(&self, found: Vec<Marker>) -> Vec<Marker> {
        found
            .into_iter()
            .filter(|m| self.pad.marker(m.id).is_some())
            .collect()
    }

    /// Camera-to-pad distance: from the track, else from the markers' apparent sizes.
    fn distance(&self, found: &[Marker]) -> Option<f64> {
        if let Some(t) = &self.track {
            return Some(t.camera_from_pad.translation.vector.norm());
        }
        let f = 0.5 * (self.calibration.fx + self.calibration.fy);
        let mut d: Vec<f64> = found
            .iter()
            .filter_map(|m| {
                let size = self.pad.marker(m.id)?.size_m;
                let side = m.side_px();
                (side > 1.0).then(|| f * size / side)
            })
            .collect();
        d.sort_by(f64::total_cmp);
        d.get(d.len() / 2).copied()
    }

    /// The markers whose active range fits the distance; all of them when none does
    /// (a pose from markers outside their best range beats no pose).
    fn active(&self, found: &[Marker]) -> Vec<Marker> {
        let Some(d) = self.distance(found) else {
            return found.to_vec();
        };
        let slack = self.settings.range_slack;
        let keep: Vec<Marker> = found
            .iter()
            .filter(|m| {
                self.pad.marker(m.id).is_some_and(|pm| {
                    let [lo, hi] = pm.active_range_m;
                    d >= lo * (1.0 - slack) && d <= hi * (1.0 + slack)
                })
            })
            .copied()
            .collect();
        if keep.is_empty() {
            found.to_vec()
        } else {
            keep
        }
    }

    /// Side in px of the smallest marker in range at the tracked distance.
    fn smallest_active_px(&self, track: &Track) -> Option<f64> {
        let d = track.camera_from_pad.translation.vector.norm();
        let slack = self.settings.range_slack * 2.0;
        let f = 0.5 * (self.calibration.fx + self.calibration.fy);
        self.pad
            .markers
            .iter()
            .filter(|m| {
                let [a, b] = m.active_range_m;
                d >= a * (1.0 - slack) && d <= b * (1.0 + slack)
            })
            .map(|m| f * m.size_m / d.max(1e-3))
            .min_by(f64::total_cmp)
    }

    /// Bounding box of the markers that should be in range at the tracked distance,
    /// projected with the tracked pose and widened by the margin; `None` when that is
    /// not possible (a corner behind the camera).
    fn region(&self, track: &Track) -> Option<Rect> {
        let d = track.camera_from_pad.translation.vector.norm();
        let slack = self.settings.range_slack * 2.0;
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for m in &self.pad.markers {
            let [a, b] = m.active_range_m;
            if !(d >= a * (1.0 - slack) && d <= b * (1.0 + slack)) {
                continue;
            }
            for c in self.pad.marker_corners_pad(m.id).ok()? {
                let p = self.lens().project(
                    &track
                        .camera_from_pad
                        .transform_point(&Point3::from(c.coords)),
                )?;
                lo = [lo[0].min(p.x), lo[1].min(p.y)];
                hi = [hi[0].max(p.x), hi[1].max(p.y)];
            }
        }
        if !(lo[0].is_finite() && hi[0].is_finite()) {
            return None;
        }
        let size = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        let margin = (size * self.settings.region_margin).max(self.settings.region_margin_min_px);
        let (x0, y0) = ((lo[0] - margin).floor(), (lo[1] - margin).floor());
        let (x1, y1) = ((hi[0] + margin).ceil(), (hi[1] + margin).ceil());
        let (w, h) = (
            f64::from(self.calibration.width),
            f64::from(self.calibration.height),
        );
        let (x0, y0, x1, y1) = (x0.max(0.0), y0.max(0.0), x1.min(w), y1.min(h));
        (x1 - x0 >= 8.0 && y1 - y0 >= 8.0)
            .then(|| Rect::new(x0 as i32, y0 as i32, (x1 - x0) as i32, (y1 - y0) as i32))
    }
}

pub use optics::down_camera_from_body;
