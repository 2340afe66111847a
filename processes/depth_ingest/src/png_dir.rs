//! A directory of 16-bit PNG depth images (one depth unit per count, 0 = no return, as
//! `rs-convert -p` and most depth-camera tools write them), read in file-name order.

use std::path::{Path, PathBuf};

use opencv::core::{CV_16UC1, Mat};
use opencv::imgcodecs;
use opencv::prelude::*;

/// One depth image: its size and its depths, row after row.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct DepthImage {
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
    /// Depth units, `width * height` of them.
    pub depths: Vec<u16>,
}

/// Why a PNG directory could not be opened or an image in it read.
#[derive(Debug, thiserror::Error)]
pub enum PngDirError {
    /// The directory could not be listed.
    #[error("{path}: cannot list: {reason}")]
    List {
        /// The directory.
        path: PathBuf,
        /// The I/O error.
        reason: String,
    },
    /// No `.png` file in it.
    #[error("{0}: no .png files")]
    Empty(PathBuf),
    /// A file that is not a decodable PNG.
    #[error("{0}: not a readable image")]
    Unreadable(PathBuf),
    /// A PNG that is not 16-bit single-channel (an 8-bit or colour image is not depth).
    #[error("{0}: not a 16-bit single-channel image (a depth image has one 16-bit channel)")]
    NotDepth(PathBuf),
}

/// The images of a directory, played in file-name order.
pub struct PngDir {
    dir: PathBuf,
    files: Vec<PathBuf>,
    next: usize,
}

impl PngDir {
    /// Lists `dir`'s `.png` files (others, such as notes, are ignored).
    pub fn open(dir: &Path) -> Result<Self, PngDirError> {
        let entries = std::fs::read_dir(dir).map_err(|e| PngDirError::List {
            path: dir.to_path_buf(),
            reason: e.to_string(),
        })?;
        let mut files: Vec<PathBuf> = entries
            .flatten()
            .map(|e| e.path())
            .filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("png")))
            .collect();
        if files.is_empty() {
            return Err(PngDirError::Empty(dir.to_path_buf()));
        }
        files.sort();
        Ok(Self {
            dir: dir.to_path_buf(),
            files,
            next: 0,
        })
    }

    /// The directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// How many images it holds.
    pub fn len(&self) -> usize {
        self.files.len()
    }

    /// Whether it holds none (never, once opened).
    pub fn is_empty(&self) -> bool {
        self.files.is_empty()
    }

    /// Reads the next image into `into` (its buffer reused); `None` at the end.
    pub fn next_image(&mut self, into: &mut DepthImage) -> Option<Result<(), PngDirError>> {
        let path = self.files.get(self.next)?.clone();
        self.next += 1;
        Some(read_png16(&path, into))
    }

    /// Back to the first image.
    pub fn rewind(&mut self) {
        self.next = 0;
    }
}

/// Reads one 16-bit single-channel image into `into`.
pub fn read_png16(path: &Path, into: &mut DepthImage) -> Result<(), PngDirError> {
    let unreadable = || PngDirError::Unreadable(path.to_path_buf());
    let mat: Mat = imgcodecs::imread(&*path.to_string_lossy(), imgcodecs::IMREAD_UNCHANGED)
        .map_err(|_| unreadable())?;
    if mat.empty() {
        return Err(unreadable());
    }
    if mat.typ() != CV_16UC1 {
        return Err(PngDirError::NotDepth(path.to_path_buf()));
    }
    let depths = mat.data_typed::<u16>().map_err(|_| unreadable())?;
    into.width = u32::try_from(mat.cols()).map_err(|_| unreadable())?;
    into.height = u32::try_from(mat.rows()).map_err(|_| unreadable())?;
    into.depths.clear();
    into.depths.extend_from_slice(depths);
    Ok(())
}

#[cfg(test)]
#[path = "png_dir_test.rs"]
mod tests;
