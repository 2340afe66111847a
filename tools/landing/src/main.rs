//! `landing`: the one user-facing command of the landing stack.

mod calibrate_cmd;
mod config_cmd;
mod doctor_cmd;
mod eval;
mod graph_cmd;
mod inject_cmd;
mod latency_cmd;
mod link_cmd;
mod pad_detect;
mod pad_print;
mod plan_cmd;
mod plot_cmd;
mod replay_cmd;
mod run_cmd;
mod status_cmd;
mod touchdown_cmd;

use benches::{
    aruco as bench_aruco, depth as bench_depth, faults as bench_faults, ipc as bench_ipc,
    latency as bench_latency, perception as bench_perception, planner as bench_planner,
    recorder as bench_recorder, sim as bench_sim,
};
use stack::mapping as map_cmd;
// The libraries' modules under the names the command modules use.
use evaluation::{flight_log, plot, referee as run_eval};
use stack::inject;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// Autonomous quadrotor landing on a moving platform: missions, benchmarks, tools.
#[derive(Debug, Parser)]
#[command(name = "landing", version, about, long_about = None)]
struct Cli {
    /// iceoryx2 prefix that isolates this run from other stacks on the host
    /// (default: $LANDING_IPC_PREFIX, else a fresh one per benchmark).
    #[arg(long, global = true, value_name = "PREFIX")]
    ipc_prefix: Option<String>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum LinkCommand {
    /// Install `[px4_link] signing_key` on the autopilot (MAVLink SETUP_SIGNING) from
    /// px4-link's address, and check that its heartbeats then come signed with it. Run
    /// with the stack stopped.
    SetupSigning(link_cmd::SetupSigningArgs),
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Measure parts of the stack on this machine.
    #[command(subcommand)]
    Bench(BenchCommand),
    /// Calibrate a camera from views of a ChArUco board, or print the board.
    #[command(subcommand)]
    Calibrate(calibrate_cmd::CalibrateCommand),
    /// Work with configuration files.
    #[command(subcommand)]
    Config(ConfigCommand),
    /// Check a vehicle before flight, one line per check: the stack file, the camera and
    /// depth source it names, the autopilot answering on the link, the PX4 parameters
    /// the stack relies on (read over MAVLink), the autopilot's clock (TIMESYNC), the
    /// iceoryx2 prefix, free disk for recordings. Exit code 1 when a check fails; run it
    /// with the stack stopped (it opens px4-link's port).
    Doctor(doctor_cmd::DoctorArgs),
    /// The MAVLink link to the autopilot.
    #[command(subcommand)]
    Link(LinkCommand),
    /// The landing pad: print it, find it in an image.
    #[command(subcommand)]
    Pad(PadCommand),
    /// Fly a short scripted path in the lockstep simulator, map every depth frame with
    /// the autopilot's estimated pose, and draw the map (top and side views) into a PNG;
    /// prints where the obstacles really are against where the map put them.
    Map(map_cmd::MapArgs),
    /// Plan one trajectory offline on a map of boxes (exit code 3 when there is none).
    Plan(plan_cmd::PlanArgs),
    /// Fly one whole autonomous landing mission in the simulator: take off, find the pad
    /// on its moving vehicle, track it around obstacles, descend and land on it. Prints a
    /// progress line, every state transition and a summary (exit code 1 when the vehicle
    /// did not land on the pad).
    Run(run_cmd::RunArgs),
    /// Fly scenarios many times (a Monte Carlo campaign) in lockstep worker processes,
    /// or one shard of it for a batch engine, and print the table: per scenario the
    /// success rate with its 95 % interval, touchdown error and contact percentiles, the
    /// failed and worst runs with the command that flies each again; figures in
    /// OUT/plots (docs/eval.md). `landing eval merge DIR..` gathers shards.
    Eval(eval::EvalArgs),
    /// Look into MCAP recordings (`landing run --record`).
    #[command(subcommand)]
    Mcap(McapCommand),
    /// Per-stage and end-to-end latency of a recording, or of the running stack with
    /// --live (camera frame -> pad observation -> setpoint on the MAVLink wire),
    /// p50/p90/p99/max, message rates, drops by sequence gaps and CPU per process; --plot
    /// draws the end-to-end histogram (docs/recording.md).
    Latency(latency_cmd::LatencyArgs),
    /// Run one stage again on a recording's inputs through its own library and compare
    /// its outputs, bit for bit, with what it published in flight (aruco-pnp, recorded with
    /// --raw-images: its observations; fsm: its transitions). Exit code 1 when they differ.
    Replay(replay_cmd::ReplayArgs),
    /// Draw a recording's trajectory plots into a directory: the plots `landing run
    /// --plot` draws (from FILE.truth.mcap beside it when there is one; else the stack's
    /// own estimates, as on a real flight).
    Plot(plot_cmd::PlotArgs),
    /// Print the pipeline's dataflow graph (deploy/graph.toml): every process with the
    /// topics it reads and publishes, rates, drop policies, heartbeat deadlines; as text,
    /// JSON or Graphviz DOT. A graph that breaks a rule (an undeclared topic, a cycle
    /// without a delayed input, a node without a binary, a rate of 0, ...) is one line
    /// and exit code 2.
    Graph(graph_cmd::GraphArgs),
    /// Remove what dead processes of a stack left in shared memory (/dev/shm,
    /// /tmp/iceoryx2) under its iceoryx2 prefix (--ipc-prefix, else $LANDING_IPC_PREFIX,
    /// else `landing_`), so that restarted processes reconnect; the resources of live
    /// processes are kept. systemd runs it before the stack (landing-clean.service).
    Clean,
    /// The watchdog's view of a running stack (under --ipc-prefix, else
    /// $LANDING_IPC_PREFIX, else `landing_`): every process alive, hung or dead, its last
    /// heartbeat and missed deadlines, the newest fault and what the watchdog decided.
    /// Once, or live with --watch; exit code 2 when no watchdog answers.
    Status(status_cmd::StatusArgs),
    /// Do a fault to a running stack now: kill or stop (SIGSTOP) one of its processes,
    /// cont to resume it, or delay, drop, corrupt or blank its outputs (processes started with
    /// LANDING_FAULT_INJECTION=1 only), clear to undo. For fault tests by hand; `landing
    /// run --processes --inject` does the same on a schedule.
    Inject(inject_cmd::InjectArgs),
}

#[derive(Debug, Subcommand)]
enum McapCommand {
    /// Print what a recording holds: topics, schemas, message counts and rates, time
    /// range. A recording whose writer died (no summary) is read to where it ends and
    /// flagged NOT FINISHED. Open it in Foxglove Studio to see the messages (JSON).
    Info {
        /// The recording (.mcap).
        #[arg(value_name = "FILE")]
        file: PathBuf,
        /// Print the same as one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Take a recorded touchdown apart against the simulator's truth (FILE.truth.mcap
    /// beside it): the offset over the pad when the drop began, how much of it the stack
    /// could not see, the velocity and lean it dropped with, and what the fall added. Exit
    /// code 2, one line, without a truth file, a touchdown or a drop (docs/recording.md).
    Touchdown(touchdown_cmd::TouchdownArgs),
}

#[derive(Debug, Subcommand)]
enum PadCommand {
    /// Find the pad in one image and print its pose (exit code 3 when there is none).
    Detect(pad_detect::DetectArgs),
    /// Write the landing pad as a PNG and an SVG to print at true scale.
    ///
    /// The PNG covers exactly the board of the pad file (deploy/config/pad.toml), edge to
    /// edge: round(board width / 25.4 mm * DPI) x round(board height / 25.4 mm * DPI)
    /// pixels, black and white only (1 bit per pixel), the DPI recorded in its pHYs chunk
    /// so a print dialog at 100% prints it actual size. Image right is pad +x (the
    /// carrier's heading), image up is pad +y. The board is centred on the pad origin
    /// (the landing point; the pad file is refused otherwise), so the image centre is the
    /// landing point: a point u px right and v px down from the top-left corner of the
    /// image is pad x = min_x + u * 25.4 mm / DPI, y = max_y - v * 25.4 mm / DPI (OpenCV's
    /// pixel (c, r) has its centre at u = c + 0.5, v = r + 0.5). Every marker cell edge
    /// lies on the pixel boundary nearest its true position (off by at most half a
    /// pixel, no blur); a DPI that makes the cells whole numbers of pixels makes them all
    /// the same size.
    ///
    /// The SVG (default: --out with the extension .svg) is in millimetres: the board
    /// with every black marker cell as a rectangle (bits from OpenCV's ARUCO_ORIGINAL
    /// dictionary), a small red cross at the pad origin, and below the board a 10 cm scale
    /// bar and a caption naming the marker ids and sizes. Print either at 100%, then
    /// check the scale bar (SVG) or the board size (PNG) with a ruler.
    ///
    /// The shipped 84 x 84 cm board is 9921 px a side at 300 dpi; at 1200 dpi it is
    /// 39685 px a side and takes about 1.6 GB of memory to write.
    Print(pad_print::PrintArgs),
}

#[derive(Debug, Subcommand)]
enum BenchCommand {
    /// One-way latency of camera frames between two OS processes: iceoryx2 zero-copy
    /// against a Unix domain socket copy.
    Ipc(bench_ipc::IpcArgs),
    /// Real-time factor of the simulator with both cameras, and render times.
    Sim(bench_sim::SimArgs),
    /// Pad detection + pose time per frame, ours against plain OpenCV, same frames.
    Aruco(bench_aruco::ArucoArgs),
    /// sim -> camera-ingest -> aruco-pnp as processes: observation rate and latency.
    Perception(bench_perception::PerceptionArgs),
    /// Depth mapping: integration, inflation and wire time of one 640x480 depth frame.
    Depth(bench_depth::DepthArgs),
    /// Planner success rate and planning time on random pillar fields and the paper's
    /// obstacle scene.
    Planner(bench_planner::PlannerArgs),
    /// The fault matrix: every watched process killed and hung while tracking and while
    /// descending; how each flight ends and how fast the watchdog orders.
    Faults(bench_faults::FaultsArgs),
    /// The recorder process under a flight's load (1280x720 camera at 30 Hz and every
    /// other topic): drops and its CPU, JPEG + zstd and raw + lz4.
    Recorder(bench_recorder::RecorderArgs),
    /// Camera frame -> setpoint on the MAVLink wire, every stage its own process and the
    /// simulator beside them: the shipped config and new_setpoints_at_once turned over.
    Latency(bench_latency::LatencyBenchArgs),
    /// Internal: the publishing side of `bench ipc`, started by it in a second process.
    #[command(hide = true)]
    IpcPeer(bench_ipc::PeerArgs),
}

#[derive(Debug, Subcommand)]
enum ConfigCommand {
    /// Check a stack configuration file; prints one line naming any problem.
    Check {
        /// The file (e.g. deploy/config/landing.toml).
        #[arg(value_name = "FILE")]
        file: PathBuf,
    },
}

/// `landing clean`.
fn clean(prefix: Option<&str>) -> anyhow::Result<()> {
    let prefix = runtime::IpcPrefix::from_flag_or_env(prefix)?;
    let c = runtime::ipc::clean(&prefix)?;
    println!(
        "prefix {}: removed the resources of {} dead process(es); {} alive, kept",
        prefix.as_str(),
        c.dead_nodes,
        c.alive_nodes
    );
    Ok(())
}

/// `landing mcap info`.
fn mcap_info(file: &std::path::Path, json: bool) -> anyhow::Result<()> {
    let info = recorder::info(file)?;
    if json {
        println!("{}", serde_json::to_string_pretty(&info)?);
    } else {
        println!("{info}");
    }
    // What was readable is reported above; the damage is the error.
    match &info.broken {
        Some(b) => anyhow::bail!("{}: {b}", file.display()),
        None => Ok(()),
    }
}

fn main() -> ExitCode {
    // `landing ... | head` must end quietly when the pipe closes, as CLI tools do, not
    // panic in println!.
    // SAFETY: restoring the default disposition of SIGPIPE before any thread starts.
    unsafe { libc::signal(libc::SIGPIPE, libc::SIG_DFL) };
    // A usage mistake is one line naming what is wrong, as in every stack binary.
    let cli = match runtime::process_main::parse_args::<Cli>() {
        Ok(c) => c,
        Err(code) => return code,
    };
    runtime::logging::init("warn");
    let result = match cli.command {
        Command::Bench(BenchCommand::Ipc(args)) => bench_ipc::run(&args, cli.ipc_prefix.as_deref()),
        Command::Bench(BenchCommand::Sim(args)) => bench_sim::run(&args),
        Command::Bench(BenchCommand::Aruco(args)) => bench_aruco::run(&args),
        Command::Bench(BenchCommand::Depth(args)) => bench_depth::run(&args),
        Command::Bench(BenchCommand::Perception(args)) => {
            bench_perception::run(&args, cli.ipc_prefix.as_deref())
        }
        Command::Bench(BenchCommand::IpcPeer(args)) => {
            bench_ipc::run_peer(&args, cli.ipc_prefix.as_deref())
        }
        Command::Bench(BenchCommand::Planner(args)) => bench_planner::run(&args),
        Command::Bench(BenchCommand::Faults(args)) => bench_faults::run(&args),
        Command::Bench(BenchCommand::Recorder(args)) => bench_recorder::run(&args),
        Command::Bench(BenchCommand::Latency(args)) => bench_latency::run(&args),
        Command::Plan(args) => match plan_cmd::run(&args) {
            Ok(false) => return ExitCode::from(plan_cmd::NO_PLAN),
            other => other.map(|_| ()),
        },
        Command::Calibrate(cmd) => match calibrate_cmd::run(&cmd) {
            Ok(false) => return ExitCode::from(1),
            other => other.map(|_| ()),
        },
        Command::Config(ConfigCommand::Check { file }) => config_cmd::check(&file),
        Command::Doctor(args) => match doctor_cmd::run_doctor(&args, cli.ipc_prefix.as_deref()) {
            Ok(false) => return ExitCode::from(1),
            other => other.map(|_| ()),
        },
        Command::Link(LinkCommand::SetupSigning(args)) => link_cmd::setup_signing(&args),
        Command::Pad(PadCommand::Detect(args)) => match pad_detect::run(&args) {
            Ok(false) => return ExitCode::from(pad_detect::NOT_FOUND),
            other => other.map(|_| ()),
        },
        Command::Pad(PadCommand::Print(args)) => pad_print::run(&args),
        Command::Map(args) => map_cmd::run(&args),
        Command::Run(args) => match run_cmd::run(&args, cli.ipc_prefix.as_deref()) {
            Ok(false) => return ExitCode::from(1),
            other => other.map(|_| ()),
        },
        Command::Mcap(McapCommand::Info { file, json }) => mcap_info(&file, json),
        Command::Mcap(McapCommand::Touchdown(args)) => touchdown_cmd::run(&args),
        Command::Eval(args) => eval::run(&args),
        Command::Latency(args) => latency_cmd::run(&args, cli.ipc_prefix.as_deref()),
        Command::Replay(args) => match replay_cmd::run(&args) {
            Ok(false) => return ExitCode::from(1),
            other => other.map(|_| ()),
        },
        Command::Plot(args) => plot_cmd::run(&args),
        Command::Graph(args) => graph_cmd::run(&args),
        Command::Clean => clean(cli.ipc_prefix.as_deref()),
        Command::Status(args) => status_cmd::run(&args, cli.ipc_prefix.as_deref()),
        Command::Inject(args) => inject_cmd::run(&args, cli.ipc_prefix.as_deref()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // One line, whole chain: what failed and why.
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
