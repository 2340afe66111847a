#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test
//! `landing map`: the scripted flight past obstacle-demo's box gives a map with the box
//! where it is (within what the estimator's drift allows) and nothing else, and a figure.

mod common;
use std::process::Output;

use opencv::imgcodecs;
use opencv::prelude::*;

fn landing(args: &[&str]) -> Output {
    common::landing_env(
        args,
        &[(
            "LANDING_DEPLOY_DIR",
            concat!(env!("CARGO_MANIFEST_DIR"), "/../../deploy"),
        )],
    )
}

/// The four numbers of `x [a, b]  y [c, d]` style ranges after `axis [`.
fn range(line: &str, axis: &str) -> (f64, f64) {
    let rest = line.split(&format!("{axis} [")).nth(1).unwrap();
    let inner = rest.split(']').next().unwrap();
    let mut it = inner.split(',').map(|v| v.trim().parse::<f64>().unwrap());
    (it.next().unwrap(), it.next().unwrap())
}

#[test]
fn the_obstacle_demo_map_puts_the_box_where_it_is_and_draws_both_views() {
    let dir = std::env::temp_dir().join(format!("landing-map-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let png = dir.join("map.png");
    let o = landing(&[
        "map",
        "--scenario",
        "obstacle-demo",
        "--png",
        png.to_str().unwrap(),
    ]);
    let out = String::from_utf8_lossy(&o.stdout);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{out}\n{err}");
    assert!(err.contains("offboard legs"), "progress on stderr: {err}");

    let truth = out
        .lines()
        .find(|l| l.starts_with("obstacle 0 truth"))
        .unwrap();
    let map = out
        .lines()
        .find(|l| l.starts_with("obstacle 0 map"))
        .unwrap();
    for axis in ["x", "y", "z"] {
        let (t0, t1) = range(truth, axis);
        let (m0, m1) = range(map, axis);
        // The faces the camera saw, within the estimate's error plus a cell.
        assert!(
            m0 < t1 && m1 > t0,
            "{axis}: map {m0}..{m1} vs truth {t0}..{t1}"
        );
        assert!((m0 - t0).abs() <= 0.4, "{axis} low: {m0} vs {t0}");
    }
    let summary = out
        .lines()
        .find(|l| l.starts_with("occupied cells above"))
        .unwrap();
    let phantoms: u64 = summary
        .split("of which ")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap();
    assert!(phantoms <= 5, "{summary}");

    let img = imgcodecs::imread(png.to_str().unwrap(), imgcodecs::IMREAD_COLOR).unwrap();
    assert!(
        img.cols() >= 68 * 8 && img.rows() >= (68 + 32) * 8,
        "{}x{}",
        img.cols(),
        img.rows()
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_bad_cell_size_or_an_unwritable_png_is_one_line_and_exit_code_2() {
    let o = landing(&["map", "--png", "/tmp/x.png", "--cell-px", "1"]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains("allowed: 2 to 20"), "{err}");

    let o = landing(&["map", "--png", "/nonexistent/dir/map.png"]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains("/nonexistent/dir/map.png"), "{err}");
}
