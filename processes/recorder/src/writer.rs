//! The recording being written: one MCAP file per run through the Foxglove SDK's MCAP
//! writer, on a [`foxglove::Context`] of its own (no global state, so two recorders can
//! run in one process).
//!
//! Every stack message goes in twice over: as JSON on its own topic (`/vehicle/state`,
//! every field, plottable, what `landing latency` and `landing replay` read back), and,
//! where Foxglove has a panel for it, as the Foxglove schema (images, transforms, the
//! 3-D scene, logs; [`crate::visual`]). Chunks are compressed (zstd or lz4) in the
//! caller's thread and the file is flushed (the open chunk closed and written) at least
//! every [`RecordOptions::flush_period_ns`] of log time, so a recorder killed mid-run
//! leaves a file that reads up to its last second.

use std::collections::{BTreeMap, HashMap};
use std::fmt;
use std::fs::File;
use std::io::BufWriter;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use foxglove::schemas::{CompressedImage, FrameTransforms, Log, RawImage, SceneUpdate, VoxelGrid};
use foxglove::{
    Channel, Context, McapCompression, McapWriteOptions, McapWriter, McapWriterHandle,
    PartialMetadata, RawChannel, Schema,
};
use stage::Message;

use crate::schema::{
    HEADER_SUFFIX, MESSAGE_ENCODING, Recordable, SCHEMA_ENCODING, SchemaError, schema_for,
};
use crate::visual::{self, Visuals};

/// Why a recording could not be written.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The file cannot be created (missing directory, permissions).
    #[error("cannot create the recording {}: {error}", path.display())]
    Create {
        /// The recording.
        path: PathBuf,
        /// What the OS said.
        error: std::io::Error,
    },
    /// The MCAP writer failed (disk full, I/O error, writing after `finish`).
    #[error("writing the recording {}: {error}", path.display())]
    Write {
        /// The recording.
        path: PathBuf,
        /// What the writer said.
        error: foxglove::FoxgloveError,
    },
    /// A message could not be turned into JSON.
    #[error(transparent)]
    Encode(#[from] SchemaError),
    /// The live view's WebSocket server did not start (address in use, not allowed).
    #[error("the live view cannot listen on {address}: {error}")]
    Live {
        /// The address asked for.
        address: String,
        /// What the server said.
        error: foxglove::FoxgloveError,
    },
    /// A topic was given a second message type.
    #[error("topic {topic} carries {has}, not {got}")]
    TopicType {
        /// The topic.
        topic: String,
        /// The type it was made with.
        has: &'static str,
        /// The type given now.
        got: &'static str,
    },
    /// The writer thread panicked: what it had not written is lost.
    #[error("the recorder's writer thread panicked")]
    WriterPanicked,
}

/// How camera frames are stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImageFormat {
    /// `foxglove.CompressedImage`, JPEG at this quality (1-100) through OpenCV: about a
    /// tenth of the raw size; lossy, so a replay of aruco-pnp cannot be exact.
    Jpeg {
        /// libjpeg quality, 1-100.
        quality: u8,
    },
    /// `foxglove.RawImage`, the pixels as published: what an exact replay needs.
    Raw,
}

/// How chunks are compressed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChunkCompression {
    /// zstd: smaller files, more CPU.
    Zstd,
    /// lz4: the cheap one, for raw images.
    Lz4,
    /// None.
    None,
}

/// What a recording keeps and how.
#[derive(Debug, Clone, Copy)]
pub struct RecordOptions {
    /// Camera frames as JPEG or raw.
    pub images: ImageFormat,
    /// Chunk compression.
    pub compression: ChunkCompression,
    /// The file is flushed (the open chunk written) at least this often in log time.
    pub flush_period_ns: u64,
    /// The occupancy map's 3-D scene at most this often (its header and counts go in
    /// with every map).
    pub map_period_ns: u64,
    /// Where the down camera sits on the body (FLU), for the transform tree; `None`
    /// leaves the camera frame out of the tree.
    pub body_from_camera: Option<ipc_types::msg::Pose>,
    /// Where the depth camera sits on the body, likewise.
    pub body_from_depth: Option<ipc_types::msg::Pose>,
}

impl Default for RecordOptions {
    fn default() -> Self {
        Self {
            images: ImageFormat::Jpeg { quality: 80 },
            compression: ChunkCompression::Zstd,
            flush_period_ns: 1_000_000_000,
            map_period_ns: 500_000_000,
            body_from_camera: None,
            body_from_depth: None,
        }
    }
}

/// A JSON channel and the type it carries.
struct JsonChannel {
    channel: Arc<RawChannel>,
    schema: &'static str,
}

/// Writes one MCAP recording.
///
/// Dropping it finishes the file too, but silently: call [`Recorder::finish`] to learn
/// whether the end of the file was written.
pub struct Recorder {
    path: PathBuf,
    ctx: Arc<Context>,
    handle: Option<McapWriterHandle<BufWriter<File>>>,
    live: Option<foxglove::WebSocketServerHandle>,
    options: RecordOptions,
    json: HashMap<String, JsonChannel>,
    compressed: HashMap<String, Channel<CompressedImage>>,
    raw: HashMap<String, Channel<RawImage>>,
    voxels: HashMap<String, Channel<VoxelGrid>>,
    tf: Channel<FrameTransforms>,
    scene: HashMap<&'static str, Channel<SceneUpdate>>,
    log: Channel<Log>,
    visuals: Visuals,
    messages: u64,
    last_flush_ns: Option<u64>,
    last_map_ns: Option<u64>,
}

impl fmt::Debug for Recorder {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Recorder")
            .field("path", &self.path)
            .field("channels", &self.json.len())
            .field("messages", &self.messages)
            .finish()
    }
}

/// The transform tree's topic.
pub const TF_TOPIC: &str = "/tf";
/// The mission's log (transitions, watchdog actions).
pub const LOG_TOPIC: &str = "/log";

impl Recorder {
    /// Creates (or truncates) the recording at `path` with the default options.
    pub fn create(path: &Path) -> Result<Self, RecordError> {
        Self::with_options(path, RecordOptions::default())
    }

    /// Creates (or truncates) the recording at `path`.
    pub fn with_options(path: &Path, options: RecordOptions) -> Result<Self, RecordError> {
        let write_err = |error| RecordError::Write {
            path: path.to_path_buf(),
            error,
        };
        let file = File::create(path).map_err(|error| RecordError::Create {
            path: path.to_path_buf(),
            error,
        })?;
        let compression = match options.compression {
            ChunkCompression::Zstd => Some(McapCompression::Zstd),
            ChunkCompression::Lz4 => Some(McapCompression::Lz4),
            ChunkCompression::None => None,
        };
        // Compression in the caller's thread: no hidden worker threads next to the stack.
        let mcap = McapWriteOptions::new()
            .compression(compression)
            .compression_threads(0)
            .library(concat!("landing ", env!("CARGO_PKG_VERSION")));
        let ctx = Context::new();
        let handle = McapWriter::with_options(mcap)
            .context(&ctx)
            .create(BufWriter::new(file))
            .map_err(write_err)?;
        Ok(Self::on(ctx, path.to_path_buf(), Some(handle), options))
    }

    /// A recorder without a file: what it records goes only to the live view
    /// ([`Recorder::serve_live`]).
    pub fn without_file(options: RecordOptions) -> Self {
        Self::on(Context::new(), PathBuf::from("(no file)"), None, options)
    }

    fn on(
        ctx: Arc<Context>,
        path: PathBuf,
        handle: Option<McapWriterHandle<BufWriter<File>>>,
        options: RecordOptions,
    ) -> Self {
        let tf = ctx.channel_builder(TF_TOPIC).build::<FrameTransforms>();
        let log = ctx.channel_builder(LOG_TOPIC).build::<Log>();
        let mut scene = HashMap::new();
        for topic in visual::SCENE_TOPICS {
            scene.insert(topic, ctx.channel_builder(topic).build::<SceneUpdate>());
        }
        Self {
            path,
            ctx,
            handle,
            live: None,
            options,
            json: HashMap::new(),
            compressed: HashMap::new(),
            raw: HashMap::new(),
            voxels: HashMap::new(),
            tf,
            scene,
            log,
            visuals: Visuals::new(options.body_from_camera, options.body_from_depth),
            messages: 0,
            last_flush_ns: None,
            last_map_ns: None,
        }
    }

    /// Serves everything recorded from now on over Foxglove's WebSocket protocol at
    /// `address` (`HOST:PORT`; port 0 picks a free one), through the same SDK that
    /// writes the file: a ground station opens `ws://HOST:PORT` in Foxglove. Returns the
    /// address it listens on. The server runs on the SDK's own threads and stops with
    /// [`Recorder::finish`].
    pub fn serve_live(&mut self, address: SocketAddr) -> Result<SocketAddr, RecordError> {
        let fail = |error| RecordError::Live {
            address: address.to_string(),
            error,
        };
        let handle = foxglove::WebSocketServer::new()
            .name(concat!("landing ", env!("CARGO_PKG_VERSION")))
            .bind(address.ip().to_string(), address.port())
            .context(&self.ctx)
            .start_blocking()
            .map_err(fail)?;
        let at = SocketAddr::new(address.ip(), handle.port());
        self.live = Some(handle);
        Ok(at)
    }

    /// Whether it writes a file ([`Recorder::without_file`] does not).
    pub fn has_file(&self) -> bool {
        self.handle.is_some()
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Messages written so far (JSON and Foxglove ones).
    pub fn message_count(&self) -> u64 {
        self.messages
    }

    fn write_error(&self, error: foxglove::FoxgloveError) -> RecordError {
        RecordError::Write {
            path: self.path.clone(),
            error,
        }
    }

    /// Stores `entries` as the MCAP metadata record `name` (the effective config, the
    /// graph, the git revision).
    pub fn write_metadata(
        &mut self,
        name: &str,
        entries: BTreeMap<String, String>,
    ) -> Result<(), RecordError> {
        let Some(h) = &self.handle else {
            return Ok(());
        };
        h.write_metadata(name, entries)
            .map_err(|e| self.write_error(e))
    }

    /// The JSON channel of `topic`, made on first use with `T`'s schema. A topic keeps the
    /// type it was made with: one topic, one message type, as on the bus.
    fn json_channel<T: Recordable>(&mut self, topic: &str) -> Result<&JsonChannel, RecordError> {
        if !self.json.contains_key(topic) {
            let doc = schema_for::<T>()?;
            let bytes = serde_json::to_vec(&doc).map_err(|error| SchemaError {
                schema: T::SCHEMA_NAME,
                error,
            })?;
            let channel = self
                .ctx
                .channel_builder(topic)
                .message_encoding(MESSAGE_ENCODING)
                .schema(Schema::new(T::SCHEMA_NAME, SCHEMA_ENCODING, bytes))
                .build_raw()
                .map_err(|e| self.write_error(e))?;
            self.json.insert(
                topic.to_string(),
                JsonChannel {
                    channel,
                    schema: T::SCHEMA_NAME,
                },
            );
        }
        let ch = self.json.get(topic).ok_or_else(|| RecordError::TopicType {
            topic: topic.to_string(),
            has: "nothing",
            got: T::SCHEMA_NAME,
        })?;
        if ch.schema != T::SCHEMA_NAME {
            return Err(RecordError::TopicType {
                topic: topic.to_string(),
                has: ch.schema,
                got: T::SCHEMA_NAME,
            });
        }
        Ok(ch)
    }

    /// Records `msg` as JSON on `topic` at `log_time_ns` (the time axis viewers play back
    /// on; one clock for the whole recording: monotonic ns in flight, simulated ns in
    /// lockstep).
    pub fn write_message<T: Recordable>(
        &mut self,
        topic: &str,
        log_time_ns: u64,
        msg: &T,
    ) -> Result<(), RecordError> {
        let data = serde_json::to_vec(msg).map_err(|error| SchemaError {
            schema: T::SCHEMA_NAME,
            error,
        })?;
        let ch = self.json_channel::<T>(topic)?;
        ch.channel
            .log_with_meta(&data, PartialMetadata::with_log_time(log_time_ns));
        self.messages += 1;
        self.after_write(log_time_ns)
    }

    /// Records one message of the bus on `topic` (its short name, `vehicle/state`): the
    /// JSON of it (for images and maps, their header) on `/<topic>`, and what Foxglove
    /// draws of it. MAVLink bytes and process events are not recorded.
    pub fn record(
        &mut self,
        topic: &str,
        log_time_ns: u64,
        msg: &Message<'_>,
    ) -> Result<(), RecordError> {
        let name = format!("/{topic}");
        self.record_json(&name, log_time_ns, msg)?;
        self.draw(&name, log_time_ns, msg)
    }

    /// What Foxglove draws of `msg` on `name` (`/<topic>`), besides its JSON: pictures,
    /// transforms, scenes, log lines; nothing for most messages.
    fn draw(&mut self, name: &str, t: u64, msg: &Message<'_>) -> Result<(), RecordError> {
        match *msg {
            Message::CameraFrame(h, pixels) => self.image(name, t, h, pixels)?,
            Message::DepthFrame(h, depths) => {
                let img = visual::depth_image(h, depths);
                self.raw_channel(name)
                    .log_with_meta(&img, PartialMetadata::with_log_time(t));
                self.messages += 1;
            }
            Message::OccupancyMap(h, cells) => {
                if let Some(grid) = visual::voxel_grid(h, cells) {
                    let ctx = &self.ctx;
                    self.voxels
                        .entry(name.to_string())
                        .or_insert_with(|| ctx.channel_builder(name).build::<VoxelGrid>())
                        .log_with_meta(&grid, PartialMetadata::with_log_time(t));
                    self.messages += 1;
                }
                let due = self
                    .last_map_ns
                    .is_none_or(|l| t.saturating_sub(l) >= self.options.map_period_ns);
                if due {
                    self.last_map_ns = Some(t);
                    let scene = visual::map_scene(h, cells);
                    self.scene_update(visual::MAP_TOPIC, t, &scene);
                }
            }
            Message::VehicleState(m) => {
                let tf = self.visuals.vehicle(m);
                self.transforms(t, &tf);
            }
            Message::PadObservation(m) => {
                let tf = self.visuals.observation(m);
                self.transforms(t, &tf);
            }
            Message::Trajectory(m) => {
                let scene = visual::trajectory_scene(m);
                self.scene_update(visual::TRAJECTORY_TOPIC, t, &scene);
            }
            Message::FsmStatus(m) => {
                if let Some(log) = self.visuals.status_log(m) {
                    self.log(t, &log);
                }
                let (tf, scene) = self.visuals.pad_estimate(m);
                self.transforms(t, &tf);
                self.scene_update(visual::PAD_TOPIC, t, &scene);
            }
            Message::WatchdogView(m) => {
                if let Some(log) = self.visuals.watchdog_log(m) {
                    self.log(t, &log);
                }
            }
            Message::SafetyCommand(m) => self.log(t, &visual::safety_log(m)),
            Message::TruthState(m) => {
                let scene = visual::truth_scene(m);
                self.scene_update(visual::TRUTH_TOPIC, t, &scene);
            }
            _ => {}
        }
        Ok(())
    }

    fn raw_channel(&mut self, topic: &str) -> &Channel<RawImage> {
        let ctx = &self.ctx;
        self.raw
            .entry(topic.to_string())
            .or_insert_with(|| ctx.channel_builder(topic).build::<RawImage>())
    }

    /// A camera frame as JPEG or raw, per the options; a frame whose pixels do not fit
    /// its header is left out (its header is recorded).
    fn image(
        &mut self,
        topic: &str,
        t: u64,
        h: &ipc_types::msg::CameraFrameHeader,
        pixels: &[u8],
    ) -> Result<(), RecordError> {
        let meta = PartialMetadata::with_log_time(t);
        match self.options.images {
            ImageFormat::Raw => {
                if let Some(img) = visual::raw_image(h, pixels) {
                    self.raw_channel(topic).log_with_meta(&img, meta);
                    self.messages += 1;
                }
            }
            ImageFormat::Jpeg { quality } => {
                if let Some(img) = self.visuals.jpeg(h, pixels, quality) {
                    let ctx = &self.ctx;
                    self.compressed
                        .entry(topic.to_string())
                        .or_insert_with(|| ctx.channel_builder(topic).build::<CompressedImage>())
                        .log_with_meta(&img, meta);
                    self.messages += 1;
                }
            }
        }
        self.after_write(t)
    }

    fn transforms(&mut self, t: u64, tf: &Option<FrameTransforms>) {
        if let Some(tf) = tf {
            self.tf.log_with_meta(tf, PartialMetadata::with_log_time(t));
            self.messages += 1;
        }
    }

    fn scene_update(&mut self, topic: &'static str, t: u64, scene: &Option<SceneUpdate>) {
        if let (Some(scene), Some(ch)) = (scene, self.scene.get(topic)) {
            ch.log_with_meta(scene, PartialMetadata::with_log_time(t));
            self.messages += 1;
        }
    }

    fn log(&mut self, t: u64, log: &Log) {
        self.log
            .log_with_meta(log, PartialMetadata::with_log_time(t));
        self.messages += 1;
    }

    /// The clock: flushes when a flush period has passed since the last flush (inputs
    /// may have stopped).
    pub fn tick(&mut self, now_ns: u64) -> Result<(), RecordError> {
        self.after_write(now_ns)
    }

    /// Flushes when a flush period of log time has passed since the last one.
    fn after_write(&mut self, log_time_ns: u64) -> Result<(), RecordError> {
        match self.last_flush_ns {
            None => self.last_flush_ns = Some(log_time_ns),
            Some(l) if log_time_ns.saturating_sub(l) >= self.options.flush_period_ns => {
                self.flush()?;
                self.last_flush_ns = Some(log_time_ns);
            }
            Some(_) => {}
        }
        Ok(())
    }

    /// Closes the open chunk and writes it out: everything recorded so far reads back
    /// even if the process dies next.
    pub fn flush(&mut self) -> Result<(), RecordError> {
        match &self.handle {
            Some(h) => h.flush().map_err(|e| self.write_error(e)),
            None => Ok(()),
        }
    }

    /// Writes the index and summary that make the file complete; returns the number of
    /// messages recorded.
    pub fn finish(mut self) -> Result<u64, RecordError> {
        if let Some(live) = self.live.take() {
            // Clients are told the server goes; the flight's file is what must not wait.
            drop(live.stop());
        }
        if let Some(h) = self.handle.take() {
            h.close().map_err(|e| self.write_error(e))?;
        }
        Ok(self.messages)
    }
}

/// Writes [`Recorder::record_json`] from the payload list
/// ([`ipc_types::for_each_payload!`]): every struct as JSON on its topic's channel, and
/// the header of every frame and map on `<channel>/header`; local payloads and bytes
/// are not recorded.
macro_rules! record_json {
    (
        structs: [$($(#[$sd:meta])* $s:ident($st:ty => $so:ty) = $sn:literal,)*],
        truth: [$($(#[$td:meta])* $t:ident($tt:ty => $to:ty) = $tn:literal,)*],
        slices: [$($(#[$cd:meta])* $c:ident($ch:ty, [$ce:ty]) = $cn:literal,)*],
        local: [$($(#[$ld:meta])* $l:ident($lt:ty) = $ln:literal,)*],
        bytes: [$($(#[$bd:meta])* $b:ident = $bn:literal,)*],
    ) => {
        impl Recorder {
            /// The JSON of `msg` on `name` (`/<topic>`), or of its header on
            /// `<name>/header` for a frame or a map.
            fn record_json(
                &mut self,
                name: &str,
                t: u64,
                msg: &Message<'_>,
            ) -> Result<(), RecordError> {
                match *msg {
                    $(Message::$s(m) => self.write_message(name, t, m),)*
                    $(Message::$t(m) => self.write_message(name, t, m),)*
                    $(Message::$c(h, _) => {
                        self.write_message(&format!("{name}{HEADER_SUFFIX}"), t, h)
                    })*
                    $(Message::$l(_) => Ok(()),)*
                    $(Message::$b(_) => Ok(()),)*
                }
            }
        }
    };
}
ipc_types::for_each_payload!(record_json);

impl Drop for Recorder {
    fn drop(&mut self) {
        if let Some(h) = self.handle.take() {
            // Dropping finishes the file as well as it can; `finish` reports errors.
            let _ = h.close();
        }
    }
}

#[cfg(test)]
#[path = "writer_test.rs"]
mod tests;
