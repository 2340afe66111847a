//! `landing replay --stage depth-map`: the occupancy mapper run again on a recording's
//! vehicle states and depth frames, every map it publishes compared, cell for cell, with
//! the one the flight's depth-map published.
//!
//! Each recorded map carries depth-map's stamp: its enter is when the flight's stage
//! made it, either on a depth frame (the map's capture time is the frame's, made at the
//! time it took the frame) or on its clock (the same map again when frames stop). The
//! replay builds a new stage as `landing run` builds it, hands it each depth frame at the
//! time the flight's stage took it, after the states its pose came from (the map header
//! names the newest: `state_ns`; later ones change nothing; recordings made before it fall back to
//! every state px4-link had published by the stage's stamp, which a state published in
//! the microseconds between the flight driver's clock read and its drain can defeat),
//! ticks it at the other map times, and compares the maps in order: the header (window
//! origin, resolution, inflation, dims, capture time) and every cell of the window
//! (`/map/occupancy`, `foxglove.VoxelGrid`, one byte per cell).

use std::collections::{BTreeSet, HashMap};

use anyhow::{Result, bail};
use foxglove::Decode;
use foxglove::schemas::RawImage;
use ipc_types::msg::{
    DepthFrameHeader, Header, OccupancyMapHeader, Stage as StageId, VehicleState,
};
use ipc_types::topics;
use stage::{Input, Message, Outbox, SliceHeader, SliceMut, StageError};

use crate::replay_cmd::{Flight, ReplayArgs, ReplayReport};
use recorder::RecordedMaps;

/// The maps the replayed stage publishes, with their cells.
#[derive(Default)]
struct Maps(Vec<(OccupancyMapHeader, Vec<u8>)>);

impl Outbox for Maps {
    fn publish(&mut self, _topic: &str, _msg: Message<'_>) -> Result<(), StageError> {
        Ok(())
    }

    fn publish_slice(
        &mut self,
        _topic: &str,
        len: usize,
        fill: &mut dyn FnMut(SliceMut<'_>) -> Option<SliceHeader>,
    ) -> Result<bool, StageError> {
        let mut cells = vec![0u8; len];
        match fill(SliceMut::U8(&mut cells)) {
            Some(SliceHeader::OccupancyMap(h)) => {
                self.0.push((h, cells));
                Ok(true)
            }
            _ => Ok(false),
        }
    }
}

/// One input of the replay, in the order the flight's stage met them.
enum Event {
    /// A depth frame, and the capture time of the newest state its pose came from.
    Frame(Box<DepthFrameHeader>, Vec<u16>, u64),
    Tick,
}

fn enter_of(h: &Header, stage: StageId) -> Option<u64> {
    h.stages()
        .iter()
        .rev()
        .find(|s| s.stage == stage as u32)
        .map(|s| s.enter_ns)
}

fn exit_of(h: &Header, stage: StageId) -> Option<u64> {
    h.stages()
        .iter()
        .rev()
        .find(|s| s.stage == stage as u32)
        .map(|s| s.exit_ns)
}

/// The header's results (what the stage computed), without the stage stamps.
fn same_header(a: &OccupancyMapHeader, b: &OccupancyMapHeader) -> Option<String> {
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    if a.msg.capture_ns != b.msg.capture_ns {
        return Some(format!(
            "capture {} replayed, {} in flight",
            a.msg.capture_ns, b.msg.capture_ns
        ));
    }
    if bits(&a.origin) != bits(&b.origin) {
        return Some(format!(
            "origin {:?} replayed, {:?} in flight",
            a.origin, b.origin
        ));
    }
    if a.resolution.to_bits() != b.resolution.to_bits()
        || a.inflation.to_bits() != b.inflation.to_bits()
        || a.dims != b.dims
    {
        return Some("resolution, inflation or dims".into());
    }
    None
}

/// Replays depth-map on the recording `args.file`.
pub fn replay(args: &ReplayArgs) -> Result<ReplayReport> {
    let mut states: Vec<(u64, VehicleState)> = vec![];
    let mut frame_headers: HashMap<u64, DepthFrameHeader> = HashMap::new();
    let mut frames: HashMap<u64, Vec<u16>> = HashMap::new();
    let mut recorded = RecordedMaps::default();
    let depth = format!("/{}", topics::SIM_DEPTH);
    let summary = recorder::read_recording(&args.file, |m| {
        let topic = m.topic;
        if topic == format!("/{}", topics::VEHICLE_STATE) {
            let s: VehicleState = m.decode()?;
            let at = exit_of(&s.msg, StageId::Px4Link).unwrap_or(m.log_time);
            states.push((at, s));
        } else if topic == format!("{depth}/header") {
            let h: DepthFrameHeader = m.decode()?;
            frame_headers.insert(h.msg.capture_ns, h);
        } else if topic == depth && m.schema == "foxglove.RawImage" {
            let img = RawImage::decode(m.data)?;
            let ns = img.timestamp.map_or(0, |t| {
                u64::from(t.sec()) * 1_000_000_000 + u64::from(t.nsec())
            });
            let depths = img
                .data
                .chunks_exact(2)
                .map(|b| u16::from_le_bytes([b[0], b[1]]))
                .collect();
            frames.insert(ns, depths);
        } else {
            recorded.take(m)?;
        }
        Ok(())
    })?;
    let flight = Flight::of(args, &summary)?;
    let RecordedMaps { maps, grids } = recorded;
    if maps.is_empty() {
        bail!("{}: no maps (/map/occupancy/header)", args.file.display());
    }
    if grids == 0 {
        bail!(
            "{}: no map cells (/map/occupancy, foxglove.VoxelGrid): recorded before the recorder kept them",
            args.file.display()
        );
    }
    if frames.is_empty() {
        bail!("{}: no depth frames (/sim/depth)", args.file.display());
    }
    let Some(mut stage) = flight.stage("depth-map")? else {
        bail!("no stage for depth-map");
    };

    // When the flight's stage made each map; a frame's map at the time it took the frame.
    let mut events: Vec<(u64, u8, Event)> = vec![];
    let mut framed: BTreeSet<u64> = BTreeSet::new();
    for m in &maps {
        let Some(at) = enter_of(&m.header.msg, StageId::DepthMap) else {
            continue;
        };
        let capture = m.header.msg.capture_ns;
        let from_frame = !framed.contains(&capture)
            && frame_headers.contains_key(&capture)
            && frames.contains_key(&capture);
        if from_frame {
            framed.insert(capture);
            let (Some(h), Some(d)) = (frame_headers.get(&capture), frames.remove(&capture)) else {
                continue;
            };
            events.push((at, 0, Event::Frame(Box::new(*h), d, m.header.state_ns)));
        } else {
            events.push((at, 1, Event::Tick));
        }
    }
    // The frame before the clock at a tie (the driver's order).
    events.sort_by_key(|(at, kind, _)| (*at, *kind));
    states.sort_by_key(|(at, _)| *at);
    let mut states = states.into_iter().peekable();
    let mut out = Maps::default();
    let mut inputs = 0u64;
    for (at, _, e) in &events {
        match e {
            Event::Frame(h, d, state_ns) => {
                // The states the pose came from: up to the newest the map names, or
                // (an older recording) every one published by the stage's stamp.
                let held = |(published, s): &(u64, VehicleState)| match *state_ns {
                    0 => *published <= *at,
                    newest => s.msg.capture_ns <= newest,
                };
                while let Some((_, s)) = states.next_if(held) {
                    let input = Input {
                        topic: topics::VEHICLE_STATE,
                        msg: Message::VehicleState(&s),
                    };
                    stage.on_input(*at, input, &mut out)?;
                    inputs += 1;
                }
                let input = Input {
                    topic: topics::SIM_DEPTH,
                    msg: Message::DepthFrame(h, d),
                };
                stage.on_input(*at, input, &mut out)?;
            }
            Event::Tick => stage.on_tick(*at, &mut out)?,
        }
        inputs += 1;
    }
    let mut report = ReplayReport {
        stage: "depth-map".into(),
        inputs,
        recorded: maps.len() as u64,
        replayed: out.0.len() as u64,
        identical: 0,
        different: 0,
        differences: vec![],
        missing: vec![],
        extra: out.0.len().saturating_sub(maps.len()) as u64,
        flown: vec![],
    };
    for (i, m) in maps.iter().enumerate() {
        let Some((h, cells)) = out.0.get(i) else {
            report.missing.push(m.header.msg.capture_ns);
            continue;
        };
        let diff = same_header(h, &m.header).or_else(|| match &m.cells {
            None => Some("no recorded cells to compare".into()),
            Some(c) if c == cells => None,
            Some(c) => {
                let n = c.iter().zip(cells).filter(|(a, b)| a != b).count();
                Some(format!("{n} of {} cells differ", c.len()))
            }
        });
        match diff {
            None => report.identical += 1,
            Some(d) => {
                report.different += 1;
                if report.differences.len() < 10 {
                    report.differences.push(format!("map {i}: {d}"));
                }
            }
        }
    }
    Ok(report)
}
