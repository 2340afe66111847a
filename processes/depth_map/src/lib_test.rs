use super::*;
use ipc_types::msg::{Header, Intrinsics, Pose};
use nalgebra::Vector3;

#[test]
fn the_default_mount_is_the_simulators_forward_depth_camera() {
    let sim = sim::depth::DepthCameraParams::default();
    let c = DepthMapConfig::default();
    assert_eq!(c.camera_position_in_body_m, sim.position_in_body_m);
    let ours = c.body_from_camera();
    let theirs = sim.camera_from_body().inverse();
    assert!((ours.translation.vector - theirs.translation.vector).norm() < 1e-12);
    assert!(ours.rotation.angle_to(&theirs.rotation) < 1e-12);
}

#[test]
fn a_positive_mount_pitch_looks_down() {
    let m = body_from_forward_camera([0.0; 3], [0.0, 20.0, 0.0]);
    let axis = m.rotation * Vector3::z();
    assert!(axis.x > 0.9 && axis.z < -0.3, "{axis:?}");
}

fn state(t_ns: u64, x: f64) -> VehicleState {
    VehicleState {
        msg: Header::captured_at(t_ns),
        world_from_body: Pose {
            translation: [x, 0.0, 1.0],
            rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
        },
        ..VehicleState::default()
    }
}

fn small_settings() -> MapSettings {
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

fn wall(depth_mm: &[u16]) -> DepthView<'_> {
    DepthView::new(
        16,
        16,
        Intrinsics {
            fx: 16.0,
            fy: 16.0,
            cx: 7.5,
            cy: 7.5,
        },
        DepthPixels::U16 {
            data: depth_mm,
            scale_m: 0.001,
        },
    )
    .unwrap()
}

#[test]
fn a_frame_is_placed_with_the_pose_interpolated_at_its_capture_time() {
    let mut m = DepthMapper::new(
        small_settings(),
        body_from_forward_camera([0.0; 3], [0.0; 3]),
        50_000_000,
    )
    .unwrap();
    assert!(m.push_state_msg(&state(1_000_000_000, 0.0)));
    assert!(m.push_state_msg(&state(1_100_000_000, 1.0)));
    let d = [2000u16; 256];
    // Halfway between the states: the camera is at x = 0.5, the wall at x = 2.5.
    for _ in 0..3 {
        m.process(&wall(&d), 1_050_000_000).unwrap();
    }
    let map = m.map();
    assert_eq!(
        map.state_at(&Point3::new(2.47, 0.05, 1.05)),
        ipc_types::msg::CellState::Occupied
    );
    assert_eq!(
        map.state_at(&Point3::new(1.5, 0.05, 1.05)),
        ipc_types::msg::CellState::Free
    );
    assert_eq!(m.counters().integrated, 3);
}

#[test]
fn a_frame_newer_than_the_newest_state_beyond_the_allowance_is_counted_and_skipped() {
    let mut m = DepthMapper::new(
        small_settings(),
        body_from_forward_camera([0.0; 3], [0.0; 3]),
        50_000_000,
    )
    .unwrap();
    let d = [2000u16; 256];
    assert!(matches!(
        m.process(&wall(&d), 1_000_000_000),
        Err(DepthError::NoState(HistoryError::Empty))
    ));
    m.push_state_msg(&state(1_000_000_000, 0.0));
    assert!(
        m.process(&wall(&d), 1_040_000_000).is_ok(),
        "within the allowance"
    );
    assert!(matches!(
        m.process(&wall(&d), 1_060_000_000),
        Err(DepthError::NoState(HistoryError::Stale(_)))
    ));
    assert!(matches!(
        m.process(&wall(&d), 900_000_000),
        Err(DepthError::NoState(HistoryError::TooOld(_)))
    ));
    let c = m.counters();
    assert_eq!(
        (c.frames, c.integrated, c.no_state, c.stale_state, c.too_old),
        (4, 1, 1, 1, 1)
    );
}

#[test]
fn non_finite_or_non_unit_states_are_refused_and_counted() {
    let mut m = DepthMapper::new(
        small_settings(),
        body_from_forward_camera([0.0; 3], [0.0; 3]),
        50_000_000,
    )
    .unwrap();
    let mut s = state(1, 0.0);
    s.world_from_body.translation[0] = f64::NAN;
    assert!(!m.push_state_msg(&s));
    let mut s = state(2, 0.0);
    s.world_from_body.rotation_xyzw = [0.0; 4];
    assert!(!m.push_state_msg(&s));
    let mut s = state(3, 0.0);
    s.velocity[2] = f64::INFINITY;
    assert!(!m.push_state_msg(&s));
    assert!(m.push_state_msg(&state(4, 0.0)));
    assert!(!m.push_state_msg(&state(4, 0.0)), "not newer");
    assert_eq!(m.counters().bad_states, 4);
}

/// Keeps the maps a stage publishes (headers only).
#[derive(Default)]
struct Maps(Vec<ipc_types::msg::OccupancyMapHeader>);

impl ::stage::Outbox for Maps {
    fn publish(&mut self, _: &str, _: ::stage::Message<'_>) -> Result<(), ::stage::StageError> {
        Ok(())
    }

    fn publish_slice(
        &mut self,
        _: &str,
        len: usize,
        fill: &mut dyn FnMut(::stage::SliceMut<'_>) -> Option<::stage::SliceHeader>,
    ) -> Result<bool, ::stage::StageError> {
        let mut cells = vec![0u8; len];
        if let Some(::stage::SliceHeader::OccupancyMap(h)) = fill(::stage::SliceMut::U8(&mut cells))
        {
            self.0.push(h);
        }
        Ok(true)
    }
}

#[test]
fn a_map_names_the_newest_state_its_pose_came_from_until_the_next_frame() {
    use ::stage::{Input, Message, Stage};
    let mapper = DepthMapper::new(
        small_settings(),
        body_from_forward_camera([0.0; 3], [0.0; 3]),
        50_000_000,
    )
    .unwrap();
    let mut s = crate::stage::DepthStage::new(mapper, 100);
    let mut out = Maps::default();
    let state_in = |s: &mut crate::stage::DepthStage, out: &mut Maps, t: u64| {
        let v = state(t, 0.0);
        let input = Input {
            topic: ipc_types::topics::VEHICLE_STATE,
            msg: Message::VehicleState(&v),
        };
        s.on_input(t, input, out).unwrap();
    };
    let frame = |capture_ns: u64| ipc_types::msg::DepthFrameHeader {
        msg: Header::captured_at(capture_ns),
        width: 16,
        height: 16,
        depth_scale_m: 0.001,
        intrinsics: Intrinsics {
            fx: 16.0,
            fy: 16.0,
            cx: 7.5,
            cy: 7.5,
        },
        camera_id: 0,
        reserved: 0,
    };
    let depth_in = |s: &mut crate::stage::DepthStage, out: &mut Maps, capture: u64, now: u64| {
        let (h, d) = (frame(capture), [2000u16; 256]);
        let input = Input {
            topic: ipc_types::topics::SIM_DEPTH,
            msg: Message::DepthFrame(&h, &d),
        };
        s.on_input(now, input, out).unwrap();
    };
    state_in(&mut s, &mut out, 1_000_000_000);
    state_in(&mut s, &mut out, 1_100_000_000);
    depth_in(&mut s, &mut out, 1_050_000_000, 1_120_000_000);
    // A newer state, then the clock: the same map again, built from the same states.
    state_in(&mut s, &mut out, 1_200_000_000);
    s.on_tick(1_300_000_000, &mut out).unwrap();
    let named: Vec<_> = out.0.iter().map(|m| m.state_ns).collect();
    assert_eq!(named, [1_100_000_000, 1_100_000_000]);
    // A state after the next frame's bracket changes nothing: the map names the bracket.
    state_in(&mut s, &mut out, 1_300_000_000);
    depth_in(&mut s, &mut out, 1_150_000_000, 1_310_000_000);
    assert_eq!(out.0.last().map(|m| m.state_ns), Some(1_200_000_000));
}
