//! Rendered depth frames with known truth, shared by the behaviour tests.
#![allow(dead_code)]

use depth_map::{DepthPixels, DepthView, MapSettings, OccupancyMap, body_from_forward_camera};
use ipc_types::msg::Intrinsics;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use sim::depth::{DepthCamera, DepthCameraParams};
use sim::world::{Aabb, Obb};

/// The obstacle-demo box: 0.6 m deep, 1.2 m wide, 1.2 m tall, 2.5 m ahead of the origin.
pub const BOX: Aabb = Aabb {
    min_m: [2.5, -0.6, 0.0],
    max_m: [3.1, 0.6, 1.2],
};

/// The simulator's forward depth camera, with its noise or without.
pub fn camera(noisy: bool) -> DepthCamera {
    let mut p = DepthCameraParams::default();
    if !noisy {
        p.noise_k_per_m = 0.0;
    }
    DepthCamera::new(p).unwrap()
}

pub fn intrinsics(cam: &DepthCamera) -> Intrinsics {
    let (fx, fy) = cam.params().focal_px();
    let (cx, cy) = cam.params().principal_point_px();
    Intrinsics { fx, fy, cx, cy }
}

/// A level body at `p` with heading `yaw` (rad).
pub fn body(p: [f64; 3], yaw: f64) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(p[0], p[1], p[2]),
        UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
    )
}

/// Where the depth camera is for body pose `b` (the default mount).
pub fn world_from_camera(b: &Isometry3<f64>) -> Isometry3<f64> {
    b * body_from_forward_camera([0.1, 0.0, 0.1], [0.0; 3])
}

pub fn render(cam: &mut DepthCamera, b: &Isometry3<f64>, boxes: &[Aabb]) -> Vec<u16> {
    let boxes: Vec<Obb> = boxes.iter().map(Obb::from).collect();
    cam.render(b, &boxes).depth_mm
}

pub fn view<'a>(cam: &DepthCamera, depth: &'a [u16]) -> DepthView<'a> {
    DepthView::new(
        cam.params().width,
        cam.params().height,
        intrinsics(cam),
        DepthPixels::U16 {
            data: depth,
            scale_m: 0.001,
        },
    )
    .unwrap()
}

/// A map with the default settings, placed around `b`.
pub fn map_at(b: &Isometry3<f64>, settings: MapSettings) -> OccupancyMap {
    let mut m = OccupancyMap::new(settings).unwrap();
    m.recenter(&Point3::from(b.translation.vector)).unwrap();
    m
}

/// Distance from `p` to the box, m (0 inside).
pub fn distance_to_box(p: &Point3<f64>, b: &Aabb) -> f64 {
    let mut d2 = 0.0;
    for i in 0..3 {
        let c = p[i].clamp(b.min_m[i], b.max_m[i]);
        d2 += (p[i] - c).powi(2);
    }
    d2.sqrt()
}
