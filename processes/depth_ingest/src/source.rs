//! Where depth frames come from: the `--source` text.

use std::fmt;
use std::path::PathBuf;
use std::str::FromStr;

/// What `--source` accepts, for error messages.
pub const ALLOWED_SOURCES: &str = "file:<directory of 16-bit PNG depth images>, bag:<RealSense .bag recording>, v4l2:/dev/videoN (Z16), realsense:any|<serial number>|<.bag played by librealsense> (the `realsense` build)";

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
    /// A V4L2 device streaming Z16 depth (`/dev/videoN`).
    V4l2(PathBuf),
    /// A RealSense through librealsense: needs the `realsense` build.
    RealSense(RealSenseTarget),
}

/// Which RealSense `realsense:` names.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RealSenseTarget {
    /// `realsense:any`: the first one plugged in.
    Any,
    /// `realsense:<serial number>` (digits, as `rs-enumerate-devices` prints it).
    Serial(String),
    /// `realsense:<file>.bag`: a recording librealsense plays.
    Recording(PathBuf),
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
            "v4l2" => Ok(Self::V4l2(PathBuf::from(rest))),
            "realsense" if rest == "any" => Ok(Self::RealSense(RealSenseTarget::Any)),
            "realsense" if rest.chars().all(|c| c.is_ascii_alphanumeric()) => {
                Ok(Self::RealSense(RealSenseTarget::Serial(rest.to_string())))
            }
            "realsense" if rest.ends_with(".bag") => Ok(Self::RealSense(
                RealSenseTarget::Recording(PathBuf::from(rest)),
            )),
            _ => Err(unknown()),
        }
    }
}

impl fmt::Display for DepthSourceSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::File(p) => write!(f, "file:{}", p.display()),
            Self::Bag(p) => write!(f, "bag:{}", p.display()),
            Self::V4l2(p) => write!(f, "v4l2:{}", p.display()),
            Self::RealSense(RealSenseTarget::Any) => write!(f, "realsense:any"),
            Self::RealSense(RealSenseTarget::Serial(s)) => write!(f, "realsense:{s}"),
            Self::RealSense(RealSenseTarget::Recording(p)) => {
                write!(f, "realsense:{}", p.display())
            }
        }
    }
}
