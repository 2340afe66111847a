//! TOML configuration loading with validation, for every crate of the stack.
//!
//! A user mistake must produce one line that names the file, the key and what is allowed,
//! so config types derive `Deserialize` with `deny_unknown_fields` and implement
//! [`Validate`] for ranges and cross-field rules; [`load`] turns every failure into a
//! [`ConfigError`] whose `Display` is that one line.
//!
//! A crate of its own, below the runtime: process libraries validate their sections with
//! it and must not depend on the runtime (iceoryx2, signals, logging); the runtime uses
//! it for the `[ipc]` prefix rules, and binaries and tools load their files with it.

use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;

/// A config value that parsed but is not allowed.
#[derive(Debug, Clone, PartialEq)]
pub struct Invalid {
    /// Dotted key path, e.g. `ipc.heartbeat_deadline_ms`.
    pub key: String,
    /// What is wrong and what is allowed.
    pub message: String,
}

impl Invalid {
    /// An invalid value at `key`.
    pub fn new(key: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
            key: key.into(),
            message: message.into(),
        }
    }

    /// Puts this error under a parent section: `key` becomes `section.key`.
    pub fn under(mut self, section: &str) -> Self {
        self.key = format!("{section}.{}", self.key);
        self
    }
}

/// Cross-field and range checks that serde cannot express.
pub trait Validate {
    /// Ok when every value is allowed.
    fn validate(&self) -> Result<(), Invalid>;
}

/// Checks `lo <= value <= hi` (and finiteness for floats).
pub fn check_range<T>(key: &str, value: T, lo: T, hi: T) -> Result<(), Invalid>
where
    T: PartialOrd + std::fmt::Display + Copy,
{
    // `!(a <= b)` rather than `a > b` so that NaN fails too.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    if !(lo <= value && value <= hi) {
        return Err(Invalid::new(
            key,
            format!("{value} is out of range (allowed: {lo} to {hi})"),
        ));
    }
    Ok(())
}

/// Why a configuration could not be used. `Display` is one line.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("config {path}: cannot read: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is not valid TOML.
    #[error("config {path}: line {line}: {message}")]
    Syntax {
        /// The file.
        path: PathBuf,
        /// 1-based line of the error.
        line: usize,
        /// What the parser said.
        message: String,
    },
    /// A key is unknown, missing or of the wrong type.
    #[error("config {path}: key `{key}`: {message}")]
    Key {
        /// The file.
        path: PathBuf,
        /// Dotted key path.
        key: String,
        /// What is wrong and what is allowed.
        message: String,
    },
    /// A value parsed but is not allowed.
    #[error("config {path}: key `{key}`: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// Dotted key path.
        key: String,
        /// What is wrong and what is allowed.
        message: String,
    },
}

/// Reads, parses and validates a whole config file.
pub fn load<T: DeserializeOwned + Validate>(path: &Path) -> Result<T, ConfigError> {
    let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    parse(&text, path)
}

/// Parses and validates config text; `origin` names it in errors.
pub fn parse<T: DeserializeOwned + Validate>(text: &str, origin: &Path) -> Result<T, ConfigError> {
    let de = toml::Deserializer::parse(text).map_err(|e| syntax_error(text, origin, &e))?;
    let value: T = serde_path_to_error::deserialize(de).map_err(|e| {
        let key = e.path().to_string();
        let inner = e.into_inner();
        // Unknown-field errors point at the parent; a value that failed to parse where the
        // syntax was fine is still a key problem.
        ConfigError::Key {
            path: origin.to_path_buf(),
            key: if key == "." {
                "(top level)".into()
            } else {
                key
            },
            message: one_line(inner.message()),
        }
    })?;
    value.validate().map_err(|inv| ConfigError::Invalid {
        path: origin.to_path_buf(),
        key: inv.key,
        message: inv.message,
    })?;
    Ok(value)
}

fn syntax_error(text: &str, origin: &Path, e: &toml::de::Error) -> ConfigError {
    let line = e
        .span()
        .map(|s| text[..s.start.min(text.len())].matches('\n').count() + 1)
        .unwrap_or(0);
    ConfigError::Syntax {
        path: origin.to_path_buf(),
        line,
        message: one_line(e.message()),
    }
}

fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// The iceoryx2 prefix when neither the `--ipc-prefix` flag, `LANDING_IPC_PREFIX` nor a
/// config file sets one.
pub const DEFAULT_PREFIX: &str = "landing_";

/// True when `prefix` can be an iceoryx2 prefix: 1 to 32 characters of `A-Z a-z 0-9 _ - .`
/// (it becomes part of file names under `/dev/shm` and `/tmp`, so no path characters).
pub fn is_valid_prefix(prefix: &str) -> bool {
    !prefix.is_empty()
        && prefix.len() <= 32
        && prefix
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-' || b == b'.')
}

/// The `[ipc]` section every process reads: how it finds the others and how often it
/// must say it is alive.
#[derive(Debug, Clone, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IpcConfig {
    /// iceoryx2 prefix (the `--ipc-prefix` flag and `LANDING_IPC_PREFIX` override it).
    pub prefix: String,
    /// How often each process beats its heartbeat, ms.
    pub heartbeat_period_ms: u64,
    /// How long the watchdog waits for a beat before it calls a process hung, ms.
    pub heartbeat_deadline_ms: u64,
}

impl Default for IpcConfig {
    fn default() -> Self {
        Self {
            prefix: DEFAULT_PREFIX.to_string(),
            heartbeat_period_ms: 100,
            heartbeat_deadline_ms: 500,
        }
    }
}

impl Validate for IpcConfig {
    fn validate(&self) -> Result<(), Invalid> {
        if !is_valid_prefix(&self.prefix) {
            return Err(Invalid::new(
                "prefix",
                format!(
                    "`{}` is not allowed (allowed: 1 to 32 characters of A-Z a-z 0-9 _ - .)",
                    self.prefix
                ),
            ));
        }
        check_range("heartbeat_period_ms", self.heartbeat_period_ms, 10, 10_000)?;
        check_range(
            "heartbeat_deadline_ms",
            self.heartbeat_deadline_ms,
            2 * self.heartbeat_period_ms,
            60_000,
        )
    }
}

/// The sections a stack config may hold: a process refuses a file with another one (a
/// misspelt section would otherwise leave its process on defaults without a word).
pub const SECTIONS: &[&str] = &[
    "ipc",
    "aruco_pnp",
    "px4_link",
    "planner",
    "camera_ingest",
    "depth_ingest",
    "depth_map",
    "fsm",
    "watchdog",
    "recorder",
];

/// What a process reads from the stack file: `[ipc]` and its own section, each strictly
/// (unknown keys are errors) and each defaulted when absent; the other processes'
/// sections are not its business. Errors name the key with its section (`aruco_pnp.x`).
pub fn load_process<T>(path: &Path, section: &str) -> Result<(IpcConfig, T), ConfigError>
where
    T: DeserializeOwned + Validate + Default,
{
    let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    let table: toml::Table = toml::from_str(&text).map_err(|e| syntax_error(&text, path, &e))?;
    if table.is_empty() {
        return Err(ConfigError::Invalid {
            path: path.to_path_buf(),
            key: "(top level)".into(),
            message: format!(
                "the file sets nothing (allowed: a stack config with its sections: {}; deploy/config/landing.toml is one)",
                SECTIONS.join(", ")
            ),
        });
    }
    if let Some(unknown) = table.keys().find(|k| !SECTIONS.contains(&k.as_str())) {
        return Err(ConfigError::Key {
            path: path.to_path_buf(),
            key: unknown.clone(),
            message: format!("unknown section (allowed: {})", SECTIONS.join(", ")),
        });
    }
    let ipc = section_of(&table, "ipc", path)?;
    let own = section_of(&table, section, path)?;
    Ok((ipc, own))
}

/// [`load_process`] when a file is given, else the defaults (a process run without
/// `--config`).
pub fn load_process_or_default<T>(
    path: Option<&Path>,
    section: &str,
) -> Result<(IpcConfig, T), ConfigError>
where
    T: DeserializeOwned + Validate + Default,
{
    match path {
        Some(p) => load_process(p, section),
        None => Ok((IpcConfig::default(), T::default())),
    }
}

fn section_of<T>(table: &toml::Table, name: &str, origin: &Path) -> Result<T, ConfigError>
where
    T: DeserializeOwned + Validate + Default,
{
    let Some(value) = table.get(name) else {
        return Ok(T::default());
    };
    let value: T = serde_path_to_error::deserialize(value.clone()).map_err(|e| {
        let key = e.path().to_string();
        ConfigError::Key {
            path: origin.to_path_buf(),
            key: if key == "." {
                name.to_string()
            } else {
                format!("{name}.{key}")
            },
            message: one_line(e.into_inner().message()),
        }
    })?;
    value.validate().map_err(|inv| ConfigError::Invalid {
        path: origin.to_path_buf(),
        key: format!("{name}.{}", inv.key),
        message: inv.message,
    })?;
    Ok(value)
}

/// Environment variable naming the deploy directory (scenarios, config, calibration).
pub const DEPLOY_DIR_ENV: &str = "LANDING_DEPLOY_DIR";

/// Where `deploy/` is: `LANDING_DEPLOY_DIR`, else the nearest `deploy/` above the current
/// directory, else above the executable (a checkout's `target/release/`), else
/// `/etc/landing` (an installed system).
pub fn deploy_dir() -> PathBuf {
    if let Ok(d) = std::env::var(DEPLOY_DIR_ENV) {
        return PathBuf::from(d);
    }
    let has_deploy = |dir: &Path| dir.join("deploy").join("config").is_dir();
    let mut starts = Vec::new();
    if let Ok(cwd) = std::env::current_dir() {
        starts.push(cwd);
    }
    if let Ok(exe) = std::env::current_exe()
        && let Some(dir) = exe.parent()
    {
        starts.push(dir.to_path_buf());
    }
    for start in starts {
        let mut dir = Some(start.as_path());
        while let Some(d) = dir {
            if has_deploy(d) {
                return d.join("deploy");
            }
            dir = d.parent();
        }
    }
    PathBuf::from("/etc/landing")
}

#[cfg(test)]
#[path = "lib_test.rs"]
mod tests;

/// A file named in the configuration at `config_dir` (the directory of the config file):
/// an absolute path as it is, a relative one from that directory, so a config means the
/// same files whoever reads it and from wherever it is run.
pub fn resolve_path(config_dir: &Path, value: &str) -> PathBuf {
    let p = Path::new(value);
    if p.is_absolute() {
        p.to_path_buf()
    } else {
        config_dir.join(p)
    }
}
