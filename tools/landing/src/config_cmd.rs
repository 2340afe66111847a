//! `landing config check`: validates the whole stack configuration file.

use std::path::Path;

use anyhow::Result;
pub use stack::StackConfig;

/// Loads and validates `file` and the files it names; prints `ok` on success.
pub fn check(file: &Path) -> Result<()> {
    let _cfg = StackConfig::load(file)?;
    println!("{}: ok", file.display());
    Ok(())
}
