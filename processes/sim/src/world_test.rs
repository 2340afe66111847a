//! Tests of `world`.

use super::*;

#[test]
fn sphere_box_intersection_uses_the_closest_point() {
    let b = Aabb {
        min_m: [0.0, 0.0, 0.0],
        max_m: [1.0, 1.0, 1.0],
    };
    assert!(b.intersects_sphere(&Vector3::new(0.5, 0.5, 0.5), 0.1));
    assert!(b.intersects_sphere(&Vector3::new(1.2, 0.5, 0.5), 0.25));
    assert!(!b.intersects_sphere(&Vector3::new(1.2, 1.2, 0.5), 0.25));
    assert!(b.intersects_sphere(&Vector3::new(1.15, 1.15, 0.5), 0.25));
}

#[test]
fn parameter_errors_name_their_section() {
    let p = WorldParams {
        airframe: AirframeParams {
            mass_kg: -1.0,
            ..AirframeParams::default()
        },
        ..WorldParams::default()
    };
    let e = World::new(p).unwrap_err().to_string();
    assert_eq!(e, "airframe.mass_kg = -1: must be > 0");
}

#[test]
fn steps_longer_than_2_ms_or_empty_are_rejected() {
    let mut w = World::new(WorldParams::default()).unwrap();
    assert!(matches!(w.step(0), Err(WorldError::InvalidStep(0))));
    assert!(w.step(MAX_STEP_NS + 1).is_err());
    assert!(w.step(MAX_STEP_NS).is_ok());
    assert_eq!(w.time_ns(), MAX_STEP_NS);
}
