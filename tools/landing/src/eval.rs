//! `landing eval`: a Monte Carlo campaign (`campaign`): scenarios flown many times in
//! lockstep worker processes, or one shard of it for a batch engine, then the table with
//! its confidence intervals and the figures; `landing eval merge` gathers shards.

use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::Result;
use campaign::record::RunRecord;
use campaign::table::Table;
use campaign::{Campaign, Shard, merge, plots, pool};
use clap::{Args, Subcommand};
use stack_config::deploy_dir;

/// The paper-speed scenarios a campaign flies by default.
const PAPER_SCENARIOS: &str = "paper-sim,indoor-static,indoor-moving,outdoor-1,outdoor-2,obstacle-demo,paper-braking,paper-lane-change,paper-turn";

/// Arguments of `landing eval`.
#[derive(Debug, Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct EvalArgs {
    #[command(subcommand)]
    command: Option<EvalCommand>,
    /// Scenarios to fly: names (deploy/scenarios/) or files, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = PAPER_SCENARIOS)]
    scenarios: Vec<String>,
    /// Runs per scenario: run i flies the seed derived from --seed, the scenario and i.
    #[arg(long, default_value_t = 100)]
    runs: u64,
    /// Worker processes (default: one per core).
    #[arg(long)]
    jobs: Option<usize>,
    /// The base seed every run's seed is derived from.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Where the run files (OUT/SCENARIO/run-NNNNNN.json), the figures (OUT/plots) and the
    /// workers' logs go; a run whose file is already there is not flown again.
    #[arg(long, default_value = "eval-out")]
    out: PathBuf,
    /// Fly only shard K of N (1-based): the runs whose index mod N is K - 1, for a batch
    /// engine's array of jobs (deploy/batch/); `landing eval merge` gathers them.
    #[arg(long, value_name = "K/N")]
    shard: Option<Shard>,
    /// Print the table as one JSON object keyed by scenario.
    #[arg(long)]
    json: bool,
    /// The worst landed runs of each scenario flown again with their tracks drawn
    /// (OUT/plots/SCENARIO-run-N/), 0 for none.
    #[arg(long, default_value_t = 1, value_name = "N")]
    tracks: usize,
    /// Stack configuration (default: the deploy directory's config/landing.toml).
    #[arg(long)]
    config: Option<PathBuf>,
    /// The deploy directory (default: found above the current directory or executable).
    #[arg(long)]
    deploy_dir: Option<PathBuf>,
    /// Internal: a worker process, flying the runs it reads on stdin.
    #[arg(long, hide = true)]
    worker: bool,
    /// Internal: the worker's campaign config hash.
    #[arg(long, hide = true, requires = "worker")]
    config_hash: Option<String>,
}

#[derive(Debug, Subcommand)]
enum EvalCommand {
    /// Gather the run files of a campaign's shards (one or more OUT directories) into
    /// its table: every file must be a run of `landing eval`, every run flown with one
    /// stack configuration, every index once.
    Merge(MergeArgs),
}

#[derive(Debug, Args)]
struct MergeArgs {
    /// The shards' output directories.
    #[arg(required = true, value_name = "DIR")]
    dirs: Vec<PathBuf>,
    /// Every scenario must hold runs 0 to N - 1, no more, no fewer.
    #[arg(long, value_name = "N")]
    expect: Option<u64>,
    /// Print the table as one JSON object keyed by scenario.
    #[arg(long)]
    json: bool,
    /// Write the figures here.
    #[arg(long, value_name = "DIR")]
    plots: Option<PathBuf>,
}

/// Runs `landing eval`.
pub fn run(args: &EvalArgs) -> Result<()> {
    if let Some(EvalCommand::Merge(m)) = &args.command {
        return merge_cmd(m);
    }
    let deploy = args.deploy_dir.clone().unwrap_or_else(deploy_dir);
    if args.worker {
        return worker(args, &deploy);
    }
    let jobs = args.jobs.unwrap_or_else(|| {
        std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
    });
    if !(1..=256).contains(&jobs) {
        return Err(campaign::CampaignError::Jobs(jobs).into());
    }
    let c = Campaign::new(
        &args.scenarios,
        args.runs,
        args.seed,
        args.shard,
        &deploy,
        args.config.as_deref(),
        &args.out,
    )?;
    let pending = c.pending()?;
    let total = c.tasks().len();
    eprintln!(
        "eval: {} scenario(s) x {} runs{}, seed {}: {} to fly, {} already in {}, {jobs} worker(s)",
        c.scenarios.len(),
        c.runs,
        args.shard
            .map_or(String::new(), |s| format!(" (shard {}/{})", s.k, s.n)),
        c.base_seed,
        pending.len(),
        total - pending.len(),
        c.out.display()
    );
    runtime::shutdown::install();
    let logs = c.out.join("logs");
    std::fs::create_dir_all(&logs)?;
    let exe = std::env::current_exe()?;
    let worker_cmd = |k: usize| -> Command {
        let mut cmd = Command::new(&exe);
        cmd.args(["eval", "--worker", "--config-hash", &c.config_hash]);
        cmd.arg("--out").arg(&c.out);
        cmd.arg("--config").arg(&c.config);
        cmd.arg("--deploy-dir").arg(&c.deploy);
        cmd.env(
            "LANDING_LOG",
            std::env::var("LANDING_LOG").unwrap_or("warn".into()),
        );
        if let Ok(f) = std::fs::File::create(logs.join(format!("worker-{k}.log"))) {
            cmd.stderr(f);
        }
        stack::processes::stop_with_parent(&mut cmd);
        cmd
    };
    let tty = std::io::stderr().is_terminal();
    let (started, todo) = (Instant::now(), pending.len());
    let (mut flown, mut landed, mut last_line) = (0usize, 0usize, 0usize);
    pool::run(&c, pending, jobs, worker_cmd, |d| {
        flown += 1;
        landed += usize::from(d.outcome == "landed");
        let rate = flown as f64 / started.elapsed().as_secs_f64().max(1e-3);
        let eta = (todo - flown) as f64 / rate;
        let line = format!(
            "eval: {flown}/{todo} flown, {landed} landed, {rate:.2} runs/s, ETA {}m{:02}s",
            (eta / 60.0) as u64,
            (eta % 60.0) as u64
        );
        if tty {
            eprint!("\r{line}   ");
            let _ = std::io::stderr().flush();
        } else if flown == todo || flown * 20 / todo.max(1) > last_line {
            last_line = flown * 20 / todo.max(1);
            eprintln!("{line}");
        }
    })?;
    if tty && todo > 0 {
        eprintln!();
    }
    let runs = c.records()?;
    report(&runs, args.json, Some(&c.out.join("plots")))?;
    if args.tracks > 0 {
        tracks(&c, &Table::of(&runs), args.tracks)?;
    }
    Ok(())
}

/// The table (text or JSON) and, into `plots`, the figures of each scenario.
fn report(
    runs: &[(RunRecord, Option<campaign::record::RunTiming>)],
    json: bool,
    plots: Option<&Path>,
) -> Result<()> {
    let table = Table::of(runs);
    if let Some(dir) = plots {
        for name in table.0.keys() {
            let of: Vec<&RunRecord> = runs
                .iter()
                .map(|r| &r.0)
                .filter(|r| &r.scenario == name)
                .collect();
            for p in plots::write(dir, name, &of)? {
                eprintln!("  plot: {}", p.display());
            }
        }
    }
    if json {
        println!("{}", serde_json::to_string(&table)?);
    } else {
        print!("{table}");
    }
    Ok(())
}

/// Flies the `n` worst landed runs of each scenario again and draws their tracks.
fn tracks(c: &Campaign, table: &Table, n: usize) -> Result<()> {
    for plan in &c.scenarios {
        let Some(s) = table.0.get(&plan.name) else {
            continue;
        };
        for r in s.worst.iter().take(n) {
            let mission = stack::mission::Mission {
                scenario: plan.spec.clone(),
                seed: Some(r.seed),
                deploy: c.deploy.clone(),
                config: Some(c.config.clone()),
                ..stack::mission::Mission::default()
            };
            let flown = mission.fly(&mut |_| {})?;
            let dir = c
                .out
                .join("plots")
                .join(format!("{}-run-{}", plan.name, r.index));
            for p in evaluation::plot::write_plots(&dir, &flown.log)? {
                eprintln!("  track: {} ({})", p.display(), r.command);
            }
        }
    }
    Ok(())
}

/// The worker process: flies what it reads on stdin (`campaign::worker`).
fn worker(args: &EvalArgs, deploy: &Path) -> Result<()> {
    let w = campaign::worker::Worker {
        deploy: deploy.to_path_buf(),
        config: args
            .config
            .clone()
            .unwrap_or_else(|| deploy.join("config").join("landing.toml")),
        config_hash: args.config_hash.clone().unwrap_or_default(),
        out: args.out.clone(),
    };
    w.serve(std::io::stdin().lock(), std::io::stdout().lock())
}

/// `landing eval merge`.
fn merge_cmd(m: &MergeArgs) -> Result<()> {
    let runs = merge::merge(&m.dirs, m.expect)?;
    eprintln!(
        "merge: {} runs from {} director(ies)",
        runs.len(),
        m.dirs.len()
    );
    report(&runs, m.json, m.plots.as_deref())
}
