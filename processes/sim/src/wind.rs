//! Wind: a constant mean plus seeded gusts.
//!
//! The gusts are a sum of sinusoids whose amplitudes follow a Dryden-like
//! spectrum `S(w) ~ 1 / (1 + (L w / V)^2)` (L the turbulence length scale, V
//! the mean wind speed, at least 1 m/s). It is a pure function of time, so the
//! wind at any instant is known without stepping, the same seed gives the same
//! gusts, and the lockstep and multi-process runs see the same air.

use nalgebra::Vector3;
use serde::Deserialize;

use crate::params::{self, ParamError};
use crate::rng::Pcg32;

/// Wind configuration.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WindParams {
    /// Mean wind (air velocity) in world ENU, m/s (e.g. `[5, 0, 0]` blows toward east).
    pub mean_m_s: [f64; 3],
    /// Standard deviation of the horizontal gusts per axis, m/s.
    pub gust_std_horizontal_m_s: f64,
    /// Standard deviation of the vertical gusts, m/s.
    pub gust_std_vertical_m_s: f64,
    /// Turbulence length scale L, m: larger means slower gusts.
    pub gust_length_scale_m: f64,
    /// Number of sinusoids per axis (more is smoother in spectrum, slower to evaluate).
    pub components: usize,
    /// Seed of the gust phases and frequencies.
    pub seed: u64,
}

impl Default for WindParams {
    /// Calm air.
    fn default() -> Self {
        Self {
            mean_m_s: [0.0; 3],
            gust_std_horizontal_m_s: 0.0,
            gust_std_vertical_m_s: 0.0,
            gust_length_scale_m: 50.0,
            components: 32,
            seed: 1,
        }
    }
}

impl WindParams {
    /// A steady wind without gusts.
    pub fn constant(mean_m_s: Vector3<f64>) -> Self {
        Self {
            mean_m_s: mean_m_s.into(),
            ..Self::default()
        }
    }

    /// Checks every field.
    pub fn validate(&self) -> Result<(), ParamError> {
        params::finite_all("mean_m_s", &self.mean_m_s)?;
        params::non_negative("gust_std_horizontal_m_s", self.gust_std_horizontal_m_s)?;
        params::non_negative("gust_std_vertical_m_s", self.gust_std_vertical_m_s)?;
        params::positive("gust_length_scale_m", self.gust_length_scale_m)?;
        if !(1..=1024).contains(&self.components) {
            return Err(ParamError::new(
                "components",
                self.components,
                "must be within [1, 1024]",
            ));
        }
        Ok(())
    }
}

/// One sinusoidal gust component.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Sinusoid {
    amplitude: f64,
    omega: f64,
    phase: f64,
}

/// The wind field (uniform in space, varying in time).
#[derive(Debug, Clone)]
pub struct Wind {
    mean: Vector3<f64>,
    axes: [Vec<Sinusoid>; 3],
}

impl Wind {
    /// Builds the wind from validated parameters, drawing the gust components from the seed.
    pub fn new(params: &WindParams) -> Result<Self, ParamError> {
        params.validate()?;
        let mean = Vector3::from(params.mean_m_s);
        let advection = mean.norm().max(1.0);
        let corner = advection / params.gust_length_scale_m;
        let stds = [
            params.gust_std_horizontal_m_s,
            params.gust_std_horizontal_m_s,
            params.gust_std_vertical_m_s,
        ];
        let mut axes: [Vec<Sinusoid>; 3] = Default::default();
        for (axis, (out, std)) in axes.iter_mut().zip(stds).enumerate() {
            if std == 0.0 {
                continue;
            }
            let mut rng = Pcg32::with_stream(params.seed, axis as u64 + 1);
            *out = gust_components(&mut rng, params.components, corner, std);
        }
        Ok(Self { mean, axes })
    }

    /// Calm air.
    pub fn calm() -> Self {
        Self {
            mean: Vector3::zeros(),
            axes: Default::default(),
        }
    }

    /// Wind velocity in world ENU at time `t_s`, m/s. Non-finite times give the mean.
    pub fn velocity_at(&self, t_s: f64) -> Vector3<f64> {
        if !t_s.is_finite() {
            return self.mean;
        }
        let mut v = self.mean;
        for (axis, comps) in self.axes.iter().enumerate() {
            v[axis] += comps
                .iter()
                .map(|c| c.amplitude * (c.omega * t_s + c.phase).sin())
                .sum::<f64>();
        }
        v
    }
}

/// Draws `n` sinusoids spanning 1/20 to 20 times the corner frequency
/// (log-spaced, jittered within their band, random phases), with amplitudes
/// from the Dryden-like spectrum, scaled to the standard deviation `std`.
fn gust_components(rng: &mut Pcg32, n: usize, corner: f64, std: f64) -> Vec<Sinusoid> {
    let lo = (corner / 20.0).ln();
    let hi = (corner * 20.0).ln();
    let band = (hi - lo) / n as f64;
    let mut comps: Vec<Sinusoid> = (0..n)
        .map(|k| {
            let a = lo + band * k as f64;
            let omega = (a + band * rng.uniform()).exp();
            let width = (a + band).exp() - a.exp();
            let psd = 1.0 / (1.0 + (omega / corner).powi(2));
            Sinusoid {
                amplitude: (2.0 * psd * width).sqrt(),
                omega,
                phase: std::f64::consts::TAU * rng.uniform(),
            }
        })
        .collect();
    let variance: f64 = comps.iter().map(|c| c.amplitude * c.amplitude / 2.0).sum();
    if variance > 0.0 {
        let scale = std / variance.sqrt();
        for c in comps.iter_mut() {
            c.amplitude *= scale;
        }
    }
    comps
}

#[cfg(test)]
#[path = "wind_test.rs"]
mod tests;
