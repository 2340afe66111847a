//! Recorded messages back into the stack's types: the inverse of what the recorder writes
//! for each message (ipc_types' `Serialize`, one JSON object per message). JSON has no
//! NaN: the recorder wrote non-finite numbers as null, read back as NaN.

use anyhow::{Context, Result};
use ipc_types::msg::{
    CameraFrameHeader, DepthFrameHeader, FsmStatus, Header, Intrinsics, LinkHealth, LinkOutcome,
    MAX_CONTROL_POINTS, MAX_MARKERS, MAX_STAGES, OccupancyMapHeader, PadObservation, Point2, Pose,
    SafetyCommand, StageStamp, Text, Trajectory, TruthEvent, TruthState, VehicleState,
};
use serde_json::Value;

/// A number; null (a non-finite number written by the recorder) is NaN.
pub(crate) fn f64_of(v: &Value) -> f64 {
    // JSON has no NaN: the recorder wrote non-finite numbers as null.
    v.as_f64().unwrap_or(f64::NAN)
}

/// An unsigned integer, or an error naming the value.
pub(crate) fn u64_of(v: &Value) -> Result<u64> {
    v.as_u64()
        .with_context(|| format!("not an unsigned integer: {v}"))
}

/// An unsigned 32-bit integer, or an error naming the value.
pub(crate) fn u32_of(v: &Value) -> Result<u32> {
    Ok(u32::try_from(u64_of(v)?)?)
}

/// A fixed-size array of numbers; missing items are NaN.
pub(crate) fn arr<const N: usize>(v: &Value) -> [f64; N] {
    let mut out = [f64::NAN; N];
    for (o, x) in out.iter_mut().zip(v.as_array().into_iter().flatten()) {
        *o = f64_of(x);
    }
    out
}

/// A message header: sequence, capture time and stage stamps.
pub(crate) fn header(v: &Value) -> Result<Header> {
    let mut h = Header {
        seq: u64_of(&v["seq"])?,
        capture_ns: u64_of(&v["capture_ns"])?,
        stage_count: u32_of(&v["stage_count"])?,
        reserved: 0,
        ..Header::default()
    };
    for (s, x) in h
        .stages
        .iter_mut()
        .zip(v["stages"].as_array().into_iter().flatten())
        .take(MAX_STAGES)
    {
        *s = StageStamp {
            stage: u32_of(&x["stage"])?,
            reserved: 0,
            enter_ns: u64_of(&x["enter_ns"])?,
            exit_ns: u64_of(&x["exit_ns"])?,
        };
    }
    Ok(h)
}

/// A pose: translation and rotation quaternion (x, y, z, w).
pub(crate) fn pose(v: &Value) -> Pose {
    Pose {
        translation: arr(&v["translation"]),
        rotation_xyzw: arr(&v["rotation_xyzw"]),
    }
}

/// A vehicle state as recorded (JSON).
pub(crate) fn vehicle_state(v: &Value) -> Result<VehicleState> {
    let l = &v["link"];
    Ok(VehicleState {
        msg: header(&v["msg"])?,
        world_from_body: pose(&v["world_from_body"]),
        velocity: arr(&v["velocity"]),
        body_rates: arr(&v["body_rates"]),
        armed: u32_of(&v["armed"])?,
        flight_mode: u32_of(&v["flight_mode"])?,
        landed_state: u32_of(&v["landed_state"])?,
        reserved: 0,
        link: LinkHealth {
            connected: u32_of(&l["connected"])?,
            parse_errors: u32_of(&l["parse_errors"])?,
            last_heartbeat_ns: u64_of(&l["last_heartbeat_ns"])?,
            last_telemetry_ns: u64_of(&l["last_telemetry_ns"])?,
            messages_lost: u64_of(&l["messages_lost"])?,
            // Recordings before VehicleState/v2 have no rejection counts.
            signed: l["signed"]
                .as_u64()
                .map_or(0, |v| u32::try_from(v).unwrap_or(0)),
            reserved: 0,
            wrong_address: l["wrong_address"].as_u64().unwrap_or(0),
            wrong_source: l["wrong_source"].as_u64().unwrap_or(0),
            unknown_id: l["unknown_id"].as_u64().unwrap_or(0),
            unsigned: l["unsigned"].as_u64().unwrap_or(0),
            bad_signature: l["bad_signature"].as_u64().unwrap_or(0),
            replayed: l["replayed"].as_u64().unwrap_or(0),
        },
    })
}

/// A camera frame's header as recorded (JSON).
pub(crate) fn frame_header(v: &Value) -> Result<CameraFrameHeader> {
    Ok(CameraFrameHeader {
        msg: header(&v["msg"])?,
        width: u32_of(&v["width"])?,
        height: u32_of(&v["height"])?,
        stride: u32_of(&v["stride"])?,
        encoding: u32_of(&v["encoding"])?,
        camera_id: u32_of(&v["camera_id"])?,
        undistorted: u32_of(&v["undistorted"])?,
        exposure_ns: u64_of(&v["exposure_ns"])?,
    })
}

/// A pad observation as recorded (JSON).
pub(crate) fn observation(v: &Value) -> Result<PadObservation> {
    let mut o = PadObservation {
        msg: header(&v["msg"])?,
        camera_from_pad: pose(&v["camera_from_pad"]),
        world_from_pad: pose(&v["world_from_pad"]),
        covariance: arr(&v["covariance"]),
        reprojection_error_px: f64_of(&v["reprojection_error_px"]),
        marker_count: u32_of(&v["marker_count"])?,
        world_valid: u32_of(&v["world_valid"])?,
        ..PadObservation::default()
    };
    let ids = v["marker_ids"].as_array().context("marker_ids")?;
    for (o, i) in o.marker_ids.iter_mut().zip(ids).take(MAX_MARKERS) {
        *o = u32_of(i)?;
    }
    Ok(o)
}

/// A planner trajectory as recorded (JSON).
pub(crate) fn trajectory(v: &Value) -> Result<Trajectory> {
    let mut t = Trajectory {
        msg: header(&v["msg"])?,
        id: u64_of(&v["id"])?,
        start_ns: u64_of(&v["start_ns"])?,
        knot_interval_s: f64_of(&v["knot_interval_s"]),
        count: u32_of(&v["count"])?,
        emergency: u32_of(&v["emergency"])?,
        ..Trajectory::default()
    };
    let points = v["control_points"].as_array().context("control_points")?;
    for (o, p) in t
        .control_points
        .iter_mut()
        .zip(points)
        .take(MAX_CONTROL_POINTS)
    {
        *o = [f64_of(&p["x"]), f64_of(&p["y"]), f64_of(&p["z"])];
    }
    Ok(t)
}

/// An answer of px4-link as recorded (JSON).
pub(crate) fn outcome(v: &Value) -> Result<LinkOutcome> {
    Ok(LinkOutcome {
        msg: header(&v["msg"])?,
        id: u64_of(&v["id"])?,
        kind: u32_of(&v["kind"])?,
        outcome: u32_of(&v["outcome"])?,
        result: u32_of(&v["result"])?,
        reserved: 0,
    })
}

/// A safety order as recorded (JSON).
pub(crate) fn safety(v: &Value) -> Result<SafetyCommand> {
    Ok(SafetyCommand {
        msg: header(&v["msg"])?,
        action: u32_of(&v["action"])?,
        reserved: 0,
        source: Text::new(v["source"].as_str().unwrap_or("")),
        reason: Text::new(v["reason"].as_str().unwrap_or("")),
    })
}

/// A status of the fsm as recorded (JSON).
pub(crate) fn fsm_status(v: &Value) -> Result<FsmStatus> {
    Ok(FsmStatus {
        msg: header(&v["msg"])?,
        state: u32_of(&v["state"])?,
        previous: u32_of(&v["previous"])?,
        since_ns: u64_of(&v["since_ns"])?,
        reason: Text::new(v["reason"].as_str().unwrap_or("")),
        pad_valid: u32_of(&v["pad_valid"])?,
        reserved: 0,
        pad_position: arr(&v["pad_position"]),
        pad_velocity: arr(&v["pad_velocity"]),
    })
}

fn feet(v: &Value) -> [Point2; 4] {
    let mut out = [Point2::default(); 4];
    for (o, p) in out.iter_mut().zip(v.as_array().into_iter().flatten()) {
        *o = Point2 {
            x: f64_of(&p["x"]),
            y: f64_of(&p["y"]),
        };
    }
    out
}

/// A truth state of the simulator as recorded in the truth file (JSON).
pub(crate) fn truth_state(v: &Value) -> Result<TruthState> {
    Ok(TruthState {
        msg: header(&v["msg"])?,
        sim_time_ns: u64_of(&v["sim_time_ns"])?,
        vehicle_position: arr(&v["vehicle_position"]),
        vehicle_velocity: arr(&v["vehicle_velocity"]),
        pad_valid: u32_of(&v["pad_valid"])?,
        armed: u32_of(&v["armed"])?,
        pad_position: arr(&v["pad_position"]),
        pad_velocity: arr(&v["pad_velocity"]),
        vehicle_velocity_rel_pad: arr(&v["vehicle_velocity_rel_pad"]),
        gear_pad: feet(&v["gear_pad"]),
        contact: u32_of(&v["contact"])?,
        reserved: 0,
    })
}

/// A truth event of the simulator as recorded in the truth file (JSON).
pub(crate) fn truth_event(v: &Value) -> Result<TruthEvent> {
    Ok(TruthEvent {
        msg: header(&v["msg"])?,
        kind: u32_of(&v["kind"])?,
        on_pad: u32_of(&v["on_pad"])?,
        rel_position_pad: arr(&v["rel_position_pad"]),
        rel_velocity: arr(&v["rel_velocity"]),
        gear_pad: feet(&v["gear_pad"]),
        tilt_deg: f64_of(&v["tilt_deg"]),
        obstacle_index: u32_of(&v["obstacle_index"])?,
        reserved: 0,
        reason: Text::new(v["reason"].as_str().unwrap_or("")),
    })
}

/// A depth frame's header as recorded (JSON).
pub(crate) fn depth_header(v: &Value) -> Result<DepthFrameHeader> {
    let k = &v["intrinsics"];
    Ok(DepthFrameHeader {
        msg: header(&v["msg"])?,
        width: u32_of(&v["width"])?,
        height: u32_of(&v["height"])?,
        depth_scale_m: f64_of(&v["depth_scale_m"]),
        intrinsics: Intrinsics {
            fx: f64_of(&k["fx"]),
            fy: f64_of(&k["fy"]),
            cx: f64_of(&k["cx"]),
            cy: f64_of(&k["cy"]),
        },
        camera_id: u32_of(&v["camera_id"])?,
        reserved: 0,
    })
}

/// An occupancy map's header as recorded (JSON).
pub(crate) fn map_header(v: &Value) -> Result<OccupancyMapHeader> {
    let d = &v["dims"];
    Ok(OccupancyMapHeader {
        msg: header(&v["msg"])?,
        origin: arr(&v["origin"]),
        resolution: f64_of(&v["resolution"]),
        inflation: f64_of(&v["inflation"]),
        dims: [u32_of(&d[0])?, u32_of(&d[1])?, u32_of(&d[2])?],
        reserved: 0,
        // Absent (0) in recordings made before the field.
        state_ns: v["state_ns"].as_u64().unwrap_or(0),
    })
}

/// Reads every message of the recording `file` with `each`; the first error `each`
/// returns ends the reading as an error naming the message (topic, log time). What the
/// reader found (metadata, where the file broke) is the summary.
pub(crate) fn read_recording(
    file: &std::path::Path,
    mut each: impl FnMut(&recorder::RecordedMessage<'_>) -> Result<()>,
) -> Result<recorder::ReadSummary> {
    let mut failure: Option<anyhow::Error> = None;
    let summary = recorder::read_messages(file, &mut |m| {
        if failure.is_none()
            && let Err(e) = each(m)
        {
            failure = Some(e.context(format!("message on {} at {} ns", m.topic, m.log_time)));
        }
    })?;
    match failure {
        Some(e) => Err(e),
        None => Ok(summary),
    }
}

/// One recorded map: the log time of its header, the header, and its cells when the
/// recording holds them.
pub(crate) struct RecordedMap {
    pub log_time: u64,
    pub header: OccupancyMapHeader,
    pub cells: Option<Vec<u8>>,
}

/// The maps of a recording, each header (`/map/occupancy/header`) paired with the cells
/// (`/map/occupancy`, `foxglove.VoxelGrid`) the recorder wrote right after it. Log times
/// alone do not pair them: they are the recorder's round start, which two maps share
/// when it takes both in one round.
#[derive(Default)]
pub(crate) struct RecordedMaps {
    pub maps: Vec<RecordedMap>,
    /// VoxelGrid messages met, paired or not.
    pub grids: usize,
}

impl RecordedMaps {
    /// Takes `m` when it is part of a map; `Ok(false)` leaves it to the caller.
    pub(crate) fn take(&mut self, m: &recorder::RecordedMessage<'_>) -> Result<bool> {
        let Some(short) = m.topic.strip_prefix('/') else {
            return Ok(false);
        };
        let map = ipc_types::topics::MAP_OCCUPANCY;
        if short == map && m.schema == "foxglove.VoxelGrid" {
            use foxglove::Decode;
            let grid = foxglove::schemas::VoxelGrid::decode(m.data)?;
            self.grids += 1;
            if let Some(last) = self.maps.last_mut()
                && last.log_time == m.log_time
                && last.cells.is_none()
            {
                last.cells = Some(grid.data.to_vec());
            }
            return Ok(true);
        }
        if short.strip_prefix(map) == Some("/header") {
            let header = map_header(&serde_json::from_slice(m.data)?)?;
            self.maps.push(RecordedMap {
                log_time: m.log_time,
                header,
                cells: None,
            });
            return Ok(true);
        }
        Ok(false)
    }
}

#[cfg(test)]
#[path = "recorded_json_test.rs"]
mod tests;
