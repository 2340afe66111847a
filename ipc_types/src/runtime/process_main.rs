//! The `main` every stack process shares: flags, logging, and one line on failure.

use std::fmt::Display;
use std::process::ExitCode;

use clap::Parser;
use clap::error::ErrorKind;

/// Parses the flags (a usage error is one line and exit code 2; `--help` and `--version`
/// print and exit 0), starts logging at `default_level`, runs `run`, and turns its error
/// into one line on stderr and exit code 2, as every process of the stack does.
pub fn process_main<A: Parser, E: Display>(
    default_level: &str,
    run: impl FnOnce(&A) -> Result<(), E>,
) -> ExitCode {
    let args = match A::try_parse() {
        Ok(a) => a,
        Err(e) if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) => {
            let _ = e.print();
            return ExitCode::SUCCESS;
        }
        Err(e) => {
            // One line: what is wrong; --help has the rest.
            let text = e.to_string();
            let first = text.lines().next().unwrap_or("error: bad arguments");
            eprintln!("{first} (see --help)");
            return ExitCode::from(2);
        }
    };
    crate::runtime::logging::init(default_level);
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
