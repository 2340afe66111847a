//! `tracing` set-up shared by every binary.

use tracing_subscriber::EnvFilter;

/// Environment variable that sets the log filter (`tracing` syntax, e.g. `info,planner=debug`).
pub const LOG_ENV: &str = "LANDING_LOG";

/// Logs to stderr (journald picks it up under systemd), filtered by `LANDING_LOG` or
/// `default_filter`. Calling it twice is harmless: the first set-up wins.
pub fn init(default_filter: &str) {
    let filter = EnvFilter::try_from_env(LOG_ENV)
        .or_else(|_| EnvFilter::try_new(default_filter))
        .unwrap_or_else(|_| EnvFilter::new("info"));
    // An error here only means a subscriber is already installed (tests, lockstep runs).
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(false)
        .try_init();
}
