//! Tests of `stack_config`.

use super::*;
use serde::Deserialize;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Inner {
    rate_hz: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Cfg {
    camera: Inner,
}

impl Validate for Cfg {
    fn validate(&self) -> Result<(), Invalid> {
        check_range("rate_hz", self.camera.rate_hz, 1.0, 120.0).map_err(|e| e.under("camera"))
    }
}

fn err(text: &str) -> String {
    parse::<Cfg>(text, Path::new("cam.toml"))
        .map(|_| ())
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default()
}

#[test]
fn a_wrong_key_names_the_file_the_key_and_the_allowed_keys() {
    let e = err("[camera]\nrate_hz = 30.0\nfps = 3\n");
    assert!(e.starts_with("config cam.toml: key `camera"), "{e}");
    assert!(e.contains("fps") && e.contains("rate_hz"), "{e}");
    assert!(!e.contains('\n'));
}

#[test]
fn a_wrong_type_names_the_key_and_the_expected_type() {
    let e = err("[camera]\nrate_hz = \"fast\"\n");
    assert!(e.contains("key `camera.rate_hz`"), "{e}");
    assert!(e.contains("expected"), "{e}");
    assert!(!e.contains('\n'));
}

#[test]
fn an_out_of_range_value_names_the_range() {
    let e = err("[camera]\nrate_hz = 500.0\n");
    assert_eq!(
        e,
        "config cam.toml: key `camera.rate_hz`: 500 is out of range (allowed: 1 to 120)"
    );
}

#[test]
fn nan_is_out_of_every_range() {
    assert!(check_range("x", f64::NAN, 0.0, 1.0).is_err());
}

#[test]
fn a_syntax_error_names_the_line() {
    let e = err("[camera]\nrate_hz = = 3\n");
    assert!(e.starts_with("config cam.toml: line 2:"), "{e}");
}

#[test]
fn a_missing_file_is_a_read_error() {
    let e = load::<Cfg>(Path::new("/nonexistent/cam.toml"))
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(
        e.starts_with("config /nonexistent/cam.toml: cannot read"),
        "{e}"
    );
}

#[test]
fn prefixes_reject_path_characters() {
    assert!(is_valid_prefix("run_1-a.b"));
    assert!(is_valid_prefix(DEFAULT_PREFIX));
    assert!(!is_valid_prefix("../x"));
    assert!(!is_valid_prefix(""));
    assert!(!is_valid_prefix(&"a".repeat(33)));
}
