use ipc_types::msg::{Header, PadObservation, Pose};
use nalgebra::Vector3;

use super::{PadFilter, Update};
use crate::config::PadFilterConfig;

const FRAME_NS: u64 = 33_333_333;

/// An observation of the pad at `at`, captured at `t_ns`, from 0.5 m.
fn observation(t_ns: u64, at: Vector3<f64>) -> PadObservation {
    PadObservation {
        msg: Header::captured_at(t_ns),
        camera_from_pad: Pose {
            translation: [0.0, 0.0, 0.5],
            rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
        },
        world_from_pad: Pose {
            translation: at.into(),
            rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
        },
        world_valid: 1,
        marker_count: 4,
        ..PadObservation::default()
    }
}

/// A deterministic +-1 cm jitter, as PnP's at half a metre.
fn jitter(k: u64) -> Vector3<f64> {
    let h = |s: u64| ((k.wrapping_mul(2_654_435_761).wrapping_add(s) % 2001) as f64 / 1000.0) - 1.0;
    Vector3::new(h(17), h(91), h(5)) * 0.01
}

/// Feeds the filter a pad moving along x, `speed(t)` m/s, for `seconds`; returns the
/// time of the last frame.
fn fly(f: &mut PadFilter, seconds: f64, speed: impl Fn(f64) -> f64) -> u64 {
    let mut x = 0.0;
    let frames = (seconds * 1e9 / FRAME_NS as f64) as u64;
    let mut t = 0;
    for k in 0..frames {
        t = k * FRAME_NS;
        let ts = t as f64 * 1e-9;
        x += speed(ts) * FRAME_NS as f64 * 1e-9;
        let u = f.update(
            t + 30_000_000,
            &observation(t, Vector3::new(x, 0.0, 0.4) + jitter(k)),
        );
        assert!(
            matches!(u, Update::Accepted | Update::Started),
            "frame {k}: {u:?}"
        );
    }
    t
}

#[test]
fn a_braking_pad_is_followed_without_the_constant_velocity_lag() {
    // 1 m/s, then 0.45 m/s^2 of braking from 4 s: a constant-velocity filter of the same
    // noise trails it by about 0.17 m/s.
    let braking = |t: f64| {
        if t < 4.0 {
            1.0
        } else {
            (1.0 - 0.45 * (t - 4.0)).max(0.0)
        }
    };
    let mut f = PadFilter::new(PadFilterConfig::default());
    let t = fly(&mut f, 5.0, braking);
    let est = f.estimate(t).expect("an estimate");
    let truth = braking(t as f64 * 1e-9);
    assert!(
        (est.velocity.x - truth).abs() < 0.08,
        "velocity {:.3} against {truth:.3}",
        est.velocity.x
    );
    assert!(
        est.acceleration.x < -0.2,
        "acceleration {:.3}",
        est.acceleration.x
    );
    assert!(
        est.manoeuvre_acceleration.x < -0.35,
        "manoeuvre acceleration {:.3}",
        est.manoeuvre_acceleration.x
    );
}

#[test]
fn a_cruising_pad_shows_no_acceleration() {
    let mut f = PadFilter::new(PadFilterConfig::default());
    let t = fly(&mut f, 6.0, |_| 0.9);
    let est = f.estimate(t).expect("an estimate");
    assert!(
        (est.velocity.x - 0.9).abs() < 0.05,
        "velocity {:.3}",
        est.velocity.x
    );
    assert!(
        est.acceleration.xy().norm() < 0.1,
        "acceleration {:?}",
        est.acceleration
    );
    let m = est.manoeuvre_acceleration.xy().norm();
    assert!(m < 0.1, "manoeuvre acceleration {m:.3}");
}

#[test]
fn a_long_extrapolation_carries_the_velocity_not_the_acceleration() {
    // Lost two seconds into a braking: the pad stops, it does not reverse.
    let braking = |t: f64| {
        if t < 3.0 {
            1.0
        } else {
            (1.0 - 0.5 * (t - 3.0)).max(0.0)
        }
    };
    let mut f = PadFilter::new(PadFilterConfig::default());
    let t = fly(&mut f, 4.0, braking);
    let now = f.estimate(t).expect("an estimate");
    let later = f.estimate(t + 2_000_000_000).expect("an estimate");
    let moved = later.position.x - now.position.x;
    assert!(
        moved > 0.0,
        "the extrapolation went backwards: {moved:.3} m"
    );
    assert!(later.position.iter().all(|c| c.is_finite()));
}

/// The filter turning its velocity at the heading rate below the chase speed (2 m/s).
fn turning() -> PadFilterConfig {
    PadFilterConfig {
        turn_with_heading_below_m_s: 2.0,
        ..PadFilterConfig::default()
    }
}

/// Feeds the filter a pad driving a left circle of `radius` m at `speed` m/s, heading
/// along its velocity, for `seconds`; returns the angle its estimated velocity trails the
/// true one by at the end, rad (positive: behind the turn).
fn circle(cfg: PadFilterConfig, speed: f64, radius: f64, seconds: f64) -> f64 {
    let mut f = PadFilter::new(cfg);
    let w = speed / radius;
    let frames = (seconds * 1e9 / FRAME_NS as f64) as u64;
    let mut t = 0;
    for k in 0..frames {
        t = k * FRAME_NS;
        let a = w * t as f64 * 1e-9;
        let at = Vector3::new(radius * a.sin(), radius * (1.0 - a.cos()), 0.4) + jitter(k);
        let mut obs = observation(t, at);
        obs.world_from_pad.rotation_xyzw = [0.0, 0.0, (0.5 * a).sin(), (0.5 * a).cos()];
        f.update(t + 30_000_000, &obs);
    }
    let est = f.estimate(t + 30_000_000).expect("an estimate");
    let heading = w * (t + 30_000_000) as f64 * 1e-9;
    super::wrap(heading - est.velocity.y.atan2(est.velocity.x))
}

#[test]
fn a_pad_on_a_curve_is_followed_by_its_heading_without_the_models_lag() {
    // paper-turn's curve: 0.9 m/s on a 3 m radius. The Cartesian models alone trail the
    // velocity's direction by 2.1 deg here, turned at the heading rate 0.9.
    let with = circle(turning(), 0.9, 3.0, 5.0);
    let without = circle(PadFilterConfig::default(), 0.9, 3.0, 5.0);
    assert!(
        with.abs() < 1.5f64.to_radians(),
        "with the heading: {:.2} deg behind",
        with.to_degrees()
    );
    assert!(
        without > 2.0 * with.abs(),
        "without it: {:.2} deg behind, with it {:.2}",
        without.to_degrees(),
        with.to_degrees()
    );
}

#[test]
fn a_fast_pad_is_not_turned_by_its_heading() {
    // Above the chase speed the chase's own turn feed-forward follows a curve: the
    // filter's velocity is the Cartesian models' alone.
    let off = PadFilterConfig::default();
    let (fast, plain) = (
        circle(turning(), 8.0, 60.0, 4.0),
        circle(off, 8.0, 60.0, 4.0),
    );
    assert!((fast - plain).abs() < 1e-12, "{fast} against {plain}");
}

#[test]
fn the_time_a_heading_was_measured_counts_what_was_seen_not_the_gaps() {
    // A pad glimpsed for a third of a second, out of view for two, then seen again for a
    // second: its heading was measured for about 1.3 s, not the 3.3 s the track spans.
    let mut f = PadFilter::new(PadFilterConfig::default());
    let mut t = 0;
    let mut seen = |f: &mut PadFilter, from: u64, frames: u64| {
        for k in 0..frames {
            t = from + k * FRAME_NS;
            let x = 10.0 * t as f64 * 1e-9;
            f.update(t, &observation(t, Vector3::new(x, 0.0, 0.4)));
        }
        t
    };
    let end = seen(&mut f, 0, 10);
    let glimpse = f.estimate(end).map(|e| e.heading_seen_s);
    assert!(
        glimpse.is_some_and(|s| (0.25..0.35).contains(&s)),
        "{glimpse:?}"
    );
    let end = seen(&mut f, end + 2_000_000_000, 31);
    let both = f.estimate(end).map(|e| e.heading_seen_s);
    assert!(both.is_some_and(|s| (1.2..1.35).contains(&s)), "{both:?}");
}
