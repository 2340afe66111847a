#![allow(clippy::unwrap_used, clippy::expect_used)]
//! The map built from the simulator's rendered depth frames (its D435-like camera, its
//! noise model) against the scene's truth: a box is where it is, the space in front of
//! it is free, a removed box clears, noise does not make obstacles.

mod common;

use common::*;
use depth_map::MapSettings;
use ipc_types::msg::CellState;
use nalgebra::Point3;

/// Points on a grid over a box of space, one per cell at most.
fn samples(min: [f64; 3], max: [f64; 3], step: f64) -> Vec<Point3<f64>> {
    let mut v = Vec::new();
    let n = |i: usize| ((max[i] - min[i]) / step).floor() as usize;
    for k in 0..=n(2) {
        for j in 0..=n(1) {
            for i in 0..=n(0) {
                v.push(Point3::new(
                    min[0] + i as f64 * step,
                    min[1] + j as f64 * step,
                    min[2] + k as f64 * step,
                ));
            }
        }
    }
    v
}

#[test]
fn a_box_in_front_of_the_camera_is_occupied_where_it_is_and_free_in_front_of_it() {
    let mut cam = camera(true);
    let b = body([0.0, 0.0, 1.0], 0.0);
    let mut map = map_at(&b, MapSettings::default());
    for k in 0..10 {
        let d = render(&mut cam, &b, &[BOX]);
        map.integrate(&view(&cam, &d), &world_from_camera(&b), k)
            .unwrap();
    }
    map.inflate();
    // The front face (x = 2.5): the cells just behind it, across the face.
    let face = samples([2.52, -0.5, 0.2], [2.52, 0.5, 1.15], 0.15);
    let occupied = face
        .iter()
        .filter(|p| map.state_at(p) == CellState::Occupied)
        .count();
    assert_eq!(occupied, face.len(), "every face cell is occupied");
    // In front of it, from 1 m out to 0.35 m short of the face, where the camera (1 m up,
    // 58 deg vertical field of view) sees, above the ground's inflation: observed free.
    let before = samples([1.0, -0.5, 0.6], [2.1, 0.5, 1.15], 0.15);
    assert!(before.len() > 200);
    let not_free: Vec<_> = before
        .iter()
        .filter(|p| !map.is_free_inflated(p))
        .map(|p| (p, map.state_at(p)))
        .collect();
    assert!(not_free.is_empty(), "not free: {not_free:?}");
    // Within the inflation radius in front of the face: inflated.
    for p in samples([2.28, -0.3, 0.5], [2.28, 0.3, 0.9], 0.15) {
        assert_eq!(map.state_at(&p), CellState::Inflated, "{p:?}");
    }
    // Behind the face, inside and behind the box: never seen.
    assert_eq!(
        map.state_at(&Point3::new(3.3, 0.0, 0.6)),
        CellState::Unknown
    );
    // Nothing occupied away from the box and the ground.
    let census = map.census();
    let [nx, ny, nz] = map.dims();
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                if map.state_at_index([x, y, z]) == CellState::Occupied {
                    let c = map.cell_centre([x, y, z]);
                    assert!(
                        distance_to_box(&c, &BOX) < 0.2 || c.z < 0.15,
                        "occupied at {c:?}"
                    );
                }
            }
        }
    }
    assert!(census.occupied > face.len());
}

#[test]
fn after_the_box_is_removed_its_cells_clear_within_a_few_frames() {
    let mut cam = camera(true);
    let b = body([0.0, 0.0, 1.0], 0.0);
    let mut map = map_at(&b, MapSettings::default());
    for k in 0..30 {
        let d = render(&mut cam, &b, &[BOX]);
        map.integrate(&view(&cam, &d), &world_from_camera(&b), k)
            .unwrap();
    }
    let face = samples([2.52, -0.5, 0.2], [2.52, 0.5, 1.15], 0.15);
    assert!(face.iter().all(|p| map.state_at(p) == CellState::Occupied));
    let mut frames = 0;
    while face.iter().any(|p| map.state_at(p) == CellState::Occupied) {
        frames += 1;
        assert!(frames <= 5, "still occupied after 5 frames");
        let d = render(&mut cam, &b, &[]);
        map.integrate(&view(&cam, &d), &world_from_camera(&b), 100 + frames)
            .unwrap();
    }
    // From the upper clamp (2.2), two misses (-0.62 each) bring a cell below 1.39.
    assert_eq!(frames, 2);
    map.inflate();
    for p in &face {
        // Low cells stay inflated by the ground below them.
        let want = if p.z > 0.45 {
            CellState::Free
        } else {
            CellState::Inflated
        };
        assert_eq!(map.state_at(p), want, "{p:?}");
    }
}

#[test]
fn depth_noise_does_not_grow_phantom_obstacles_in_free_space() {
    // The simulator's noise (sigma = 0.003 z^2, 7.5 cm at 5 m), ten seconds at 30 Hz from
    // a hovering vehicle that sways and yaws a little, as a real one does.
    let mut cam = camera(true);
    let start = body([0.0, 0.0, 1.0], 0.0);
    let mut map = map_at(&start, MapSettings::default());
    for k in 0..300 {
        let t = k as f64 / 30.0;
        let b = body(
            [
                0.05 * (1.3 * t).sin(),
                0.05 * (0.7 * t).cos(),
                1.0 + 0.05 * (0.9 * t).sin(),
            ],
            0.05 * (0.5 * t).sin(),
        );
        let d = render(&mut cam, &b, &[BOX]);
        map.integrate(&view(&cam, &d), &world_from_camera(&b), k)
            .unwrap();
    }
    // Truly free: cells whose centre is more than a cell diagonal (0.26 m) from the box
    // and from the ground.
    let [nx, ny, nz] = map.dims();
    let (mut observed_free_space, mut phantoms) = (0usize, 0usize);
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                let c = map.cell_centre([x, y, z]);
                if distance_to_box(&c, &BOX) <= 0.26 || c.z <= 0.26 {
                    continue;
                }
                match map.state_at_index([x, y, z]) {
                    CellState::Unknown => {}
                    CellState::Occupied => {
                        phantoms += 1;
                        observed_free_space += 1;
                    }
                    _ => observed_free_space += 1,
                }
            }
        }
    }
    assert!(
        observed_free_space > 5000,
        "{observed_free_space} cells observed"
    );
    let rate = phantoms as f64 / observed_free_space as f64;
    println!(
        "phantom obstacles: {phantoms} of {observed_free_space} observed free cells ({:.3} %)",
        100.0 * rate
    );
    assert!(rate < 0.01, "{phantoms} of {observed_free_space}");
}

#[test]
fn the_ground_seen_from_the_air_is_occupied_and_the_air_above_it_free() {
    let mut cam = camera(true);
    // Nose down 20 deg at 1.5 m: the ground from 1.3 m ahead.
    let b = nalgebra::Isometry3::from_parts(
        nalgebra::Translation3::new(0.0, 0.0, 1.5),
        nalgebra::UnitQuaternion::from_euler_angles(0.0, 20f64.to_radians(), 0.0),
    );
    let mut map = map_at(&b, MapSettings::default());
    for k in 0..5 {
        let d = render(&mut cam, &b, &[]);
        map.integrate(&view(&cam, &d), &world_from_camera(&b), k)
            .unwrap();
    }
    map.inflate();
    for x in [2.0, 2.5, 3.0] {
        // The ground at z = 0 is the boundary between two cell layers; the hits fall
        // on either side with the noise, in one layer or the other.
        let below = map.state_at(&Point3::new(x, 0.0, -0.05));
        let above = map.state_at(&Point3::new(x, 0.0, 0.05));
        assert!(
            below == CellState::Occupied || above == CellState::Occupied,
            "ground at x = {x}: {below:?} / {above:?}"
        );
        assert!(
            map.is_free_inflated(&Point3::new(x, 0.0, 0.8)),
            "air at x = {x}"
        );
    }
}
