#![allow(clippy::unwrap_used, clippy::expect_used)]
//! The `aruco-pnp` binary meets a user's mistakes with one line and exit code 2.

use std::process::Command;

fn run(args: &[&str]) -> (Option<i32>, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_aruco-pnp"))
        .args(args)
        .env("LANDING_LOG", "error")
        .output()
        .unwrap();
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).trim().to_string(),
    )
}

#[test]
fn a_missing_or_malformed_calibration_or_config_is_one_line_and_exit_code_2() {
    let dir = std::env::temp_dir().join(format!("aruco-pnp-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let malformed = dir.join("cam.yaml");
    std::fs::write(&malformed, "%YAML:1.0\n---\nimage_width: 640\n").unwrap();
    let bad_config = dir.join("landing.toml");
    std::fs::write(&bad_config, "[aruco_pnp]\nregion_margin = -1\n").unwrap();
    for (args, expect) in [
        (vec!["--camera", "/nonexistent/cam.yaml"], "cam.yaml"),
        (vec!["--camera", malformed.to_str().unwrap()], "cam.yaml"),
        (
            vec!["--config", bad_config.to_str().unwrap()],
            "aruco_pnp.region_margin",
        ),
    ] {
        let (code, err) = run(&args);
        assert_eq!(code, Some(2), "{args:?}: {err}");
        assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
        assert!(err.contains(expect), "{args:?}: {err}");
    }
    let o = Command::new(env!("CARGO_BIN_EXE_aruco-pnp"))
        .arg("--help")
        .output()
        .unwrap();
    assert!(o.status.success());
}
