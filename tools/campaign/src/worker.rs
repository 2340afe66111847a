//! One run flown and written, and the loop of a worker process: a run a line on stdin
//! (`INDEX<TAB>SEED<TAB>SCENARIO_HASH<TAB>SCENARIO`), a line on stdout when its file is
//! written (`ok<TAB>INDEX<TAB>OUTCOME`), or `error<TAB>INDEX<TAB>WHY` when it could not be
//! flown, after which the worker stops.

use std::io::{BufRead, Write};
use std::path::PathBuf;
use std::time::Instant;

use evaluation::referee::Touchdown;
use recorder::metadata::GIT_REVISION;
use stack::mission::Mission;

use crate::record::{FORMAT, RunRecord, RunTiming, TIMING_FORMAT};

/// What a worker flies with: the stack, and where the run files go.
#[derive(Debug, Clone)]
pub struct Worker {
    /// The deploy directory.
    pub deploy: PathBuf,
    /// The stack configuration.
    pub config: PathBuf,
    /// Its hash with the graph's (the campaign's).
    pub config_hash: String,
    /// Where the run files go.
    pub out: PathBuf,
}

/// Where the vehicle's centre came down in the pad frame: the mean of its feet.
fn centre_on_pad(t: &Touchdown) -> [f64; 2] {
    let n = t.gear_pad.len() as f64;
    let (x, y) = t
        .gear_pad
        .iter()
        .fold((0.0, 0.0), |(x, y), p| (x + p.x, y + p.y));
    [x / n, y / n]
}

impl Worker {
    /// Flies run `index` of `scenario` (a name or a file, whose file hashes to
    /// `scenario_hash`) on `seed` in lockstep and writes its files; returns the record.
    pub fn fly(
        &self,
        scenario: &str,
        scenario_hash: &str,
        index: u64,
        seed: u64,
    ) -> anyhow::Result<RunRecord> {
        let mission = Mission {
            scenario: scenario.to_string(),
            seed: Some(seed),
            deploy: self.deploy.clone(),
            config: Some(self.config.clone()),
            ..Mission::default()
        };
        let started = Instant::now();
        let flown = mission.fly(&mut |_| {})?;
        let wall_s = started.elapsed().as_secs_f64();
        let s = &flown.summary;
        let record = RunRecord {
            format: FORMAT.into(),
            scenario: flown.scenario.clone(),
            scenario_hash: scenario_hash.to_string(),
            index,
            seed,
            config_hash: self.config_hash.clone(),
            revision: GIT_REVISION.to_string(),
            outcome: flown.outcome.name().to_string(),
            referee: s.referee.clone(),
            touchdown_error_m: s.touchdown_error_m,
            touchdown_pad_m: flown.eval.final_touchdown().map(centre_on_pad),
            touchdown_rel_speed_mps: s.touchdown_rel_speed_mps,
            contact_vertical_mps: s.touchdown_vertical_speed_mps,
            contact_horizontal_mps: s.touchdown_horizontal_speed_mps,
            contact_tilt_deg: s.touchdown_tilt_deg,
            flight_time_s: s.flight_time_s,
            distance_m: s.distance_m,
            target_speed_kmh: s.target_speed_kmh,
            collisions: s.collisions,
            replans: s.replans,
        };
        let path = record.write(&self.out)?;
        let sim_s = flown.log.samples.last().map_or(0.0, |x| x.t_s);
        RunTiming {
            format: TIMING_FORMAT.into(),
            planning_ms: flown.planning_ms.clone(),
            wall_s,
            sim_s,
        }
        .write(&path)?;
        Ok(record)
    }

    /// The worker process's loop (see the module docs) until stdin closes. A worker is
    /// one core: OpenCV's own threads (the camera's remap, the detector) would take the
    /// other workers' cores, so it runs them on this one (what is computed does not
    /// depend on it).
    pub fn serve(&self, input: impl BufRead, mut output: impl Write) -> anyhow::Result<()> {
        opencv::core::set_num_threads(1)?;
        for line in input.lines() {
            let line = line?;
            let mut f = line.splitn(4, '\t');
            let (Some(index), Some(seed), Some(hash), Some(scenario)) =
                (f.next(), f.next(), f.next(), f.next())
            else {
                anyhow::bail!("a task line that is not INDEX SEED HASH SCENARIO: {line:?}");
            };
            let (index, seed): (u64, u64) = (index.parse()?, seed.parse()?);
            match self.fly(scenario, hash, index, seed) {
                Ok(r) => writeln!(output, "ok\t{index}\t{}", r.outcome)?,
                Err(e) => {
                    let why = format!("{e:#}").replace(['\n', '\t'], " ");
                    writeln!(output, "error\t{index}\t{why}")?;
                    output.flush()?;
                    return Err(e);
                }
            }
            output.flush()?;
        }
        Ok(())
    }
}
