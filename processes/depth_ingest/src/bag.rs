//! RealSense recordings (`.bag`) read without librealsense: a ROS 1 bag (format 2.0),
//! its chunks stored or LZ4-compressed, as librealsense's recorder writes it (the
//! RealSense Viewer, `rs-record`, `rs.recorder`). The depth stream is the first
//! `/device_0/sensor_<n>/Depth_<k>/` stream: its images (`sensor_msgs/Image`, `mono16`),
//! its intrinsics (`.../info/camera_info`), its frame rate (`.../info`) and its depth
//! units (written after each image's pixels, else the sensor's
//! `.../option/Depth_Units/value`). Everything else in the file is skipped. librealsense
//! 2.58 and later record ROS 2 `.db3` files instead, which this does not read.
//!
//! The file is read once, front to back, a chunk at a time: a bag of any length plays in
//! the memory of one chunk.

use std::collections::HashMap;
use std::fs::File;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};

use ipc_types::msg::Intrinsics;

use crate::png_dir::DepthImage;

/// Why a recording could not be opened or read.
#[derive(Debug, thiserror::Error)]
pub enum BagError {
    /// The file could not be opened or read.
    #[error("{path}: {reason}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        reason: String,
    },
    /// Not a ROS bag of format 2.0.
    #[error("{0}: not a RealSense .bag (a ROS bag 2.0 starts with `#ROSBAG V2.0`)")]
    NotABag(PathBuf),
    /// A record, or a message in it, ends before its fields do.
    #[error("{path}: damaged at byte {at}: {what}")]
    Damaged {
        /// The file.
        path: PathBuf,
        /// Where (in the file, or in the chunk that starts there).
        at: u64,
        /// What was being read.
        what: &'static str,
    },
    /// Chunks compressed some other way than none or LZ4.
    #[error("{path}: chunks compressed with `{compression}` (allowed: none, lz4)")]
    Compression {
        /// The file.
        path: PathBuf,
        /// The chunk's compression.
        compression: String,
    },
    /// No depth stream, or none before its first image said its size and intrinsics.
    #[error(
        "{0}: no depth stream with its camera_info (a RealSense recording of a depth sensor has /device_0/sensor_N/Depth_0/)"
    )]
    NoDepth(PathBuf),
}

/// What the recording says about its depth stream.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DepthStreamInfo {
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
    /// Pinhole intrinsics of the depth image (`K` of its camera_info).
    pub intrinsics: Intrinsics,
    /// Metres per depth unit (the sensor's Depth Units option; 0.001 when not recorded).
    pub depth_scale_m: f64,
    /// The stream's frame rate, Hz (0 when not recorded).
    pub fps: u32,
}

/// What a connection (a topic of the bag) carries, for the depth stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Image,
    CameraInfo,
    StreamInfo,
    DepthUnits,
}

/// The stream a topic belongs to and what it carries, or `None` for anything else.
fn classify(topic: &str) -> Option<(String, Kind)> {
    let rest = topic.strip_prefix("/device_0/sensor_")?;
    let (sensor, rest) = rest.split_once('/')?;
    if rest == "option/Depth_Units/value" {
        return Some((format!("sensor_{sensor}"), Kind::DepthUnits));
    }
    let (stream, what) = rest.split_once('/')?;
    if !stream.starts_with("Depth_") {
        return None;
    }
    let kind = match what {
        "image/data" => Kind::Image,
        "info/camera_info" => Kind::CameraInfo,
        "info" => Kind::StreamInfo,
        _ => return None,
    };
    Some((format!("sensor_{sensor}/{stream}"), kind))
}

/// Reads fields of a record header or a message, little-endian, by position.
struct Cursor<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Cursor<'a> {
    fn new(buf: &'a [u8]) -> Self {
        Self { buf, pos: 0 }
    }

    fn bytes(&mut self, n: usize) -> Option<&'a [u8]> {
        let end = self.pos.checked_add(n)?;
        let b = self.buf.get(self.pos..end)?;
        self.pos = end;
        Some(b)
    }

    fn u32(&mut self) -> Option<u32> {
        Some(u32::from_le_bytes(self.bytes(4)?.try_into().ok()?))
    }

    fn u8(&mut self) -> Option<u8> {
        Some(*self.bytes(1)?.first()?)
    }

    fn f32(&mut self) -> Option<f32> {
        Some(f32::from_le_bytes(self.bytes(4)?.try_into().ok()?))
    }

    fn f64(&mut self) -> Option<f64> {
        Some(f64::from_le_bytes(self.bytes(8)?.try_into().ok()?))
    }

    /// A length-prefixed byte array (a string, a `uint8[]`).
    fn array(&mut self) -> Option<&'a [u8]> {
        let n = self.u32()? as usize;
        self.bytes(n)
    }

    /// `n` float64s; `None` for a variable array whose length is not `n`.
    fn f64s<const N: usize>(&mut self) -> Option<[f64; N]> {
        let mut out = [0.0; N];
        for v in &mut out {
            *v = self.f64()?;
        }
        Some(out)
    }

    /// A `std_msgs/Header`: its stamp, ns.
    fn ros_header(&mut self) -> Option<u64> {
        let _seq = self.u32()?;
        let secs = u64::from(self.u32()?);
        let nsecs = u64::from(self.u32()?);
        let _frame_id = self.array()?;
        Some(secs * 1_000_000_000 + nsecs)
    }

    fn done(&self) -> bool {
        self.pos >= self.buf.len()
    }
}

/// A record header's fields (`name=value`, each length-prefixed).
fn header_fields(header: &[u8]) -> Option<HashMap<&[u8], &[u8]>> {
    let mut c = Cursor::new(header);
    let mut fields = HashMap::new();
    while !c.done() {
        let field = c.array()?;
        let eq = field.iter().position(|b| *b == b'=')?;
        fields.insert(field.get(..eq)?, field.get(eq + 1..)?);
    }
    Some(fields)
}

fn field_u32(fields: &HashMap<&[u8], &[u8]>, name: &[u8]) -> Option<u32> {
    Some(u32::from_le_bytes(
        fields.get(name)?.get(..4)?.try_into().ok()?,
    ))
}

/// The largest record header, chunk or decompressed chunk read, bytes: librealsense
/// closes a chunk past 768 KB, so a larger number is damage, not a bigger camera.
const MAX_RECORD_BYTES: usize = 64 << 20;

const OP_MESSAGE: u8 = 0x02;
const OP_CHUNK: u8 = 0x05;
const OP_CONNECTION: u8 = 0x07;

/// A RealSense recording's depth stream, played front to back.
pub struct RsBag {
    path: PathBuf,
    file: BufReader<File>,
    /// Where the next top-level record starts, for error lines.
    offset: u64,
    /// The decompressed chunk being read, where it started, and the read position.
    chunk: Vec<u8>,
    chunk_at: u64,
    pos: usize,
    /// Connection id -> what it carries of the depth stream.
    connections: HashMap<u32, Kind>,
    /// The depth stream (its sensor and stream name), once one was seen.
    stream: Option<String>,
    info: DepthStreamInfo,
    camera_info: bool,
    /// The first image, read by `open` to learn the stream, given out first.
    first: Option<(DepthImage, u64)>,
}

/// What one message of the depth stream was.
enum Item {
    Image(u64),
    Other,
}

impl RsBag {
    /// Opens `path` and reads up to its first depth image, which says the stream's size
    /// and intrinsics.
    pub fn open(path: &Path) -> Result<Self, BagError> {
        let io = |e: std::io::Error| BagError::Io {
            path: path.to_path_buf(),
            reason: e.to_string(),
        };
        let mut file = BufReader::new(File::open(path).map_err(io)?);
        let mut magic = [0u8; 13];
        file.read_exact(&mut magic)
            .map_err(|_| BagError::NotABag(path.to_path_buf()))?;
        if &magic != b"#ROSBAG V2.0\n" {
            return Err(BagError::NotABag(path.to_path_buf()));
        }
        let mut bag = Self {
            path: path.to_path_buf(),
            file,
            offset: 13,
            chunk: Vec::new(),
            chunk_at: 0,
            pos: 0,
            connections: HashMap::new(),
            stream: None,
            info: DepthStreamInfo {
                width: 0,
                height: 0,
                intrinsics: Intrinsics::default(),
                depth_scale_m: 0.001,
                fps: 0,
            },
            camera_info: false,
            first: None,
        };
        let mut image = DepthImage::default();
        match bag.read_image(&mut image)? {
            Some(stamp) if bag.camera_info => {
                bag.first = Some((image, stamp));
                Ok(bag)
            }
            _ => Err(BagError::NoDepth(path.to_path_buf())),
        }
    }

    /// The depth stream's size, intrinsics, depth units and rate.
    pub fn info(&self) -> DepthStreamInfo {
        self.info
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Reads the next depth image into `into`; its recorded stamp, ns. `None` at the end.
    pub fn next_image(&mut self, into: &mut DepthImage) -> Result<Option<u64>, BagError> {
        if let Some((first, stamp)) = self.first.take() {
            *into = first;
            return Ok(Some(stamp));
        }
        self.read_image(into)
    }

    fn damaged(&self, at: u64, what: &'static str) -> BagError {
        BagError::Damaged {
            path: self.path.clone(),
            at,
            what,
        }
    }

    fn read_image(&mut self, into: &mut DepthImage) -> Result<Option<u64>, BagError> {
        loop {
            if self.pos < self.chunk.len() {
                if let Item::Image(stamp) = self.chunk_record(into)? {
                    return Ok(Some(stamp));
                }
                continue;
            }
            if !self.next_chunk()? {
                return Ok(None);
            }
        }
    }

    /// Reads top-level records up to the next chunk and decompresses it; false at the
    /// end of the file.
    fn next_chunk(&mut self) -> Result<bool, BagError> {
        loop {
            let at = self.offset;
            let mut len = [0u8; 4];
            match self.file.read_exact(&mut len) {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => return Ok(false),
                Err(e) => {
                    return Err(BagError::Io {
                        path: self.path.clone(),
                        reason: e.to_string(),
                    });
                }
            }
            let header = self.read_exact(u32::from_le_bytes(len) as usize, at)?;
            let data_len = self.read_exact(4, at)?;
            let data_len = u32::from_le_bytes(
                data_len
                    .as_slice()
                    .try_into()
                    .map_err(|_| self.damaged(at, "record length"))?,
            ) as usize;
            let data = self.read_exact(data_len, at)?;
            self.offset += 8 + header.len() as u64 + data_len as u64;
            let fields = header_fields(&header).ok_or_else(|| self.damaged(at, "record header"))?;
            let op = fields.get(&b"op"[..]).and_then(|v| v.first().copied());
            match op {
                Some(OP_CHUNK) => {
                    let compression = fields
                        .get(&b"compression"[..])
                        .map(|c| String::from_utf8_lossy(c).into_owned())
                        .unwrap_or_default();
                    let size = field_u32(&fields, b"size")
                        .ok_or_else(|| self.damaged(at, "chunk size"))?
                        as usize;
                    if size > MAX_RECORD_BYTES {
                        return Err(self.damaged(at, "a chunk larger than 64 MiB"));
                    }
                    self.chunk = match compression.as_str() {
                        "none" => data,
                        "lz4" => {
                            let mut out = Vec::with_capacity(size);
                            // No more than the chunk says it holds (a bomb stops there).
                            lz4_flex::frame::FrameDecoder::new(data.as_slice())
                                .take(size as u64)
                                .read_to_end(&mut out)
                                .map_err(|_| self.damaged(at, "lz4 chunk"))?;
                            out
                        }
                        _ => {
                            return Err(BagError::Compression {
                                path: self.path.clone(),
                                compression,
                            });
                        }
                    };
                    self.chunk_at = at;
                    self.pos = 0;
                    return Ok(true);
                }
                // Connections are also repeated after the chunks, with the index.
                Some(OP_CONNECTION) => self.connection(&fields, &data),
                _ => {}
            }
        }
    }

    fn read_exact(&mut self, n: usize, at: u64) -> Result<Vec<u8>, BagError> {
        if n > MAX_RECORD_BYTES {
            return Err(self.damaged(at, "a record larger than 64 MiB"));
        }
        let mut buf = vec![0u8; n];
        self.file
            .read_exact(&mut buf)
            .map_err(|_| self.damaged(at, "a record cut short"))?;
        Ok(buf)
    }

    /// Learns what a connection carries of the depth stream (the first one seen).
    fn connection(&mut self, fields: &HashMap<&[u8], &[u8]>, _data: &[u8]) {
        let (Some(conn), Some(topic)) = (field_u32(fields, b"conn"), fields.get(&b"topic"[..]))
        else {
            return;
        };
        let topic = String::from_utf8_lossy(topic);
        let Some((stream, kind)) = classify(&topic) else {
            return;
        };
        if kind == Kind::DepthUnits {
            // The option belongs to the sensor; the stream is named when its images come.
            self.connections.insert(conn, kind);
            return;
        }
        match &self.stream {
            Some(s) if *s != stream => {}
            _ => {
                self.stream = Some(stream);
                self.connections.insert(conn, kind);
            }
        }
    }

    /// One record of the current chunk.
    fn chunk_record(&mut self, into: &mut DepthImage) -> Result<Item, BagError> {
        let at = self.chunk_at;
        let chunk = std::mem::take(&mut self.chunk);
        let result = self.parse_chunk_record(&chunk, into);
        self.chunk = chunk;
        result.ok_or_else(|| self.damaged(at, "a record in a chunk"))?
    }

    fn parse_chunk_record(
        &mut self,
        chunk: &[u8],
        into: &mut DepthImage,
    ) -> Option<Result<Item, BagError>> {
        let mut c = Cursor::new(chunk.get(self.pos..)?);
        let header = c.array()?;
        let data = c.array()?;
        self.pos += c.pos;
        let fields = header_fields(header)?;
        match fields.get(&b"op"[..]).and_then(|v| v.first().copied()) {
            Some(OP_CONNECTION) => {
                self.connection(&fields, data);
                Some(Ok(Item::Other))
            }
            Some(OP_MESSAGE) => {
                let conn = field_u32(&fields, b"conn")?;
                let Some(kind) = self.connections.get(&conn).copied() else {
                    return Some(Ok(Item::Other));
                };
                Some(Ok(self.message(kind, data, into)?))
            }
            _ => Some(Ok(Item::Other)),
        }
    }

    /// Reads a message of the depth stream; `None` when it is cut short.
    fn message(&mut self, kind: Kind, data: &[u8], into: &mut DepthImage) -> Option<Item> {
        let mut c = Cursor::new(data);
        match kind {
            Kind::DepthUnits => {
                let units = f64::from(c.f32()?);
                if units.is_finite() && units > 0.0 {
                    self.info.depth_scale_m = units;
                }
            }
            Kind::StreamInfo => self.info.fps = c.u32()?,
            Kind::CameraInfo => {
                c.ros_header()?;
                let height = c.u32()?;
                let width = c.u32()?;
                let _model = c.array()?;
                let n = c.u32()? as usize;
                c.bytes(n.checked_mul(8)?)?;
                let k = c.f64s::<9>()?;
                self.info.width = width;
                self.info.height = height;
                self.info.intrinsics = Intrinsics {
                    fx: k[0],
                    fy: k[4],
                    cx: k[2],
                    cy: k[5],
                };
                self.camera_info = true;
            }
            Kind::Image => {
                let stamp = c.ros_header()?;
                let height = c.u32()?;
                let width = c.u32()?;
                let encoding = c.array()?;
                let big_endian = c.u8()? != 0;
                let step = c.u32()? as usize;
                let pixels = c.array()?;
                // librealsense writes the frame's depth units after the pixels (beyond
                // the message definition): the frame's own scale wins over the option.
                if let Some(units) = c.f32().map(f64::from)
                    && units.is_finite()
                    && units > 0.0
                {
                    self.info.depth_scale_m = units;
                }
                if !matches!(encoding, b"mono16" | b"16UC1" | b"z16") {
                    return Some(Item::Other);
                }
                let row = (width as usize).checked_mul(2)?;
                if step < row || pixels.len() < step.checked_mul(height as usize)? {
                    return None;
                }
                into.width = width;
                into.height = height;
                into.depths.clear();
                into.depths.reserve(width as usize * height as usize);
                for r in 0..height as usize {
                    let line = pixels.get(r * step..r * step + row)?;
                    into.depths.extend(line.chunks_exact(2).map(|b| {
                        let b = [b[0], b[1]];
                        if big_endian {
                            u16::from_be_bytes(b)
                        } else {
                            u16::from_le_bytes(b)
                        }
                    }));
                }
                return Some(Item::Image(stamp));
            }
        }
        Some(Item::Other)
    }
}

#[cfg(test)]
#[path = "bag_test.rs"]
mod tests;
