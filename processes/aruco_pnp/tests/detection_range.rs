#![allow(clippy::unwrap_used, clippy::expect_used)]
//! The paper's detection-range table, reproduced with the renderer and the detector: per
//! marker size, the largest height at which it is decoded in at least 95 % of frames
//! (20 frames per height, each with its own render noise and a jittered pose: the
//! camera within 5 cm of the pad centre's vertical, tilted up to 3 deg, any yaw), not
//! the highest single detection. Prints a markdown table (run with `--nocapture`);
//! docs/perception.md quotes it.

mod common;

use aruco_pnp::{DetectSettings, Detector};
use common::*;
use opencv::core::Mat;

/// The paper's table (1280x720, fx 369.5): highest detected height per marker size, m.
const PAPER: [(&str, &[u32], f64); 4] = [
    ("43 (2.5 cm)", &[43], 0.15),
    ("5-8 (6.4 cm)", &[5, 6, 7, 8], 0.50),
    ("1-4 (9.5 cm)", &[1, 2, 3, 4], 1.15),
    ("68 (25.7 cm)", &[68], 3.00),
];

/// Frames per height.
const FRAMES: u32 = 20;

/// A small deterministic generator for the pose jitter.
struct Lcg(u64);

impl Lcg {
    /// Uniform in [-r, r].
    fn within(&mut self, r: f64) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        let u = (self.0 >> 11) as f64 / (1u64 << 53) as f64;
        r * (2.0 * u - 1.0)
    }
}

#[test]
fn every_marker_size_is_detected_at_least_as_high_as_in_the_paper() {
    let pad = pad_state();
    // 5 cm steps to 2 m, then 25 cm steps to 10 m.
    let heights: Vec<f64> = (1..=40)
        .map(|k| 0.05 * k as f64)
        .chain((1..=32).map(|k| 2.0 + 0.25 * k as f64))
        .collect();
    let mut table = Vec::new();
    for file in CAMERAS {
        let mut cam = camera(file);
        let cal = calibration(file);
        let mut detector = Detector::new(DetectSettings::default()).unwrap();
        let mut highest = [0.0f64; 4];
        let mut jitter = Lcg(0x5eed);
        for &h in &heights {
            let mut seen = [0u32; 4];
            for _ in 0..FRAMES {
                let v = View {
                    height: h,
                    offset: [jitter.within(0.05), jitter.within(0.05)],
                    roll_deg: jitter.within(3.0),
                    pitch_deg: jitter.within(3.0),
                    yaw_deg: jitter.within(180.0),
                };
                let (body, _) = place(&cam, &pad, &v);
                let data = render(&mut cam, &pad, body);
                let image =
                    Mat::new_rows_cols_with_data(cal.height as i32, cal.width as i32, &data)
                        .unwrap();
                let found = detector.detect(&image, None, None).unwrap();
                for (k, (_, ids, _)) in PAPER.iter().enumerate() {
                    // A size counts as detected when every marker of it is.
                    if ids.iter().all(|id| found.iter().any(|m| m.id == *id)) {
                        seen[k] += 1;
                    }
                }
            }
            for k in 0..4 {
                if f64::from(seen[k]) >= 0.95 * f64::from(FRAMES) {
                    highest[k] = highest[k].max(h);
                }
            }
        }
        table.push((file, highest));
    }
    println!(
        "| marker | paper (1280x720, fx 369.5) | ours 1280x720 (fx 369.5) | ours 640x480 (fx 184.75) |"
    );
    println!("| --- | --- | --- | --- |");
    for (k, (name, _, paper)) in PAPER.iter().enumerate() {
        let of = |f: &str| {
            table
                .iter()
                .find(|(n, _)| *n == f)
                .map_or(0.0, |(_, h)| h[k])
        };
        println!(
            "| {name} | {paper:.2} m | {:.2} m | {:.2} m |",
            of("camera_down_1280x720.yaml"),
            of("camera_down_640x480.yaml")
        );
    }
    // The paper's camera is the 1280x720 one: our pad and detector must see every size at
    // least as high as the paper did.
    let (_, ours) = table
        .iter()
        .find(|(n, _)| *n == "camera_down_1280x720.yaml")
        .unwrap();
    for (k, (name, _, paper)) in PAPER.iter().enumerate() {
        assert!(
            ours[k] >= *paper - 1e-9,
            "{name}: detected up to {} m, paper {paper} m",
            ours[k]
        );
    }
}
