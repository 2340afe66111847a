//! The seeded random pillar fields `landing bench planner` plans through (and the
//! `hard_maps` example counts work on): the same maps on every machine, in one place.

use nalgebra::Vector3;

use crate::map::{Aabb, GridMap, MapError};

/// Where every field's plan starts, m.
pub const FIELD_START: [f64; 3] = [0.0, 0.0, 1.0];
/// Where every field's plan ends (10 m from the start), m.
pub const FIELD_GOAL: [f64; 3] = [10.0, 0.0, 1.0];
/// Pillar densities of the benchmark, per m^2 of the field.
pub const FIELD_DENSITIES: [f64; 4] = [0.05, 0.1, 0.15, 0.2];

/// xorshift64*: a tiny seeded generator, so the fields are the same on every machine.
#[derive(Debug, Clone)]
pub struct FieldRng(u64);

impl FieldRng {
    /// A generator for `seed` (any value; 0 is fine).
    pub fn new(seed: u64) -> Self {
        Self(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }

    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// The next field: x 1..9, y -4..4 (64 m^2), `density` pillars per m^2, each 0.3 x 0.3 m
/// and floor to ceiling (3 m), none within 1 m of the start or the goal; mapped at
/// `resolution` with `inflation`.
pub fn pillar_field(
    rng: &mut FieldRng,
    density: f64,
    resolution: f64,
    inflation: f64,
) -> Result<GridMap, MapError> {
    let flat = |p: [f64; 3]| Vector3::new(p[0], p[1], 0.0);
    let (start, goal) = (flat(FIELD_START), flat(FIELD_GOAL));
    let count = (density * 64.0).round().max(0.0) as usize;
    let mut boxes = Vec::with_capacity(count);
    while boxes.len() < count {
        let c = Vector3::new(1.0 + 8.0 * rng.uniform(), -4.0 + 8.0 * rng.uniform(), 0.0);
        if (c - start).norm() < 1.0 || (c - goal).norm() < 1.0 {
            continue;
        }
        let w = 0.15;
        boxes.push(Aabb {
            min: Vector3::new(c.x - w, c.y - w, 0.0),
            max: Vector3::new(c.x + w, c.y + w, 3.0),
        });
    }
    GridMap::from_boxes(
        Vector3::new(-1.0, -5.0, 0.0),
        Vector3::new(11.0, 5.0, 3.0),
        resolution,
        inflation,
        &boxes,
    )
}
