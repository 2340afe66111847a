//! The `main` every stack process shares: flags, logging, signals, and one line on failure.

use std::fmt::Display;
use std::io::Write;
use std::process::ExitCode;

use clap::Parser;
use clap::error::ErrorKind;

/// The command line as `A`, or the exit code to end with: `--help` and `--version` print
/// and give 0; a usage mistake is one line naming what is wrong (clap's first line) and
/// gives 2; a missing subcommand prints the help and gives 2. Every stack binary and
/// `landing` parse through it.
pub fn parse_args<A: Parser>() -> Result<A, ExitCode> {
    match A::try_parse() {
        Ok(a) => Ok(a),
        Err(e) if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) => {
            let _ = e.print();
            Err(ExitCode::SUCCESS)
        }
        Err(e) if e.kind() == ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => {
            let _ = e.print();
            Err(ExitCode::from(2))
        }
        Err(e) => {
            // One line: what is wrong; --help has the rest.
            let text = e.to_string();
            let first = text.lines().next().unwrap_or("error: bad arguments");
            eprintln!("{first} (see --help)");
            Err(ExitCode::from(2))
        }
    }
}

/// Installs the SIGTERM/SIGINT handler before anything else (a stop that arrives while
/// the process starts is kept, never fatal), parses the flags (a usage error is one line
/// and exit code 2; `--help` and `--version` print and exit 0), starts logging at
/// `default_level` and runs `run`. An error is one line on stderr and exit code 2, except
/// a thread that could not be joined ([`crate::threads::JoinError`]): the
/// process then ends at once with that thread's exit code, through `_exit`, so no C++
/// exit handler runs under the thread still inside a library. `run` must have dropped
/// its iceoryx2 resources by then (it has, by returning).
pub fn process_main<A, E>(default_level: &str, run: impl FnOnce(&A) -> Result<(), E>) -> ExitCode
where
    A: Parser,
    E: Display + AsRef<dyn std::error::Error + Send + Sync + 'static>,
{
    crate::shutdown::install();
    let args = match parse_args::<A>() {
        Ok(a) => a,
        Err(code) => return code,
    };
    crate::logging::init(default_level);
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            if let Some(code) = crate::threads::exit_code_of(e.as_ref()) {
                let _ = std::io::stderr().flush();
                // SAFETY: `_exit` ends the process without running exit handlers; it has
                // no preconditions. Nothing is left to flush (stderr is unbuffered).
                unsafe { libc::_exit(i32::from(code)) };
            }
            ExitCode::from(2)
        }
    }
}
