//! What Foxglove draws of the stack's messages, in the schemas Foxglove ships: camera
//! frames as `foxglove.CompressedImage` or `foxglove.RawImage`, depth as `RawImage`
//! (16UC1, millimetres as published), one transform tree on `/tf` (world -> body ->
//! camera -> pad_observed, body -> depth_camera, world -> pad for the mission's
//! estimate), the occupancy map,
//! the B-spline with its control points, the pad estimate and the simulator's truth as
//! `foxglove.SceneUpdate`, mission transitions and safety orders as `foxglove.Log`.
//!
//! Frames: world ENU, body FLU, camera optical (x right, y down, z forward), as in the
//! stack; Foxglove's 3-D panel takes any right-handed frames.

use foxglove::bytes::Bytes;
use foxglove::schemas::{
    Color, CompressedImage, CubePrimitive, Duration, FrameTransform, FrameTransforms,
    LinePrimitive, Log, PackedElementField, Point3, Pose as FxPose, Quaternion, RawImage,
    SceneEntity, SceneUpdate, SpherePrimitive, Timestamp, Vector3, VoxelGrid, line_primitive, log,
    packed_element_field,
};
use ipc_types::msg::{
    CameraFrameHeader, CellState, DepthFrameHeader, FsmStatus, MissionState, OccupancyMapHeader,
    PadObservation, PixelEncoding, Pose, SafetyCommand, Trajectory, TruthState, VehicleState,
    WatchdogView,
};
use opencv::core::{Mat, Vector};

/// The occupancy map's scene.
pub const MAP_TOPIC: &str = "/scene/map";
/// The planned B-spline and its control points.
pub const TRAJECTORY_TOPIC: &str = "/scene/trajectory";
/// The mission's pad estimate.
pub const PAD_TOPIC: &str = "/scene/pad";
/// The simulator's truth (the pad where it really is): evaluator recordings only.
pub const TRUTH_TOPIC: &str = "/scene/truth";
/// Every scene topic.
pub const SCENE_TOPICS: [&str; 4] = [MAP_TOPIC, TRAJECTORY_TOPIC, PAD_TOPIC, TRUTH_TOPIC];

/// The world frame (ENU).
pub const WORLD: &str = "world";
/// The vehicle's body frame (FLU).
pub const BODY: &str = "body";
/// The down camera (optical).
pub const CAMERA: &str = "camera";
/// The forward depth camera (optical).
pub const DEPTH_CAMERA: &str = "depth_camera";
/// The pad where the mission estimates it (world-aligned).
pub const PAD: &str = "pad";
/// The pad where the last observation saw it (from the camera).
pub const PAD_OBSERVED: &str = "pad_observed";

/// Pad side drawn for the estimate, m (the layout's board; the drawing only).
const PAD_SIDE_M: f64 = 0.5;
/// Trajectory samples per B-spline segment.
const SAMPLES_PER_SEGMENT: usize = 8;

/// A nanosecond stamp as Foxglove's timestamp.
pub fn stamp(ns: u64) -> Timestamp {
    Timestamp::new((ns / 1_000_000_000) as u32, (ns % 1_000_000_000) as u32)
}

fn finite(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite())
}

fn vec3(v: [f64; 3]) -> Vector3 {
    Vector3 {
        x: v[0],
        y: v[1],
        z: v[2],
    }
}

fn point(v: [f64; 3]) -> Point3 {
    Point3 {
        x: v[0],
        y: v[1],
        z: v[2],
    }
}

fn colour(r: f64, g: f64, b: f64, a: f64) -> Option<Color> {
    Some(Color { r, g, b, a })
}

fn identity() -> Option<FxPose> {
    Some(FxPose {
        position: Some(vec3([0.0; 3])),
        orientation: Some(Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }),
    })
}

fn at(p: [f64; 3]) -> Option<FxPose> {
    Some(FxPose {
        position: Some(vec3(p)),
        orientation: identity().and_then(|i| i.orientation),
    })
}

/// `parent_from_child` as a transform; `None` for a non-finite pose.
fn transform(parent: &str, child: &str, pose: &Pose, ns: u64) -> Option<FrameTransform> {
    if !finite(&pose.translation) || !finite(&pose.rotation_xyzw) {
        return None;
    }
    let [x, y, z, w] = pose.rotation_xyzw;
    Some(FrameTransform {
        timestamp: Some(stamp(ns)),
        parent_frame_id: parent.into(),
        child_frame_id: child.into(),
        translation: Some(vec3(pose.translation)),
        rotation: Some(Quaternion { x, y, z, w }),
    })
}

fn entity(ns: u64, frame: &str, id: &str) -> SceneEntity {
    SceneEntity {
        timestamp: Some(stamp(ns)),
        frame_id: frame.into(),
        id: id.into(),
        // Zero: shown until replaced by the next entity of the same id.
        lifetime: Some(Duration::new(0, 0)),
        ..Default::default()
    }
}

fn log_entry(ns: u64, level: log::Level, name: &str, message: String) -> Log {
    Log {
        timestamp: Some(stamp(ns)),
        level: level as i32,
        message,
        name: name.into(),
        file: String::new(),
        line: 0,
    }
}

/// The state a recording carries from message to message: the camera mount, the last
/// mission state and watchdog action (a log line on change), and the JPEG buffers.
pub struct Visuals {
    body_from_camera: Option<Pose>,
    body_from_depth: Option<Pose>,
    last_state: Option<(u32, String)>,
    last_watchdog: String,
    jpeg: Vector<u8>,
    rgb: Mat,
}

impl Visuals {
    /// With the cameras mounted at `body_from_camera` and `body_from_depth` (`None`: that
    /// camera's frame is left out of the tree).
    pub fn new(body_from_camera: Option<Pose>, body_from_depth: Option<Pose>) -> Self {
        Self {
            body_from_camera,
            body_from_depth,
            last_state: None,
            last_watchdog: String::new(),
            jpeg: Vector::new(),
            rgb: Mat::default(),
        }
    }

    /// world -> body at the state's measurement, and the cameras' mounts under it.
    pub fn vehicle(&self, m: &VehicleState) -> Option<FrameTransforms> {
        let ns = m.msg.capture_ns;
        let mut transforms = vec![transform(WORLD, BODY, &m.world_from_body, ns)?];
        if let Some(mount) = &self.body_from_camera {
            transforms.extend(transform(BODY, CAMERA, mount, ns));
        }
        if let Some(mount) = &self.body_from_depth {
            transforms.extend(transform(BODY, DEPTH_CAMERA, mount, ns));
        }
        Some(FrameTransforms { transforms })
    }

    /// camera -> pad_observed at the frame's capture.
    pub fn observation(&self, m: &PadObservation) -> Option<FrameTransforms> {
        let tf = transform(CAMERA, PAD_OBSERVED, &m.camera_from_pad, m.msg.capture_ns)?;
        Some(FrameTransforms {
            transforms: vec![tf],
        })
    }

    /// A log line when the mission changes state (or reason).
    pub fn status_log(&mut self, m: &FsmStatus) -> Option<Log> {
        let reason = m.reason.as_str().to_string();
        if self
            .last_state
            .as_ref()
            .is_some_and(|(s, r)| *s == m.state && *r == reason)
        {
            return None;
        }
        let name = |raw: u32| MissionState::from_raw(raw).map_or("unknown", |s| s.name());
        let line = match &self.last_state {
            Some((s, _)) => format!("{} -> {}: {reason}", name(*s), name(m.state)),
            None => format!("{}: {reason}", name(m.state)),
        };
        let level = match MissionState::from_raw(m.state) {
            Some(MissionState::Abort | MissionState::SafeLand | MissionState::Lost) => {
                log::Level::Warning
            }
            _ => log::Level::Info,
        };
        self.last_state = Some((m.state, reason));
        Some(log_entry(m.msg.capture_ns, level, "fsm", line))
    }

    /// world -> pad and its drawing (a board and its velocity over the next second) when
    /// the mission has an estimate.
    pub fn pad_estimate(&self, m: &FsmStatus) -> (Option<FrameTransforms>, Option<SceneUpdate>) {
        if m.pad_valid == 0 || !finite(&m.pad_position) || !finite(&m.pad_velocity) {
            return (None, None);
        }
        let ns = m.msg.capture_ns;
        let tf = transform(
            WORLD,
            PAD,
            &Pose {
                translation: m.pad_position,
                rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
            },
            ns,
        );
        let mut e = entity(ns, PAD, "pad-estimate");
        e.cubes.push(CubePrimitive {
            pose: identity(),
            size: Some(vec3([PAD_SIDE_M, PAD_SIDE_M, 0.02])),
            color: colour(0.1, 0.8, 0.2, 0.6),
        });
        e.lines.push(LinePrimitive {
            r#type: line_primitive::Type::LineStrip as i32,
            pose: identity(),
            thickness: 0.03,
            points: vec![point([0.0; 3]), point(m.pad_velocity)],
            color: colour(0.1, 0.8, 0.2, 1.0),
            ..Default::default()
        });
        let scene = SceneUpdate {
            deletions: vec![],
            entities: vec![e],
        };
        (
            tf.map(|t| FrameTransforms {
                transforms: vec![t],
            }),
            Some(scene),
        )
    }

    /// A log line when the watchdog's action changes.
    pub fn watchdog_log(&mut self, m: &WatchdogView) -> Option<Log> {
        let action = m.action.as_str();
        if action.is_empty() || action == self.last_watchdog {
            return None;
        }
        self.last_watchdog = action.to_string();
        let line = format!("{action} ({})", m.last_fault.as_str());
        Some(log_entry(
            m.msg.capture_ns,
            log::Level::Warning,
            "watchdog",
            line,
        ))
    }

    /// A camera frame as JPEG at `quality`; `None` when the pixels do not fit the header
    /// or OpenCV refuses them.
    pub fn jpeg(
        &mut self,
        h: &CameraFrameHeader,
        pixels: &[u8],
        quality: u8,
    ) -> Option<CompressedImage> {
        let enc = PixelEncoding::from_raw(h.encoding)?;
        let len = h.expected_len()?;
        let data = pixels.get(..len)?;
        let kind = match enc {
            PixelEncoding::Mono8 => opencv::core::CV_8UC1,
            PixelEncoding::Bgr8 | PixelEncoding::Rgb8 => opencv::core::CV_8UC3,
        };
        let (rows, cols) = (i32::try_from(h.height).ok()?, i32::try_from(h.width).ok()?);
        // A header over the shared-memory pixels: no copy before the encoder.
        // SAFETY: `data` holds `height * stride` bytes (expected_len), outlives `mat`, and
        // the encoder only reads it.
        let mat = unsafe {
            Mat::new_rows_cols_with_data_unsafe(
                rows,
                cols,
                kind,
                data.as_ptr() as *mut std::ffi::c_void,
                h.stride as usize,
            )
        }
        .ok()?;
        let src = if enc == PixelEncoding::Rgb8 {
            opencv::imgproc::cvt_color_def(&mat, &mut self.rgb, opencv::imgproc::COLOR_RGB2BGR)
                .ok()?;
            &self.rgb
        } else {
            &mat
        };
        let params = Vector::from_slice(&[
            opencv::imgcodecs::IMWRITE_JPEG_QUALITY,
            i32::from(quality.clamp(1, 100)),
        ]);
        self.jpeg.clear();
        opencv::imgcodecs::imencode(".jpg", src, &mut self.jpeg, &params).ok()?;
        Some(CompressedImage {
            timestamp: Some(stamp(h.msg.capture_ns)),
            frame_id: CAMERA.into(),
            data: Bytes::copy_from_slice(self.jpeg.as_slice()),
            format: "jpeg".into(),
        })
    }
}

/// A camera frame as published (`mono8`, `bgr8`, `rgb8`); `None` when the pixels do not
/// fit the header.
pub fn raw_image(h: &CameraFrameHeader, pixels: &[u8]) -> Option<RawImage> {
    let encoding = match PixelEncoding::from_raw(h.encoding)? {
        PixelEncoding::Mono8 => "mono8",
        PixelEncoding::Bgr8 => "bgr8",
        PixelEncoding::Rgb8 => "rgb8",
    };
    let data = pixels.get(..h.expected_len()?)?;
    Some(RawImage {
        timestamp: Some(stamp(h.msg.capture_ns)),
        frame_id: CAMERA.into(),
        width: h.width,
        height: h.height,
        encoding: encoding.into(),
        step: h.stride,
        data: Bytes::copy_from_slice(data),
    })
}

/// A depth frame as `16UC1` (the published units: `depth_scale_m` per count).
pub fn depth_image(h: &DepthFrameHeader, depths: &[u16]) -> RawImage {
    let n = (h.width as usize * h.height as usize).min(depths.len());
    let mut data = Vec::with_capacity(n * 2);
    for d in &depths[..n] {
        data.extend_from_slice(&d.to_le_bytes());
    }
    RawImage {
        timestamp: Some(stamp(h.msg.capture_ns)),
        frame_id: DEPTH_CAMERA.into(),
        width: h.width,
        height: if h.width == 0 {
            0
        } else {
            (n / h.width as usize) as u32
        },
        encoding: "16UC1".into(),
        step: h.width * 2,
        data: Bytes::from(data),
    }
}

/// The occupied cells of the map as cubes (red), the inflated ones as faint cubes.
pub fn map_scene(h: &OccupancyMapHeader, cells: &[u8]) -> Option<SceneUpdate> {
    let [nx, ny, nz] = h.dims.map(|d| d as usize);
    let res = h.resolution;
    if res.is_nan() || res <= 0.0 || !finite(&h.origin) || nx * ny * nz > cells.len() {
        return None;
    }
    let mut e = entity(h.msg.capture_ns, WORLD, "occupancy");
    let mut occupied = CubePrimitive {
        size: Some(vec3([res; 3])),
        color: colour(0.9, 0.2, 0.1, 0.8),
        ..Default::default()
    };
    let mut cubes = Vec::new();
    for (i, c) in cells[..nx * ny * nz].iter().enumerate() {
        if CellState::from_raw(*c) != CellState::Occupied {
            continue;
        }
        let (x, y, z) = (i % nx, (i / nx) % ny, i / (nx * ny));
        let centre = [x, y, z].map(|k| k as f64 + 0.5);
        occupied.pose = at([
            h.origin[0] + centre[0] * res,
            h.origin[1] + centre[1] * res,
            h.origin[2] + centre[2] * res,
        ]);
        cubes.push(occupied);
    }
    e.cubes = cubes;
    Some(SceneUpdate {
        deletions: vec![],
        entities: vec![e],
    })
}

/// The field of [`voxel_grid`]'s cells: the raw [`CellState`].
pub const VOXEL_FIELD: &str = "state";

/// The whole map, every cell, as `foxglove.VoxelGrid` (one byte per cell, the raw
/// [`CellState`], x fastest then y then z, as the map is laid out): exact, what a replay
/// of depth-map compares and a replay of the planner feeds; Foxglove draws it in 3-D.
/// `None` for a header that does not fit its cells.
pub fn voxel_grid(h: &OccupancyMapHeader, cells: &[u8]) -> Option<VoxelGrid> {
    let [nx, ny, nz] = h.dims;
    let n = (nx as usize)
        .checked_mul(ny as usize)?
        .checked_mul(nz as usize)?;
    let res = h.resolution;
    if res.is_nan() || res <= 0.0 || !finite(&h.origin) || n > cells.len() {
        return None;
    }
    Some(VoxelGrid {
        timestamp: Some(stamp(h.msg.capture_ns)),
        frame_id: WORLD.into(),
        pose: at(h.origin),
        row_count: ny,
        column_count: nx,
        cell_size: Some(vec3([res; 3])),
        slice_stride: nx.checked_mul(ny)?,
        row_stride: nx,
        cell_stride: 1,
        fields: vec![PackedElementField {
            name: VOXEL_FIELD.into(),
            offset: 0,
            r#type: packed_element_field::NumericType::Uint8 as i32,
        }],
        data: Bytes::copy_from_slice(cells.get(..n)?),
    })
}

/// The B-spline (sampled) and its control points.
pub fn trajectory_scene(m: &Trajectory) -> Option<SceneUpdate> {
    let n = (m.count as usize).min(m.control_points.len());
    let pts = &m.control_points[..n];
    if pts.iter().any(|p| !finite(p)) {
        return None;
    }
    let mut e = entity(m.msg.capture_ns, WORLD, "trajectory");
    let mut curve = Vec::new();
    for s in 0..n.saturating_sub(3) {
        for k in 0..=SAMPLES_PER_SEGMENT {
            if k == SAMPLES_PER_SEGMENT && s + 4 < n {
                continue;
            }
            let u = k as f64 / SAMPLES_PER_SEGMENT as f64;
            // The uniform cubic basis.
            let b = [
                (1.0 - u).powi(3) / 6.0,
                (3.0 * u.powi(3) - 6.0 * u * u + 4.0) / 6.0,
                (-3.0 * u.powi(3) + 3.0 * u * u + 3.0 * u + 1.0) / 6.0,
                u.powi(3) / 6.0,
            ];
            let mut p = [0.0; 3];
            for (j, w) in b.iter().enumerate() {
                for (a, c) in p.iter_mut().zip(pts[s + j]) {
                    *a += w * c;
                }
            }
            curve.push(point(p));
        }
    }
    let colour_of = if m.emergency != 0 {
        colour(1.0, 0.5, 0.0, 1.0)
    } else {
        colour(0.2, 0.5, 1.0, 1.0)
    };
    e.lines.push(LinePrimitive {
        r#type: line_primitive::Type::LineStrip as i32,
        pose: identity(),
        thickness: 0.04,
        points: curve,
        color: colour_of,
        ..Default::default()
    });
    e.lines.push(LinePrimitive {
        r#type: line_primitive::Type::LineStrip as i32,
        pose: identity(),
        thickness: 0.01,
        points: pts.iter().map(|p| point(*p)).collect(),
        color: colour(0.6, 0.6, 0.6, 0.8),
        ..Default::default()
    });
    e.spheres = pts
        .iter()
        .map(|p| SpherePrimitive {
            pose: at(*p),
            size: Some(vec3([0.06; 3])),
            color: colour(0.6, 0.6, 0.6, 1.0),
        })
        .collect();
    Some(SceneUpdate {
        deletions: vec![],
        entities: vec![e],
    })
}

/// Where the simulator really has the pad and the vehicle (evaluator recordings only).
pub fn truth_scene(m: &TruthState) -> Option<SceneUpdate> {
    if !finite(&m.pad_position) || !finite(&m.vehicle_position) {
        return None;
    }
    let mut e = entity(m.msg.capture_ns, WORLD, "truth");
    if m.pad_valid != 0 {
        e.cubes.push(CubePrimitive {
            pose: at(m.pad_position),
            size: Some(vec3([PAD_SIDE_M, PAD_SIDE_M, 0.01])),
            color: colour(1.0, 1.0, 1.0, 0.4),
        });
    }
    e.spheres.push(SpherePrimitive {
        pose: at(m.vehicle_position),
        size: Some(vec3([0.1; 3])),
        color: colour(1.0, 1.0, 1.0, 0.6),
    });
    Some(SceneUpdate {
        deletions: vec![],
        entities: vec![e],
    })
}

/// A safety order as a log line.
pub fn safety_log(m: &SafetyCommand) -> Log {
    log_entry(
        m.msg.capture_ns,
        log::Level::Error,
        m.source.as_str(),
        format!("safety order {}: {}", m.action, m.reason.as_str()),
    )
}

#[cfg(test)]
#[path = "visual_test.rs"]
mod tests;
