//! `landing bench depth`: what one depth frame costs the mapper, on this machine.
//!
//! A 10 s flight at 30 Hz past obstacle-demo's box and two more (climbing, sweeping its
//! heading, moving the window), each frame rendered by the simulator's D435-like camera
//! (640x480, noise on) and mapped with the shipped `[depth_map]` defaults (every 2nd
//! pixel, 5 m rays, 0.15 m cells, 0.299 m inflation). Timed separately: moving the
//! window, integrating the frame, inflating, writing the wire form. The same frames
//! also go into a second map that casts every ray to the camera (exact), to report how
//! much of what an exact cast sees the default cast sees, and what exactness would cost.

use std::time::Instant;

use anyhow::Result;
use clap::Args;
use depth_map::{DepthMapConfig, DepthPixels, DepthView, OccupancyMap};
use ipc_types::msg::{CellState, Intrinsics};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use serde_json::json;
use sim::depth::{DepthCamera, DepthCameraParams};
use sim::world::{Aabb, Obb};

use evaluation::stats::percentile;

/// Arguments of `landing bench depth`.
#[derive(Debug, Args)]
pub struct DepthArgs {
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
    /// Frames rendered and mapped (30 per simulated second).
    #[arg(long, default_value_t = 300)]
    frames: usize,
}

/// The scene: obstacle-demo's box, a pillar to its left, a wall segment to its right.
const OBSTACLES: [Aabb; 3] = [
    Aabb {
        min_m: [2.5, -0.6, 0.0],
        max_m: [3.1, 0.6, 1.2],
    },
    Aabb {
        min_m: [3.5, 1.5, 0.0],
        max_m: [3.9, 1.9, 2.5],
    },
    Aabb {
        min_m: [4.0, -2.5, 0.0],
        max_m: [4.3, -1.2, 1.8],
    },
];

/// The body pose at time `t` s: from the origin toward the box and back (0 to 2 m ahead,
/// +-0.4 m sideways), climbing from 0.6 m to 1.8 m, the heading sweeping +-35 deg.
fn body_at(t: f64) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(
            1.0 - (0.3 * t).cos(),
            0.4 * (0.3 * t).sin(),
            1.2 - 0.6 * (0.4 * t).cos(),
        ),
        UnitQuaternion::from_euler_angles(
            0.03 * (2.1 * t).sin(),
            0.05 * (1.7 * t).sin(),
            0.6 * (0.5 * t).sin(),
        ),
    )
}

/// Timings of one run, ms per frame.
#[derive(Default)]
struct Times {
    recenter: Vec<f64>,
    integrate: Vec<f64>,
    inflate: Vec<f64>,
    wire: Vec<f64>,
    rays: Vec<f64>,
    touched: Vec<f64>,
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

fn round3(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

/// Runs the benchmark and prints the figures.
pub fn run(args: &DepthArgs) -> Result<()> {
    if !(10..=100_000).contains(&args.frames) {
        anyhow::bail!(
            "--frames {} is not allowed (allowed: 10 to 100000)",
            args.frames
        );
    }
    let cfg = DepthMapConfig::default();
    let settings = cfg.map_settings();
    let mut exact_settings = settings;
    exact_settings.rays.shared_run_to_stop = 0;
    let mut map = OccupancyMap::new(settings)?;
    let mut exact = OccupancyMap::new(exact_settings)?;
    let mut cam = DepthCamera::new(DepthCameraParams::default())?;
    let (fx, fy) = cam.params().focal_px();
    let (cx, cy) = cam.params().principal_point_px();
    let k = Intrinsics { fx, fy, cx, cy };
    let (w, h) = (cam.params().width, cam.params().height);
    let body_from_camera = cfg.body_from_camera();
    let mut depth = vec![0u16; cam.frame_len()];
    let boxes: Vec<Obb> = OBSTACLES.iter().map(Obb::from).collect();
    let mut wire = vec![0u8; map.cell_count()];
    let mut t = Times::default();
    let mut exact_ms = Vec::new();
    let mut coverage = Vec::new();
    eprintln!(
        "bench depth: {} frames of {w}x{h}, every {} px, {} m rays, {} m cells...",
        args.frames, cfg.pixel_step, cfg.max_ray_m, cfg.resolution_m
    );
    for i in 0..args.frames {
        let time = i as f64 / 30.0;
        let body = body_at(time);
        cam.render_into(&body, &boxes, &mut depth);
        let view = DepthView::new(
            w,
            h,
            k,
            DepthPixels::U16 {
                data: &depth,
                scale_m: sim::depth::DEPTH_SCALE_M as f32,
            },
        )?;
        let world_from_camera = body * body_from_camera;
        let centre = Point3::from(body.translation.vector);
        let capture = (time * 1e9) as u64;

        let s = Instant::now();
        map.recenter(&centre)?;
        t.recenter.push(ms(s));
        let s = Instant::now();
        let stats = map.integrate(&view, &world_from_camera, capture)?;
        t.integrate.push(ms(s));
        let s = Instant::now();
        map.inflate();
        t.inflate.push(ms(s));
        let s = Instant::now();
        map.write_wire(&mut wire)?;
        t.wire.push(ms(s));
        t.rays
            .push(f64::from(stats.pixels - stats.invalid - stats.too_near));
        t.touched.push(f64::from(stats.cells_touched));

        exact.recenter(&centre)?;
        let s = Instant::now();
        exact.integrate(&view, &world_from_camera, capture)?;
        exact_ms.push(ms(s));
        // Observed cells of this map against the exact one, every 30 frames.
        if i % 30 == 29 {
            let (mut ours, mut theirs) = (0usize, 0usize);
            let [nx, ny, nz] = map.dims();
            for z in 0..nz {
                for y in 0..ny {
                    for x in 0..nx {
                        let p = map.cell_centre([x, y, z]);
                        if exact.log_odds_at(&p).is_some() {
                            theirs += 1;
                            if map.log_odds_at(&p).is_some() {
                                ours += 1;
                            }
                        }
                    }
                }
            }
            coverage.push(ours as f64 / theirs.max(1) as f64);
        }
    }
    let census = map.census();
    let publish: Vec<f64> = t.inflate.iter().zip(&t.wire).map(|(a, b)| a + b).collect();
    let dims = map.dims();
    let occupied_cells = wire
        .iter()
        .filter(|&&c| c == CellState::Occupied as u8)
        .count();
    let out = json!({
        "integrate_ms_p50": round3(percentile(&t.integrate, 50.0)),
        "integrate_ms_p99": round3(percentile(&t.integrate, 99.0)),
        "inflate_ms_p50": round3(percentile(&t.inflate, 50.0)),
        "inflate_ms_p99": round3(percentile(&t.inflate, 99.0)),
        "write_wire_ms_p50": round3(percentile(&t.wire, 50.0)),
        "inflate_and_wire_ms_p99": round3(percentile(&publish, 99.0)),
        "recenter_ms_max": round3(percentile(&t.recenter, 100.0)),
        "exact_integrate_ms_p50": round3(percentile(&exact_ms, 50.0)),
        "observed_vs_exact_min": round3(coverage.iter().copied().fold(1.0, f64::min)),
        "frames": args.frames,
        "rays_per_frame_p50": percentile(&t.rays, 50.0),
        "cells_touched_p50": percentile(&t.touched, 50.0),
        "window_cells": dims,
        "resolution_m": cfg.resolution_m,
        "memory_kib": map.memory_bytes() / 1024,
        "occupied_cells_at_end": occupied_cells,
        "free_cells_at_end": census.free,
    });
    if args.json {
        println!("{out}");
    } else {
        println!(
            "integrate one 640x480 frame: p50 {:.2} ms, p99 {:.2} ms ({} rays, {} cells touched p50)",
            percentile(&t.integrate, 50.0),
            percentile(&t.integrate, 99.0),
            percentile(&t.rays, 50.0),
            percentile(&t.touched, 50.0)
        );
        println!(
            "inflate: p50 {:.3} ms, p99 {:.3} ms; write the wire form: p50 {:.3} ms; both p99 {:.3} ms",
            percentile(&t.inflate, 50.0),
            percentile(&t.inflate, 99.0),
            percentile(&t.wire, 50.0),
            percentile(&publish, 99.0)
        );
        println!(
            "window {}x{}x{} cells of {} m ({} KiB); moving it: at most {:.3} ms",
            dims[0],
            dims[1],
            dims[2],
            cfg.resolution_m,
            map.memory_bytes() / 1024,
            percentile(&t.recenter, 100.0)
        );
        println!(
            "exact cast (every ray to the camera): p50 {:.2} ms; the default cast observes at least {:.1} % of its cells",
            percentile(&exact_ms, 50.0),
            100.0 * coverage.iter().copied().fold(1.0, f64::min)
        );
    }
    Ok(())
}
