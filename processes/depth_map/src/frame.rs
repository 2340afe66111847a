//! A depth frame as the mapper reads it: borrowed depths, their layout and the pinhole
//! model, checked once so that the hot loop never meets an inconsistent frame.

use ipc_types::msg::{DepthFrameHeader, Intrinsics};

use crate::DepthError;

/// The depths of one frame, borrowed from wherever they live (a shared-memory sample, a
/// renderer's buffer, a decoded recording).
#[derive(Debug, Clone, Copy)]
pub enum DepthPixels<'a> {
    /// Integer depths along the optical axis, `scale_m` metres per unit (Z16 as a D435
    /// and the simulator deliver it: 0.001). 0 = no return; `u16::MAX` = saturated,
    /// treated as invalid.
    U16 {
        /// Row-major, `width * height` values.
        data: &'a [u16],
        /// Metres per unit.
        scale_m: f32,
    },
    /// Depths in metres along the optical axis (32FC1 as some drivers and recordings
    /// deliver it). 0 = no return; NaN, infinite or negative = invalid.
    F32(&'a [f32]),
}

impl DepthPixels<'_> {
    /// Number of depth values.
    pub fn len(&self) -> usize {
        match self {
            Self::U16 { data, .. } => data.len(),
            Self::F32(d) => d.len(),
        }
    }

    /// True when there is no depth value at all.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A depth image with its geometry. Build it with [`DepthView::new`] or
/// [`DepthView::from_wire`], which check that the numbers agree with each other.
#[derive(Debug, Clone, Copy)]
pub struct DepthView<'a> {
    width: u32,
    height: u32,
    intrinsics: Intrinsics,
    pixels: DepthPixels<'a>,
}

impl<'a> DepthView<'a> {
    /// Checks and wraps a frame: positive size, `width * height` depths, finite positive
    /// focal lengths and scale, finite principal point.
    pub fn new(
        width: u32,
        height: u32,
        intrinsics: Intrinsics,
        pixels: DepthPixels<'a>,
    ) -> Result<Self, DepthError> {
        if width == 0 || height == 0 {
            return Err(DepthError::BadHeader("zero width or height"));
        }
        let want = (width as usize)
            .checked_mul(height as usize)
            .ok_or(DepthError::BadHeader("width * height overflows"))?;
        if pixels.len() != want {
            return Err(DepthError::PayloadLength {
                got: pixels.len(),
                want,
                width,
                height,
            });
        }
        let Intrinsics { fx, fy, cx, cy } = intrinsics;
        if !(fx.is_finite() && fy.is_finite() && fx > 0.0 && fy > 0.0) {
            return Err(DepthError::BadHeader(
                "focal lengths must be finite and positive",
            ));
        }
        if !(cx.is_finite() && cy.is_finite()) {
            return Err(DepthError::BadHeader("principal point must be finite"));
        }
        if let DepthPixels::U16 { scale_m, .. } = pixels
            && !(scale_m.is_finite() && scale_m > 0.0 && scale_m <= 1.0)
        {
            return Err(DepthError::BadHeader(
                "depth scale must be finite, above 0 and at most 1 m per unit",
            ));
        }
        Ok(Self {
            width,
            height,
            intrinsics,
            pixels,
        })
    }

    /// The frame a shared-memory sample holds (`landing/sim/depth`,
    /// `landing/depth/frame`), if its header agrees with its payload.
    pub fn from_wire(header: &DepthFrameHeader, payload: &'a [u16]) -> Result<Self, DepthError> {
        let scale = header.depth_scale_m;
        if !(scale.is_finite() && scale > 0.0 && scale <= 1.0) {
            return Err(DepthError::BadHeader(
                "depth scale must be finite, above 0 and at most 1 m per unit",
            ));
        }
        Self::new(
            header.width,
            header.height,
            header.intrinsics,
            DepthPixels::U16 {
                data: payload,
                scale_m: scale as f32,
            },
        )
    }

    /// Width, px.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height, px.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The pinhole model of the depth image.
    pub fn intrinsics(&self) -> Intrinsics {
        self.intrinsics
    }

    /// The depths.
    pub fn pixels(&self) -> DepthPixels<'a> {
        self.pixels
    }
}

#[cfg(test)]
#[path = "frame_test.rs"]
mod tests;
