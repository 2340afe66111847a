//! `landing run --processes`: every stage as its own OS process, as systemd starts them
//! on the vehicle (the nodes of deploy/graph.toml: sim, camera-ingest, aruco-pnp,
//! depth-map, planner, fsm, px4-link, each with the graph's arguments), over iceoryx2
//! and MAVLink/UDP on the wall clock. This process only watches: the fsm's
//! status and the planner's statistics (pipeline topics) and the simulator's
//! evaluator-only truth topics.

use std::fs::File;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use graph::{Graph, Node, RunValues};
use ipc_types::msg::{
    FaultOrder, FsmStatus, Header, MissionState, PlannerStats, Stage, Text, TruthEvent, TruthState,
    WatchdogView,
};
use ipc_types::{services, topics};
use runtime::ipc::{LoopExit, Wake, run_wait_loop};
use runtime::{Ipc, IpcPrefix, monotonic_ns};
use sim::scenario::LoadedScenario;

use crate::inject::{Fault, FaultRecord, Injection};
use crate::procs::{Children, binary, free_udp_port};
use crate::px4_sitl::Px4Sitl;
use evaluation::referee::stage_ms;
use evaluation::{End, Referee};
use recorder::Recorder;
use stage::Message;

/// What `--processes` needs to start the stack.
pub struct Launch<'a> {
    /// The scenario.
    pub scenario: &'a LoadedScenario,
    /// Seed of the simulator.
    pub seed: u64,
    /// The stack configuration every process reads.
    pub config: &'a Path,
    /// The deploy directory.
    pub deploy: &'a Path,
    /// Where each process's log goes.
    pub log_dir: &'a Path,
    /// The iceoryx2 prefix (`--ipc-prefix`); a fresh one when `None`.
    pub ipc_prefix: Option<&'a str>,
    /// The dataflow graph: which processes to start, in which order, with which
    /// arguments.
    pub graph: &'a Graph,
    /// Its file, handed to every process (`--graph`): each finds its node there.
    pub graph_path: &'a Path,
    /// Faults to do to the processes in flight (`--inject`).
    pub injections: &'a [Injection],
    /// The `recorder` process: `--record` and `--live`.
    pub recorder: RecorderLaunch<'a>,
    /// The MAVLink signing key file (`[px4_link] signing_key`, resolved), empty for an
    /// unsigned link: the simulated autopilot gets it too.
    pub signing_key: &'a str,
    /// `--realtime`: the deployment's SCHED_FIFO priorities on the processes that have
    /// them (deploy/systemd drop-ins).
    pub realtime: bool,
    /// `--router`: the autopilot and px4-link talk through a MAVLink router with a
    /// second ground station behind it (`crate::router`).
    pub router: bool,
    /// `--autopilot px4-sitl`: this PX4 SITL build flies instead of the built-in
    /// autopilot.
    pub px4: Option<&'a Path>,
}

/// What the `recorder` process is started for (not at all when both are off).
#[derive(Debug, Clone, Copy, Default)]
pub struct RecorderLaunch<'a> {
    /// `--record`: the recording it writes.
    pub out: Option<&'a Path>,
    /// `--raw-images`: camera frames raw.
    pub raw_images: bool,
    /// `--live`: it serves the live view on `[recorder] live_address`.
    pub live: bool,
}

/// How a `--processes` run ended.
pub struct ProcessesRun {
    /// The end.
    pub end: End,
    /// The referee's record.
    pub referee: Referee,
    /// The simulator exited during the mission: which way, and where its log is.
    pub died: Option<String>,
    /// Faults injected, and processes that exited on their own.
    pub faults: Vec<FaultRecord>,
    /// With `--router`: what went through the router and the ground station.
    pub router: Option<(
        crate::router::RouterCounts,
        crate::router::GroundStationCounts,
    )>,
}

/// The values of the graph's argument placeholders for one run of `scn`: the files, the
/// seed, how long the simulator runs, and the UDP ports of the simulator and px4-link.
pub fn run_values(
    scn: &LoadedScenario,
    seed: u64,
    duration_s: f64,
    config: &Path,
    deploy: &Path,
    (sim_port, link_port): (u16, u16),
    signing_key: &str,
) -> Result<RunValues> {
    let preset = scn.scenario.mission.preset_m;
    let search_height_max = crate::lockstep::search_height_max_m(scn)?;
    Ok(RunValues {
        config: config.display().to_string(),
        deploy: deploy.display().to_string(),
        calibration: scn.calibration_path().display().to_string(),
        pad: scn.pad_path().display().to_string(),
        scenario: scn.path.display().to_string(),
        seed: seed.to_string(),
        duration: duration_s.to_string(),
        sim_addr: format!("127.0.0.1:{sim_port}"),
        link_addr: format!("127.0.0.1:{link_port}"),
        sim_remote: format!("127.0.0.1:{link_port}"),
        link_remote: format!("127.0.0.1:{sim_port}"),
        // The fsm gets `--preset={preset}`: the `--x=v` form, as a preset may start
        // with a minus sign.
        preset: format!("{},{},{}", preset[0], preset[1], preset[2]),
        commit_height: scn.scenario.mission.commit_height_m.to_string(),
        search_height_max: search_height_max.to_string(),
        signing_key: signing_key.to_string(),
    })
}

/// The command line of graph node `node` for one run: its binary (beside this
/// executable), the graph's arguments with `values` filled in, the iceoryx2 prefix and
/// the graph file (each process finds its node there).
pub fn command(
    node: &Node,
    values: &RunValues,
    prefix: &IpcPrefix,
    graph_path: &Path,
) -> Result<Command> {
    let mut cmd = Command::new(binary(&node.binary)?);
    cmd.args(node.command_args(values))
        .args(["--ipc-prefix", prefix.as_str()])
        .arg("--graph")
        .arg(graph_path);
    stop_with_parent(&mut cmd);
    Ok(cmd)
}

/// The child gets SIGTERM when this process dies, however it dies (SIGKILL included):
/// it then stops as systemd would stop it, releasing its shared memory, instead of
/// flying on as an orphan. Must be spawned from the thread that lives as long as the
/// child should (Linux ties the signal to the spawning thread): the main thread here.
pub fn stop_with_parent(cmd: &mut Command) {
    use std::os::unix::process::CommandExt;
    // SAFETY: getpid and getppid are async-signal-safe.
    let parent = unsafe { libc::getpid() };
    // SAFETY: the closure runs between fork and exec and calls only async-signal-safe
    // functions (prctl, getppid, raise); it allocates nothing.
    unsafe {
        cmd.pre_exec(move || {
            if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            // The parent died before the line above: nobody would send the signal.
            if libc::getppid() != parent {
                libc::raise(libc::SIGTERM);
            }
            Ok(())
        });
    }
}

/// Runs the mission with every stage as a process, doing `launch.injections` on the way.
/// A stage that dies (injected or not) does not end the run: the world flies on, and the
/// referee ends it once the vehicle is down and disarmed (or by the fsm's end, or the time
/// limit).
/// The simulator's death ends it at once.
pub fn run(
    launch: &Launch<'_>,
    truth_recorder: &mut Option<Recorder>,
    mut progress: impl FnMut(f64, MissionState, Option<f64>),
) -> Result<ProcessesRun> {
    let prefix = match launch.ipc_prefix {
        Some(p) => IpcPrefix::new(p)?,
        None => IpcPrefix::unique("run"),
    };
    // One stack per prefix: a second run on a prefix in use stops here, before it starts
    // a process.
    let ipc = Ipc::open_exclusive("landing-run", &prefix)?;
    // Subscribers before the publishers start: no event may be missed.
    let truth = ipc.subscriber::<TruthEvent>(services::SIM_TRUTH)?;
    let truth_state = ipc.subscriber::<TruthState>(services::SIM_TRUTH_STATE)?;
    let status = ipc.subscriber::<FsmStatus>(services::FSM_STATUS)?;
    let planner_stats = ipc.subscriber::<PlannerStats>(services::PLANNER_STATS)?;
    let views = ipc.subscriber::<WatchdogView>(services::WATCHDOG_VIEW)?;
    // Faults in the data paths go to the stages' output ports through this.
    let mut fault_orders = ipc.publisher::<FaultOrder>(services::FAULT_INJECT)?;

    let scn = launch.scenario;
    let px4 = launch.px4.map(Px4Sitl::at).transpose()?;
    // PX4 talks to px4-link on its own fixed ports; the built-in autopilot on any.
    let ports = match px4 {
        Some(_) => crate::px4_sitl::PX4_ONBOARD_PORTS,
        None => (free_udp_port()?, free_udp_port()?),
    };
    let mut values = run_values(
        scn,
        launch.seed,
        scn.scenario.duration_s,
        launch.config,
        launch.deploy,
        ports,
        launch.signing_key,
    )?;
    // Behind a router, each of the two sends to its own endpoint of it; a second
    // ground station talks to the autopilot through it too.
    let router = if launch.router {
        let r = crate::router::Router::start(values.sim_addr.parse()?, values.link_addr.parse()?)?;
        values.sim_remote = r.autopilot_side().to_string();
        values.link_remote = r.link_side().to_string();
        let gcs = crate::router::GroundStation::start(r.ground_station_side())?;
        Some((r, gcs))
    } else {
        None
    };
    std::fs::create_dir_all(launch.log_dir)
        .with_context(|| format!("creating {}", launch.log_dir.display()))?;
    let mut children = Children::default();
    if let Some(px4) = &px4 {
        // First: it waits for the simulator, which starts last.
        let file = log_file(launch.log_dir, "px4")?;
        let mut cmd = px4.command(&launch.log_dir.join("px4"), scn)?;
        stop_with_parent(&mut cmd);
        let child = cmd
            .stdin(Stdio::null())
            .stdout(file.try_clone()?)
            .stderr(file)
            .spawn()
            .context("starting PX4 (--px4)")?;
        children.push("px4", child);
    }
    let r = launch.recorder;
    if r.out.is_some() || r.live {
        // First: it subscribes before anything is published.
        let file = log_file(launch.log_dir, "recorder")?;
        let mut cmd = Command::new(binary("recorder")?);
        cmd.arg("--config")
            .arg(launch.config)
            .arg("--deploy-dir")
            .arg(launch.deploy)
            .arg("--graph")
            .arg(launch.graph_path)
            .args(["--ipc-prefix", prefix.as_str()]);
        if let Some(out) = r.out {
            cmd.arg("--out").arg(out);
        }
        if r.raw_images {
            cmd.arg("--raw-images");
        }
        if r.live {
            cmd.arg("--live");
        }
        cmd.arg(format!("--meta=scenario={}", launch.scenario.scenario.name))
            .arg(format!("--meta=seed={}", launch.seed))
            .arg("--meta=mode=processes");
        stop_with_parent(&mut cmd);
        let child = cmd
            .env("LANDING_LOG", "info")
            .stdout(Stdio::null())
            .stderr(file)
            .spawn()
            .context("starting recorder")?;
        children.push("recorder", child);
        std::thread::sleep(Duration::from_millis(150));
    }
    // The graph's start order: the nodes marked start_last (the simulator, whose clock
    // starts the world) after the others.
    for node in launch.graph.start_order() {
        let file = log_file(launch.log_dir, &node.name)?;
        let child = start(node, &values, &prefix, launch, file)?;
        children.push(&node.name, child);
        if node.binary == "watchdog" {
            children.stop_first(&node.name);
        }
        if !node.start_last {
            // Let each stage open its ports before the simulator's clock starts.
            std::thread::sleep(Duration::from_millis(150));
        }
    }

    let mut referee = Referee::new(monotonic_ns());
    let mut result: Option<End> = None;
    let mut failure: Option<anyhow::Error> = None;
    let mut died: Option<String> = None;
    let mut faults: Vec<FaultRecord> = Vec::new();
    let mut done = vec![false; launch.injections.len()];
    let mut exits_seen: Vec<String> = Vec::new();
    // Floods running, with the index of their record.
    let mut floods: Vec<(usize, crate::flood::Flood)> = Vec::new();
    let mut next_progress = 0.0f64;
    let wall_limit = Instant::now() + Duration::from_secs_f64(scn.scenario.duration_s + 15.0);
    // A recording wakes on every recorded topic: subscriber queues are short.
    let listeners = vec![
        truth_state.listener(),
        status.listener(),
        truth.listener(),
        views.listener(),
    ];
    let exit = run_wait_loop(
        &listeners,
        &[],
        Some(Duration::from_millis(100)),
        |_wake: Wake| {
            let step = (|| -> Result<()> {
                while let Some(s) = status.receive()? {
                    referee.on_status(s.payload());
                }
                while let Some(p) = planner_stats.receive()? {
                    // The planner's stamp: from the call to the statistics leaving.
                    let ms = stage_ms(&p.payload().msg, Stage::Planner).unwrap_or(0.0);
                    referee.on_planner_stats(p.payload(), ms);
                }
                while let Some(t) = truth.receive()? {
                    let t = *t.payload();
                    if let Some(r) = truth_recorder.as_mut() {
                        r.record(topics::SIM_TRUTH, monotonic_ns(), &Message::TruthEvent(&t))?;
                    }
                    referee.on_truth(&t);
                }
                while let Some(v) = views.receive()? {
                    for f in faults.iter_mut() {
                        note_detection(f, v.payload());
                    }
                }
                while let Some(s) = truth_state.receive()? {
                    if let Some(r) = truth_recorder.as_mut() {
                        let m = Message::TruthState(s.payload());
                        r.record(topics::SIM_TRUTH_STATE, monotonic_ns(), &m)?;
                    }
                    referee.on_truth_state(s.payload());
                }
                Ok(())
            })();
            if let Err(e) = step {
                failure = Some(e);
                return false;
            }
            let t_s = referee.sim_time_ns() as f64 * 1e-9;
            if t_s >= next_progress {
                next_progress = t_s.floor() + 1.0;
                progress(t_s, referee.phase, referee.distance_to_pad());
            }
            if let Some(end) = referee.finished() {
                result = Some(end);
                return false;
            }
            if t_s >= scn.scenario.duration_s || Instant::now() >= wall_limit {
                result = Some(End::Timeout);
                return false;
            }
            for (inj, done) in launch.injections.iter().zip(done.iter_mut()) {
                if *done || !inj.due(t_s, referee.phase) {
                    continue;
                }
                *done = true;
                let Some(pid) = children.pid_of(&inj.process) else {
                    continue;
                };
                let mut record = fault_record(&inj.fault.name(), &inj.process, t_s);
                if let Some(t) = &inj.topic {
                    record.process = t.clone();
                }
                if let Some(sig) = inj.fault.signal() {
                    // SAFETY: signalling our own child.
                    unsafe { libc::kill(pid as i32, sig) };
                    if inj.fault == Fault::Restart {
                        // As systemd restarts a unit: once the old process has exited,
                        // the same command, its log appended to.
                        children.reap(&inj.process);
                        let again = launch
                            .graph
                            .nodes
                            .iter()
                            .find(|n| n.name == inj.process)
                            .context("the restarted process left the graph")
                            .and_then(|node| {
                                let log = launch.log_dir.join(format!("{}.log", node.name));
                                let file = File::options().append(true).open(&log)?;
                                start(node, &values, &prefix, launch, file)
                            });
                        match again {
                            Ok(child) => children.replace(&inj.process, child),
                            Err(e) => {
                                failure = Some(e);
                                return false;
                            }
                        }
                    }
                } else if let Fault::Garbage(n) = inj.fault {
                    match crate::flood::burst(&values.link_addr, n) {
                        Ok(sent) => record.datagrams_sent = Some(sent),
                        Err(e) => {
                            failure = Some(e);
                            return false;
                        }
                    }
                } else if let Fault::Flood(kind, rate) = inj.fault {
                    match crate::flood::Flood::start(&values.link_addr, kind, rate) {
                        Ok(f) => floods.push((faults.len(), f)),
                        Err(e) => {
                            failure = Some(e);
                            return false;
                        }
                    }
                } else if let Some((fault, value)) = inj.fault.order() {
                    let order = FaultOrder {
                        process: Text::new(&inj.process),
                        fault: fault as u32,
                        value,
                        topic: Text::new(inj.topic.as_deref().unwrap_or("")),
                        for_s: inj.fault.duration_s(),
                        ..FaultOrder::default()
                    };
                    if let Err(e) = fault_orders.send(Header::captured_at(record.at_ns), &order) {
                        failure = Some(e.into());
                        return false;
                    }
                }
                tracing::warn!(fault = %inj, at_s = t_s, "fault injected");
                faults.push(record);
                // A process gone or hung may be the fsm, which would never end the
                // mission: the referee ends the run once the vehicle is down. Faults in
                // the data and the world leave every process running: the fsm's end is
                // the run's, as in a flight without faults.
                if inj.fault.signal().is_some() {
                    referee.on_fault();
                }
                if inj.fault == Fault::Kill {
                    exits_seen.push(inj.process.clone());
                }
            }
            while let Some((name, status)) = children.newly_exited(&exits_seen) {
                exits_seen.push(name.clone());
                let log = launch.log_dir.join(format!("{name}.log"));
                if name == "sim" {
                    died = Some(format!(
                        "{name} exited ({status}) during the mission; its log: {}",
                        log.display()
                    ));
                    result = Some(End::ProcessDied);
                    return false;
                }
                tracing::warn!(process = name.as_str(), %status, "process exited during the mission");
                faults.push(fault_record("exited", &name, t_s));
                referee.on_fault();
            }
            true
        },
    )?;
    if exit == LoopExit::Signal {
        result = Some(End::Interrupted);
    }
    // Floods stop before the processes do: px4-link's last counts include them all.
    for (i, f) in floods {
        let sent = f.stop();
        if let Some(r) = faults.get_mut(i) {
            r.datagrams_sent = Some(sent);
        }
    }
    // The router forwards nothing more while the processes still read: what it
    // forwarded is what they received.
    if let Some((r, _)) = &router {
        r.hold();
    }
    std::thread::sleep(Duration::from_millis(50));
    drop(children);
    if let Some(e) = failure {
        return Err(e);
    }
    // The processes are stopped: every datagram is in, or lost, by now.
    let router = router.map(|(r, gcs)| {
        let g = gcs.stop();
        (r.stop(), g)
    });
    Ok(ProcessesRun {
        end: result.unwrap_or(End::Timeout),
        referee,
        died,
        faults,
        router,
    })
}

/// Starts graph node `node` of the run, its stderr to `log`.
fn start(
    node: &graph::Node,
    values: &RunValues,
    prefix: &IpcPrefix,
    launch: &Launch<'_>,
    log: File,
) -> Result<std::process::Child> {
    let mut cmd = command(node, values, prefix, launch.graph_path)?;
    if launch.px4.is_some() {
        cmd.args(Px4Sitl::extra_args(&node.name));
    }
    if !launch.injections.is_empty() {
        cmd.env(runtime::port_faults::ENV, "1");
    }
    let child = cmd
        .env("LANDING_LOG", "info")
        .stdout(Stdio::null())
        .stderr(log)
        .spawn()
        .with_context(|| format!("starting {}", node.binary))?;
    if launch.realtime
        && let Some(priority) = crate::procs::deploy_fifo_priority(launch.deploy, &node.binary)
    {
        crate::procs::set_fifo(child.id(), priority).with_context(|| {
            format!(
                "--realtime: SCHED_FIFO {priority} for {} refused (needs root or CAP_SYS_NICE)",
                node.binary
            )
        })?;
    }
    Ok(child)
}

/// `dir/NAME.log`, created for a child's output.
fn log_file(dir: &Path, name: &str) -> Result<File> {
    let log = dir.join(format!("{name}.log"));
    File::create(&log).with_context(|| format!("creating {}", log.display()))
}

fn fault_record(fault: &str, process: &str, at_s: f64) -> FaultRecord {
    FaultRecord {
        fault: fault.to_string(),
        process: process.to_string(),
        at_s,
        detected_after_ms: None,
        action: None,
        ordered_after_ms: None,
        rejoined_after_ms: None,
        datagrams_sent: None,
        outcome: String::new(),
        at_ns: monotonic_ns(),
    }
}

/// What the watchdog's `view` says of the fault `f`: when it found the process hung or
/// dead (a fault in a process's data paths: the first fault it found after it), what it
/// decided, and when it ordered (the first time each, after the fault).
fn note_detection(f: &mut FaultRecord, view: &WatchdogView) {
    let after_ms = |t: u64| (t >= f.at_ns).then(|| (t - f.at_ns) as f64 * 1e-6);
    let whole_process = ["kill", "stop", "restart", "exited"].contains(&f.fault.as_str());
    if f.fault.starts_with("garbage") || f.fault.starts_with("flood") {
        // Noise on the link is px4-link's to drop (its stop line counts it), not a fault
        // of the stack's.
        return;
    }
    if f.detected_after_ms.is_none() {
        f.detected_after_ms = if whole_process {
            view.watched()
                .iter()
                .find(|p| p.name.as_str() == f.process)
                .and_then(|p| after_ms(p.fault_ns))
        } else {
            after_ms(view.last_fault_ns)
        };
    }
    if f.fault == "restart" && f.rejoined_after_ms.is_none() {
        f.rejoined_after_ms = view
            .watched()
            .iter()
            .find(|p| p.name.as_str() == f.process && p.restarts > 0)
            .and_then(|p| after_ms(p.rejoined_ns));
    }
    if f.detected_after_ms.is_some() {
        let line = view.action.as_str();
        let about_it = !whole_process || line.starts_with(&format!("{} ", f.process));
        if f.action.is_none() && about_it && !line.is_empty() {
            f.action = Some(line.to_string());
        }
        if f.ordered_after_ms.is_none() && view.order_ns > 0 {
            f.ordered_after_ms = after_ms(view.order_ns);
        }
    }
}
