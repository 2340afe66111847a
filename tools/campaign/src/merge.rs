//! The run files of a campaign's shards gathered into one table: every file must be ours,
//! every run flown with one stack configuration (and each scenario from one file), and
//! every index appear once; with an expected count, every index below it must be there.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use crate::record::{RecordError, RunRecord, RunTiming, run_files};

/// Why run files do not make one campaign.
#[derive(Debug, thiserror::Error)]
pub enum MergeError {
    /// No directory given, or none holds a run.
    #[error("no run files in {0}")]
    Empty(String),
    /// A file that is not ours, or that does not read.
    #[error(transparent)]
    Record(#[from] RecordError),
    /// Runs of two stack configurations.
    #[error(
        "{a} and {b} were flown with different stack configurations ({ha:.12} and {hb:.12}): a campaign has one"
    )]
    Configs {
        /// One file.
        a: PathBuf,
        /// Another.
        b: PathBuf,
        /// Its config hash.
        ha: String,
        /// The other's.
        hb: String,
    },
    /// One scenario from two files.
    #[error("{a} and {b}: scenario {scenario} from two different scenario files")]
    Scenarios {
        /// One file.
        a: PathBuf,
        /// Another.
        b: PathBuf,
        /// The scenario.
        scenario: String,
    },
    /// An index twice.
    #[error("run {index} of {scenario} is there twice: {a} and {b}")]
    Duplicate {
        /// The scenario.
        scenario: String,
        /// The index.
        index: u64,
        /// One file.
        a: PathBuf,
        /// The other.
        b: PathBuf,
    },
    /// An index missing, or beyond the expected count.
    #[error("{scenario}: {what} (--expect {expect})")]
    Count {
        /// The scenario.
        scenario: String,
        /// Which indices.
        what: String,
        /// The count expected.
        expect: u64,
    },
}

/// Every run under `dirs`, checked (see the module docs); with `expect`, each scenario
/// must hold runs 0 to expect - 1 exactly.
pub fn merge(
    dirs: &[PathBuf],
    expect: Option<u64>,
) -> Result<Vec<(RunRecord, Option<RunTiming>)>, MergeError> {
    let mut files = Vec::new();
    for d in dirs {
        files.extend(run_files(d)?);
    }
    if files.is_empty() {
        let names: Vec<String> = dirs.iter().map(|d| d.display().to_string()).collect();
        return Err(MergeError::Empty(names.join(", ")));
    }
    let mut runs = Vec::new();
    let mut first: Option<(PathBuf, String)> = None;
    let mut scenario_files: BTreeMap<String, (PathBuf, String)> = BTreeMap::new();
    let mut seen: BTreeMap<(String, u64), PathBuf> = BTreeMap::new();
    for f in files {
        let r = RunRecord::read(&f)?;
        match &first {
            None => first = Some((f.clone(), r.config_hash.clone())),
            Some((a, h)) if *h != r.config_hash => {
                return Err(MergeError::Configs {
                    a: a.clone(),
                    b: f,
                    ha: h.clone(),
                    hb: r.config_hash,
                });
            }
            Some(_) => {}
        }
        match scenario_files.get(&r.scenario) {
            Some((a, h)) if *h != r.scenario_hash => {
                return Err(MergeError::Scenarios {
                    a: a.clone(),
                    b: f,
                    scenario: r.scenario,
                });
            }
            Some(_) => {}
            None => {
                scenario_files.insert(r.scenario.clone(), (f.clone(), r.scenario_hash.clone()));
            }
        }
        if let Some(a) = seen.insert((r.scenario.clone(), r.index), f.clone()) {
            return Err(MergeError::Duplicate {
                scenario: r.scenario,
                index: r.index,
                a,
                b: f,
            });
        }
        let timing = RunTiming::read(&f);
        runs.push((r, timing));
    }
    if let Some(n) = expect {
        for scenario in scenario_files.keys() {
            let have: BTreeSet<u64> = seen
                .keys()
                .filter(|(s, _)| s == scenario)
                .map(|(_, i)| *i)
                .collect();
            let missing: Vec<u64> = (0..n).filter(|i| !have.contains(i)).collect();
            let beyond: Vec<u64> = have.iter().copied().filter(|i| *i >= n).collect();
            let list = |v: &[u64]| {
                let shown: Vec<String> = v.iter().take(8).map(u64::to_string).collect();
                let more = if v.len() > 8 { ", ..." } else { "" };
                format!("{}{more}", shown.join(", "))
            };
            if !missing.is_empty() {
                return Err(MergeError::Count {
                    scenario: scenario.clone(),
                    what: format!("{} runs missing: {}", missing.len(), list(&missing)),
                    expect: n,
                });
            }
            if !beyond.is_empty() {
                return Err(MergeError::Count {
                    scenario: scenario.clone(),
                    what: format!("runs beyond the count: {}", list(&beyond)),
                    expect: n,
                });
            }
        }
    }
    Ok(runs)
}

/// `dir` holds run files of a campaign (for a quick check before a merge).
pub fn holds_runs(dir: &Path) -> bool {
    run_files(dir).is_ok_and(|f| !f.is_empty())
}
