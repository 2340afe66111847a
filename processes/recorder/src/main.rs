//! `recorder`: every topic of the graph into one MCAP file (Foxglove schemas, JSON for
//! everything plottable), flushed every second so that it reads back if killed, finished
//! on SIGTERM. Everything it computes is `recorder::RecorderStage`; this file builds the
//! node (all iceoryx2 topics of the graph as queued inputs), the recording and its
//! metadata, and hands them to the iceoryx2 driver.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::{Context as _, Result};
use clap::Parser;
use graph::{Graph, Transport};
use ipc_types::msg::Pose;
use recorder::{Recorder, RecorderConfig, RecorderStage, metadata};
use runtime::StageArgs;
use runtime::driver::{self, Beat};
use runtime::ipc::{Ipc, IpcPrefix};
use stage::lockstep::{InputSpec, NodeSpec};

/// Records every topic of the landing pipeline into one MCAP file for Foxglove.
#[derive(Debug, Parser)]
#[command(name = "recorder", version, about)]
struct Args {
    #[command(flatten)]
    stage: StageArgs,
    /// The recording to write (created or truncated). Without it (or --out-dir), only the
    /// live view.
    #[arg(long, conflicts_with = "out_dir")]
    out: Option<PathBuf>,
    /// Write the recording into this directory, named by the UTC time it starts
    /// (20261126T201500Z.mcap): what the systemd unit does, one file per start.
    #[arg(long, value_name = "DIR")]
    out_dir: Option<PathBuf>,
    /// Serve the live view (Foxglove's WebSocket protocol) on [recorder] live_address,
    /// as [recorder] live = true does.
    #[arg(long)]
    live: bool,
    /// Camera frames as foxglove.RawImage (exact; what `landing replay --stage
    /// aruco-pnp` needs) instead of [recorder] images.
    #[arg(long)]
    raw_images: bool,
    /// Chunk compression instead of [recorder] compression: zstd, lz4 or none.
    #[arg(long, value_name = "zstd|lz4|none")]
    compression: Option<String>,
    /// Adds KEY=VALUE to the recording's `landing` metadata (repeatable): what the
    /// starter knows (`landing run` adds scenario, seed and mode).
    #[arg(long, value_name = "KEY=VALUE", value_parser = parse_meta)]
    meta: Vec<(String, String)>,
}

fn parse_meta(s: &str) -> Result<(String, String), String> {
    match s.split_once('=') {
        Some((k, v)) if !k.is_empty() => Ok((k.to_string(), v.to_string())),
        _ => Err(format!("`{s}` is not KEY=VALUE")),
    }
}

fn main() -> ExitCode {
    runtime::process_main("info", run)
}

fn run(args: &Args) -> Result<()> {
    let (ipc_cfg, mut cfg): (_, RecorderConfig) = args.stage.load("recorder")?;
    if args.raw_images {
        cfg.images = "raw".into();
    }
    if let Some(c) = &args.compression {
        cfg.compression = c.clone();
    }
    let graph_path = args
        .stage
        .graph
        .clone()
        .unwrap_or_else(|| graph::default_path(&args.stage.deploy()));
    let graph = Graph::load(&graph_path)?;
    let spec = node_spec(&graph, &cfg.skip);
    let mut options = cfg
        .options()
        .map_err(|e| anyhow::anyhow!("[recorder] {}: {}", e.key, e.message))?;
    let (camera, depth) = mounts(args.stage.config.as_deref())?;
    options.body_from_camera = camera;
    options.body_from_depth = depth;
    let live = args.live || cfg.live;
    let out = match (&args.out, &args.out_dir) {
        (Some(p), _) => Some(p.clone()),
        (None, Some(dir)) => Some(recorder::dated_path(dir, std::time::SystemTime::now())?),
        (None, None) => None,
    };
    let mut rec = match &out {
        Some(out) => Recorder::with_options(out, options)?,
        None if live => Recorder::without_file(options),
        None => anyhow::bail!(
            "nothing to do: give --out FILE.mcap (or --out-dir DIR), --live, or both ([recorder] live = true)"
        ),
    };
    if live {
        let address = cfg
            .live_socket()
            .map_err(|e| anyhow::anyhow!("[recorder] {}: {}", e.key, e.message))?;
        let at = rec.serve_live(address)?;
        tracing::info!(address = %at, "live view: open ws://{at} in Foxglove");
    }
    let mut meta = metadata::stack(args.stage.config.as_deref(), &graph_path)?;
    meta.insert("topics".into(), spec_topics(&spec));
    meta.extend(args.meta.iter().cloned());
    rec.write_metadata("landing", meta)?;
    let prefix = IpcPrefix::resolve(args.stage.ipc_prefix.as_deref(), &ipc_cfg.prefix)?;
    let ipc = Ipc::open("recorder", &prefix)?;
    let beat = Beat {
        period: Duration::from_millis(ipc_cfg.heartbeat_period_ms),
        deadline: Duration::from_millis(500),
    };
    let mut stage = RecorderStage::new(rec);
    let out = out.as_ref().map_or_else(
        || "(live view only)".to_string(),
        |p| p.display().to_string(),
    );
    tracing::info!(out = %out, topics = spec.inputs.len(), "recording");
    let served = driver::run(&ipc, &spec, &mut stage, None, beat);
    // The file is finished whatever ended the run.
    let n = stage.finish().with_context(|| format!("finishing {out}"))?;
    served?;
    tracing::info!(messages = n, out = %out, "recording finished");
    Ok(())
}

/// The cameras' mounts from the config file (none without one).
fn mounts(config: Option<&std::path::Path>) -> Result<(Option<Pose>, Option<Pose>)> {
    let Some(path) = config else {
        return Ok((None, None));
    };
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    recorder::config::mounts(&text).with_context(|| format!("{}: not TOML", path.display()))
}

/// Every iceoryx2 topic of the graph that is not ground truth or skipped, taken in
/// full (queued) in the order of the graph.
fn node_spec(graph: &Graph, skip: &[String]) -> NodeSpec {
    let inputs = graph
        .topics
        .iter()
        .filter(|t| t.transport == Transport::Iceoryx2 && !t.evaluator_only)
        .filter(|t| !skip.contains(&t.name))
        .map(|t| InputSpec {
            topic: t.name.clone(),
            newest: false,
            delay: false,
            // Every message counts: the deepest buffer the topic allows.
            depth: Some(stage::max_depth(t.elements.as_deref())),
        })
        .collect();
    NodeSpec {
        name: "recorder".into(),
        inputs,
        outputs: vec![],
        latency_ns: 0,
        periodic: None,
    }
}

fn spec_topics(spec: &NodeSpec) -> String {
    let names: Vec<&str> = spec.inputs.iter().map(|i| i.topic.as_str()).collect();
    names.join(",")
}
