#![allow(clippy::unwrap_used, clippy::expect_used)]
//! What a driver, a bus or a bug could deliver: invalid depths, frames of the wrong size,
//! headers that contradict their payload, vehicle states that are stale or not finite.
//! Counted and skipped, never a panic, never a non-finite number in the output.

mod common;

use common::*;
use depth_map::{
    DepthError, DepthMapConfig, DepthMapper, DepthPixels, DepthView, MapSettings, OccupancyMap,
};
use ipc_types::msg::{CellState, DepthFrameHeader, Header, Pose, VehicleState};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use state_history::HistoryError;

const W: usize = 640;
const H: usize = 480;

fn mapper() -> DepthMapper {
    DepthMapper::from_config(&DepthMapConfig::default()).unwrap()
}

fn hover_state(t_ns: u64) -> VehicleState {
    VehicleState {
        msg: Header::captured_at(t_ns),
        world_from_body: Pose {
            translation: [0.0, 0.0, 1.0],
            rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
        },
        ..VehicleState::default()
    }
}

/// The map's wire form is all valid cell states and its header all finite.
fn assert_clean(map: &OccupancyMap) {
    let mut out = vec![0u8; map.cell_count()];
    let h = map.write_wire(&mut out).unwrap();
    assert!(out.iter().all(|&c| c <= CellState::Inflated as u8));
    assert!(h.origin.iter().all(|v| v.is_finite()));
    assert!(h.resolution.is_finite() && h.inflation.is_finite());
}

#[test]
fn nan_infinite_and_negative_float_depths_are_counted_and_ignored() {
    let cam = camera(false);
    let k = intrinsics(&cam);
    let mut d = vec![2.0f32; W * H];
    for (i, v) in d.iter_mut().enumerate() {
        *v = match i % 5 {
            0 => f32::NAN,
            1 => f32::INFINITY,
            2 => -1.0,
            3 => f32::NEG_INFINITY,
            _ => 2.0,
        };
    }
    let view = DepthView::new(640, 480, k, DepthPixels::F32(&d)).unwrap();
    let b = body([0.0, 0.0, 1.0], 0.0);
    let mut map = map_at(&b, MapSettings::default());
    let s = map.integrate(&view, &world_from_camera(&b), 1).unwrap();
    // Every 2nd pixel of every 2nd row: 76800 sampled, one in five valid.
    assert_eq!(s.pixels, 76_800);
    assert_eq!(s.invalid + s.hits, 76_800);
    assert_eq!(s.hits, 76_800 / 5);
    assert_eq!(map.census().occupied, 0, "one frame is one hit, not enough");
    assert_clean(&map);
}

#[test]
fn zero_depths_free_their_rays_and_saturated_ones_are_ignored() {
    let cam = camera(false);
    let mut d = vec![0u16; W * H];
    for row in d.chunks_mut(W).skip(240) {
        row.fill(u16::MAX);
    }
    let b = body([0.0, 0.0, 1.0], 0.0);
    let mut map = map_at(&b, MapSettings::default());
    let s = map
        .integrate(&view(&cam, &d), &world_from_camera(&b), 1)
        .unwrap();
    assert_eq!((s.no_return, s.invalid, s.hits), (38_400, 38_400, 0));
    // The upper half freed up to 5 m; the lower half (saturated) left unknown.
    assert_eq!(
        map.state_at(&Point3::new(4.0, 0.0, 1.8)),
        CellState::Free,
        "above the axis"
    );
    assert_eq!(
        map.state_at(&Point3::new(4.0, 0.0, 0.2)),
        CellState::Unknown,
        "below the axis"
    );
    assert_eq!(map.census().occupied, 0);
    assert_clean(&map);
}

#[test]
fn a_frame_of_the_wrong_size_is_counted_and_skipped() {
    let mut m = mapper();
    m.push_state_msg(&hover_state(1_000_000_000));
    let d = vec![2000u16; 320 * 240];
    let k = intrinsics(&camera(false));
    let small = DepthView::new(
        320,
        240,
        k,
        DepthPixels::U16 {
            data: &d,
            scale_m: 0.001,
        },
    )
    .unwrap();
    let e = m.process(&small, 1_000_000_000).unwrap_err();
    assert!(matches!(e, DepthError::FrameSize { .. }));
    assert!(
        e.to_string().contains("320x240") && e.to_string().contains("640x480"),
        "{e}"
    );
    assert_eq!((m.counters().bad_frames, m.counters().integrated), (1, 0));
    assert_eq!(m.map().census().unknown, m.map().cell_count());
}

#[test]
fn a_header_inconsistent_with_its_payload_is_refused_and_counted() {
    let cam = camera(false);
    let good = DepthFrameHeader {
        width: 640,
        height: 480,
        depth_scale_m: 0.001,
        intrinsics: intrinsics(&cam),
        ..DepthFrameHeader::default()
    };
    let d = vec![1500u16; W * H];
    assert!(DepthView::from_wire(&good, &d).is_ok());
    let mut m = mapper();
    let bad_headers = [
        DepthFrameHeader { width: 641, ..good },
        DepthFrameHeader { height: 0, ..good },
        DepthFrameHeader {
            depth_scale_m: 0.0,
            ..good
        },
        DepthFrameHeader {
            depth_scale_m: f64::NAN,
            ..good
        },
        DepthFrameHeader {
            intrinsics: ipc_types::msg::Intrinsics {
                fx: f64::NAN,
                ..good.intrinsics
            },
            ..good
        },
        DepthFrameHeader {
            intrinsics: ipc_types::msg::Intrinsics {
                fy: -300.0,
                ..good.intrinsics
            },
            ..good
        },
        DepthFrameHeader {
            width: u32::MAX,
            height: u32::MAX,
            ..good
        },
    ];
    for h in &bad_headers {
        assert!(DepthView::from_wire(h, &d).is_err(), "{h:?}");
        m.record_bad_frame();
    }
    // A payload shorter than the header says.
    let e = DepthView::from_wire(&good, &d[..W * H - 1]).unwrap_err();
    assert!(e.to_string().contains("307199"), "{e}");
    assert_eq!(m.counters().bad_frames, bad_headers.len() as u64);
}

#[test]
fn a_vehicle_state_older_than_the_frame_beyond_the_threshold_skips_the_frame() {
    let cam = camera(false);
    let d = vec![2000u16; W * H];
    let mut m = mapper();
    // Newest state at 1.00 s; the allowance is 50 ms.
    m.push_state_msg(&hover_state(900_000_000));
    m.push_state_msg(&hover_state(1_000_000_000));
    assert!(m.process(&view(&cam, &d), 1_030_000_000).is_ok());
    let e = m.process(&view(&cam, &d), 1_080_000_000).unwrap_err();
    assert_eq!(e, DepthError::NoState(HistoryError::Stale(80_000_000)));
    assert!(e.to_string().contains("80000000"), "{e}");
    let c = m.counters();
    assert_eq!((c.frames, c.integrated, c.stale_state), (2, 1, 1));
    assert_eq!(m.map().last_capture_ns(), 1_030_000_000);
}

#[test]
fn non_finite_vehicle_states_and_camera_poses_are_refused() {
    let cam = camera(false);
    let d = vec![2000u16; W * H];
    let mut m = mapper();
    for bad in [
        [f64::NAN, 0.0, 1.0],
        [0.0, f64::INFINITY, 1.0],
        [0.0, 0.0, f64::NEG_INFINITY],
    ] {
        let mut s = hover_state(1_000_000_000);
        s.world_from_body.translation = bad;
        assert!(!m.push_state_msg(&s));
    }
    let mut s = hover_state(1_000_000_000);
    s.world_from_body.rotation_xyzw = [f64::NAN, 0.0, 0.0, 1.0];
    assert!(!m.push_state_msg(&s));
    assert_eq!(m.counters().bad_states, 4);
    // Nothing usable arrived: the frame has no state.
    assert!(matches!(
        m.process(&view(&cam, &d), 1_000_000_000),
        Err(DepthError::NoState(HistoryError::Empty))
    ));

    // A finite state that is absurdly far: the window cannot go there.
    let mut far = hover_state(2_000_000_000);
    far.world_from_body.translation = [1e300, 0.0, 0.0];
    assert!(m.push_state_msg(&far));
    assert_eq!(
        m.process(&view(&cam, &d), 2_000_000_000),
        Err(DepthError::NonFinitePose)
    );
    assert_eq!(m.counters().bad_poses, 1);

    // A mount with a NaN in it (a bad calibration file that got through).
    let mut m = DepthMapper::new(
        MapSettings::default(),
        Isometry3::from_parts(
            Translation3::new(f64::NAN, 0.0, 0.0),
            UnitQuaternion::identity(),
        ),
        50_000_000,
    )
    .unwrap();
    m.push_state_msg(&hover_state(1_000_000_000));
    assert_eq!(
        m.process(&view(&cam, &d), 1_000_000_000),
        Err(DepthError::NonFinitePose)
    );
    assert_eq!(m.map().census().unknown, m.map().cell_count());
    assert_clean(m.map());
}

#[test]
fn random_frames_and_poses_never_panic_and_never_leave_a_non_finite_number() {
    let cam = camera(false);
    let mut seed = 0x5eed_u64;
    let mut next = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        seed >> 16
    };
    let mut m = mapper();
    let mut d = vec![0u16; W * H];
    for k in 0..40u64 {
        for v in d.iter_mut() {
            *v = next() as u16;
        }
        let t = 1_000_000_000 + k * 33_000_000;
        let mut s = hover_state(t);
        let r = |x: u64| (x % 20_000) as f64 / 100.0 - 100.0;
        // Anywhere within 100 m, up to 10 m high (the window has a floor just below 0).
        s.world_from_body.translation = [r(next()), r(next()), r(next()).abs() / 10.0];
        let q = UnitQuaternion::from_euler_angles(r(next()), r(next()), r(next()));
        s.world_from_body.rotation_xyzw = [q.i, q.j, q.k, q.w];
        m.push_state_msg(&s);
        let _ = m.process(&view(&cam, &d), t);
        assert_clean(m.map());
    }
    assert_eq!(m.counters().integrated, 40);
    let p = m.map().origin();
    assert!(p.x.is_finite() && p.y.is_finite() && p.z.is_finite());
}
