//! What the `recorder` process is built from: its flags, its node (every iceoryx2 topic
//! of the graph as a queued input: the recorder is no node of the graph, it reads them
//! all), the recording and its metadata (`RecorderStage::from_config`). Its `main.rs`
//! hands the stage to the iceoryx2 driver; what it does with each message is
//! [`RecorderStage`]'s.

use std::path::{Path, PathBuf};

use graph::{Graph, GraphError, Transport};
use ipc_types::msg::Pose;
use stack_config::{ConfigError, Invalid};
use stage::lockstep::{InputSpec, NodeSpec};

use crate::metadata::{self, MetadataError};
use crate::{RecordError, Recorder, RecorderConfig, RecorderStage};

/// The recorder's own flags (beside [`StageArgs`]).
#[derive(Debug, Clone, clap::Args)]
pub struct RecorderArgs {
    /// The recording to write (created or truncated). Without it (or --out-dir), only the
    /// live view.
    #[arg(long, conflicts_with = "out_dir")]
    pub out: Option<PathBuf>,
    /// Write the recording into this directory, named by the UTC time it starts
    /// (20261126T201500Z.mcap): what the systemd unit does, one file per start.
    #[arg(long, value_name = "DIR")]
    pub out_dir: Option<PathBuf>,
    /// Serve the live view (Foxglove's WebSocket protocol) on [recorder] live_address,
    /// as [recorder] live = true does.
    #[arg(long)]
    pub live: bool,
    /// Camera frames as foxglove.RawImage (exact; what `landing replay --stage
    /// aruco-pnp` needs) instead of [recorder] images.
    #[arg(long)]
    pub raw_images: bool,
    /// Chunk compression instead of [recorder] compression: zstd, lz4 or none.
    #[arg(long, value_name = "zstd|lz4|none")]
    pub compression: Option<String>,
    /// Adds KEY=VALUE to the recording's `landing` metadata (repeatable): what the
    /// starter knows (`landing run` adds scenario, seed and mode).
    #[arg(long, value_name = "KEY=VALUE", value_parser = parse_meta)]
    pub meta: Vec<(String, String)>,
}

/// `KEY=VALUE`, for `--meta`.
fn parse_meta(s: &str) -> Result<(String, String), String> {
    match s.split_once('=') {
        Some((k, v)) if !k.is_empty() => Ok((k.to_string(), v.to_string())),
        _ => Err(format!("`{s}` is not KEY=VALUE")),
    }
}

/// Why the recorder could not record (one line on stderr, exit code 2).
#[derive(Debug, thiserror::Error)]
pub enum ProcessError {
    /// The config file.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// A `[recorder]` value that parsed but is not allowed.
    #[error("[recorder] {}: {}", .0.key, .0.message)]
    Invalid(Invalid),
    /// The config file, read again for the cameras' mounts.
    #[error("reading {}: {error}", path.display())]
    ReadConfig {
        /// The config file.
        path: PathBuf,
        /// What the OS said.
        error: std::io::Error,
    },
    /// The config file does not parse as TOML (for the cameras' mounts).
    #[error("{}: not TOML", path.display())]
    NotToml {
        /// The config file.
        path: PathBuf,
        /// What the parser said.
        #[source]
        error: toml::de::Error,
    },
    /// The graph file.
    #[error(transparent)]
    Graph(#[from] GraphError),
    /// `--out-dir` cannot be made.
    #[error("cannot create the recording directory {}: {error}", dir.display())]
    OutDir {
        /// The directory.
        dir: PathBuf,
        /// What the OS said.
        error: std::io::Error,
    },
    /// The writer thread cannot be started.
    #[error("cannot start the recorder's writer thread: {0}")]
    Thread(std::io::Error),
    /// Neither a file nor the live view was asked for.
    #[error(
        "nothing to do: give --out FILE.mcap (or --out-dir DIR), --live, or both ([recorder] live = true)"
    )]
    NothingToDo,
    /// The recording (creating it, the live view, its metadata).
    #[error(transparent)]
    Record(#[from] RecordError),
    /// The recording's metadata.
    #[error(transparent)]
    Metadata(#[from] MetadataError),
}

impl RecorderStage {
    /// The one way the recorder's stage is built: from its `[recorder]` section (with
    /// `args`' overrides applied here), the config file it came from (the cameras'
    /// mounts) and the graph (every iceoryx2 topic, as the node's queued inputs: the
    /// recorder is no node of the graph, it reads them all). The recording is created,
    /// its metadata written, the live view served. Returns the stage, its node and what
    /// it writes to (for the log).
    pub fn from_config(
        mut cfg: RecorderConfig,
        args: &RecorderArgs,
        config: Option<&Path>,
        graph_path: &Path,
    ) -> Result<(Self, NodeSpec, String), ProcessError> {
        if args.raw_images {
            cfg.images = "raw".into();
        }
        if let Some(c) = &args.compression {
            cfg.compression = c.clone();
        }
        let graph = Graph::load(graph_path)?;
        let spec = node_spec(&graph, &cfg.skip);
        let mut options = cfg.options().map_err(ProcessError::Invalid)?;
        let (camera, depth) = mounts(config)?;
        options.body_from_camera = camera;
        options.body_from_depth = depth;
        let live = args.live || cfg.live;
        let out = match (&args.out, &args.out_dir) {
            (Some(p), _) => Some(p.clone()),
            (None, Some(dir)) => Some(
                crate::dated_path(dir, std::time::SystemTime::now()).map_err(|error| {
                    ProcessError::OutDir {
                        dir: dir.clone(),
                        error,
                    }
                })?,
            ),
            (None, None) => None,
        };
        let mut rec = match &out {
            Some(out) => Recorder::with_options(out, options)?,
            None if live => Recorder::without_file(options),
            None => return Err(ProcessError::NothingToDo),
        };
        if live {
            let address = cfg.live_socket().map_err(ProcessError::Invalid)?;
            let at = rec.serve_live(address)?;
            tracing::info!(address = %at, "live view: open ws://{at} in Foxglove");
        }
        let mut meta = metadata::stack(config, graph_path)?;
        meta.insert("topics".into(), spec_topics(&spec));
        meta.extend(args.meta.iter().cloned());
        rec.write_metadata("landing", meta)?;
        let out = out.as_ref().map_or_else(
            || "(live view only)".to_string(),
            |p| p.display().to_string(),
        );
        tracing::info!(out = %out, topics = spec.inputs.len(), "recording");
        let stage = Self::new(rec).map_err(ProcessError::Thread)?;
        Ok((stage, spec, out))
    }
}

/// The cameras' mounts from the config file (none without one).
fn mounts(config: Option<&Path>) -> Result<(Option<Pose>, Option<Pose>), ProcessError> {
    let Some(path) = config else {
        return Ok((None, None));
    };
    let text = std::fs::read_to_string(path).map_err(|error| ProcessError::ReadConfig {
        path: path.to_path_buf(),
        error,
    })?;
    crate::config::mounts(&text).map_err(|error| ProcessError::NotToml {
        path: path.to_path_buf(),
        error,
    })
}

/// The recorder's node: every iceoryx2 topic of the graph that is not ground truth or
/// skipped, taken in full (queued) in the order of the graph.
pub fn node_spec(graph: &Graph, skip: &[String]) -> NodeSpec {
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

/// The topics the node records, for the metadata: `vehicle/state,fsm/status,...`.
fn spec_topics(spec: &NodeSpec) -> String {
    let names: Vec<&str> = spec.inputs.iter().map(|i| i.topic.as_str()).collect();
    names.join(",")
}
