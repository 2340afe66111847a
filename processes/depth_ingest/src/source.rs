//! Where depth frames come from: the `--source` text.

use std::fmt;
use std::path::PathBuf;
use std::str::FromStr;

/// What `--source` accepts, for error messages.
pub const ALLOWED_SOURCES: &str =
    "file:<directory of 16-bit PNG depth images>, bag:<RealSense .bag recording>";

/// Why a `--source` text names no source.
#[derive(Debug, thiserror::Error)]
#[error("unknown --source `{0}` (allowed: {ALLOWED_SOURCES})")]
pub struct UnknownSource(pub String);

/// Where depth frames come from, as `--source` names it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DepthSourceSpec {
    /// A directory of 16-bit single-channel PNG images, played in file-name order.
    File(PathBuf),
    /// A RealSense recording (`.bag`, as the RealSense Viewer, `rs-record` or
    /// `rs.recorder` write it), read without librealsense.
    Bag(PathBuf),
}

impl FromStr for DepthSourceSpec {
    type Err = UnknownSource;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let unknown = || UnknownSource(s.to_string());
        let (scheme, rest) = s.split_once(':').ok_or_else(unknown)?;
        if rest.is_empty() {
            return Err(unknown());
        }
        match scheme {
            "file" => Ok(Self::File(PathBuf::from(rest))),
            "bag" => Ok(Self::Bag(PathBuf::from(rest))),
            _ => Err(unknown()),
        }
    }
}

impl fmt::Display for DepthSourceSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::File(p) => write!(f, "file:{}", p.display()),
            Self::Bag(p) => write!(f, "bag:{}", p.display()),
        }
    }
}
