//! The recorder: every topic of the pipeline into one MCAP file per run, in Foxglove's
//! schemas (images, transforms, the 3-D scene, logs) and as plottable JSON, written with
//! the Foxglove SDK. [`RecorderStage`] is the stage both drivers run: the `recorder`
//! process under the iceoryx2 driver, and `landing run` in lockstep with the same code.
//! [`read`] reads recordings back, up to where a damaged one breaks, and [`decode`] turns
//! what they hold back into the stack's messages. [`process`] is the `recorder` binary's
//! whole work.

pub mod config;
pub mod decode;
pub mod metadata;
pub mod process;
pub mod read;
pub mod schema;
pub mod stage;
pub mod visual;
pub mod writer;

pub use config::RecorderConfig;
pub use decode::{
    CallerError, DecodeError, Decoded, ReadRecordingError, RecordedMap, RecordedMaps,
    read_recording,
};
pub use read::{
    Broken, ReadError, ReadSummary, RecordedMessage, RecordingInfo, info, read_messages,
};
pub use schema::{Recordable, SchemaError, json_schema_of, schema_for};
pub use stage::RecorderStage;
pub use writer::{ChunkCompression, ImageFormat, RecordError, RecordOptions, Recorder};

/// A new recording's path in `dir`, named by the UTC time `at` (`20261126T201500Z.mcap`;
/// `-1`, `-2`, ... when that name is taken): a recorder restarted within the second never
/// truncates the file before it. Creates `dir`.
pub fn dated_path(
    dir: &std::path::Path,
    at: std::time::SystemTime,
) -> std::io::Result<std::path::PathBuf> {
    std::fs::create_dir_all(dir)?;
    let secs = at
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let (days, rest) = (secs / 86_400, secs % 86_400);
    let (y, m, d) = civil_from_days(days as i64);
    let stem = format!(
        "{y:04}{m:02}{d:02}T{:02}{:02}{:02}Z",
        rest / 3600,
        rest / 60 % 60,
        rest % 60
    );
    let mut path = dir.join(format!("{stem}.mcap"));
    let mut k = 0;
    while path.exists() {
        k += 1;
        path = dir.join(format!("{stem}-{k}.mcap"));
    }
    Ok(path)
}

/// Year, month, day of the civil (proleptic Gregorian) calendar `days` after 1970-01-01
/// (Howard Hinnant's `civil_from_days`).
fn civil_from_days(days: i64) -> (i64, u32, u32) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let y = yoe + era * 400 + i64::from(m <= 2);
    (y, m, d)
}

#[cfg(test)]
#[path = "lib_test.rs"]
mod dated_tests;
