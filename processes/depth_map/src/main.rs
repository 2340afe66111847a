//! `depth-map`: the occupancy window as its own process.
//!
//! Reads depth frames (`landing/sim/depth`, or `landing/depth/frame` with
//! `--input depth-frame`) and the vehicle state (`landing/vehicle/state`), publishes the
//! inflated window on `landing/map/occupancy`, written in place into a loaned
//! shared-memory slice. Everything it computes is `depth_map::DepthMapper`; this file
//! binds it to iceoryx2, the clock and the logs.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::{Context, Result, anyhow};
use clap::Parser;
use depth_map::{DepthError, DepthMapConfig, DepthMapper, DepthView, Input};
use ipc_types::msg::{DepthFrameHeader, Header, OccupancyMapHeader, Stage, VehicleState};
use ipc_types::services;
use runtime::ipc::{Wake, run_wait_loop};
use runtime::{Ipc, IpcPrefix, SendError, SlicePublisher, Subscriber, monotonic_ns};
use stack_config::{IpcConfig, load_process_or_default};

/// The iceoryx2 node and heartbeat name.
const PROCESS: &str = "depth-map";

/// Builds the local occupancy map from depth frames and the vehicle state, and publishes
/// it (landing/map/occupancy) at least every publish_period_ms.
#[derive(Debug, Parser)]
#[command(name = "depth-map", version, about)]
struct Args {
    /// Stack configuration (reads [ipc] and [depth_map]; defaults when absent).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Where depth frames come from: `sim` (landing/sim/depth) or `depth-frame`
    /// (landing/depth/frame) [default: [depth_map] input, else sim].
    #[arg(long)]
    input: Option<String>,
    /// iceoryx2 prefix (default: $LANDING_IPC_PREFIX, else [ipc] prefix).
    #[arg(long)]
    ipc_prefix: Option<String>,
}

fn main() -> ExitCode {
    runtime::process_main("info", run)
}

/// Losses the process counts besides the mapper's own counters.
#[derive(Debug, Default, Clone, Copy, PartialEq)]
struct Counts {
    published: u64,
    skipped_stale: u64,
    lost_upstream: u64,
    dropped_no_buffer: u64,
}

/// Logs losses at most once per second, with every counter and the latest reason.
struct DropLog {
    next_ns: u64,
    logged_faults: u64,
    last: Option<DepthError>,
}

impl DropLog {
    fn maybe_log(&mut self, mapper: &DepthMapper, counts: &Counts, now_ns: u64) {
        let c = mapper.counters();
        let faults = c.frames - c.integrated
            + c.bad_states
            + counts.skipped_stale
            + counts.lost_upstream
            + counts.dropped_no_buffer;
        if faults == self.logged_faults || now_ns < self.next_ns {
            return;
        }
        self.logged_faults = faults;
        self.next_ns = now_ns + 1_000_000_000;
        let last = self.last.take();
        tracing::warn!(
            frames = c.frames,
            integrated = c.integrated,
            no_state = c.no_state,
            stale_state = c.stale_state,
            too_old = c.too_old,
            bad_frames = c.bad_frames,
            bad_poses = c.bad_poses,
            bad_states = c.bad_states,
            skipped_stale = counts.skipped_stale,
            lost_upstream = counts.lost_upstream,
            dropped_no_buffer = counts.dropped_no_buffer,
            last = %last.as_ref().map_or(String::new(), ToString::to_string),
            "depth frames skipped"
        );
    }
}

fn run(args: &Args) -> Result<()> {
    let (ipc_cfg, mut cfg): (IpcConfig, DepthMapConfig) =
        load_process_or_default(args.config.as_deref(), "depth_map")?;
    if let Some(i) = args.input.as_deref() {
        cfg.input = Input::parse(i)
            .ok_or_else(|| anyhow!("--input `{i}` is not allowed (allowed: sim, depth-frame)"))?;
    }
    let mut mapper = DepthMapper::from_config(&cfg)?;
    let prefix = IpcPrefix::resolve(args.ipc_prefix.as_deref(), &ipc_cfg.prefix)?;
    let ipc = Ipc::open(PROCESS, &prefix)?;
    let frames = ipc
        .slice_subscriber::<u16, DepthFrameHeader>(cfg.input.service())
        .context("depth frames")?;
    let states = ipc
        .subscriber::<VehicleState>(services::VEHICLE_STATE)
        .context("vehicle state")?;
    let cells = mapper.map().cell_count();
    let mut maps = ipc
        .slice_publisher::<u8, OccupancyMapHeader>(services::MAP_OCCUPANCY, cells)
        .context("occupancy map")?;
    let mut heartbeat = ipc.heartbeat(Duration::from_millis(ipc_cfg.heartbeat_deadline_ms))?;
    let dims = mapper.map().dims();
    tracing::info!(
        input = cfg.input.service(),
        dims = ?dims,
        resolution_m = cfg.resolution_m,
        memory_kib = mapper.map().memory_bytes() / 1024,
        "depth-map running"
    );

    let publish_period_ns = cfg.publish_period_ms * 1_000_000;
    let beat_period_ns = ipc_cfg.heartbeat_period_ms * 1_000_000;
    let tick = Duration::from_millis(cfg.publish_period_ms.min(ipc_cfg.heartbeat_period_ms) / 2);
    let mut counts = Counts::default();
    let mut drops = DropLog {
        next_ns: 0,
        logged_faults: 0,
        last: None,
    };
    let mut upstream = Header::default();
    let mut last_publish_ns = 0u64;
    let mut next_beat_ns = 0u64;
    let mut next_report_ns = monotonic_ns() + 10_000_000_000;
    let mut gaps_seen = 0;
    let mut failure = None;
    let exit = run_wait_loop(
        &[frames.listener(), states.listener()],
        &[],
        Some(tick.max(Duration::from_millis(5))),
        |wake| {
            let now = monotonic_ns();
            if let Wake::Data(0) = wake {
                // States first: the frame's capture time may need the newest one.
                drain_states(&states, &mut mapper);
                let enter = monotonic_ns();
                // Only the newest waiting frame is mapped: older ones are counted.
                let mut newest = None;
                loop {
                    match frames.receive() {
                        Ok(Some(s)) => {
                            if newest.replace(s).is_some() {
                                counts.skipped_stale += 1;
                            }
                        }
                        Ok(None) => break,
                        Err(e) => {
                            failure = Some(anyhow::Error::from(e));
                            return false;
                        }
                    }
                }
                let gaps = frames.gaps();
                if gaps > gaps_seen {
                    counts.lost_upstream += gaps - gaps_seen;
                    gaps_seen = gaps;
                }
                if let Some(sample) = newest {
                    let header = *sample.user_header();
                    let result = DepthView::from_wire(&header, sample.payload())
                        .inspect_err(|_| mapper.record_bad_frame())
                        .and_then(|view| mapper.process(&view, header.msg.capture_ns));
                    drop(sample);
                    match result {
                        Ok(_) => {
                            upstream = header.msg;
                            match publish(&mut maps, &mapper, &upstream, enter, &mut counts) {
                                Ok(()) => last_publish_ns = monotonic_ns(),
                                Err(e) => {
                                    failure = Some(e.into());
                                    return false;
                                }
                            }
                        }
                        Err(e) => drops.last = Some(e),
                    }
                }
            } else if let Wake::Data(_) = wake {
                drain_states(&states, &mut mapper);
            }
            if now.saturating_sub(last_publish_ns) >= publish_period_ns {
                // Nothing new for a period: the same map again (same capture time), so
                // the planner keeps a rate it can supervise.
                if let Err(e) = publish(&mut maps, &mapper, &upstream, now, &mut counts) {
                    failure = Some(e.into());
                    return false;
                }
                last_publish_ns = monotonic_ns();
            }
            if now >= next_beat_ns {
                if let Err(e) = heartbeat.beat() {
                    failure = Some(e.into());
                    return false;
                }
                next_beat_ns = now + beat_period_ns;
                drops.maybe_log(&mapper, &counts, now);
            }
            if now >= next_report_ns {
                next_report_ns = now + 10_000_000_000;
                report(&mapper, &counts, "depth-map");
            }
            true
        },
    )?;
    if let Some(e) = failure {
        return Err(e);
    }
    report(&mapper, &counts, "depth-map stopped");
    tracing::info!(?exit, "depth-map exiting");
    Ok(())
}

fn report(mapper: &DepthMapper, counts: &Counts, what: &'static str) {
    let c = mapper.counters();
    let census = mapper.map().census();
    tracing::info!(
        frames = c.frames,
        integrated = c.integrated,
        published = counts.published,
        no_state = c.no_state,
        stale_state = c.stale_state,
        too_old = c.too_old,
        bad_frames = c.bad_frames,
        bad_poses = c.bad_poses,
        bad_states = c.bad_states,
        recenters = c.recenters,
        lost_upstream = counts.lost_upstream,
        dropped_no_buffer = counts.dropped_no_buffer,
        occupied = census.occupied,
        free = census.free,
        unknown = census.unknown,
        "{what}"
    );
}

fn drain_states(states: &Subscriber<VehicleState>, mapper: &mut DepthMapper) {
    while let Ok(Some(s)) = states.receive() {
        mapper.push_state_msg(s.payload());
    }
}

/// Writes the map straight into a loaned sample and sends it. A loan that fails (every
/// sample held by subscribers) drops this map, counted: the process never waits.
fn publish(
    maps: &mut SlicePublisher<u8, OccupancyMapHeader>,
    mapper: &DepthMapper,
    upstream: &Header,
    enter_ns: u64,
    counts: &mut Counts,
) -> Result<(), SendError> {
    let map = mapper.map();
    let Ok(mut sample) = maps.loan(map.cell_count()) else {
        counts.dropped_no_buffer += 1;
        return Ok(());
    };
    let Ok(wire) = map.write_wire(sample.payload_mut()) else {
        counts.dropped_no_buffer += 1;
        return Ok(());
    };
    // Never publish a non-finite number (the map's geometry is finite by construction;
    // this is the last line of defence).
    if !(wire.origin.iter().all(|v| v.is_finite())
        && wire.resolution.is_finite()
        && wire.inflation.is_finite())
    {
        return Ok(());
    }
    let mut msg = Header::derived_from(upstream);
    msg.push_stage(Stage::DepthMap, enter_ns, monotonic_ns());
    *sample.user_header_mut() = OccupancyMapHeader { msg, ..wire };
    maps.send(sample)?;
    counts.published += 1;
    Ok(())
}
