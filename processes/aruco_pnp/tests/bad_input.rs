#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Frames a camera or a bug could deliver: wrong size, wrong layout, nothing in them,
//! noise. Errors or "no pad", never a panic, never a non-finite pose.

mod common;

use aruco_pnp::{Estimate, EstimateError, Frame, Search};
use common::*;
use ipc_types::msg::{Header, PixelEncoding};
use nalgebra::{Isometry3, Matrix6};

const CAM: &str = "camera_down_640x480.yaml";

#[test]
fn a_frame_of_the_wrong_size_is_an_error_naming_both_sizes() {
    let cam = camera(CAM);
    let mut est = estimator(CAM, &cam);
    let data = vec![0u8; 320 * 240];
    let f = Frame {
        width: 320,
        height: 240,
        stride: 320,
        encoding: PixelEncoding::Mono8,
        data: &data,
        undistorted: false,
    };
    let e = est.process(&f, 0, None).unwrap_err();
    assert!(matches!(e, EstimateError::FrameSize { .. }));
    assert!(
        e.to_string().contains("320x240") && e.to_string().contains("640x480"),
        "{e}"
    );
}

#[test]
fn a_stride_shorter_than_a_row_or_too_few_bytes_is_a_layout_error() {
    let cam = camera(CAM);
    let mut est = estimator(CAM, &cam);
    let data = vec![0u8; 640 * 480];
    let short_stride = Frame {
        width: 640,
        height: 480,
        stride: 600,
        encoding: PixelEncoding::Mono8,
        data: &data,
        undistorted: false,
    };
    assert!(matches!(
        est.process(&short_stride, 0, None),
        Err(EstimateError::Layout(_))
    ));
    let colour_claim = Frame {
        encoding: PixelEncoding::Bgr8,
        stride: 640 * 3,
        ..short_stride
    };
    assert!(matches!(
        est.process(&colour_claim, 0, None),
        Err(EstimateError::Layout(_))
    ));
}

#[test]
fn blank_and_noise_frames_give_no_pad_and_no_panic() {
    let cam = camera(CAM);
    let mut est = estimator(CAM, &cam);
    let cal = calibration(CAM);
    for fill in [0u8, 255] {
        let data = vec![fill; 640 * 480];
        assert!(est.process(&frame(&cal, &data), 0, None).unwrap().is_none());
    }
    let mut x = 12345u32;
    let data: Vec<u8> = (0..640 * 480)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            (x >> 24) as u8
        })
        .collect();
    if let Some(e) = est.process(&frame(&cal, &data), 0, None).unwrap() {
        assert!(e.observation(Header::default()).is_some());
    }
}

#[test]
fn a_colour_frame_with_padded_rows_is_read_like_the_grey_one() {
    let mut cam = camera(CAM);
    let pad = pad_state();
    let v = View {
        height: 1.0,
        offset: [0.0, 0.0],
        roll_deg: 0.0,
        pitch_deg: 0.0,
        yaw_deg: 0.0,
    };
    let (body, truth) = place(&cam, &pad, &v);
    let grey = render(&mut cam, &pad, body);
    let stride = 640 * 3 + 64;
    let mut bgr = vec![0u8; stride * 480];
    for r in 0..480 {
        for c in 0..640 {
            let g = grey[r * 640 + c];
            bgr[r * stride + 3 * c..r * stride + 3 * c + 3].copy_from_slice(&[g, g, g]);
        }
    }
    let mut est = estimator(CAM, &cam);
    let f = Frame {
        width: 640,
        height: 480,
        stride: stride as u32,
        encoding: PixelEncoding::Bgr8,
        data: &bgr,
        undistorted: false,
    };
    let e = est
        .process(&f, 0, None)
        .unwrap()
        .expect("pad in a colour frame");
    let (dt, _, _) = errors(&e.camera_from_pad, &truth);
    assert!(dt < 0.01, "{dt}");
}

#[test]
fn a_tracked_pad_is_searched_in_its_region_and_found_again_after_it_jumps() {
    let mut cam = camera(CAM);
    let cal = calibration(CAM);
    let pad = pad_state();
    let mut est = estimator(CAM, &cam);
    let mut searches = Vec::new();
    for (k, off) in [0.0, 0.01, 0.02, 0.6].iter().enumerate() {
        let v = View {
            height: 1.5,
            offset: [*off, 0.0],
            roll_deg: 0.0,
            pitch_deg: 0.0,
            yaw_deg: 0.0,
        };
        let (body, _) = place(&cam, &pad, &v);
        let data = render(&mut cam, &pad, body);
        let e = est
            .process(&frame(&cal, &data), k as u64 * 33_000_000, None)
            .unwrap()
            .unwrap();
        searches.push(e.search);
    }
    assert_eq!(
        searches,
        vec![Search::Full, Search::Region, Search::Region, Search::Full]
    );
    assert_eq!(est.counters().fallbacks, 1);
}

#[test]
fn an_estimate_with_a_non_finite_number_is_never_turned_into_a_message() {
    let mut e = Estimate {
        camera_from_pad: Isometry3::identity(),
        world_from_pad: None,
        covariance: Matrix6::identity(),
        rms_px: 0.1,
        used: vec![68],
        rejected: vec![],
        detected: vec![68],
        search: Search::Full,
    };
    assert!(e.observation(Header::default()).is_some());
    e.covariance[(2, 3)] = f64::NAN;
    assert!(e.observation(Header::default()).is_none());
    e.covariance[(2, 3)] = 0.0;
    e.camera_from_pad.translation.vector.x = f64::INFINITY;
    assert!(e.observation(Header::default()).is_none());
}
