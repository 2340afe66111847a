//! `landing`: the one user-facing command of the landing stack.

mod bench_aruco;
mod bench_ipc;
mod bench_perception;
mod bench_sim;
mod config_cmd;
mod pad_detect;
mod stats;

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
enum Command {
    /// Measure parts of the stack on this machine.
    #[command(subcommand)]
    Bench(BenchCommand),
    /// Work with configuration files.
    #[command(subcommand)]
    Config(ConfigCommand),
    /// The landing pad: find it in an image.
    #[command(subcommand)]
    Pad(PadCommand),
}

#[derive(Debug, Subcommand)]
enum PadCommand {
    /// Find the pad in one image and print its pose (exit code 3 when there is none).
    Detect(pad_detect::DetectArgs),
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

fn main() -> ExitCode {
    let cli = Cli::parse();
    ipc_types::runtime::logging::init("warn");
    let result = match cli.command {
        Command::Bench(BenchCommand::Ipc(args)) => bench_ipc::run(&args, cli.ipc_prefix.as_deref()),
        Command::Bench(BenchCommand::Sim(args)) => bench_sim::run(&args),
        Command::Bench(BenchCommand::Aruco(args)) => bench_aruco::run(&args),
        Command::Bench(BenchCommand::Perception(args)) => {
            bench_perception::run(&args, cli.ipc_prefix.as_deref())
        }
        Command::Bench(BenchCommand::IpcPeer(args)) => {
            bench_ipc::run_peer(&args, cli.ipc_prefix.as_deref())
        }
        Command::Config(ConfigCommand::Check { file }) => config_cmd::check(&file),
        Command::Pad(PadCommand::Detect(args)) => match pad_detect::run(&args) {
            Ok(false) => return ExitCode::from(pad_detect::NOT_FOUND),
            other => other.map(|_| ()),
        },
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
