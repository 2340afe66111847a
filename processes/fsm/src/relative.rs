//! The pad's motion relative to the vehicle, straight from the camera: each observation
//! minus the position estimate it was placed in the world through, over the last fraction
//! of a second, and the slope of a line fitted to them.
//!
//! The touchdown's drop flies open loop for the 0.3-0.5 s of its fall, so whatever the
//! vehicle moves relative to the pad when it begins lands it that much off. The pad
//! filter's velocity lags a braking that has just begun by about a third of a second of it:
//! over the worst runs of the paper-speed scenarios (seed 5) the drop began with the
//! vehicle really moving 9-16 cm/s relative to the pad where the filter said 4, and
//! touched down 5-9 cm off. Low over the pad the camera's relative measurement is good
//! to millimetres between frames (its centimetre of calibration bias is the same in
//! every frame and falls out of a slope), so a line through 0.25 s of it reads the
//! relative velocity to a few millimetres per second, with no model of how the pad moves.

use std::collections::VecDeque;

use nalgebra::Vector3;

/// Fewer observations in the window than this give no velocity (a 30 Hz camera gives 7).
const MIN_POINTS: usize = 5;
/// A newest observation older than this gives no velocity, ns: the pad is out of view.
const MAX_AGE_NS: u64 = 150_000_000;
/// Enough for the window at any camera rate the stack flies (120 Hz).
const CAPACITY: usize = 64;

/// Recent relative positions `pad - vehicle` (world axes, m) at their capture times.
#[derive(Debug, Clone)]
pub struct RelativeTrack {
    points: VecDeque<(u64, Vector3<f64>)>,
    /// How far back the fit reaches, ns.
    window_ns: u64,
}

impl Default for RelativeTrack {
    /// A quarter-second line: 7-8 frames at 30 Hz.
    fn default() -> Self {
        Self::new(0.25)
    }
}

impl RelativeTrack {
    /// A track fitting its line through the last `window_s` seconds.
    pub fn new(window_s: f64) -> Self {
        Self {
            points: VecDeque::new(),
            window_ns: (window_s.max(0.0) * 1e9) as u64,
        }
    }

    /// One observation's relative position at its capture time; an older time than the
    /// newest held, or a non-finite position, is ignored.
    pub fn push(&mut self, t_ns: u64, pad_from_vehicle: Vector3<f64>) {
        if !pad_from_vehicle.iter().all(|x| x.is_finite()) {
            return;
        }
        if self.points.back().is_some_and(|&(t, _)| t_ns <= t) {
            return;
        }
        if self.points.len() == CAPACITY {
            self.points.pop_front();
        }
        self.points.push_back((t_ns, pad_from_vehicle));
        let oldest = t_ns.saturating_sub(self.window_ns);
        while self.points.front().is_some_and(|&(t, _)| t < oldest) {
            self.points.pop_front();
        }
    }

    /// Forgets every observation (a restarted pad filter: they may be of another pad).
    pub fn clear(&mut self) {
        self.points.clear();
    }

    /// The pad's velocity relative to the vehicle, m/s (least squares over the window),
    /// or None without enough fresh observations at `now_ns`.
    pub fn velocity(&self, now_ns: u64) -> Option<Vector3<f64>> {
        let &(newest, _) = self.points.back()?;
        if now_ns.saturating_sub(newest) > MAX_AGE_NS || self.points.len() < MIN_POINTS {
            return None;
        }
        let n = self.points.len() as f64;
        let secs = |t: u64| t.saturating_sub(self.points[0].0) as f64 * 1e-9;
        let t_mean = self.points.iter().map(|&(t, _)| secs(t)).sum::<f64>() / n;
        let r_mean = self.points.iter().map(|&(_, r)| r).sum::<Vector3<f64>>() / n;
        let mut stt = 0.0;
        let mut str_ = Vector3::zeros();
        for &(t, r) in &self.points {
            let dt = secs(t) - t_mean;
            stt += dt * dt;
            str_ += (r - r_mean) * dt;
        }
        let v = str_ / stt;
        (stt > 0.0 && v.iter().all(|x| x.is_finite())).then_some(v)
    }
}

#[cfg(test)]
#[path = "relative_test.rs"]
mod tests;
