use super::*;

/// A flight of `n` samples over a pad at the origin: the body moves through a box of
/// 2 x 2 x 1.5 m above it, tilting a few degrees and yawing, with its camera mounted at
/// `truth`.
fn flight(truth: &Isometry3<f64>, n: usize) -> Vec<Sample> {
    let world_from_pad = Isometry3::from_parts(
        Translation3::new(0.3, -0.2, 0.0),
        UnitQuaternion::from_euler_angles(0.0, 0.0, 0.4),
    );
    (0..n)
        .map(|i| {
            let t = i as f64 / n as f64 * std::f64::consts::TAU;
            let world_from_body = Isometry3::from_parts(
                Translation3::new(t.cos(), (2.0 * t).sin(), 1.5 + 0.75 * (3.0 * t).sin()),
                UnitQuaternion::from_euler_angles(
                    0.05 * (5.0 * t).sin(),
                    0.05 * (7.0 * t).cos(),
                    0.5 * t.sin(),
                ),
            );
            let camera_from_pad = (world_from_body * truth).inverse() * world_from_pad;
            Sample {
                at_s: i as f64 * 0.05,
                world_from_body,
                camera_from_pad,
            }
        })
        .collect()
}

fn straight_down() -> Isometry3<f64> {
    optics::down_camera_from_body([0.05, 0.0, -0.05]).inverse()
}

#[test]
fn a_mount_two_degrees_off_its_drawing_is_found_from_a_flight_over_the_pad() {
    let nominal = straight_down();
    let off = Isometry3::from_parts(
        Translation3::new(0.01, -0.01, 0.0),
        UnitQuaternion::from_euler_angles(0.03, -0.02, 0.01),
    );
    let truth = off * nominal;
    let fit = fit_mount(&flight(&truth, 200), &nominal).unwrap();
    let err = (fit.body_from_camera.rotation.inverse() * truth.rotation)
        .angle()
        .to_degrees();
    assert!(err < 0.05, "rotation {err} deg off");
    assert!(fit.rms_position_m < 1e-3, "{}", fit.rms_position_m);
}

#[test]
fn a_hover_in_place_is_too_little_motion_and_says_what_to_fly() {
    let nominal = straight_down();
    let mut samples = flight(&nominal, 100);
    for s in &mut samples {
        s.world_from_body.translation.vector *= 0.1;
        s.camera_from_pad = samples_pad(s, &nominal);
    }
    let err = fit_mount(&samples, &nominal).unwrap_err();
    assert!(err.to_string().contains("fly a box over it"), "{err}");
    assert!(matches!(
        fit_mount(&samples[..10], &nominal),
        Err(MountError::TooFewSamples(10))
    ));
}

fn samples_pad(s: &Sample, mount: &Isometry3<f64>) -> Isometry3<f64> {
    (s.world_from_body * mount).inverse()
}
