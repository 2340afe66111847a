//! One run of a campaign as a file: what it flew (scenario, index, seed, the stack's
//! config and revision) and how it ended, written atomically, one JSON object. A run's
//! file holds only what the flight computed, so the same run flown by another worker,
//! shard or job count writes the same bytes; what the machine measured (planning and
//! wall time) goes to a timing file beside it.

use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// The `format` of a run file: a file without it is not ours.
pub const FORMAT: &str = "landing-eval-run/1";

/// The `format` of a timing file.
pub const TIMING_FORMAT: &str = "landing-eval-timing/1";

/// One run, as flown and judged.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunRecord {
    /// [`FORMAT`].
    pub format: String,
    /// The scenario's name.
    pub scenario: String,
    /// SHA-256 of the scenario file, hex.
    pub scenario_hash: String,
    /// The run's index in its scenario (0-based).
    pub index: u64,
    /// The seed it flew (`landing run --scenario S --seed N` flies it again).
    pub seed: u64,
    /// SHA-256 of the stack configuration and the graph, hex: runs of one campaign share
    /// it.
    pub config_hash: String,
    /// The git revision of the build that flew it.
    pub revision: String,
    /// The referee's outcome (`landed`, `hard_landing`, ...).
    pub outcome: String,
    /// The referee's reason, one line.
    pub referee: String,
    /// Horizontal distance from the pad centre at the final touchdown, m.
    pub touchdown_error_m: Option<f64>,
    /// Where the vehicle's centre (the mean of its feet) came down, in the pad frame
    /// (x along the pad vehicle's heading, y left), m.
    pub touchdown_pad_m: Option<[f64; 2]>,
    /// Speed relative to the surface at the final touchdown, m/s.
    pub touchdown_rel_speed_mps: Option<f64>,
    /// Downward speed at the final landing's first contact, m/s.
    pub contact_vertical_mps: Option<f64>,
    /// Sideways speed there, m/s.
    pub contact_horizontal_mps: Option<f64>,
    /// Tilt there, deg.
    pub contact_tilt_deg: Option<f64>,
    /// Take-off to touchdown, s.
    pub flight_time_s: f64,
    /// Path length, m.
    pub distance_m: f64,
    /// The pad vehicle's mean speed while it moves, km/h.
    pub target_speed_kmh: Option<f64>,
    /// Obstacle contacts (`None`: no obstacles).
    pub collisions: Option<u32>,
    /// Successful plans after the first.
    pub replans: u32,
}

/// What the machine measured flying a run (not the same twice).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunTiming {
    /// [`TIMING_FORMAT`].
    pub format: String,
    /// Every planning call's wall time, ms.
    pub planning_ms: Vec<f64>,
    /// The run's wall time, s.
    pub wall_s: f64,
    /// The simulated time flown, s.
    pub sim_s: f64,
}

/// Why a run file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The file system.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What the OS said.
        error: std::io::Error,
    },
    /// Not a run file of ours (no or another `format`, or not its fields).
    #[error("{path}: not a run file of `landing eval` ({why})")]
    NotOurs {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        why: String,
    },
}

/// The run file of run `index` of `scenario` under `dir`.
pub fn run_path(dir: &Path, scenario: &str, index: u64) -> PathBuf {
    dir.join(scenario).join(format!("run-{index:06}.json"))
}

/// The timing file beside a run file.
pub fn timing_path(run: &Path) -> PathBuf {
    run.with_extension("timing.json")
}

/// Writes `bytes` to `path` atomically: into a temporary file beside it, then renamed,
/// so a reader (a resumed shard, a merge) sees the whole file or none.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), RecordError> {
    let io = |error| RecordError::Io {
        path: path.to_path_buf(),
        error,
    };
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(io)?;
    }
    let tmp = path.with_extension(format!("tmp.{}", std::process::id()));
    let mut f = std::fs::File::create(&tmp).map_err(io)?;
    f.write_all(bytes).map_err(io)?;
    f.sync_all().map_err(io)?;
    std::fs::rename(&tmp, path).map_err(io)
}

impl RunRecord {
    /// Writes the record at its place under `dir`, atomically; returns the path.
    pub fn write(&self, dir: &Path) -> Result<PathBuf, RecordError> {
        let path = run_path(dir, &self.scenario, self.index);
        let mut bytes = serde_json::to_vec_pretty(self).map_err(|e| RecordError::NotOurs {
            path: path.clone(),
            why: e.to_string(),
        })?;
        bytes.push(b'\n');
        write_atomically(&path, &bytes)?;
        Ok(path)
    }

    /// Reads a run file; a file that is not ours is an error naming it.
    pub fn read(path: &Path) -> Result<Self, RecordError> {
        let bytes = std::fs::read(path).map_err(|error| RecordError::Io {
            path: path.to_path_buf(),
            error,
        })?;
        let not_ours = |why: String| RecordError::NotOurs {
            path: path.to_path_buf(),
            why,
        };
        let value: serde_json::Value =
            serde_json::from_slice(&bytes).map_err(|e| not_ours(e.to_string()))?;
        match value.get("format").and_then(|f| f.as_str()) {
            Some(FORMAT) => {}
            Some(other) => return Err(not_ours(format!("format `{other}`, not `{FORMAT}`"))),
            None => return Err(not_ours("no `format`".into())),
        }
        serde_json::from_value(value).map_err(|e| not_ours(e.to_string()))
    }
}

impl RunTiming {
    /// Writes the timing beside the run file `run`, atomically.
    pub fn write(&self, run: &Path) -> Result<(), RecordError> {
        let path = timing_path(run);
        let bytes = serde_json::to_vec(self).map_err(|e| RecordError::NotOurs {
            path: path.clone(),
            why: e.to_string(),
        })?;
        write_atomically(&path, &bytes)
    }

    /// The timing beside the run file `run`, if there is one that reads.
    pub fn read(run: &Path) -> Option<Self> {
        let bytes = std::fs::read(timing_path(run)).ok()?;
        serde_json::from_slice::<Self>(&bytes)
            .ok()
            .filter(|t| t.format == TIMING_FORMAT)
    }
}

/// Every run file under `dir` (its scenario folders), sorted.
pub fn run_files(dir: &Path) -> Result<Vec<PathBuf>, RecordError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |error| RecordError::Io { path, error }
    };
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(io(dir))? {
        let entry = entry.map_err(io(dir))?;
        let sub = entry.path();
        if !sub.is_dir() {
            continue;
        }
        for f in std::fs::read_dir(&sub).map_err(io(&sub))? {
            let p = f.map_err(io(&sub))?.path();
            let name = p.file_name().and_then(|n| n.to_str()).unwrap_or_default();
            if name.starts_with("run-")
                && name.ends_with(".json")
                && !name.ends_with(".timing.json")
            {
                out.push(p);
            }
        }
    }
    out.sort();
    Ok(out)
}
