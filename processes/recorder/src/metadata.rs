//! What a recording says about the stack that made it (MCAP metadata `landing`): the
//! git revision and version of the build, the config file and the graph as they were.

use std::collections::BTreeMap;
use std::path::Path;

use ipc_types::msg::Pose;
use nalgebra::Isometry3;

/// Why the metadata could not be gathered.
#[derive(Debug, thiserror::Error)]
#[error("reading {path} for the recording's metadata: {error}")]
pub struct MetadataError {
    /// The file.
    pub path: String,
    /// What the OS said.
    pub error: std::io::Error,
}

/// The git revision this build came from (`-dirty` with uncommitted changes).
pub const GIT_REVISION: &str = env!("LANDING_GIT_REV");

/// `landing` metadata: revision, version, and the text of the config file (when one is
/// used) and of the graph.
pub fn stack(
    config: Option<&Path>,
    graph: &Path,
) -> Result<BTreeMap<String, String>, MetadataError> {
    let read = |p: &Path| {
        std::fs::read_to_string(p).map_err(|error| MetadataError {
            path: p.display().to_string(),
            error,
        })
    };
    let mut m = BTreeMap::new();
    m.insert("git_revision".into(), GIT_REVISION.into());
    m.insert("version".into(), env!("CARGO_PKG_VERSION").into());
    m.insert("graph_file".into(), graph.display().to_string());
    m.insert("graph".into(), read(graph)?);
    match config {
        Some(c) => {
            m.insert("config_file".into(), c.display().to_string());
            m.insert("config".into(), read(c)?);
        }
        None => {
            m.insert(
                "config_file".into(),
                "(none: every section's defaults)".into(),
            );
        }
    }
    Ok(m)
}

/// A rigid transform as the messages' pose.
pub fn pose_of(iso: &Isometry3<f64>) -> Pose {
    let t = iso.translation.vector;
    let q = iso.rotation.quaternion();
    Pose {
        translation: [t.x, t.y, t.z],
        rotation_xyzw: [q.i, q.j, q.k, q.w],
    }
}
