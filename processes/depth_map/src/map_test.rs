use super::*;
use crate::body_from_forward_camera;
use nalgebra::{Translation3, UnitQuaternion};

const K: Intrinsics = Intrinsics {
    fx: 16.0,
    fy: 16.0,
    cx: 7.5,
    cy: 7.5,
};

fn settings() -> MapSettings {
    MapSettings {
        rays: RaySettings {
            width: 16,
            height: 16,
            pixel_step: 1,
            ..RaySettings::default()
        },
        ..MapSettings::default()
    }
}

fn view(d: &[u16]) -> DepthView<'_> {
    DepthView::new(
        16,
        16,
        K,
        DepthPixels::U16 {
            data: d,
            scale_m: 0.001,
        },
    )
    .unwrap()
}

/// A forward camera on a level body at `p`, yawed by `yaw` rad.
fn camera_at(p: [f64; 3], yaw: f64) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(p[0], p[1], p[2]),
        UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
    ) * body_from_forward_camera([0.0; 3], [0.0; 3])
}

fn placed(p: [f64; 3]) -> OccupancyMap {
    let mut m = OccupancyMap::new(settings()).unwrap();
    m.recenter(&Point3::new(p[0], p[1], p[2])).unwrap();
    m
}

#[test]
fn a_fresh_map_is_unknown_everywhere_and_outside_it_too() {
    let m = placed([0.0, 0.0, 1.0]);
    let c = m.census();
    assert_eq!(c.unknown, m.cell_count());
    for p in [
        Point3::new(0.0, 0.0, 1.0),
        Point3::new(100.0, 0.0, 1.0),
        Point3::new(0.0, 0.0, -50.0),
        Point3::new(f64::NAN, 0.0, 0.0),
        Point3::new(f64::INFINITY, 0.0, 0.0),
    ] {
        assert_eq!(m.state_at(&p), CellState::Unknown, "{p:?}");
        assert!(!m.is_free_inflated(&p));
    }
}

#[test]
fn a_wall_becomes_occupied_after_three_hits_and_the_space_before_it_free() {
    let mut m = placed([0.0, 0.0, 1.0]);
    let d = [2000u16; 256];
    let cam = camera_at([0.0, 0.0, 1.0], 0.0);
    let wall = Point3::new(2.05, 0.05, 1.05);
    let before = Point3::new(1.0, 0.05, 1.05);
    let s1 = m.integrate(&view(&d), &cam, 10).unwrap();
    assert_eq!(s1.pixels, 256);
    assert_eq!(s1.hits, 256);
    assert!(s1.shared_ends > 0, "several pixels end in one cell");
    assert_eq!(m.log_odds_at(&wall), Some(0.62));
    assert_eq!(m.state_at(&before), CellState::Free);
    m.integrate(&view(&d), &cam, 20).unwrap();
    assert_ne!(
        m.state_at(&wall),
        CellState::Occupied,
        "two hits: 1.24 < 1.39"
    );
    let s3 = m.integrate(&view(&d), &cam, 30).unwrap();
    assert!(s3.became_occupied > 0);
    assert_eq!(m.state_at(&wall), CellState::Occupied);
    assert_eq!(m.last_capture_ns(), 30);
    // Behind the wall: never seen.
    assert_eq!(
        m.state_at(&Point3::new(3.0, 0.05, 1.05)),
        CellState::Unknown
    );
    // Log-odds saturate at the clamp.
    for _ in 0..10 {
        m.integrate(&view(&d), &cam, 40).unwrap();
    }
    assert_eq!(m.log_odds_at(&wall), Some(2.2));
    assert_eq!(m.log_odds_at(&before), Some(-2.0));
}

#[test]
fn no_return_frees_the_ray_up_to_its_maximum_length_and_nothing_beyond() {
    let mut m = placed([0.0, 0.0, 1.0]);
    let d = [0u16; 256];
    let cam = camera_at([0.0, 0.0, 1.0], 0.0);
    let s = m.integrate(&view(&d), &cam, 1).unwrap();
    assert_eq!((s.no_return, s.hits), (256, 0));
    assert_eq!(m.state_at(&Point3::new(4.8, 0.05, 1.05)), CellState::Free);
    assert_eq!(
        m.state_at(&Point3::new(5.1, 0.05, 1.05)),
        CellState::Unknown
    );
    assert_eq!(m.census().occupied, 0);

    let mut s = settings();
    s.rays.no_return_as_free = false;
    let mut m = OccupancyMap::new(s).unwrap();
    m.recenter(&Point3::new(0.0, 0.0, 1.0)).unwrap();
    m.integrate(&view(&d), &cam, 1).unwrap();
    assert_eq!(m.census().unknown, m.cell_count(), "ignored");
}

#[test]
fn a_return_beyond_the_maximum_length_frees_up_to_it_without_a_hit() {
    let mut m = placed([0.0, 0.0, 1.0]);
    let d = [9000u16; 256];
    let cam = camera_at([0.0, 0.0, 1.0], 0.0);
    for _ in 0..5 {
        let s = m.integrate(&view(&d), &cam, 1).unwrap();
        assert_eq!(s.beyond_range, 256);
    }
    assert_eq!(m.census().occupied, 0);
    assert_eq!(m.state_at(&Point3::new(4.8, 0.05, 1.05)), CellState::Free);
}

#[test]
fn a_ray_leaving_the_window_is_cut_at_its_edge_and_frees_only_inside() {
    let mut s = settings();
    s.size_m = [3.0, 3.0, 3.0];
    let mut m = OccupancyMap::new(s).unwrap();
    m.recenter(&Point3::new(0.0, 0.0, 1.0)).unwrap();
    let d = [4000u16; 256];
    let st = m
        .integrate(&view(&d), &camera_at([0.0, 0.0, 1.0], 0.0), 1)
        .unwrap();
    assert_eq!(st.clipped, 256);
    assert_eq!(m.census().occupied, 0, "the wall at 4 m is outside: no hit");
    assert_eq!(m.state_at(&Point3::new(1.4, 0.05, 1.05)), CellState::Free);
}

#[test]
fn inflation_surrounds_occupied_cells_and_occupied_wins() {
    let mut m = placed([0.0, 0.0, 1.0]);
    let d = [2000u16; 256];
    let cam = camera_at([0.0, 0.0, 1.0], 0.0);
    for _ in 0..3 {
        m.integrate(&view(&d), &cam, 1).unwrap();
    }
    assert!(!m.inflation_is_current());
    m.inflate();
    assert!(m.inflation_is_current());
    let wall = Point3::new(2.05, 0.05, 1.05);
    assert_eq!(m.state_at(&wall), CellState::Occupied);
    // Two cells (0.3 m) in front of the wall: within 0.299 m of its box.
    assert_eq!(
        m.state_at(&Point3::new(1.75, 0.05, 1.05)),
        CellState::Inflated
    );
    assert!(!m.is_free_inflated(&Point3::new(1.75, 0.05, 1.05)));
    // Three cells in front: free.
    assert_eq!(m.state_at(&Point3::new(1.6, 0.05, 1.05)), CellState::Free);
    assert!(m.is_free_inflated(&Point3::new(1.6, 0.05, 1.05)));
    assert_eq!(m.inflation_kernel_cells(), 81);
}

#[test]
fn the_window_follows_the_vehicle_keeping_what_stays_inside() {
    let mut m = placed([0.0, 0.0, 1.0]);
    let d = [2000u16; 256];
    for _ in 0..3 {
        m.integrate(&view(&d), &camera_at([0.0, 0.0, 1.0], 0.0), 1)
            .unwrap();
    }
    m.inflate();
    let wall = Point3::new(2.05, 0.05, 1.05);
    let before = m.census();
    // Small motions: no move.
    assert!(!m.recenter(&Point3::new(0.5, -0.5, 1.4)).unwrap());
    // 1.5 m along -x: moves; the wall is still inside and still occupied, inflated
    // around as before.
    let o = m.origin();
    assert!(m.recenter(&Point3::new(-1.5, 0.0, 1.0)).unwrap());
    assert!(
        (m.origin().x - (o.x - 1.5)).abs() < 1e-9,
        "{:?} -> {:?}",
        o,
        m.origin()
    );
    assert_eq!(m.state_at(&wall), CellState::Occupied);
    assert_eq!(
        m.state_at(&Point3::new(1.75, 0.05, 1.05)),
        CellState::Inflated
    );
    assert_eq!(m.census().occupied, before.occupied);
    // Far away: the wall leaves the window; coming back, it is unknown.
    assert!(m.recenter(&Point3::new(-20.0, 0.0, 1.0)).unwrap());
    assert_eq!(m.census().unknown, m.cell_count());
    m.recenter(&Point3::new(0.0, 0.0, 1.0)).unwrap();
    assert_eq!(m.state_at(&wall), CellState::Unknown);
}

#[test]
fn cells_entering_the_window_are_unknown_after_a_partial_move() {
    let mut m = placed([0.0, 0.0, 1.0]);
    let d = [0u16; 256];
    // Free rays toward -y and +y, filling cells near both y edges.
    for yaw in [std::f64::consts::FRAC_PI_2, -std::f64::consts::FRAC_PI_2] {
        m.integrate(&view(&d), &camera_at([0.0, 0.0, 1.0], yaw), 1)
            .unwrap();
    }
    let free_before = m.census().free;
    assert!(m.recenter(&Point3::new(0.0, 2.0, 1.0)).unwrap());
    let c = m.census();
    assert!(c.free < free_before && c.free > 0);
    // What entered (beyond the old +y edge) is unknown.
    let o = m.origin();
    let top = o.y + m.dims()[1] as f64 * m.resolution() - 0.05;
    assert_eq!(
        m.state_at(&Point3::new(0.05, top, 1.05)),
        CellState::Unknown
    );
    assert_eq!(
        m.state_at(&Point3::new(0.05, 4.5, 1.05)),
        CellState::Free,
        "kept"
    );
}

#[test]
fn the_window_never_reaches_below_the_floor() {
    let mut m = placed([0.0, 0.0, 0.0]);
    assert!((m.origin().z - -0.45).abs() < 1e-9, "{:?}", m.origin());
    m.recenter(&Point3::new(0.0, 0.0, 30.0)).unwrap();
    assert!(m.origin().z > 25.0);
    m.recenter(&Point3::new(0.0, 0.0, -10.0)).unwrap();
    assert!((m.origin().z - -0.45).abs() < 1e-9);
}

#[test]
fn a_camera_outside_the_window_or_a_bad_pose_is_refused_and_changes_nothing() {
    let mut m = placed([0.0, 0.0, 1.0]);
    let d = [2000u16; 256];
    assert_eq!(
        m.integrate(&view(&d), &camera_at([30.0, 0.0, 1.0], 0.0), 1),
        Err(DepthError::OutsideWindow)
    );
    let mut bad = camera_at([0.0, 0.0, 1.0], 0.0);
    bad.translation.vector.x = f64::NAN;
    assert_eq!(
        m.integrate(&view(&d), &bad, 1),
        Err(DepthError::NonFinitePose)
    );
    let mut bad = camera_at([0.0, 0.0, 1.0], 0.0);
    bad.rotation = UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(2.0, 0.0, 0.0, 0.0));
    assert_eq!(
        m.integrate(&view(&d), &bad, 1),
        Err(DepthError::NonFinitePose)
    );
    assert_eq!(
        m.recenter(&Point3::new(f64::NAN, 0.0, 0.0)),
        Err(DepthError::NonFinitePose)
    );
    assert_eq!(m.census().unknown, m.cell_count());
    assert_eq!(m.last_capture_ns(), 0);
}

#[test]
fn the_wire_form_matches_the_queries_and_its_header_describes_the_window() {
    let mut m = placed([0.3, -0.2, 1.0]);
    let d = [2000u16; 256];
    for _ in 0..3 {
        m.integrate(&view(&d), &camera_at([0.3, -0.2, 1.0], 0.4), 77)
            .unwrap();
    }
    m.inflate();
    let mut out = vec![0xffu8; m.cell_count()];
    let h = m.write_wire(&mut out).unwrap();
    let [nx, ny, nz] = m.dims();
    assert_eq!(h.dims, [nx as u32, ny as u32, nz as u32]);
    assert_eq!(h.msg.capture_ns, 77);
    assert_eq!((h.resolution, h.inflation), (0.15, 0.299));
    let o = m.origin();
    assert_eq!(h.origin, [o.x, o.y, o.z]);
    let mut seen = [0usize; 4];
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                let b = out[x + nx * (y + ny * z)];
                assert_eq!(b, m.state_at_index([x, y, z]) as u8);
                seen[b as usize] += 1;
            }
        }
    }
    assert!(seen.iter().all(|&n| n > 0), "every state appears: {seen:?}");
    let c = m.census();
    assert_eq!(seen, [c.unknown, c.free, c.occupied, c.inflated]);
    let mut short = vec![0u8; 10];
    assert!(matches!(
        m.write_wire(&mut short),
        Err(DepthError::WireSize { .. })
    ));
}

#[test]
fn a_frame_of_another_size_is_refused() {
    let mut m = placed([0.0, 0.0, 1.0]);
    let d = [2000u16; 64];
    let v = DepthView::new(
        8,
        8,
        K,
        DepthPixels::U16 {
            data: &d,
            scale_m: 0.001,
        },
    )
    .unwrap();
    assert!(matches!(
        m.integrate(&v, &camera_at([0.0, 0.0, 1.0], 0.0), 1),
        Err(DepthError::FrameSize { got_w: 8, .. })
    ));
}

#[test]
fn new_intrinsics_rebuild_the_rays_in_place() {
    let mut m = placed([0.0, 0.0, 1.0]);
    let d = [2000u16; 256];
    let cam = camera_at([0.0, 0.0, 1.0], 0.0);
    m.integrate(&view(&d), &cam, 1).unwrap();
    let before = m.storage();
    let wide = Intrinsics {
        fx: 4.0,
        fy: 4.0,
        ..K
    };
    let v = DepthView::new(
        16,
        16,
        wide,
        DepthPixels::U16 {
            data: &d,
            scale_m: 0.001,
        },
    )
    .unwrap();
    m.integrate(&v, &cam, 2).unwrap();
    assert_eq!(m.storage(), before);
    // Pixel (3, 7) of the wide lens looks 48 deg left: 1 m ahead its ray is 1.125 m
    // left and 0.125 m up, where the narrow lens never looked.
    assert_eq!(m.state_at(&Point3::new(1.0, 1.125, 1.125)), CellState::Free);
}

#[test]
fn settings_out_of_range_are_refused_with_their_name() {
    type Case = (fn(&mut MapSettings), &'static str);
    let cases: [Case; 6] = [
        (|s| s.resolution_m = 0.0, "resolution_m"),
        (|s| s.size_m[1] = f64::NAN, "size_m[1]"),
        (|s| s.size_m = [100.0, 100.0, 100.0], "cells"),
        (|s| s.log_odds.occupied = 5.0, "log-odds"),
        (|s| s.rays.pixel_step = 0, "pixel_step"),
        (|s| s.recenter_threshold_m = 9.0, "recenter_threshold_m"),
    ];
    for (f, name) in cases {
        let mut s = MapSettings::default();
        f(&mut s);
        let e = OccupancyMap::new(s).unwrap_err().to_string();
        assert!(e.contains(name), "{e}");
    }
}
