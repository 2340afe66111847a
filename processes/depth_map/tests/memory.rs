#![allow(clippy::unwrap_used, clippy::expect_used)]
//! Ten minutes of flight through a long course of boxes, many window lengths: the map's
//! buffers are the ones allocated at construction (same addresses, same capacities), and
//! integrating, moving the window, inflating and writing the wire form allocate nothing.
//!
//! This file is its own test binary with a counting global allocator, and holds one test
//! so that nothing else allocates while it counts.

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use common::*;
use depth_map::{DepthMapConfig, DepthMapper};
use ipc_types::msg::{CellState, Header, Pose, VehicleState};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use sim::world::Aabb;

struct CountingAlloc;

static COUNTING: AtomicBool = AtomicBool::new(false);
static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

// SAFETY: forwards to the system allocator unchanged; only counts calls.
unsafe impl GlobalAlloc for CountingAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if COUNTING.load(Ordering::Relaxed) {
            ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if COUNTING.load(Ordering::Relaxed) {
            ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

/// Counts the allocations `f` makes.
fn counted<T>(f: impl FnOnce() -> T) -> (T, u64) {
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    COUNTING.store(true, Ordering::Relaxed);
    let out = f();
    COUNTING.store(false, Ordering::Relaxed);
    (out, ALLOCATIONS.load(Ordering::Relaxed) - before)
}

/// A racetrack 150 m long and 30 m wide at 2 m/s, climbing and descending between 0.5 m
/// and 3 m: four laps in ten minutes, about 120 window lengths.
fn pose_at(t: f64) -> (Isometry3<f64>, [f64; 3]) {
    let (straight, radius, speed) = (60.0, 15.0, 2.0);
    let lap = 2.0 * straight + 2.0 * std::f64::consts::PI * radius;
    let s = (t * speed) % lap;
    let arc = std::f64::consts::PI * radius;
    let (x, y, heading) = if s < straight {
        (s, 0.0, 0.0)
    } else if s < straight + arc {
        let a = (s - straight) / radius;
        (straight + radius * a.sin(), radius - radius * a.cos(), a)
    } else if s < 2.0 * straight + arc {
        let d = s - straight - arc;
        (straight - d, 2.0 * radius, std::f64::consts::PI)
    } else {
        let a = (s - 2.0 * straight - arc) / radius;
        (
            -radius * a.sin(),
            radius + radius * a.cos(),
            std::f64::consts::PI + a,
        )
    };
    let z = 1.75 + 1.25 * (t / 20.0).sin();
    let v = [speed * heading.cos(), speed * heading.sin(), 0.0];
    (
        Isometry3::from_parts(
            Translation3::new(x, y, z),
            UnitQuaternion::from_euler_angles(0.0, 0.0, heading),
        ),
        v,
    )
}

fn state(t_ns: u64, b: &Isometry3<f64>, v: [f64; 3]) -> VehicleState {
    let q = b.rotation.coords;
    VehicleState {
        msg: Header::captured_at(t_ns),
        world_from_body: Pose {
            translation: b.translation.vector.into(),
            rotation_xyzw: [q.x, q.y, q.z, q.w],
        },
        velocity: v,
        ..VehicleState::default()
    }
}

#[test]
fn ten_minutes_of_flight_over_many_window_lengths_neither_grow_the_map_nor_allocate() {
    // Boxes along both straights, every 7 m, beside the track.
    let mut boxes = Vec::new();
    for k in 0..9 {
        let x = 3.0 + 7.0 * k as f64;
        for (y0, y1) in [(2.0, 2.8), (-2.8, -2.0), (28.0, 28.8), (31.2, 32.0)] {
            boxes.push(Aabb {
                min_m: [x, y0, 0.0],
                max_m: [x + 0.8, y1, 2.0],
            });
        }
    }
    let mut cam = camera(true);
    let cfg = DepthMapConfig::default();
    let mut mapper = DepthMapper::from_config(&cfg).unwrap();
    let mut wire = vec![0u8; mapper.map().cell_count()];
    let storage = mapper.map().storage();
    let bytes = mapper.map().memory_bytes();

    // 10 minutes: states at 50 Hz; a depth frame every 10th camera period (3 Hz) is
    // rendered and mapped, so the run takes seconds, not minutes.
    let duration_ns: u64 = 600_000_000_000;
    let state_period: u64 = 20_000_000;
    let frame_period: u64 = 333_333_333;
    let mut next_frame = frame_period;
    let (mut allocations, mut frames, mut moved, mut occupied_seen) = (0u64, 0u64, 0u64, 0usize);
    let mut t_ns = 0;
    while t_ns <= duration_ns {
        let (b, v) = pose_at(t_ns as f64 * 1e-9);
        let (_, a) = counted(|| mapper.push_state_msg(&state(t_ns, &b, v)));
        allocations += a;
        if t_ns >= next_frame {
            // The frame captured 10 ms before the newest state, as a real one arrives.
            let capture = t_ns - 10_000_000;
            let (cb, _) = pose_at(capture as f64 * 1e-9);
            let depth = render(&mut cam, &cb, &boxes);
            let view = view(&cam, &depth);
            let recenters = mapper.counters().recenters;
            let (r, a) = counted(|| {
                let r = mapper.process(&view, capture);
                mapper.map().write_wire(&mut wire).map(|_| r)
            });
            r.unwrap().unwrap();
            allocations += a;
            frames += 1;
            moved += mapper.counters().recenters - recenters;
            occupied_seen = occupied_seen.max(
                wire.iter()
                    .filter(|&&c| c == CellState::Occupied as u8)
                    .count(),
            );
            next_frame += frame_period;
        }
        t_ns += state_period;
    }
    let c = mapper.counters();
    println!(
        "{frames} frames, {} integrated, window moved {moved} times, {allocations} allocations, {} KiB",
        c.integrated,
        bytes / 1024
    );
    assert!(frames >= 1799, "{frames} frames");
    assert_eq!(c.integrated, frames);
    assert!(
        moved > 500,
        "the window followed the vehicle ({moved} moves)"
    );
    assert!(occupied_seen > 100, "the boxes were mapped on the way");
    assert_eq!(allocations, 0);
    assert_eq!(mapper.map().storage(), storage);
    assert_eq!(mapper.map().memory_bytes(), bytes);
}
