//! Monte Carlo campaigns: scenarios flown many times in lockstep, on seeds derived from
//! one base seed, in parallel worker processes or spread over a batch engine's shards,
//! each run written as one file, and the table of them with confidence intervals.
//!
//! - [`seed`]: run `i` of a scenario flies `derive(base, scenario, i)`, whatever flies it.
//! - [`Campaign`]: what to fly (scenarios, runs, base seed, a shard of it) and where the
//!   run files go; a run whose file is already there is not flown again.
//! - [`worker`]: one run flown and written (the worker processes' loop).
//! - [`pool`]: worker processes fed one run at a time over pipes.
//! - [`merge`]: run files of shards gathered and checked (one config, every index once).
//! - [`table`]: per scenario, success with its Wilson interval, percentiles, the failed
//!   and worst runs; [`plots`] draws them.
//!
//! A mission that does not land is a result; only what stops runs from being flown (a
//! scenario that does not load, a worker that dies, a disk that fails) is an error.

pub mod merge;
pub mod plots;
pub mod pool;
pub mod record;
pub mod seed;
pub mod table;
pub mod worker;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use sha2::{Digest, Sha256};

use crate::record::{RecordError, RunRecord, RunTiming, run_path};

/// Why a campaign cannot be flown as asked. Each is one line naming what is wrong and
/// what is allowed.
#[derive(Debug, thiserror::Error)]
pub enum CampaignError {
    /// `--runs 0` or too many.
    #[error("--runs {0} is not allowed (allowed: 1 to 1000000)")]
    Runs(u64),
    /// `--jobs 0` or too many.
    #[error("--jobs {0} is not allowed (allowed: 1 to 256)")]
    Jobs(usize),
    /// No scenario given.
    #[error("--scenarios is empty (allowed: scenario names or files, comma-separated)")]
    NoScenario,
    /// A scenario that does not load.
    #[error("scenario `{spec}`: {error}")]
    Scenario {
        /// What was asked.
        spec: String,
        /// Why it does not load.
        error: String,
    },
    /// The same scenario twice.
    #[error("scenario `{0}` is asked for twice")]
    Duplicate(String),
    /// A file of the stack that could not be read.
    #[error("{path}: {error}")]
    Read {
        /// The file.
        path: PathBuf,
        /// What the OS said.
        error: std::io::Error,
    },
    /// The output directory holds a run of another campaign at a place this one writes.
    #[error(
        "{path} is run {index} of {scenario} from another campaign ({why}): give another --out, or delete it"
    )]
    Foreign {
        /// The file.
        path: PathBuf,
        /// Its scenario.
        scenario: String,
        /// Its index.
        index: u64,
        /// What differs.
        why: String,
    },
    /// A run file.
    #[error(transparent)]
    Record(#[from] RecordError),
}

/// A part of a campaign for one machine of a batch engine: `K/N` flies the runs whose
/// index mod N is K - 1 (1-based, as cargo-nextest's `--partition count:K/N`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// This shard, 1-based.
    pub k: u64,
    /// Shards in all.
    pub n: u64,
}

impl FromStr for Shard {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let bad = || format!("`{s}` is not a shard (allowed: K/N with 1 <= K <= N, e.g. 1/3)");
        let (k, n) = s.split_once('/').ok_or_else(bad)?;
        let (k, n): (u64, u64) = (
            k.trim().parse().map_err(|_| bad())?,
            n.trim().parse().map_err(|_| bad())?,
        );
        if k == 0 || n == 0 || k > n {
            return Err(bad());
        }
        Ok(Self { k, n })
    }
}

impl Shard {
    /// Whether this shard flies run `index`.
    pub fn has(&self, index: u64) -> bool {
        index % self.n == self.k - 1
    }
}

/// One scenario of a campaign.
#[derive(Debug, Clone, PartialEq)]
pub struct ScenarioPlan {
    /// As asked (a name, or a file).
    pub spec: String,
    /// Its name (the file's `name`): the run files' folder.
    pub name: String,
    /// SHA-256 of its file, hex.
    pub hash: String,
}

/// One run to fly.
#[derive(Debug, Clone, PartialEq)]
pub struct Task {
    /// Which of the campaign's scenarios.
    pub scenario: usize,
    /// Its index.
    pub index: u64,
    /// Its seed.
    pub seed: u64,
}

/// What to fly, with what stack, and where the run files go.
#[derive(Debug, Clone)]
pub struct Campaign {
    /// The scenarios, in the order asked.
    pub scenarios: Vec<ScenarioPlan>,
    /// Runs per scenario.
    pub runs: u64,
    /// The base seed.
    pub base_seed: u64,
    /// This machine's part, if sharded.
    pub shard: Option<Shard>,
    /// The deploy directory.
    pub deploy: PathBuf,
    /// The stack configuration.
    pub config: PathBuf,
    /// SHA-256 of the configuration and the graph, hex.
    pub config_hash: String,
    /// Where the run files go.
    pub out: PathBuf,
}

fn sha256_hex(parts: &[&[u8]]) -> String {
    let mut h = Sha256::new();
    for p in parts {
        h.update((p.len() as u64).to_le_bytes());
        h.update(p);
    }
    h.finalize().iter().map(|b| format!("{b:02x}")).collect()
}

fn read(path: &Path) -> Result<Vec<u8>, CampaignError> {
    std::fs::read(path).map_err(|error| CampaignError::Read {
        path: path.to_path_buf(),
        error,
    })
}

impl Campaign {
    /// A campaign of `runs` runs of each of `specs` (names or files) from `base_seed`,
    /// with the stack in `deploy` (its `config`, default `config/landing.toml`), writing
    /// into `out`; every scenario loaded and checked now.
    pub fn new(
        specs: &[String],
        runs: u64,
        base_seed: u64,
        shard: Option<Shard>,
        deploy: &Path,
        config: Option<&Path>,
        out: &Path,
    ) -> Result<Self, CampaignError> {
        if runs == 0 || runs > 1_000_000 {
            return Err(CampaignError::Runs(runs));
        }
        if specs.is_empty() {
            return Err(CampaignError::NoScenario);
        }
        let config = config.map_or_else(
            || deploy.join("config").join("landing.toml"),
            Path::to_path_buf,
        );
        let graph = graph::default_path(deploy);
        let config_hash = sha256_hex(&[&read(&config)?, &read(&graph)?]);
        let mut scenarios = Vec::new();
        let mut names = BTreeSet::new();
        for spec in specs {
            let scn = sim::scenario::load(spec, deploy).map_err(|e| CampaignError::Scenario {
                spec: spec.clone(),
                error: e.to_string(),
            })?;
            let name = scn.scenario.name.clone();
            if !names.insert(name.clone()) {
                return Err(CampaignError::Duplicate(name));
            }
            scenarios.push(ScenarioPlan {
                spec: spec.clone(),
                name,
                hash: sha256_hex(&[&read(&scn.path)?]),
            });
        }
        Ok(Self {
            scenarios,
            runs,
            base_seed,
            shard,
            deploy: deploy.to_path_buf(),
            config,
            config_hash,
            out: out.to_path_buf(),
        })
    }

    /// Every run of this campaign (of this shard), scenario by scenario.
    pub fn tasks(&self) -> Vec<Task> {
        let mut tasks = Vec::new();
        for (s, plan) in self.scenarios.iter().enumerate() {
            for index in 0..self.runs {
                if self.shard.is_some_and(|sh| !sh.has(index)) {
                    continue;
                }
                tasks.push(Task {
                    scenario: s,
                    index,
                    seed: seed::derive(self.base_seed, &plan.name, index),
                });
            }
        }
        tasks
    }

    /// The run file of `task`.
    pub fn path_of(&self, task: &Task) -> PathBuf {
        let name = self
            .scenarios
            .get(task.scenario)
            .map_or("", |p| p.name.as_str());
        run_path(&self.out, name, task.index)
    }

    /// The tasks whose run file is not there yet; a file that is there must be this
    /// campaign's run (same seed, scenario and config), else an error.
    pub fn pending(&self) -> Result<Vec<Task>, CampaignError> {
        let mut pending = Vec::new();
        for task in self.tasks() {
            let path = self.path_of(&task);
            if !path.exists() {
                pending.push(task);
                continue;
            }
            let r = RunRecord::read(&path)?;
            let plan = &self.scenarios[task.scenario];
            let why = if r.seed != task.seed {
                Some(format!("seed {}, this campaign's {}", r.seed, task.seed))
            } else if r.config_hash != self.config_hash {
                Some("another stack configuration or graph".to_string())
            } else if r.scenario_hash != plan.hash {
                Some("another scenario file".to_string())
            } else {
                None
            };
            if let Some(why) = why {
                return Err(CampaignError::Foreign {
                    path,
                    scenario: plan.name.clone(),
                    index: task.index,
                    why,
                });
            }
        }
        Ok(pending)
    }

    /// Every run file of this campaign (this shard's) that is there, with its timing.
    pub fn records(&self) -> Result<Vec<(RunRecord, Option<RunTiming>)>, CampaignError> {
        let mut out = Vec::new();
        for task in self.tasks() {
            let path = self.path_of(&task);
            if path.exists() {
                out.push((RunRecord::read(&path)?, RunTiming::read(&path)));
            }
        }
        Ok(out)
    }

    /// What a worker needs to fly this campaign's runs.
    pub fn worker(&self) -> worker::Worker {
        worker::Worker {
            deploy: self.deploy.clone(),
            config: self.config.clone(),
            config_hash: self.config_hash.clone(),
            out: self.out.clone(),
        }
    }
}

#[cfg(test)]
#[path = "lib_test.rs"]
mod tests;
