//! A ChArUco board: a chessboard whose white squares hold ArUco markers, so that every
//! corner found is known by its id even when the board is partly out of view.

use opencv::aruco::{self, CharucoBoard, PREDEFINED_DICTIONARY_NAME as Dict};
use opencv::core::{Mat, Ptr, Size};
use opencv::prelude::*;

/// What `--board` accepts, for error messages.
pub const BOARD_FORMAT: &str = "charuco:<squares x>x<squares y>:<square m>:<marker m>:<dictionary>, e.g. charuco:7x5:0.04:0.03:DICT_5X5_100";

/// Why a board could not be named or made.
#[derive(Debug, thiserror::Error)]
pub enum BoardError {
    /// The text is not a board.
    #[error("--board `{text}`: {why} (allowed: {BOARD_FORMAT})")]
    Parse {
        /// What was given.
        text: String,
        /// What is wrong with it.
        why: String,
    },
    /// OpenCV could not make it.
    #[error("ChArUco board: OpenCV: {0}")]
    OpenCv(String),
}

/// A ChArUco board's layout.
#[derive(Debug, Clone, PartialEq)]
pub struct CharucoSpec {
    /// Squares along x (columns) and y (rows).
    pub squares: (i32, i32),
    /// Edge of a chessboard square, m.
    pub square_m: f64,
    /// Edge of a marker, m (less than the square).
    pub marker_m: f64,
    /// The ArUco dictionary's name (`DICT_5X5_100`, ...).
    pub dictionary: String,
}

const DICTIONARIES: &[(&str, Dict)] = &[
    ("DICT_4X4_50", Dict::DICT_4X4_50),
    ("DICT_4X4_100", Dict::DICT_4X4_100),
    ("DICT_4X4_250", Dict::DICT_4X4_250),
    ("DICT_5X5_50", Dict::DICT_5X5_50),
    ("DICT_5X5_100", Dict::DICT_5X5_100),
    ("DICT_5X5_250", Dict::DICT_5X5_250),
    ("DICT_6X6_50", Dict::DICT_6X6_50),
    ("DICT_6X6_100", Dict::DICT_6X6_100),
    ("DICT_6X6_250", Dict::DICT_6X6_250),
    ("DICT_7X7_50", Dict::DICT_7X7_50),
    ("DICT_ARUCO_ORIGINAL", Dict::DICT_ARUCO_ORIGINAL),
];

impl std::str::FromStr for CharucoSpec {
    type Err = BoardError;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let fail = |why: &str| BoardError::Parse {
            text: text.to_string(),
            why: why.to_string(),
        };
        let parts: Vec<&str> = text.split(':').collect();
        let [kind, squares, square, marker, dictionary] = parts.as_slice() else {
            return Err(fail("five fields separated by `:`"));
        };
        if *kind != "charuco" {
            return Err(fail("only ChArUco boards"));
        }
        let (sx, sy) = squares
            .split_once('x')
            .and_then(|(x, y)| Some((x.parse::<i32>().ok()?, y.parse::<i32>().ok()?)))
            .ok_or_else(|| fail("squares as <x>x<y>"))?;
        if !(3..=50).contains(&sx) || !(3..=50).contains(&sy) {
            return Err(fail("3 to 50 squares along each side"));
        }
        let length = |s: &str| s.parse::<f64>().ok().filter(|v| v.is_finite() && *v > 0.0);
        let square_m = length(square).ok_or_else(|| fail("a square edge in metres above 0"))?;
        let marker_m = length(marker).ok_or_else(|| fail("a marker edge in metres above 0"))?;
        if marker_m >= square_m {
            return Err(fail("a marker smaller than its square"));
        }
        let spec = Self {
            squares: (sx, sy),
            square_m,
            marker_m,
            dictionary: dictionary.to_string(),
        };
        let n = DICTIONARIES
            .iter()
            .find(|(name, _)| name == dictionary)
            .ok_or_else(|| {
                fail("a dictionary DICT_4X4_50 .. DICT_7X7_50 or DICT_ARUCO_ORIGINAL")
            })?;
        let needed = (sx * sy) / 2;
        let size = dictionary_size(n.0);
        if needed > size {
            return Err(fail(&format!(
                "{needed} markers, more than {} holds ({size})",
                n.0
            )));
        }
        Ok(spec)
    }
}

fn dictionary_size(name: &str) -> i32 {
    name.rsplit('_')
        .next()
        .and_then(|n| n.parse().ok())
        .unwrap_or(1024)
}

impl std::fmt::Display for CharucoSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "charuco:{}x{}:{}:{}:{}",
            self.squares.0, self.squares.1, self.square_m, self.marker_m, self.dictionary
        )
    }
}

impl CharucoSpec {
    /// The board's ArUco dictionary.
    pub fn dictionary(&self) -> Result<Ptr<aruco::Dictionary>, BoardError> {
        let dict = DICTIONARIES
            .iter()
            .find(|(name, _)| *name == self.dictionary)
            .map(|(_, d)| *d)
            .unwrap_or(Dict::DICT_5X5_100);
        aruco::get_predefined_dictionary(dict).map_err(|e| BoardError::OpenCv(e.message))
    }

    /// The board as OpenCV's detector and calibration take it.
    pub fn board(&self) -> Result<Ptr<CharucoBoard>, BoardError> {
        let err = |e: opencv::Error| BoardError::OpenCv(e.message);
        let dictionary = self.dictionary()?;
        CharucoBoard::create(
            self.squares.0,
            self.squares.1,
            self.square_m as f32,
            self.marker_m as f32,
            &dictionary,
        )
        .map_err(err)
    }

    /// The board drawn at `px_per_square` pixels per square (8-bit grey, no margin): to
    /// print at `square_m` per square, or to render views from.
    pub fn image(&self, px_per_square: i32) -> Result<Mat, BoardError> {
        let mut board = self.board()?;
        let size = Size::new(
            self.squares.0 * px_per_square,
            self.squares.1 * px_per_square,
        );
        let mut out = Mat::default();
        board
            .draw(size, &mut out, 0, 1)
            .map_err(|e| BoardError::OpenCv(e.message))?;
        Ok(out)
    }
}
