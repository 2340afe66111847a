//! Parameter validation shared by every configurable part of the simulator.
//!
//! A rejected parameter must tell the user which field is wrong, what value it
//! had and what is allowed, so a scenario file can be fixed without reading code.

use thiserror::Error;

/// A configuration value outside its allowed range.
///
/// Displayed as `mass_kg = -1: must be > 0` so the message points straight at
/// the line of the scenario file to fix.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{field} = {value}: {allowed}")]
pub struct ParamError {
    /// The field name as written in the configuration (with its section when useful).
    pub field: String,
    /// The offending value, formatted.
    pub value: String,
    /// What the field accepts.
    pub allowed: String,
}

impl ParamError {
    /// Builds an error for `field` holding `value` that should satisfy `allowed`.
    pub fn new(field: impl Into<String>, value: impl ToString, allowed: impl Into<String>) -> Self {
        Self {
            field: field.into(),
            value: value.to_string(),
            allowed: allowed.into(),
        }
    }
}

/// Requires a finite value strictly above zero.
pub(crate) fn positive(field: &str, value: f64) -> Result<(), ParamError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(ParamError::new(field, value, "must be > 0"))
    }
}

/// Requires a finite value at or above zero.
pub(crate) fn non_negative(field: &str, value: f64) -> Result<(), ParamError> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(ParamError::new(field, value, "must be >= 0"))
    }
}

/// Requires any finite value.
pub(crate) fn finite(field: &str, value: f64) -> Result<(), ParamError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(ParamError::new(field, value, "must be finite"))
    }
}

/// Requires a finite value within `[lo, hi]`.
pub(crate) fn in_range(field: &str, value: f64, lo: f64, hi: f64) -> Result<(), ParamError> {
    if value.is_finite() && value >= lo && value <= hi {
        Ok(())
    } else {
        Err(ParamError::new(
            field,
            value,
            format!("must be within [{lo}, {hi}]"),
        ))
    }
}

/// Requires every component of a vector to be finite.
pub(crate) fn finite_all(field: &str, values: &[f64]) -> Result<(), ParamError> {
    for (i, v) in values.iter().enumerate() {
        finite(&format!("{field}[{i}]"), *v)?;
    }
    Ok(())
}

#[cfg(test)]
#[path = "params_test.rs"]
mod tests;
