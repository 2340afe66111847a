//! `landing mcap touchdown run.mcap`: a recorded touchdown taken apart against the
//! simulator's truth (`evaluation::touchdown`), to read a tail part by part: the offset
//! the drop began from, how much of it the stack could not see, and what the fall added.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::Args;
use evaluation::touchdown::{TouchdownAnatomy, TouchdownSeries, touchdown_anatomy};
use fsm::FsmConfig;
use ipc_types::topics;
use stack::StackConfig;

/// Arguments of `landing mcap touchdown`.
#[derive(Debug, Args)]
pub struct TouchdownArgs {
    /// The recording (`landing run --record FILE.mcap`).
    #[arg(value_name = "FILE.mcap")]
    file: PathBuf,
    /// The simulator's truth (default: FILE.truth.mcap beside the recording).
    #[arg(long, value_name = "FILE.truth.mcap")]
    truth: Option<PathBuf>,
    /// Print the anatomy as one JSON object (metres, m/s, m/s^2).
    #[arg(long)]
    json: bool,
}

/// What the recording says about the run: its scenario, its seed and the configuration
/// it flew (the text).
#[derive(Default)]
struct About {
    scenario: Option<String>,
    seed: Option<String>,
    config: Option<String>,
}

fn read(path: &Path, series: &mut TouchdownSeries, about: &mut About) -> Result<()> {
    let summary = recorder::read_recording(path, |m| {
        if m.encoding != "json" {
            return Ok(());
        }
        let t = m.log_time;
        match m.topic.trim_start_matches('/') {
            topics::SIM_TRUTH_STATE => series.truth.push((t, m.decode()?)),
            topics::SIM_TRUTH => series.events.push((t, m.decode()?)),
            topics::FSM_SETPOINT => series.setpoints.push((t, m.decode()?)),
            topics::VEHICLE_STATE => series.states.push((t, m.decode()?)),
            topics::FSM_STATUS => series.statuses.push((t, m.decode()?)),
            _ => {}
        }
        Ok(())
    })
    .with_context(|| format!("reading {}", path.display()))?;
    if let Some(b) = &summary.broken {
        eprintln!("  {}: {b}", path.display());
    }
    if let Some(meta) = summary.metadata.get("landing") {
        about.scenario = about.scenario.take().or(meta.get("scenario").cloned());
        about.seed = about.seed.take().or(meta.get("seed").cloned());
        about.config = about.config.take().or(meta.get("config").cloned());
    }
    Ok(())
}

/// The touchdown's and the drop's descent rates, m/s: the recorded configuration's
/// `[fsm] land_rate_m_s` and `drop_rate_m_s`, read as the stack reads its configuration
/// (the defaults where the recording carries none). A recorded configuration that does
/// not parse is an error: rates guessed past it would find the wrong drop.
fn rates(config: Option<&str>, origin: &Path) -> Result<(f64, f64)> {
    let fsm = match config {
        Some(text) => {
            stack_config::parse::<StackConfig>(text, origin)
                .context("the recording's config (metadata)")?
                .fsm
        }
        None => FsmConfig::default(),
    };
    Ok((fsm.land_rate_m_s, fsm.drop_rate_m_s))
}

/// Runs `landing mcap touchdown`.
pub fn run(args: &TouchdownArgs) -> Result<()> {
    let truth = args
        .truth
        .clone()
        .unwrap_or_else(|| args.file.with_extension("truth.mcap"));
    if !truth.exists() {
        bail!(
            "{}: no truth file; the anatomy needs the simulator's truth (`landing run --record` \
             writes FILE.truth.mcap beside the recording; or name it with --truth)",
            truth.display()
        );
    }
    let mut series = TouchdownSeries::default();
    let mut about = About::default();
    read(&truth, &mut series, &mut about)?;
    read(&args.file, &mut series, &mut about)?;
    series.truth.sort_by_key(|(t, _)| *t);
    series.events.sort_by_key(|(t, _)| *t);
    series.setpoints.sort_by_key(|(t, _)| *t);
    series.states.sort_by_key(|(t, _)| *t);
    series.statuses.sort_by_key(|(t, _)| *t);
    let (land, drop) = rates(about.config.as_deref(), &args.file)?;
    let a = touchdown_anatomy(&series, land, drop)
        .with_context(|| format!("{}", args.file.display()))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&a)?);
    } else {
        print!("{}", table(&a, &about));
    }
    Ok(())
}

/// The anatomy as a table: centimetres, cm/s, and the lean in m/s^2.
fn table(a: &TouchdownAnatomy, about: &About) -> String {
    let row = |v: [f64; 2], scale: f64, digits: usize| {
        format!(
            "{:7.digits$} {:7.digits$} {:7.digits$}",
            v[0] * scale,
            v[1] * scale,
            v[0].hypot(v[1]) * scale
        )
    };
    let run = match (&about.scenario, &about.seed) {
        (Some(s), Some(n)) => format!("{s}, seed {n}"),
        (Some(s), None) => s.clone(),
        _ => "a recorded flight".into(),
    };
    let mut out = format!(
        "touchdown of {run}: the drop began {:.2} m over the pad, {:.2} s before contact; \
         the pad at {:.2} m/s\n",
        a.drop_height_m, a.drop_lead_s, a.pad_speed_m_s
    );
    out += "x along the pad's velocity, y to its left        x       y     |xy|\n";
    let rows: [(&str, [f64; 2], f64, usize, &str); 8] = [
        (
            "offset at the drop's start (truth)",
            a.offset_at_drop_m,
            100.0,
            1,
            "cm",
        ),
        (
            "  as the stack read it",
            a.offset_read_at_drop_m,
            100.0,
            1,
            "cm",
        ),
        (
            "  not seen (truth - read)",
            a.read_error_at_drop_m,
            100.0,
            1,
            "cm",
        ),
        (
            "velocity over the pad at the drop",
            a.rel_velocity_at_drop_m_s,
            100.0,
            1,
            "cm/s",
        ),
        ("drift through the fall", a.fall_drift_m, 100.0, 1, "cm"),
        (
            "offset at contact (truth)",
            a.offset_at_contact_m,
            100.0,
            1,
            "cm",
        ),
        (
            "touchdown, the pad's own frame",
            a.touchdown_pad_m,
            100.0,
            1,
            "cm",
        ),
        (
            "lean held before the drop",
            a.lean_before_drop_m_s2,
            1.0,
            2,
            "m/s^2",
        ),
    ];
    for (name, v, scale, digits, unit) in rows {
        out += &format!("{name:<46}{} {unit}\n", row(v, scale, digits));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rates_come_from_the_recorded_configuration_else_the_defaults() {
        let origin = Path::new("run.mcap");
        let shipped = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../deploy/config/landing.toml"
        );
        let text = std::fs::read_to_string(shipped).unwrap();
        let c = text
            .replace("\nland_rate_m_s = 0.7\n", "\nland_rate_m_s = 0.5\n")
            .replace("\ndrop_rate_m_s = 0.8\n", "\ndrop_rate_m_s = 0.9\n");
        assert_eq!(rates(Some(&c), origin).unwrap(), (0.5, 0.9));
        let d = FsmConfig::default();
        assert_eq!(
            rates(None, origin).unwrap(),
            (d.land_rate_m_s, d.drop_rate_m_s)
        );
        // What the stack would refuse is refused, not read past.
        assert!(rates(Some("not toml ["), origin).is_err());
        let negative = text.replace("\ndrop_rate_m_s = 0.8\n", "\ndrop_rate_m_s = -1.0\n");
        let e = rates(Some(&negative), origin).unwrap_err();
        assert!(format!("{e:#}").contains("drop_rate_m_s"), "{e:#}");
    }
}
