//! One whole mission in the simulator, in lockstep or with every stage its own process,
//! judged by the referee: what `landing run` flies and what a campaign flies many times.
//! Nothing here prints: what a user sees goes through [`Event`]s and the [`Flown`]
//! result, and the caller shows it.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use evaluation::flight_log::{FaultRecord, FlightLog, Outcome, RunSummary};
use evaluation::referee::{self, Evaluator, Referee, Rules};
use ipc_types::msg::MissionState;
use recorder::Recorder;

use crate::StackConfig;
use crate::inject::Injection;
use crate::lockstep::{self, Recording};
use crate::processes;

/// What to fly and how.
#[derive(Debug, Clone, Default)]
pub struct Mission {
    /// Scenario name (from the deploy directory's scenarios/) or a TOML file.
    pub scenario: String,
    /// The seed of every random process (default: the scenario's).
    pub seed: Option<u64>,
    /// The deploy directory.
    pub deploy: PathBuf,
    /// The stack configuration (default: the deploy directory's config/landing.toml).
    pub config: Option<PathBuf>,
    /// The dataflow graph (default: the deploy directory's graph.toml).
    pub graph: Option<PathBuf>,
    /// Every stage its own OS process, on the wall clock, instead of lockstep.
    pub processes: bool,
    /// Record the pipeline here (MCAP), and the truth beside it ([`truth_path`]).
    pub record: Option<PathBuf>,
    /// Camera frames recorded raw rather than JPEG.
    pub raw_images: bool,
    /// Serve the flight live to Foxglove; lockstep then keeps to the wall clock's pace.
    pub live: bool,
    /// Processes: the deployment's real-time priorities.
    pub realtime: bool,
    /// `--router`: through a MAVLink router with a second ground station.
    pub router: bool,
    /// Processes: where each process's log goes (default: a new temporary directory).
    pub log_dir: Option<PathBuf>,
    /// Processes: faults to do in flight.
    pub inject: Vec<Injection>,
    /// Processes: the iceoryx2 prefix (default: a fresh one).
    pub ipc_prefix: Option<String>,
    /// Processes: this PX4 SITL build directory flies instead of the built-in autopilot.
    pub px4: Option<PathBuf>,
}

/// What the caller is told while a mission flies.
#[derive(Debug, Clone)]
pub enum Event<'a> {
    /// The mission starts.
    Start {
        /// The scenario's name.
        scenario: &'a str,
        /// The seed flown.
        seed: u64,
        /// The scenario's one-line description.
        description: &'a str,
    },
    /// The live view is served here (`ws://ADDRESS`).
    Live {
        /// The address.
        address: String,
        /// Served by the recorder process (`--processes`), not by this one.
        by_recorder_process: bool,
    },
    /// About once a simulated second.
    Progress {
        /// Simulated time, s.
        t_s: f64,
        /// The fsm's state.
        state: MissionState,
        /// Horizontal distance to the pad, m.
        to_pad_m: Option<f64>,
    },
}

/// A mission flown and judged.
#[derive(Debug)]
pub struct Flown {
    /// The scenario's name.
    pub scenario: String,
    /// The seed flown.
    pub seed: u64,
    /// The referee's verdict.
    pub outcome: Outcome,
    /// The summary a user reads (`--json`).
    pub summary: RunSummary,
    /// The flight log (truth), for plots.
    pub log: FlightLog,
    /// The evaluator's record: touchdowns, crashes, samples.
    pub eval: Evaluator,
    /// The fsm's transitions, as its status showed them.
    pub transitions: Vec<fsm::Transition>,
    /// Planning times, ms.
    pub planning_ms: Vec<f64>,
    /// The recordings written, with their message counts (a recording the recorder
    /// process wrote has no count).
    pub recordings: Vec<(PathBuf, Option<u64>)>,
    /// Processes: where their logs are.
    pub log_dir: Option<PathBuf>,
}

/// Where the evaluator's ground truth of a run recorded in `pipeline` goes: `run.mcap`
/// -> `run.truth.mcap`.
pub fn truth_path(pipeline: &Path) -> PathBuf {
    let stem = pipeline
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "recording".into());
    pipeline.with_file_name(format!("{stem}.truth.mcap"))
}

impl Mission {
    /// The configuration file flown with.
    pub fn config_path(&self) -> PathBuf {
        self.config
            .clone()
            .unwrap_or_else(|| self.deploy.join("config").join("landing.toml"))
    }

    /// Flies the mission to its end and judges it; `events` hears about it as it goes.
    /// An error is a mission that could not be flown (a bad file, a process that could
    /// not start); a mission that did not land is an [`Outcome`].
    pub fn fly(&self, events: &mut dyn FnMut(Event<'_>)) -> Result<Flown> {
        let cfg_path = self.config_path();
        let cfg = StackConfig::load(&cfg_path)?;
        let scn = sim::scenario::load(&self.scenario, &self.deploy)?;
        // Both modes run what the graph declares; checked before anything starts.
        let graph_path = self
            .graph
            .clone()
            .unwrap_or_else(|| graph::default_path(&self.deploy));
        let graph = graph::Graph::load(&graph_path)?;
        // Faults go to processes of this graph, in the processes mode only.
        if !self.inject.is_empty() && !self.processes {
            bail!("--inject needs --processes (faults are done to the stage processes)");
        }
        if self.px4.is_some() && !self.processes {
            bail!("--autopilot px4-sitl needs --processes (PX4 runs as its own process)");
        }
        let mut injections = self.inject.clone();
        for i in &mut injections {
            i.resolve(&graph).map_err(anyhow::Error::msg)?;
        }
        let seed = self.seed.unwrap_or(scn.scenario.seed);
        let fsm_cfg = lockstep::mission(&cfg, &scn)?;
        let rules = Rules::of(&scn)?;
        let mut rec = Recording {
            skip: cfg.recorder.skip.clone(),
            ..Recording::default()
        };
        let mut meta = recorder::metadata::stack(Some(&cfg_path), &graph_path)?;
        meta.insert("scenario".into(), scn.scenario.name.clone());
        meta.insert("seed".into(), seed.to_string());
        let mode = if self.processes {
            "processes"
        } else {
            "lockstep"
        };
        meta.insert("mode".into(), mode.into());
        if let Some(p) = &self.record {
            // As --plot does: a new directory for the outputs is made, not refused.
            if let Some(dir) = p.parent().filter(|d| !d.as_os_str().is_empty()) {
                std::fs::create_dir_all(dir)
                    .with_context(|| format!("--record: cannot create {}", dir.display()))?;
            }
            let mut truth = Recorder::create(&truth_path(p))?;
            truth.write_metadata("landing", meta.clone())?;
            rec.truth = Some(truth);
        }
        let config_error =
            |e: stack_config::Invalid| anyhow::anyhow!("[recorder] {}: {}", e.key, e.message);
        // In lockstep this process records the pipeline and serves the live view, with
        // the recorder process's code; --processes starts that process for them.
        if !self.processes && (self.record.is_some() || self.live) {
            let mut options = cfg.recorder.options().map_err(config_error)?;
            if self.raw_images {
                options.images = recorder::ImageFormat::Raw;
            }
            // The mounts as the recorder process reads them.
            let text = std::fs::read_to_string(&cfg_path)
                .with_context(|| format!("reading {}", cfg_path.display()))?;
            (options.body_from_camera, options.body_from_depth) = recorder::config::mounts(&text)?;
            let mut pipeline = match &self.record {
                Some(p) => {
                    let mut r = Recorder::with_options(p, options)?;
                    r.write_metadata("landing", meta)?;
                    r
                }
                None => Recorder::without_file(options),
            };
            if self.live {
                let at = pipeline.serve_live(cfg.recorder.live_socket().map_err(config_error)?)?;
                events(Event::Live {
                    address: at.to_string(),
                    by_recorder_process: false,
                });
            }
            rec.pipeline = Some(pipeline);
        }
        if self.processes && self.live {
            let at = cfg.recorder.live_socket().map_err(config_error)?;
            events(Event::Live {
                address: at.to_string(),
                by_recorder_process: true,
            });
        }
        events(Event::Start {
            scenario: &scn.scenario.name,
            seed,
            description: &scn.scenario.description,
        });
        let mut progress = |t_s: f64, state: MissionState, to_pad_m: Option<f64>| {
            events(Event::Progress {
                t_s,
                state,
                to_pad_m,
            });
        };
        let mut died = None;
        let mut faults: Vec<FaultRecord> = Vec::new();
        let mut log_dir = None;
        let mut router = None;
        let (end, referee) = if self.processes {
            let dir = self.log_dir.clone().unwrap_or_else(|| {
                std::env::temp_dir().join(format!("landing-run-{}", std::process::id()))
            });
            let launch = processes::Launch {
                scenario: &scn,
                seed,
                config: &cfg_path,
                deploy: &self.deploy,
                log_dir: &dir,
                ipc_prefix: self.ipc_prefix.as_deref(),
                graph: &graph,
                graph_path: &graph_path,
                injections: &injections,
                recorder: processes::RecorderLaunch {
                    out: self.record.as_deref(),
                    raw_images: self.raw_images,
                    live: self.live,
                },
                signing_key: &cfg.px4_link.signing_key,
                realtime: self.realtime,
                router: self.router,
                px4: self.px4.as_deref(),
            };
            let r = processes::run(&launch, &mut rec.truth, &mut progress)?;
            log_dir = Some(dir);
            died = r.died;
            faults = r.faults;
            router = r.router.map(
                |(counts, gcs)| serde_json::json!({"endpoints": counts, "ground_station": gcs}),
            );
            (r.end, r.referee)
        } else {
            let setup = lockstep::Setup {
                scenario: &scn,
                seed,
                config: &cfg,
                fsm: fsm_cfg,
            };
            let mut driver = lockstep::driver(&graph, &setup, |_| None)?;
            let mut referee = Referee::new(0);
            let end = lockstep::run(
                &mut driver,
                scn.scenario.duration_s,
                &mut referee,
                &mut rec,
                self.live,
                &mut progress,
            )?;
            (end, referee)
        };
        let last_state = referee.last_state().copied();
        let Referee {
            eval,
            stats,
            transitions,
            ..
        } = referee;
        let obstacles = scn
            .obstacles(seed)
            .iter()
            .map(|b| (b.min_m, b.max_m))
            .collect();
        let log = eval.flight_log(&scn.scenario.name, seed, obstacles);
        let (outcome, why) = referee::verdict(end, &eval, last_state.as_ref(), &rules);
        let why = died.unwrap_or(why);
        let replans = u32::try_from(stats.plans.saturating_sub(1)).unwrap_or(u32::MAX);
        let mut summary = RunSummary::from_log(
            &log,
            outcome,
            &stats.planning_ms,
            replans,
            Some(eval.collisions),
        );
        summary.referee = why;
        for f in &mut faults {
            f.outcome = outcome.name().to_string();
        }
        summary.faults = faults;
        summary.router = router;
        let mut recordings = Vec::new();
        for r in [rec.pipeline.take(), rec.truth.take()]
            .into_iter()
            .flatten()
        {
            let path = r.path().to_path_buf();
            let file = r.has_file();
            let n = r.finish()?;
            if file {
                recordings.push((path, Some(n)));
            }
        }
        if let (true, Some(p)) = (self.processes, &self.record) {
            recordings.push((p.clone(), None));
        }
        Ok(Flown {
            scenario: scn.scenario.name.clone(),
            seed,
            outcome,
            summary,
            log,
            eval,
            transitions,
            planning_ms: stats.planning_ms,
            recordings,
            log_dir,
        })
    }
}
