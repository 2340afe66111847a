//! Tests of `params`.

use super::*;

#[test]
fn error_names_the_field_value_and_rule() {
    let e = positive("mass_kg", -1.0).unwrap_err();
    assert_eq!(e.to_string(), "mass_kg = -1: must be > 0");
}

#[test]
fn nan_is_rejected_by_every_check() {
    assert!(positive("a", f64::NAN).is_err());
    assert!(non_negative("a", f64::NAN).is_err());
    assert!(finite("a", f64::NAN).is_err());
    assert!(in_range("a", f64::NAN, 0.0, 1.0).is_err());
    assert!(finite_all("a", &[0.0, f64::INFINITY]).is_err());
}
