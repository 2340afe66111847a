//! Boxes in world ENU: axis-aligned obstacles ([`Aabb`], as scenarios give them) and
//! boxes in any orientation ([`Obb`]: the ground vehicle's body, an obstacle seen by the
//! depth camera). Below the world, the ground vehicle and the depth camera, which all
//! use them.

use nalgebra::{Isometry3, Vector3};
use serde::Deserialize;

use crate::params::{self, ParamError};

/// An axis-aligned box obstacle in world ENU.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Aabb {
    /// Lowest corner (x, y, z), m.
    pub min_m: [f64; 3],
    /// Highest corner (x, y, z), m.
    pub max_m: [f64; 3],
}

impl Aabb {
    /// True if a sphere of `radius` around `centre` touches or enters the box.
    pub fn intersects_sphere(&self, centre: &Vector3<f64>, radius: f64) -> bool {
        let mut d2 = 0.0;
        for i in 0..3 {
            let c = centre[i].clamp(self.min_m[i], self.max_m[i]);
            d2 += (centre[i] - c).powi(2);
        }
        d2 <= radius * radius
    }

    pub(crate) fn validate(&self, index: usize) -> Result<(), ParamError> {
        for i in 0..3 {
            params::finite(&format!("obstacles[{index}].min_m[{i}]"), self.min_m[i])?;
            params::finite(&format!("obstacles[{index}].max_m[{i}]"), self.max_m[i])?;
            if self.max_m[i] < self.min_m[i] {
                return Err(ParamError::new(
                    format!("obstacles[{index}].max_m[{i}]"),
                    self.max_m[i],
                    format!("must be >= min_m[{i}] ({})", self.min_m[i]),
                ));
            }
        }
        Ok(())
    }
}

/// A box in any orientation: the ground vehicle's body, or an obstacle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Obb {
    /// Pose of the box centre; the box's axes are its frame's axes.
    pub world_from_box: Isometry3<f64>,
    /// Half the size along the box's x, y, z, m.
    pub half_m: [f64; 3],
}

impl Obb {
    /// The eight corners in world (bit 0 of the index picks +x, bit 1 +y, bit 2 +z).
    pub fn corners(&self) -> [nalgebra::Point3<f64>; 8] {
        let h = self.half_m;
        std::array::from_fn(|k| {
            let sign = |bit: usize, half: f64| if k & bit == 0 { -half } else { half };
            self.world_from_box * nalgebra::Point3::new(sign(1, h[0]), sign(2, h[1]), sign(4, h[2]))
        })
    }

    /// True if a sphere of `radius` around `centre` touches or enters the box.
    pub fn intersects_sphere(&self, centre: &Vector3<f64>, radius: f64) -> bool {
        let local = self
            .world_from_box
            .inverse_transform_point(&(*centre).into());
        let mut d2 = 0.0;
        for i in 0..3 {
            let c = local[i].clamp(-self.half_m[i], self.half_m[i]);
            d2 += (local[i] - c).powi(2);
        }
        d2 <= radius * radius
    }
}

impl From<&Aabb> for Obb {
    fn from(b: &Aabb) -> Self {
        let centre = Vector3::from_fn(|i, _| (b.min_m[i] + b.max_m[i]) / 2.0);
        Self {
            world_from_box: Isometry3::translation(centre.x, centre.y, centre.z),
            half_m: std::array::from_fn(|i| (b.max_m[i] - b.min_m[i]) / 2.0),
        }
    }
}
