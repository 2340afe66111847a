//! A campaign's table: per scenario, the success rate with its Wilson 95 % interval,
//! touchdown error and contact percentiles over the landed runs, outcomes by kind, and the
//! failed and worst runs with the command that flies each again.

use std::collections::BTreeMap;
use std::fmt;

use serde::Serialize;

use crate::record::{RunRecord, RunTiming};

/// z of a two-sided 95 % interval.
const Z95: f64 = 1.959_963_984_540_054;

/// How many worst landed runs a scenario lists.
pub const WORST: usize = 3;

/// The Wilson score interval of `k` successes in `n` trials at 95 %: unlike the normal
/// approximation it stays inside [0, 1] and says something at k = n (300 of 300: the
/// failure rate is below 1.3 %).
pub fn wilson95(k: u64, n: u64) -> [f64; 2] {
    if n == 0 {
        return [0.0, 1.0];
    }
    let (n, p) = (n as f64, k as f64 / n as f64);
    let z2 = Z95 * Z95;
    let centre = (p + z2 / (2.0 * n)) / (1.0 + z2 / n);
    let half = Z95 / (1.0 + z2 / n) * (p * (1.0 - p) / n + z2 / (4.0 * n * n)).sqrt();
    // At k = 0 and k = n the bounds are exactly 0 and 1; rounding would leave them a hair off.
    let lo = if k == 0 {
        0.0
    } else {
        (centre - half).max(0.0)
    };
    let hi = if k as f64 == n {
        1.0
    } else {
        (centre + half).min(1.0)
    };
    [lo, hi]
}

/// The `q`-th quantile (0..=1) of `v`, interpolated between ranks; `None` when empty.
pub fn quantile(v: &[f64], q: f64) -> Option<f64> {
    let mut v: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let k = (v.len() - 1) as f64 * q.clamp(0.0, 1.0);
    let (lo, hi) = (k.floor() as usize, k.ceil() as usize);
    Some(v[lo] + (v[hi] - v[lo]) * (k - lo as f64))
}

fn max(v: &[f64]) -> Option<f64> {
    v.iter().copied().filter(|x| x.is_finite()).reduce(f64::max)
}

/// A run worth a second look, and how to fly it again.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunRef {
    /// Its index.
    pub index: u64,
    /// Its seed.
    pub seed: u64,
    /// Its outcome.
    pub outcome: String,
    /// Its touchdown error, m.
    pub touchdown_error_m: Option<f64>,
    /// The command that flies it again.
    pub command: String,
}

/// One scenario's line of the table.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScenarioStats {
    /// Runs flown.
    pub runs: u64,
    /// Of them, `landed`.
    pub landed: u64,
    /// landed / runs.
    pub success_rate: f64,
    /// Wilson 95 % interval of the success rate.
    pub success_ci95: [f64; 2],
    /// Runs that ended `crashed`.
    pub crashes: u64,
    /// Runs by outcome.
    pub outcomes: BTreeMap<String, u64>,
    /// Touchdown error of the landed runs, m.
    pub touchdown_error_m_p50: Option<f64>,
    /// 95th percentile.
    pub touchdown_error_m_p95: Option<f64>,
    /// Largest.
    pub touchdown_error_m_max: Option<f64>,
    /// Downward speed at first contact of the landed runs, m/s: median.
    pub contact_vertical_mps_p50: Option<f64>,
    /// Largest.
    pub contact_vertical_mps_max: Option<f64>,
    /// Sideways speed at first contact, m/s: median.
    pub contact_horizontal_mps_p50: Option<f64>,
    /// Largest.
    pub contact_horizontal_mps_max: Option<f64>,
    /// Tilt at first contact, deg: median.
    pub contact_tilt_deg_p50: Option<f64>,
    /// Largest.
    pub contact_tilt_deg_max: Option<f64>,
    /// Take-off to touchdown, s: median over every run.
    pub flight_time_s_p50: Option<f64>,
    /// Planning calls of every run with a timing file, wall ms: median.
    pub planning_time_ms_p50: Option<f64>,
    /// 99th percentile.
    pub planning_time_ms_p99: Option<f64>,
    /// Every run that did not land.
    pub failed: Vec<RunRef>,
    /// The landed runs with the largest touchdown errors.
    pub worst: Vec<RunRef>,
}

/// The table: scenario name -> its line (`--json` prints exactly this object).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
#[serde(transparent)]
pub struct Table(pub BTreeMap<String, ScenarioStats>);

/// How a run is flown again: `landing run --scenario S --seed N`.
pub fn refly_command(scenario: &str, seed: u64) -> String {
    format!("landing run --scenario {scenario} --seed {seed}")
}

impl Table {
    /// The table of `runs` (with their timings, where read), scenarios in name order.
    pub fn of(runs: &[(RunRecord, Option<RunTiming>)]) -> Self {
        let mut by: BTreeMap<&str, Vec<&(RunRecord, Option<RunTiming>)>> = BTreeMap::new();
        for r in runs {
            by.entry(r.0.scenario.as_str()).or_default().push(r);
        }
        Self(
            by.into_iter()
                .map(|(name, rs)| (name.to_string(), stats(&rs)))
                .collect(),
        )
    }
}

fn stats(runs: &[&(RunRecord, Option<RunTiming>)]) -> ScenarioStats {
    let mut runs: Vec<&(RunRecord, Option<RunTiming>)> = runs.to_vec();
    runs.sort_by_key(|r| r.0.index);
    let n = runs.len() as u64;
    let landed: Vec<&RunRecord> = runs
        .iter()
        .map(|r| &r.0)
        .filter(|r| r.outcome == "landed")
        .collect();
    let k = landed.len() as u64;
    let mut outcomes = BTreeMap::new();
    for r in &runs {
        *outcomes.entry(r.0.outcome.clone()).or_insert(0) += 1;
    }
    let of = |f: fn(&RunRecord) -> Option<f64>| -> Vec<f64> {
        landed.iter().filter_map(|r| f(r)).collect()
    };
    let err = of(|r| r.touchdown_error_m);
    let vert = of(|r| r.contact_vertical_mps);
    let hor = of(|r| r.contact_horizontal_mps);
    let tilt = of(|r| r.contact_tilt_deg);
    let flight: Vec<f64> = runs.iter().map(|r| r.0.flight_time_s).collect();
    let planning: Vec<f64> = runs
        .iter()
        .filter_map(|r| r.1.as_ref())
        .flat_map(|t| t.planning_ms.iter().copied())
        .collect();
    let reference = |r: &RunRecord| RunRef {
        index: r.index,
        seed: r.seed,
        outcome: r.outcome.clone(),
        touchdown_error_m: r.touchdown_error_m,
        command: refly_command(&r.scenario, r.seed),
    };
    let mut worst: Vec<&RunRecord> = landed.clone();
    worst.sort_by(|a, b| {
        b.touchdown_error_m
            .unwrap_or(0.0)
            .total_cmp(&a.touchdown_error_m.unwrap_or(0.0))
            .then(a.index.cmp(&b.index))
    });
    ScenarioStats {
        runs: n,
        landed: k,
        success_rate: if n == 0 { 0.0 } else { k as f64 / n as f64 },
        success_ci95: wilson95(k, n),
        crashes: runs.iter().filter(|r| r.0.outcome == "crashed").count() as u64,
        outcomes,
        touchdown_error_m_p50: quantile(&err, 0.5),
        touchdown_error_m_p95: quantile(&err, 0.95),
        touchdown_error_m_max: max(&err),
        contact_vertical_mps_p50: quantile(&vert, 0.5),
        contact_vertical_mps_max: max(&vert),
        contact_horizontal_mps_p50: quantile(&hor, 0.5),
        contact_horizontal_mps_max: max(&hor),
        contact_tilt_deg_p50: quantile(&tilt, 0.5),
        contact_tilt_deg_max: max(&tilt),
        flight_time_s_p50: quantile(&flight, 0.5),
        planning_time_ms_p50: quantile(&planning, 0.5),
        planning_time_ms_p99: quantile(&planning, 0.99),
        failed: runs
            .iter()
            .map(|r| &r.0)
            .filter(|r| r.outcome != "landed")
            .map(reference)
            .collect(),
        worst: worst.into_iter().take(WORST).map(reference).collect(),
    }
}

fn cm(v: Option<f64>) -> String {
    v.map_or("-".into(), |x| format!("{:.1}", x * 100.0))
}

fn num(v: Option<f64>, digits: usize) -> String {
    v.map_or("-".into(), |x| format!("{x:.digits$}"))
}

impl fmt::Display for Table {
    /// A markdown table, then the failed and worst runs with their commands.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "| scenario | landed | success, 95 % CI | touchdown error p50 / p95 / max, cm | first contact down p50 / max, m/s | sideways p50 / max, m/s | tilt p50 / max, deg | flight p50, s | planning p50 / p99, ms |"
        )?;
        writeln!(f, "| --- | --- | --- | --- | --- | --- | --- | --- | --- |")?;
        for (name, s) in &self.0 {
            writeln!(
                f,
                "| {name} | {}/{} | {:.1} % [{:.1}, {:.1}] | {} / {} / {} | {} / {} | {} / {} | {} / {} | {} | {} / {} |",
                s.landed,
                s.runs,
                s.success_rate * 100.0,
                s.success_ci95[0] * 100.0,
                s.success_ci95[1] * 100.0,
                cm(s.touchdown_error_m_p50),
                cm(s.touchdown_error_m_p95),
                cm(s.touchdown_error_m_max),
                num(s.contact_vertical_mps_p50, 2),
                num(s.contact_vertical_mps_max, 2),
                num(s.contact_horizontal_mps_p50, 2),
                num(s.contact_horizontal_mps_max, 2),
                num(s.contact_tilt_deg_p50, 1),
                num(s.contact_tilt_deg_max, 1),
                num(s.flight_time_s_p50, 1),
                num(s.planning_time_ms_p50, 3),
                num(s.planning_time_ms_p99, 3),
            )?;
        }
        for (name, s) in &self.0 {
            let others: Vec<String> = s
                .outcomes
                .iter()
                .filter(|(o, _)| o.as_str() != "landed")
                .map(|(o, n)| format!("{n} {o}"))
                .collect();
            if !others.is_empty() {
                writeln!(f, "{name}: {}", others.join(", "))?;
            }
            for r in s.failed.iter().take(10) {
                writeln!(
                    f,
                    "  failed  run {:>4}: {:<12} {}",
                    r.index, r.outcome, r.command
                )?;
            }
            if s.failed.len() > 10 {
                writeln!(
                    f,
                    "  ... and {} more failed runs (--json lists them)",
                    s.failed.len() - 10
                )?;
            }
            for r in &s.worst {
                writeln!(
                    f,
                    "  worst   run {:>4}: {} cm     {}",
                    r.index,
                    cm(r.touchdown_error_m),
                    r.command
                )?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
#[path = "table_test.rs"]
mod tests;
