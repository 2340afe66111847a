//! `[recorder]` of landing.toml: what a recording keeps and how.

use serde::Deserialize;
use stack_config::{Invalid, Validate, check_range};

use ipc_types::msg::Pose;

use crate::metadata::pose_of;
use crate::writer::{ChunkCompression, ImageFormat, RecordOptions};

/// `[recorder]`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RecorderConfig {
    /// Camera frames as "jpeg" (foxglove.CompressedImage) or "raw" (foxglove.RawImage,
    /// what an exact replay of aruco-pnp needs).
    pub images: String,
    /// JPEG quality, 1-100.
    pub jpeg_quality: u8,
    /// Chunk compression: "zstd", "lz4" or "none".
    pub compression: String,
    /// The file is flushed at least this often, ms (what a killed recorder can lose).
    pub flush_period_ms: u64,
    /// The occupancy map's 3-D scene at most this often, ms.
    pub map_period_ms: u64,
    /// Topics left out: the simulator's camera, which camera-ingest republishes as
    /// camera/frame (recording both would encode every frame twice).
    pub skip: Vec<String>,
    /// Serve the live view (Foxglove's WebSocket protocol) on `live_address`.
    pub live: bool,
    /// Where the live view listens, `IP:PORT`: loopback by default; the vehicle's
    /// network address (or 0.0.0.0) lets a ground-station laptop connect.
    pub live_address: String,
}

impl Default for RecorderConfig {
    fn default() -> Self {
        Self {
            images: "jpeg".into(),
            jpeg_quality: 80,
            compression: "zstd".into(),
            flush_period_ms: 1000,
            map_period_ms: 500,
            skip: vec!["sim/camera".into()],
            live: false,
            live_address: "127.0.0.1:8765".into(),
        }
    }
}

impl Validate for RecorderConfig {
    fn validate(&self) -> Result<(), Invalid> {
        self.image_format()?;
        self.chunk_compression()?;
        check_range("jpeg_quality", self.jpeg_quality, 1, 100)?;
        check_range("flush_period_ms", self.flush_period_ms, 10, 1000)?;
        check_range("map_period_ms", self.map_period_ms, 0, 60_000)?;
        self.live_socket()?;
        Ok(())
    }
}

impl RecorderConfig {
    fn image_format(&self) -> Result<ImageFormat, Invalid> {
        match self.images.as_str() {
            "jpeg" => Ok(ImageFormat::Jpeg {
                quality: self.jpeg_quality,
            }),
            "raw" => Ok(ImageFormat::Raw),
            other => Err(Invalid::new(
                "images",
                format!("`{other}` (allowed: \"jpeg\", \"raw\")"),
            )),
        }
    }

    fn chunk_compression(&self) -> Result<ChunkCompression, Invalid> {
        match self.compression.as_str() {
            "zstd" => Ok(ChunkCompression::Zstd),
            "lz4" => Ok(ChunkCompression::Lz4),
            "none" => Ok(ChunkCompression::None),
            other => Err(Invalid::new(
                "compression",
                format!("`{other}` (allowed: \"zstd\", \"lz4\", \"none\")"),
            )),
        }
    }

    /// Where the live view listens.
    pub fn live_socket(&self) -> Result<std::net::SocketAddr, Invalid> {
        self.live_address.parse().map_err(|_| {
            Invalid::new(
                "live_address",
                format!(
                    "`{}` (allowed: IP:PORT, e.g. \"127.0.0.1:8765\" or \"0.0.0.0:8765\")",
                    self.live_address
                ),
            )
        })
    }

    /// The writer's options (the camera mount is the caller's to add).
    pub fn options(&self) -> Result<RecordOptions, Invalid> {
        Ok(RecordOptions {
            images: self.image_format()?,
            compression: self.chunk_compression()?,
            flush_period_ns: self.flush_period_ms * 1_000_000,
            map_period_ns: self.map_period_ms * 1_000_000,
            body_from_camera: None,
            body_from_depth: None,
        })
    }
}

/// The cameras' mounts for the transform tree (down camera, depth camera), read from a
/// stack config's text: `[aruco_pnp] camera_position_in_body_m`, `[depth_map]
/// camera_position_in_body_m` and `camera_rpy_deg`. Read here rather than through those
/// stages' crates (a process depends on no other process); a camera whose keys are
/// absent is left out of the tree.
pub fn mounts(config_text: &str) -> Result<(Option<Pose>, Option<Pose>), toml::de::Error> {
    let table: toml::Table = toml::from_str(config_text)?;
    let triple = |section: &str, key: &str| -> Option<[f64; 3]> {
        let a = table.get(section)?.get(key)?.as_array()?;
        let v: Vec<f64> = a
            .iter()
            .filter_map(|x| x.as_float().or_else(|| x.as_integer().map(|i| i as f64)))
            .collect();
        <[f64; 3]>::try_from(v).ok()
    };
    let camera = triple("aruco_pnp", "camera_position_in_body_m")
        .map(|p| pose_of(&optics::down_camera_from_body(p).inverse()));
    let depth = triple("depth_map", "camera_position_in_body_m").map(|p| {
        let rpy = triple("depth_map", "camera_rpy_deg").unwrap_or([0.0; 3]);
        pose_of(&optics::body_from_forward_camera(p, rpy))
    });
    Ok((camera, depth))
}

#[cfg(test)]
#[path = "config_test.rs"]
mod tests;
