use std::path::{Path, PathBuf};

use stack_config::{self as config, ConfigError};

use super::*;

fn parse(text: &str) -> Result<IngestFileConfig, ConfigError> {
    config::parse(text, Path::new("landing.toml"))
}

#[test]
fn without_a_section_camera_ingest_reads_the_simulator() {
    let c =
        parse("[ipc]\nprefix = \"x_\"\nheartbeat_period_ms = 100\nheartbeat_deadline_ms = 500\n")
            .unwrap();
    assert_eq!(c.camera_ingest, CameraIngestConfig::default());
    assert_eq!(c.camera_ingest.source, "sim");
    assert_eq!(
        c.camera_ingest
            .camera_path(Path::new("/etc/landing/config")),
        PathBuf::from("/etc/landing/config/camera_down_640x480.yaml")
    );
}

#[test]
fn other_processes_sections_are_left_to_them() {
    let c = parse("[camera_ingest]\nundistort = true\n[planner]\nanything = 1\n").unwrap();
    assert!(c.camera_ingest.undistort);
}

#[test]
fn an_unknown_source_scheme_names_the_key_and_what_is_allowed() {
    let e = parse("[camera_ingest]\nsource = \"usb:0\"\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("camera_ingest.source"), "{e}");
    assert!(
        e.contains("usb:0") && e.contains("allowed: sim, v4l2:"),
        "{e}"
    );
    assert!(!e.contains('\n'), "one line: {e}");
}

#[test]
fn an_unknown_key_in_the_section_is_named() {
    let e = parse("[camera_ingest]\nundistrot = true\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("undistrot"), "{e}");
}

#[test]
fn an_absolute_camera_path_is_kept() {
    let c = CameraIngestConfig {
        camera: PathBuf::from("/opt/cal.yaml"),
        ..CameraIngestConfig::default()
    };
    assert_eq!(
        c.camera_path(Path::new("/x")),
        PathBuf::from("/opt/cal.yaml")
    );
}

#[test]
fn the_shipped_stack_file_is_valid_for_camera_ingest() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../deploy/config/landing.toml");
    let c: IngestFileConfig = config::load(&path).unwrap();
    let cal = c.camera_ingest.camera_path(path.parent().unwrap());
    assert!(cal.is_file(), "{}", cal.display());
}
