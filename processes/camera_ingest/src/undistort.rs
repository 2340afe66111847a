//! Undistortion through maps computed once: every frame then costs one `remap`, written
//! straight into the output buffer (the loaned shared memory), with no intermediate image.

use opencv::calib3d;
use opencv::core::{CV_16SC2, Mat, Scalar, Size, ToInputArray, ToOutputArray, Vec3b};
use opencv::imgproc;
use opencv::prelude::*;
use optics::CameraCalibration;

/// Why the undistortion maps could not be computed ([`Undistorter::new`]).
#[derive(Debug, thiserror::Error)]
pub enum UndistortMapsError {
    /// OpenCV failed while building the maps.
    #[error("OpenCV: {0}")]
    OpenCv(#[from] opencv::Error),
}

/// Why a frame could not be undistorted ([`Undistorter::remap_into`]).
#[derive(Debug, thiserror::Error)]
pub enum RemapError {
    /// OpenCV failed while applying the maps (or was handed a pixel format it cannot remap).
    #[error("OpenCV: {0}")]
    OpenCv(#[from] opencv::Error),
    /// OpenCV wrote the undistorted image somewhere other than the caller's buffer; the
    /// frame is not published rather than published blank.
    #[error("remap did not write into the output buffer")]
    NotInPlace,
}

/// Maps from each pixel of the ideal pinhole image (same camera matrix, no distortion) to
/// where the lens put it, as OpenCV's `initUndistortRectifyMap` computes them.
///
/// Fixed-point maps (`CV_16SC2` plus interpolation weights) rather than float maps: OpenCV
/// would otherwise convert float maps on every call, which costs about a third of `remap`.
pub struct Undistorter {
    map_xy: Mat,
    map_weights: Mat,
    width: i32,
    height: i32,
}

impl std::fmt::Debug for Undistorter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Undistorter")
            .field("width", &self.width)
            .field("height", &self.height)
            .finish()
    }
}

impl Undistorter {
    /// Computes the maps for `calibration`. The undistorted image keeps the calibration's
    /// camera matrix, so a consumer of undistorted frames uses the same intrinsics with
    /// zero distortion.
    pub fn new(calibration: &CameraCalibration) -> Result<Self, UndistortMapsError> {
        let k = calibration.camera_matrix_mat()?;
        let d = calibration.distortion_mat()?;
        let (width, height) = (calibration.width as i32, calibration.height as i32);
        let mut map_xy = Mat::default();
        let mut map_weights = Mat::default();
        calib3d::init_undistort_rectify_map(
            &k,
            &d,
            &Mat::default(),
            &k,
            Size::new(width, height),
            CV_16SC2,
            &mut map_xy,
            &mut map_weights,
        )?;
        Ok(Self {
            map_xy,
            map_weights,
            width,
            height,
        })
    }

    /// Undistorts a tightly packed 8-bit image with `channels` (1 or 3) per pixel from
    /// `input` into `out`, which must have the same length. Pixels the lens never saw
    /// are black.
    pub fn remap_into(
        &self,
        input: &[u8],
        channels: usize,
        out: &mut [u8],
    ) -> Result<(), RemapError> {
        let (w, h) = (self.width, self.height);
        match channels {
            1 => {
                let src = Mat::new_rows_cols_with_bytes::<u8>(h, w, input)?;
                let mut dst = Mat::new_rows_cols_with_bytes_mut::<u8>(h, w, out)?;
                self.remap(&src, &mut dst)
            }
            3 => {
                let src = Mat::new_rows_cols_with_bytes::<Vec3b>(h, w, input)?;
                let mut dst = Mat::new_rows_cols_with_bytes_mut::<Vec3b>(h, w, out)?;
                self.remap(&src, &mut dst)
            }
            _ => Err(RemapError::OpenCv(opencv::Error::new(
                opencv::core::StsBadArg,
                format!("{channels} channels per pixel (allowed: 1 or 3)"),
            ))),
        }
    }

    fn remap(
        &self,
        src: &impl ToInputArray,
        dst: &mut (impl ToOutputArray + MatTraitConst),
    ) -> Result<(), RemapError> {
        let before = dst.data();
        imgproc::remap(
            src,
            dst,
            &self.map_xy,
            &self.map_weights,
            imgproc::INTER_LINEAR,
            opencv::core::BORDER_CONSTANT,
            Scalar::all(0.0),
        )?;
        // `dst` has the right size and type, so OpenCV writes in place; if it ever
        // reallocated, the caller's buffer would silently keep the old pixels.
        if dst.data() != before {
            return Err(RemapError::NotInPlace);
        }
        Ok(())
    }
}

#[cfg(test)]
#[path = "undistort_test.rs"]
mod tests;
