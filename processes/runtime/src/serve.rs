//! What every stage binary shares: the common flags and `serve`, which finds the node
//! in the graph, opens the process's iceoryx2 node and runs the stage on the iceoryx2
//! driver. A stage binary's `main.rs` builds its stage from its config and calls this.

use std::path::PathBuf;
use std::time::Duration;

use graph::{Graph, GraphError};
use stack_config::{ConfigError, IpcConfig, Validate, deploy_dir, load_process_or_default};
use stage::lockstep::NodeSpec;
use stage::{External, Stage};

use crate::driver::{self, Beat, DriverError};
use crate::ipc::{Ipc, IpcPrefix, NodeError, PrefixError};

/// The flags every stage binary takes.
#[derive(Debug, Clone, clap::Args)]
pub struct StageArgs {
    /// Stack configuration (deploy/config/landing.toml; defaults when absent).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// The dataflow graph (default: graph.toml in the deploy directory): which topics
    /// this node reads and publishes, with which policy.
    #[arg(long)]
    pub graph: Option<PathBuf>,
    /// The deploy directory (default: $LANDING_DEPLOY_DIR, else found above the current
    /// directory or the executable).
    #[arg(long)]
    pub deploy_dir: Option<PathBuf>,
    /// iceoryx2 prefix (default: $LANDING_IPC_PREFIX, else [ipc] prefix).
    #[arg(long)]
    pub ipc_prefix: Option<String>,
}

/// Why a stage binary could not serve.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    /// The graph file.
    #[error(transparent)]
    Graph(#[from] GraphError),
    /// The graph has no node of this stage's name.
    #[error("{file}: no node `{node}` (this binary runs that stage)")]
    NotInGraph {
        /// The graph file.
        file: String,
        /// The stage's node name.
        node: String,
    },
    /// The prefix.
    #[error(transparent)]
    Prefix(#[from] PrefixError),
    /// The iceoryx2 node.
    #[error(transparent)]
    Node(#[from] NodeError),
    /// The driver.
    #[error(transparent)]
    Driver(#[from] DriverError),
}

impl StageArgs {
    /// The deploy directory.
    pub fn deploy(&self) -> PathBuf {
        self.deploy_dir.clone().unwrap_or_else(deploy_dir)
    }

    /// The directory files named in the config are relative to: the config file's, else
    /// (no `--config`) the deploy directory's `config/`.
    pub fn config_dir(&self) -> PathBuf {
        match &self.config {
            Some(file) => file
                .parent()
                .filter(|d| !d.as_os_str().is_empty())
                .map_or_else(|| PathBuf::from("."), PathBuf::from),
            None => self.deploy().join("config"),
        }
    }

    /// `[ipc]` of the config (defaults without `--config`), for a binary with no section
    /// of its own.
    pub fn ipc(&self) -> Result<IpcConfig, ConfigError> {
        load_process_or_default::<IpcConfig>(self.config.as_deref(), "ipc").map(|(ipc, _)| ipc)
    }

    /// `[ipc]` and the stage's `[section]` of the config (defaults without `--config`).
    pub fn load<T>(&self, section: &str) -> Result<(IpcConfig, T), ConfigError>
    where
        T: serde::de::DeserializeOwned + Validate + Default,
    {
        load_process_or_default(self.config.as_deref(), section)
    }
}

/// Runs `stage` as its graph node until SIGTERM/SIGINT. `rename` reads an input from
/// another topic of the same type (depth-map `--input depth-frame`).
pub fn serve(
    args: &StageArgs,
    ipc_cfg: &IpcConfig,
    stage: &mut dyn Stage,
    external: Option<&mut dyn External>,
    rename: Option<(&str, &str)>,
) -> Result<(), ServeError> {
    let path = args
        .graph
        .clone()
        .unwrap_or_else(|| graph::default_path(&args.deploy()));
    let graph = Graph::load(&path)?;
    let node = graph
        .node(stage.name())
        .ok_or_else(|| ServeError::NotInGraph {
            file: path.display().to_string(),
            node: stage.name().to_string(),
        })?;
    let mut spec = node.spec();
    if let Some((from, to)) = rename {
        for i in spec.inputs.iter_mut().filter(|i| i.topic == from) {
            i.topic = to.to_string();
        }
    }
    let prefix = IpcPrefix::resolve(args.ipc_prefix.as_deref(), &ipc_cfg.prefix)?;
    // One stack per prefix: a second process of this node refuses to start.
    let ipc = Ipc::open_exclusive(stage.name(), &prefix)?;
    let beat = Beat {
        period: Duration::from_millis(ipc_cfg.heartbeat_period_ms),
        deadline: Duration::from_millis(node.heartbeat_deadline_ms),
    };
    driver::run(&ipc, &spec, stage, external, beat)?;
    Ok(())
}

/// Runs `stage` as a process on the iceoryx2 driver with a node of its own, `spec`, for a
/// process that reads the graph rather than being one of its nodes (the recorder: every
/// topic; depth-ingest, a sensor driver the simulated graph does without, with its capture
/// thread as `external`): its prefix from `args`, its heartbeat every `[ipc]
/// heartbeat_period_ms` with `deadline`. Returns when SIGTERM or SIGINT stops it.
pub fn serve_spec(
    args: &StageArgs,
    ipc_cfg: &IpcConfig,
    spec: &NodeSpec,
    deadline: Duration,
    stage: &mut dyn Stage,
    external: Option<&mut dyn External>,
) -> Result<(), ServeError> {
    let prefix = IpcPrefix::resolve(args.ipc_prefix.as_deref(), &ipc_cfg.prefix)?;
    let ipc = Ipc::open(stage.name(), &prefix)?;
    let beat = Beat {
        period: Duration::from_millis(ipc_cfg.heartbeat_period_ms),
        deadline,
    };
    driver::run(&ipc, spec, stage, external, beat)?;
    Ok(())
}
