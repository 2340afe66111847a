//! The frame the pad filter runs in: the vehicle's estimated velocity integrated.
//!
//! The autopilot's position estimate carries centimetres of fast noise (VIO-fed EKF, about
//! 2 cm per axis in the simulator); every pad observation is placed in the world through
//! that estimate at its capture time, and the fsm compares the pad estimate with the
//! estimate at a later time. Both noises add up in "how far off the pad am I" and a 4 cm
//! touchdown gate fires on lucky samples (outdoor-2: 2-6 cm of error in that offset at the
//! start of the drop). Integrated velocity is smooth: observations placed through it keep
//! only the camera's error, and the pad estimate handed out is shifted back by the current
//! offset between the estimate and the odometry, so `pad - vehicle` is the camera's
//! relative measurement and the autopilot, which steers by the same estimate, flies it.

use std::collections::VecDeque;

use nalgebra::Vector3;

/// How many offsets are kept: 2.5 s of 100 Hz telemetry, older than any observation the
/// filter accepts (`pad_filter.max_age_s`).
const CAPACITY: usize = 256;

/// The integrated velocity and the recent offsets `estimate - odometry`.
#[derive(Debug, Clone, Default)]
pub struct Odometry {
    /// Time and estimated velocity of the newest state.
    last: Option<(u64, Vector3<f64>)>,
    /// The odometry at that state.
    odometry: Vector3<f64>,
    /// (time ns, estimate - odometry, estimate), in time order.
    offsets: VecDeque<(u64, Vector3<f64>, Vector3<f64>)>,
}

impl Odometry {
    /// Takes in a vehicle state (finite, checked by the caller) at its time `t_ns`; a state
    /// not newer than the last one (a repeat) changes nothing.
    pub fn on_state(&mut self, t_ns: u64, position: Vector3<f64>, velocity: Vector3<f64>) {
        match self.last {
            Some((t0, _)) if t_ns <= t0 => return,
            Some((t0, v0)) => {
                let dt = (t_ns - t0) as f64 * 1e-9;
                self.odometry += 0.5 * (v0 + velocity) * dt;
            }
            None => self.odometry = position,
        }
        self.last = Some((t_ns, velocity));
        if self.offsets.len() == CAPACITY {
            self.offsets.pop_front();
        }
        self.offsets
            .push_back((t_ns, position - self.odometry, position));
    }

    /// `estimate - odometry` at `t_ns`, interpolated between the states around it (the
    /// oldest or newest one outside them); zero before any state.
    pub fn offset_at(&self, t_ns: u64) -> Vector3<f64> {
        self.at(t_ns, |&(_, d, _)| d)
    }

    /// The position estimate at `t_ns`, interpolated as [`Self::offset_at`]: what a pad
    /// observation placed in the world through, so that subtracting it leaves the camera's
    /// own relative measurement.
    pub fn position_at(&self, t_ns: u64) -> Vector3<f64> {
        self.at(t_ns, |&(_, _, p)| p)
    }

    fn at(
        &self,
        t_ns: u64,
        field: impl Fn(&(u64, Vector3<f64>, Vector3<f64>)) -> Vector3<f64>,
    ) -> Vector3<f64> {
        let i = self.offsets.partition_point(|&(t, _, _)| t <= t_ns);
        match (
            i.checked_sub(1).and_then(|k| self.offsets.get(k)),
            self.offsets.get(i),
        ) {
            (Some(a), Some(b)) => {
                let w = (t_ns - a.0) as f64 / (b.0 - a.0).max(1) as f64;
                field(a) + (field(b) - field(a)) * w
            }
            (Some(a), None) | (None, Some(a)) => field(a),
            (None, None) => Vector3::zeros(),
        }
    }

    /// `estimate - odometry` at the newest state.
    pub fn offset_now(&self) -> Vector3<f64> {
        self.offsets
            .back()
            .map_or_else(Vector3::zeros, |&(_, d, _)| d)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_noisy_estimate_over_a_steady_flight_leaves_the_odometry_smooth() {
        let mut o = Odometry::default();
        let v = Vector3::new(1.0, 0.0, 0.0);
        for k in 0..100u64 {
            let t = k * 10_000_000;
            // The odometry starts at the first estimate: noise-free here.
            let noise = match k {
                0 => 0.0,
                k if k % 2 == 0 => 0.02,
                _ => -0.02,
            };
            o.on_state(t, Vector3::new(k as f64 * 0.01 + noise, 0.0, 0.0), v);
            let d = o.offset_now();
            assert!((d.x - noise).abs() < 1e-9, "offset {d} at {k}");
        }
    }

    #[test]
    fn offsets_between_states_are_interpolated_and_repeats_ignored() {
        let mut o = Odometry::default();
        o.on_state(0, Vector3::zeros(), Vector3::zeros());
        o.on_state(10, Vector3::new(0.1, 0.0, 0.0), Vector3::zeros());
        o.on_state(10, Vector3::new(9.0, 0.0, 0.0), Vector3::zeros());
        assert!((o.offset_at(5).x - 0.05).abs() < 1e-12);
        assert!((o.offset_at(50).x - 0.1).abs() < 1e-12);
        assert_eq!(Odometry::default().offset_at(5), Vector3::zeros());
    }
}
