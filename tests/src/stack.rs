//! The whole stack as OS processes in a test, started from the graph
//! (deploy/graph.toml) with the arguments `landing run --processes` gives them
//! (`landing::run_processes::run_values`), under a fresh iceoryx2 prefix and fresh UDP
//! ports, so a test can stop and restart any one of them while the others keep running.

use std::collections::BTreeMap;
use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus};
use std::time::Duration;

use graph::{Graph, RunValues};
use runtime::IpcPrefix;
use stack::processes::run_values;

use crate::process::Running;

/// Every stack process, in the order `landing run --processes` starts them (the
/// simulator last, so the stages' ports exist before its clock starts); the shipped
/// graph's start order (each [`Stack`] checks the two agree).
pub const STAGES: [&str; 8] = [
    "px4-link",
    "camera-ingest",
    "aruco-pnp",
    "depth-map",
    "planner",
    "fsm",
    "watchdog",
    "sim",
];

/// The workspace root (this crate is `tests/` in it).
pub fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The shipped deploy directory.
pub fn deploy_dir() -> PathBuf {
    workspace().join("deploy")
}

/// The stack binary `name` next to the running test executable (`target/<profile>/name`,
/// the test being `target/<profile>/deps/<test>`). `cargo test --release --workspace`
/// (and `make test`) builds every binary; panics with how to build it otherwise.
pub fn stack_binary(name: &str) -> PathBuf {
    let profile_dir = std::env::current_exe()
        .ok()
        .and_then(|exe| exe.parent().and_then(Path::parent).map(Path::to_path_buf))
        .unwrap_or_default();
    let path = profile_dir.join(name);
    assert!(
        path.is_file(),
        "{} is missing: build it with `cargo build --release --workspace` \
         (`cargo test --release --workspace` builds it)",
        path.display()
    );
    path
}

/// A free local UDP port (bound and released).
fn free_udp_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .map(|a| a.port())
        .unwrap_or_else(|e| panic!("no free UDP port: {e}"))
}

/// The stack of one scenario: its processes, any of which may be stopped and started
/// again. Whatever still runs is killed when it is dropped.
pub struct Stack {
    graph: Graph,
    values: RunValues,
    prefix: IpcPrefix,
    running: BTreeMap<&'static str, Running>,
}

impl Stack {
    /// A stack for the shipped `scenario` with nothing started yet; the simulator runs
    /// for `duration_s` simulated seconds once started.
    pub fn new(scenario: &str, duration_s: f64) -> Self {
        let deploy = deploy_dir();
        let scenario = sim::scenario::load(scenario, &deploy)
            .unwrap_or_else(|e| panic!("scenario {scenario}: {e}"));
        let graph = Graph::load(&deploy.join("graph.toml")).unwrap_or_else(|e| panic!("{e}"));
        let order: Vec<&str> = graph
            .start_order()
            .into_iter()
            .map(|n| n.name.as_str())
            .collect();
        assert_eq!(order, STAGES, "the graph's start order");
        let values = run_values(
            &scenario,
            scenario.scenario.seed,
            duration_s,
            &deploy.join("config/landing.toml"),
            &deploy,
            (free_udp_port(), free_udp_port()),
            "",
        )
        .unwrap_or_else(|e| panic!("run values: {e}"));
        Self {
            graph,
            values,
            prefix: IpcPrefix::unique("stack"),
            running: BTreeMap::new(),
        }
    }

    /// The stack's iceoryx2 prefix (for the test's own subscribers).
    pub fn prefix(&self) -> &IpcPrefix {
        &self.prefix
    }

    /// The command line of stage `name`: the graph's, as `landing run --processes`
    /// builds it.
    pub fn command(&self, name: &str) -> Command {
        let node = self
            .graph
            .node(name)
            .unwrap_or_else(|| panic!("{name} is not a node of the graph (allowed: {STAGES:?})"));
        let mut cmd = Command::new(stack_binary(&node.binary));
        cmd.args(node.command_args(&self.values));
        cmd.arg("--ipc-prefix").arg(self.prefix.as_str());
        cmd.env("LANDING_LOG", "info");
        cmd
    }

    /// Starts stage `name` outside the stack's own set (the caller stops it) and waits
    /// until it says it runs.
    pub fn spawn(&self, name: &'static str) -> Running {
        let running = Running::start(name, &mut self.command(name));
        running.wait_for(&format!("{name} running"), Duration::from_secs(30));
        running
    }

    /// Starts stage `name` as one of the stack's own and waits until it says it runs.
    pub fn start(&mut self, name: &'static str) {
        assert!(
            !self.running.contains_key(name),
            "{name} is already running"
        );
        let running = self.spawn(name);
        self.running.insert(name, running);
    }

    /// Starts every stage except those in `except`, in the launch order.
    pub fn start_all_but(&mut self, except: &[&str]) {
        for name in STAGES {
            if !except.contains(&name) {
                self.start(name);
                if name != "sim" {
                    // As `landing run --processes`: ports open before the clock starts.
                    std::thread::sleep(Duration::from_millis(150));
                }
            }
        }
    }

    /// Stops every stage with SIGTERM, the simulator first, and returns how each ended
    /// with its log.
    pub fn stop_all(&mut self) -> Vec<(&'static str, ExitStatus, String)> {
        let mut order: Vec<&'static str> = self.running.keys().copied().collect();
        order.sort_by_key(|n| *n != "sim");
        let mut ended = Vec::new();
        for name in order {
            if let Some(mut r) = self.running.remove(name) {
                let status = r.terminate();
                ended.push((name, status, r.log()));
            }
        }
        ended
    }
}
