//! ArUco marker detection, tuned for the pad and restricted to where the pad is.
//!
//! OpenCV's `detectMarkers` spends its time thresholding and tracing contours over the
//! whole frame three times (three adaptive-threshold windows). The pad's markers in
//! their active ranges are 14-60 px wide, so one window sized for them finds them, and
//! when the pad was seen in the previous frame only the region around it needs looking
//! at (the ArUco3 idea of reusing the last detection). Corners are refined per marker
//! with a window scaled to its bit cell: OpenCV's fixed 5 px window reaches across the
//! inner bit corners of a 15 px marker and drags its corners.

use nalgebra::Point2;
use opencv::aruco;
use opencv::core::{Mat, MatTraitConst, Point2f, Ptr, Rect, Size, TermCriteria, Vector};
use opencv::imgproc;
use opencv::prelude::*;
use thiserror::Error;

/// Why a frame could not be searched.
#[derive(Debug, Error)]
pub enum DetectError {
    /// OpenCV failed.
    #[error("detect: {0}")]
    OpenCv(#[from] opencv::Error),
}

/// One decoded marker.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Marker {
    /// Dictionary id.
    pub id: u32,
    /// Corners in full-frame pixels, OpenCV's ArUco order (top-left, top-right,
    /// bottom-right, bottom-left of the marker as printed).
    pub corners: [Point2<f64>; 4],
}

impl Marker {
    /// Mean side length, px.
    pub fn side_px(&self) -> f64 {
        (0..4)
            .map(|k| (self.corners[k] - self.corners[(k + 1) % 4]).norm())
            .sum::<f64>()
            / 4.0
    }
}

/// Detector settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectSettings {
    /// Smallest marker side worth decoding, px (smaller ones are too coarse to
    /// decode reliably and are never in their active range).
    pub min_marker_px: f64,
    /// Adaptive threshold window, px (odd). One window, sized for 14-60 px markers.
    pub threshold_window_px: i32,
}

impl Default for DetectSettings {
    fn default() -> Self {
        Self {
            min_marker_px: 10.0,
            threshold_window_px: 13,
        }
    }
}

/// Side in px a marker keeps in the downscaled image ArUco3 searches.
const CANONICAL_PX: i32 = 20;

/// ARUCO_ORIGINAL detection with the pad's settings.
pub struct Detector {
    dictionary: Ptr<aruco::Dictionary>,
    params: Ptr<aruco::DetectorParameters>,
    settings: DetectSettings,
    corners: Vector<Vector<Point2f>>,
    ids: Vector<i32>,
    rejected: Vector<Vector<Point2f>>,
}

impl std::fmt::Debug for Detector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Detector")
            .field("settings", &self.settings)
            .finish_non_exhaustive()
    }
}

impl Detector {
    /// Builds the dictionary and the detector parameters once.
    pub fn new(settings: DetectSettings) -> Result<Self, DetectError> {
        let dictionary = aruco::get_predefined_dictionary(
            aruco::PREDEFINED_DICTIONARY_NAME::DICT_ARUCO_ORIGINAL,
        )?;
        let mut params = aruco::DetectorParameters::create()?;
        let w = settings.threshold_window_px.max(3) | 1;
        params.set_adaptive_thresh_win_size_min(w);
        params.set_adaptive_thresh_win_size_max(w);
        params.set_adaptive_thresh_win_size_step(10);
        params.set_corner_refinement_method(aruco::CORNER_REFINE_NONE);
        Ok(Self {
            dictionary,
            params,
            settings,
            corners: Vector::new(),
            ids: Vector::new(),
            rejected: Vector::new(),
        })
    }

    /// Detects markers in `region` of the mono8 `image` (the whole image when `None`);
    /// corners come back in full-frame pixels, refined to subpixel.
    pub fn detect(
        &mut self,
        image: &impl MatTraitConst,
        region: Option<Rect>,
        smallest_px: Option<f64>,
    ) -> Result<Vec<Marker>, DetectError> {
        let full = Rect::new(0, 0, image.cols(), image.rows());
        let region = region.map_or(full, |r| r & full);
        if region.width < 8 || region.height < 8 {
            return Ok(Vec::new());
        }
        let view = Mat::roi(image, region)?;
        // Perimeter rate is relative to the larger side of the searched image.
        let longest = f64::from(region.width.max(region.height));
        self.params
            .set_min_marker_perimeter_rate((4.0 * self.settings.min_marker_px / longest).min(1.0));
        // ArUco3: when the smallest marker expected is large, OpenCV thresholds and
        // traces a downscaled image in which it is still `min_side_length_canonical_img`
        // px (our edge refinement then places the corners at full resolution). Asked for
        // around a 40-80 px marker it found nothing in the search region (the whole frame
        // was searched again, ten times the time: tests/tracking.rs), so only from 80 px.
        match smallest_px.filter(|s| *s > 4.0 * f64::from(CANONICAL_PX)) {
            Some(s) => {
                self.params.set_use_aruco3_detection(true);
                self.params.set_min_side_length_canonical_img(CANONICAL_PX);
                self.params
                    .set_min_marker_length_ratio_original_img((0.7 * s / longest).min(1.0) as f32);
            }
            None => {
                self.params.set_use_aruco3_detection(false);
                self.params.set_min_marker_length_ratio_original_img(0.0);
            }
        }
        self.corners.clear();
        self.ids.clear();
        self.rejected.clear();
        aruco::detect_markers(
            &view,
            &self.dictionary,
            &mut self.corners,
            &mut self.ids,
            &self.params,
            &mut self.rejected,
        )?;
        let criteria = TermCriteria::new(3, 20, 0.01)?;
        let mut out = Vec::with_capacity(self.ids.len());
        for (id, mut c) in self.ids.iter().zip(self.corners.iter()) {
            if c.len() != 4 || id < 0 {
                continue;
            }
            let mut pts = [Point2::origin(); 4];
            for (k, p) in c.iter().enumerate().take(4) {
                pts[k] = Point2::new(f64::from(p.x), f64::from(p.y));
            }
            let marker = Marker {
                id: id as u32,
                corners: pts,
            };
            // About a third of a bit cell (7 cells a side), at least 1 px.
            let win = ((marker.side_px() / 7.0 / 3.0).round() as i32).clamp(1, 5);
            imgproc::corner_sub_pix(
                &view,
                &mut c,
                Size::new(win, win),
                Size::new(-1, -1),
                criteria,
            )?;
            let (ox, oy) = (f64::from(region.x), f64::from(region.y));
            let mut corners = [Point2::origin(); 4];
            for (k, p) in c.iter().enumerate().take(4) {
                corners[k] = Point2::new(f64::from(p.x) + ox, f64::from(p.y) + oy);
            }
            if corners.iter().all(|p| p.x.is_finite() && p.y.is_finite()) {
                out.push(Marker {
                    id: id as u32,
                    corners,
                });
            }
        }
        Ok(out)
    }
}
