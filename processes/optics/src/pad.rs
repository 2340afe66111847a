//! The landing pad model: which ArUco markers (dictionary ARUCO_ORIGINAL) sit
//! where on the board, in the pad frame (origin at the centre of the pad
//! surface, x along the carrier's heading, y left, z up).
//!
//! The model comes from `deploy/config/pad.toml` so the printed pad, the
//! simulator's texture and the detector's object points are one and the same.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use nalgebra::Point3;
use opencv::aruco;
use opencv::core::{CV_8UC1, Mat, Rect, Scalar};
use opencv::prelude::*;
use serde::Deserialize;
use thiserror::Error;

/// Number of markers in OpenCV's ARUCO_ORIGINAL dictionary (valid ids 0..1024).
pub const ARUCO_ORIGINAL_SIZE: u32 = 1024;

/// The only dictionary the pad uses (the paper's); named in pad.toml so a file
/// written for another dictionary is rejected instead of silently misread.
pub const DICTIONARY_NAME: &str = "ARUCO_ORIGINAL";

/// Cells along a side of an ARUCO_ORIGINAL marker as printed: 5 data bits plus a
/// one-cell black border on each side.
pub const MARKER_CELLS: usize = 7;

/// How far from symmetric about the origin the board may be (m): rounding in a
/// hand-written file, not a design choice.
const BOARD_CENTRE_TOLERANCE_M: f64 = 1e-9;

/// The smallest marker side, px, the detector reads reliably: about 2 px per cell of an
/// ARUCO_ORIGINAL marker's 7. The 25.7 cm marker on the 640x480 120 deg camera was read
/// from 3.1 m (15.3 px) and never from 3.6 m (13.2 px) (highspeed-10, docs/highspeed.md).
pub const MIN_MARKER_PX: f64 = 15.0;

/// Texture scales [`PadModel::render_texture`] accepts (pixels per metre): from a
/// coarse mip level to a 1200 dpi print (47 244 px/m).
pub const TEXTURE_PX_PER_M: std::ops::RangeInclusive<f64> = 100.0..=50_000.0;

/// Why a pad model could not be loaded or drawn.
#[derive(Debug, Error)]
pub enum PadError {
    /// The file could not be read.
    #[error("pad file {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is not valid TOML for a pad.
    #[error("pad file {path}: {message}")]
    Parse {
        /// The file (empty when parsed from a string).
        path: PathBuf,
        /// What the parser said.
        message: String,
    },
    /// A value is wrong; `key` is the field as written in the file.
    #[error("pad: {key} = {value}: {allowed}")]
    Invalid {
        /// The field, e.g. `markers[2].size_m`.
        key: String,
        /// The value found.
        value: String,
        /// What is accepted.
        allowed: String,
    },
    /// A marker id that is not on the pad was asked for.
    #[error("pad: no marker with id {0}")]
    UnknownMarker(u32),
    /// OpenCV failed while drawing the texture.
    #[error("pad texture: {0}")]
    OpenCv(#[from] opencv::Error),
}

fn invalid(key: impl Into<String>, value: impl ToString, allowed: impl Into<String>) -> PadError {
    PadError::Invalid {
        key: key.into(),
        value: value.to_string(),
        allowed: allowed.into(),
    }
}

/// One square marker on the board.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Marker {
    /// ARUCO_ORIGINAL id.
    pub id: u32,
    /// Centre (x, y) in the pad frame, m.
    pub centre_m: [f64; 2],
    /// Side length of the black square (including its black border), m.
    pub size_m: f64,
    /// Camera distances (min, max) over which the detector should use this
    /// marker for the pose: small markers near, big ones far.
    pub active_range_m: [f64; 2],
}

/// The rectangle of the printed board in the pad frame, centred on the pad origin
/// (`validate` insists) so the sheet's centre is the landing point.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Board {
    /// Lowest (x, y) corner, m.
    pub min_m: [f64; 2],
    /// Highest (x, y) corner, m.
    pub max_m: [f64; 2],
}

impl Board {
    /// How far the pad-frame point `(x, y)` is outside the board, m (0 inside or on the
    /// edge; NaN for a NaN point).
    pub fn outside_m(&self, x: f64, y: f64) -> f64 {
        let d = |v: f64, i: usize| (self.min_m[i] - v).max(v - self.max_m[i]).max(0.0);
        if x.is_nan() || y.is_nan() {
            return f64::NAN;
        }
        d(x, 0).hypot(d(y, 1))
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PadFile {
    dictionary: String,
    board: Board,
    markers: Vec<Marker>,
}

/// The landing pad: a white board with ARUCO_ORIGINAL markers.
#[derive(Debug, Clone, PartialEq)]
pub struct PadModel {
    /// Board extent in the pad frame (white outside the markers).
    pub board: Board,
    /// The markers, in file order.
    pub markers: Vec<Marker>,
}

impl PadModel {
    /// Loads and validates a pad file (`deploy/config/pad.toml`).
    pub fn load(path: impl AsRef<Path>) -> Result<Self, PadError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| PadError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_toml(&text).map_err(|e| match e {
            PadError::Parse { message, .. } => PadError::Parse {
                path: path.to_path_buf(),
                message,
            },
            other => other,
        })
    }

    /// Parses and validates a pad from TOML text.
    pub fn from_toml(text: &str) -> Result<Self, PadError> {
        // One line (the CLI prints errors as one line): the line number and the
        // parser's message, without toml's multi-line source excerpt.
        let file: PadFile = toml::from_str(text).map_err(|e| {
            let message = e.message().split_whitespace().collect::<Vec<_>>().join(" ");
            let line = e
                .span()
                .and_then(|s| text.get(..s.start))
                .map(|before| before.matches('\n').count() + 1);
            PadError::Parse {
                path: PathBuf::new(),
                message: match line {
                    Some(l) => format!("line {l}: {message}"),
                    None => message,
                },
            }
        })?;
        if file.dictionary != DICTIONARY_NAME {
            return Err(invalid(
                "dictionary",
                &file.dictionary,
                format!("must be \"{DICTIONARY_NAME}\""),
            ));
        }
        let pad = Self {
            board: file.board,
            markers: file.markers,
        };
        pad.validate()?;
        Ok(pad)
    }

    /// Checks the layout: finite numbers, ids valid and unique, markers inside
    /// the board and not overlapping, the board centred on the pad origin.
    pub fn validate(&self) -> Result<(), PadError> {
        let b = &self.board;
        for i in 0..2 {
            if !b.min_m[i].is_finite() {
                return Err(invalid(
                    format!("board.min_m[{i}]"),
                    b.min_m[i],
                    "must be finite",
                ));
            }
            if !(b.max_m[i].is_finite() && b.max_m[i] > b.min_m[i]) {
                return Err(invalid(
                    format!("board.max_m[{i}]"),
                    b.max_m[i],
                    format!("must be finite and > board.min_m[{i}] ({})", b.min_m[i]),
                ));
            }
            // Centred: the printed sheet's centre is then the landing point, which is
            // how the sheet is mounted on the carrier and what `landing pad print`
            // promises. It also keeps the origin on the board.
            if (b.max_m[i] + b.min_m[i]).abs() > BOARD_CENTRE_TOLERANCE_M {
                return Err(invalid(
                    format!("board.max_m[{i}]"),
                    b.max_m[i],
                    format!(
                        "must be -board.min_m[{i}] ({}): the board is centred on the pad \
                         origin (the landing point)",
                        -b.min_m[i]
                    ),
                ));
            }
        }
        if self.markers.is_empty() {
            return Err(invalid("markers", "[]", "at least one marker"));
        }
        let mut ids = HashSet::new();
        for (k, m) in self.markers.iter().enumerate() {
            if m.id >= ARUCO_ORIGINAL_SIZE {
                return Err(invalid(
                    format!("markers[{k}].id"),
                    m.id,
                    format!("must be < {ARUCO_ORIGINAL_SIZE} (ARUCO_ORIGINAL)"),
                ));
            }
            if !ids.insert(m.id) {
                return Err(invalid(format!("markers[{k}].id"), m.id, "duplicate id"));
            }
            if !(m.size_m.is_finite() && m.size_m > 0.0) {
                return Err(invalid(
                    format!("markers[{k}].size_m"),
                    m.size_m,
                    "must be > 0",
                ));
            }
            let [lo, hi] = m.active_range_m;
            if !(lo.is_finite() && lo >= 0.0) {
                return Err(invalid(
                    format!("markers[{k}].active_range_m[0]"),
                    lo,
                    "must be >= 0",
                ));
            }
            if !(hi.is_finite() && hi > lo) {
                return Err(invalid(
                    format!("markers[{k}].active_range_m[1]"),
                    hi,
                    format!("must be finite and > active_range_m[0] ({lo})"),
                ));
            }
            let h = m.size_m / 2.0;
            for i in 0..2 {
                let c = m.centre_m[i];
                if !(c.is_finite() && c - h >= b.min_m[i] && c + h <= b.max_m[i]) {
                    return Err(invalid(
                        format!("markers[{k}].centre_m[{i}]"),
                        c,
                        format!(
                            "the marker (half size {h}) must lie inside the board [{}, {}]",
                            b.min_m[i], b.max_m[i]
                        ),
                    ));
                }
            }
        }
        for (k, a) in self.markers.iter().enumerate() {
            for b2 in &self.markers[..k] {
                let gap = (0..2)
                    .map(|i| (a.centre_m[i] - b2.centre_m[i]).abs() - (a.size_m + b2.size_m) / 2.0)
                    .fold(f64::NEG_INFINITY, f64::max);
                if gap <= 0.0 {
                    return Err(invalid(
                        format!("markers[{k}].centre_m"),
                        format!("{:?}", a.centre_m),
                        format!("overlaps marker {}", b2.id),
                    ));
                }
            }
        }
        Ok(())
    }

    /// The farthest depth (along the optical axis, m) at which a camera of focal length
    /// `focal_px` still reads the pad's largest marker: where that marker's side spans
    /// [`MIN_MARKER_PX`]. A search for the pad beyond it cannot succeed.
    pub fn detection_depth_m(&self, focal_px: f64) -> f64 {
        let largest = self.markers.iter().map(|m| m.size_m).fold(0.0, f64::max);
        focal_px * largest / MIN_MARKER_PX
    }

    /// The marker with this id, if it is on the pad.
    pub fn marker(&self, id: u32) -> Option<&Marker> {
        self.markers.iter().find(|m| m.id == id)
    }

    /// The four corners of marker `id` in the pad frame (z = 0), in OpenCV's
    /// ArUco order: top-left, top-right, bottom-right, bottom-left of the
    /// printed image, where image up is pad +y and image right is pad +x.
    /// These are the object points for `solve_pnp`.
    pub fn marker_corners_pad(&self, id: u32) -> Result<[Point3<f64>; 4], PadError> {
        let m = self.marker(id).ok_or(PadError::UnknownMarker(id))?;
        let h = m.size_m / 2.0;
        let [x, y] = m.centre_m;
        Ok([
            Point3::new(x - h, y + h, 0.0),
            Point3::new(x + h, y + h, 0.0),
            Point3::new(x + h, y - h, 0.0),
            Point3::new(x - h, y - h, 0.0),
        ])
    }

    /// Size in pixels (width, height) of the texture drawn at `pixels_per_metre`.
    pub fn texture_size(&self, pixels_per_metre: f64) -> (i32, i32) {
        let w = ((self.board.max_m[0] - self.board.min_m[0]) * pixels_per_metre).round();
        let h = ((self.board.max_m[1] - self.board.min_m[1]) * pixels_per_metre).round();
        (w as i32, h as i32)
    }

    /// Draws the pad as seen from above (mono8, white board, black markers from
    /// OpenCV's own ARUCO_ORIGINAL dictionary). Column 0 is the board's min x,
    /// row 0 its max y; texel (c, r) covers pad x = min_x + (c .. c+1) / ppm,
    /// y = max_y - (r .. r+1) / ppm. Every marker cell is filled with whole
    /// texels, its edges at the texel boundary nearest their true position (off
    /// by at most half a texel, no blur), so a texel is black exactly when its
    /// centre lies in a black cell. Used to print the pad and to render it.
    pub fn render_texture(&self, pixels_per_metre: f64) -> Result<Mat, PadError> {
        if !TEXTURE_PX_PER_M.contains(&pixels_per_metre) {
            return Err(invalid(
                "pixels_per_metre",
                pixels_per_metre,
                format!(
                    "must be in [{}, {}]",
                    TEXTURE_PX_PER_M.start(),
                    TEXTURE_PX_PER_M.end()
                ),
            ));
        }
        let (w, h) = self.texture_size(pixels_per_metre);
        let mut tex = Mat::new_rows_cols_with_default(h, w, CV_8UC1, Scalar::all(255.0))?;
        let [min_x, max_y] = [self.board.min_m[0], self.board.max_m[1]];
        // Texel boundary nearest to a distance in metres from the board's left or
        // top edge, kept on the texture.
        let edge =
            |metres: f64, limit: i32| ((metres * pixels_per_metre).round() as i32).clamp(0, limit);
        for m in &self.markers {
            let cells = marker_cells(m.id)?;
            let cell = m.size_m / MARKER_CELLS as f64;
            let left = m.centre_m[0] - m.size_m / 2.0 - min_x;
            let top = max_y - (m.centre_m[1] + m.size_m / 2.0);
            let cols: Vec<i32> = (0..=MARKER_CELLS)
                .map(|k| edge(left + cell * k as f64, w))
                .collect();
            let rows: Vec<i32> = (0..=MARKER_CELLS)
                .map(|k| edge(top + cell * k as f64, h))
                .collect();
            for (r, row) in cells.iter().enumerate() {
                for (c, &black) in row.iter().enumerate() {
                    let (cw, ch) = (cols[c + 1] - cols[c], rows[r + 1] - rows[r]);
                    if black && cw > 0 && ch > 0 {
                        let mut roi = Mat::roi_mut(&mut tex, Rect::new(cols[c], rows[r], cw, ch))?;
                        roi.set_to_def(&Scalar::all(0.0))?;
                    }
                }
            }
        }
        Ok(tex)
    }
}

/// The cells of ARUCO_ORIGINAL marker `id` as printed, row 0 at the top of the
/// image, `true` for black (the border cells are all black). Taken from OpenCV's
/// own dictionary so the printed pad, the simulator's texture and the detector
/// agree bit for bit.
pub fn marker_cells(id: u32) -> Result<[[bool; MARKER_CELLS]; MARKER_CELLS], PadError> {
    if id >= ARUCO_ORIGINAL_SIZE {
        return Err(PadError::UnknownMarker(id));
    }
    let dict =
        aruco::get_predefined_dictionary(aruco::PREDEFINED_DICTIONARY_NAME::DICT_ARUCO_ORIGINAL)?;
    let mut img = Mat::default();
    // One pixel per cell: the drawn image is the bit matrix itself.
    aruco::draw_marker(&dict, id as i32, MARKER_CELLS as i32, &mut img, 1)?;
    let mut cells = [[false; MARKER_CELLS]; MARKER_CELLS];
    for (r, row) in cells.iter_mut().enumerate() {
        for (c, cell) in row.iter_mut().enumerate() {
            *cell = *img.at_2d::<u8>(r as i32, c as i32)? < 128;
        }
    }
    Ok(cells)
}
