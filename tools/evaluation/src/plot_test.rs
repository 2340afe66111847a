//! Tests of `plot`.

use opencv::core::Vec3b;

use super::*;
use crate::flight_log::FlightSample;

fn temp(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("landing-plot-{}-{name}", std::process::id()))
}

/// A flight like the paper's simulation: take off at the origin, climb to a preset point,
/// wait, track the pad vehicle driving +x at 0.8 m/s, descend onto it. One box obstacle.
fn paper_like_log() -> FlightLog {
    let mut samples = Vec::new();
    let dt = 0.1;
    let mut uav = [0.0, 0.0, 0.0];
    for i in 0..=400 {
        let t = f64::from(i) * dt;
        let pad = [-6.0 + 0.8 * t, 1.0, 0.3];
        let (phase, target) = if t < 1.0 {
            ("Idle", uav)
        } else if t < 8.0 {
            ("Takeoff", [0.0, 0.0, 4.5])
        } else if t < 16.0 {
            ("GoToPreset", [-4.0, -2.0, 4.5])
        } else if t < 30.0 {
            ("Track", [pad[0], pad[1], 4.5 - (t - 16.0) * 0.2])
        } else {
            (
                "Descend",
                [pad[0], pad[1], (1.7 - (t - 30.0) * 0.2).max(0.3)],
            )
        };
        let mut vel = [0.0; 3];
        for k in 0..3 {
            let d = (target[k] - uav[k]).clamp(-0.15, 0.15);
            vel[k] = d / dt;
            uav[k] += d;
        }
        samples.push(FlightSample {
            t_s: t,
            uav,
            ugv_pad: Some(pad),
            phase: phase.to_string(),
            uav_velocity: vel,
            ugv_velocity: Some([0.8, 0.0, 0.0]),
        });
    }
    let last = samples.last().map(|s| (s.t_s, s.uav, s.ugv_pad)).unwrap();
    FlightLog {
        scenario: "paper-like".to_string(),
        seed: 3,
        contact: None,
        touchdown: Some(Touchdown {
            t_s: last.0,
            uav: last.1,
            pad: last.2.unwrap(),
            error_m: 0.12,
            rel_speed_mps: 0.3,
            on_pad: true,
        }),
        samples,
        obstacles: vec![([2.0, -3.0, 0.0], [2.6, -1.8, 1.2])],
    }
}

/// True when a pixel within `r` of `at` is within 40 (sum over channels) of `colour`.
fn colour_near(img: &Mat, at: Point, r: i32, colour: Scalar) -> bool {
    for dy in -r..=r {
        for dx in -r..=r {
            let (x, y) = (at.x + dx, at.y + dy);
            if x < 0 || y < 0 || x >= img.cols() || y >= img.rows() {
                continue;
            }
            let p = img.at_2d::<Vec3b>(y, x).unwrap();
            let d: f64 = (0..3).map(|k| (f64::from(p[k]) - colour[k]).abs()).sum();
            if d < 40.0 {
                return true;
            }
        }
    }
    false
}

fn non_white(img: &Mat) -> usize {
    let mut n = 0;
    for y in 0..img.rows() {
        for x in 0..img.cols() {
            let p = img.at_2d::<Vec3b>(y, x).unwrap();
            if p[0] < 250 || p[1] < 250 || p[2] < 250 {
                n += 1;
            }
        }
    }
    n
}

fn read(path: &Path) -> Mat {
    let img = imgcodecs::imread(path.to_str().unwrap(), imgcodecs::IMREAD_COLOR).unwrap();
    assert!(!img.empty(), "{} decodes", path.display());
    img
}

#[test]
fn both_views_are_written_decodable_full_size_and_show_the_uav_path_in_phase_colours() {
    let log = paper_like_log();
    let dir = temp("views").join("new-subdir");
    let _ = std::fs::remove_dir_all(&dir);
    let files = write_plots(&dir, &log).unwrap();
    eprintln!("wrote {} and {}", files[0].display(), files[1].display());
    assert_eq!(files, vec![dir.join("top.png"), dir.join("3d.png")]);
    let phases = phase_colours(&log);
    assert_eq!(phases.len(), 5);

    let top = read(&files[0]);
    assert_eq!((top.cols(), top.rows()), FIGURE_SIZE);
    assert!(non_white(&top) > 20_000, "top view is not blank");
    let f = TopFrame::fit(&xy_points(&log), top_area());
    let iso = read(&files[1]);
    assert_eq!((iso.cols(), iso.rows()), FIGURE_SIZE);
    assert!(non_white(&iso) > 20_000, "3-D view is not blank");
    let (lo, hi, pts) = world_box(&log);
    let g = IsoFrame::fit(lo, hi, &pts, iso_area());

    // Mid-phase samples, away from the start and touchdown markers.
    for t in [12.0, 20.0, 25.0, 33.0] {
        let s = log.samples.iter().find(|s| s.t_s >= t).unwrap();
        let c = colour_of(&phases, &s.phase);
        let at = f.to_px(s.uav[0], s.uav[1]);
        assert!(
            colour_near(&top, at, 2, c),
            "top: {} colour at t = {t} ({at:?})",
            s.phase
        );
        let at = g.to_px(s.uav);
        assert!(
            colour_near(&iso, at, 2, c),
            "3d: {} colour at t = {t} ({at:?})",
            s.phase
        );
    }
    // The pad vehicle's path (where the UAV does not fly over it) and the obstacle are
    // drawn too.
    let s = &log.samples[20];
    let p = s.ugv_pad.unwrap();
    assert!(colour_near(&top, f.to_px(p[0], p[1]), 2, ugv_colour()));
    assert!(colour_near(&top, f.to_px(2.3, -2.4), 0, grey(185.0)));
}

#[test]
fn the_top_view_keeps_equal_scale_and_everything_inside_the_plot_area() {
    let log = paper_like_log();
    let area = top_area();
    let f = TopFrame::fit(&xy_points(&log), area);
    let a = f.to_px(0.0, 0.0);
    let b = f.to_px(10.0, 10.0);
    assert!(
        ((b.x - a.x) - (a.y - b.y)).abs() <= 1,
        "ten metres are as long in x as in y: {a:?} {b:?}"
    );
    for p in xy_points(&log) {
        assert!(area.contains(f.to_px(p[0], p[1])), "{p:?}");
    }
}

#[test]
fn the_3d_view_draws_heights_upward_and_fits_the_box() {
    let (lo, hi) = ([-2.0, -2.0, 0.0], [8.0, 3.0, 4.0]);
    let area = iso_area();
    let mut corners = Vec::new();
    for i in 0..8 {
        corners.push([
            if i & 1 == 0 { lo[0] } else { hi[0] },
            if i & 2 == 0 { lo[1] } else { hi[1] },
            if i & 4 == 0 { lo[2] } else { hi[2] },
        ]);
    }
    let f = IsoFrame::fit(lo, hi, &corners, area);
    let ground = f.to_px([0.0, 0.0, 0.0]);
    let above = f.to_px([0.0, 0.0, 2.0]);
    assert_eq!(ground.x, above.x);
    assert!(above.y < ground.y);
    for p in corners {
        let q = f.to_px(p);
        let inside = Rect::new(area.x - 1, area.y - 1, area.width + 2, area.height + 2);
        assert!(inside.contains(q), "{p:?} -> {q:?}");
    }
}

#[test]
fn a_plot_directory_that_cannot_be_made_is_one_clear_error() {
    let file = temp("a-file");
    std::fs::write(&file, b"x").unwrap();
    let err = write_plots(&file.join("plots"), &paper_like_log()).unwrap_err();
    assert!(matches!(err, PlotError::CreateDir { .. }), "{err:?}");
    let msg = err.to_string();
    assert!(msg.contains("cannot create the plot directory"), "{msg}");
    assert!(msg.contains("a-file/plots"), "{msg}");
}

#[test]
fn an_empty_log_is_refused() {
    let err = write_plots(&temp("empty"), &FlightLog::default()).unwrap_err();
    assert!(matches!(err, PlotError::NoData { .. }), "{err:?}");
}

#[test]
fn a_histogram_shows_bars_and_marks_p50_and_p99() {
    // A body around 2 ms and a tail to 40 ms.
    let mut v: Vec<f64> = (0..2000)
        .map(|i| 1.5 + f64::from(i % 100) / 100.0)
        .collect();
    v.extend((0..30).map(|i| 5.0 + f64::from(i)));
    v.push(f64::NAN);
    let path = temp("hist").join("lat.png");
    write_histogram(&path, "planner latency", &v).unwrap();
    eprintln!("wrote {}", path.display());
    let img = read(&path);
    assert_eq!((img.cols(), img.rows()), HISTOGRAM_SIZE);
    let finite: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    let b = bin(&finite);
    assert_eq!(b.counts.iter().sum::<u64>(), finite.len() as u64);
    let area = hist_area();
    let cmax = b.counts.iter().copied().max().unwrap() as f64;
    let f = HistFrame {
        area,
        lo: b.lo,
        hi: b.hi,
        decades: cmax.log10().ceil().max(1.0),
    };
    // A bar at the body, near the bottom of the plot.
    let x = f.x(2.0) + 2;
    let y = area.y + area.height - 5;
    assert!(colour_near(&img, Point::new(x, y), 2, bar_colour()));
    // The p50 marker line, green, at its value.
    let p50 = percentile(&finite, 50.0);
    let x = f.x(p50);
    let mut green = false;
    for y in (area.y..area.y + area.height).step_by(3) {
        green |= colour_near(
            &img,
            Point::new(x, y),
            1,
            Scalar::new(40.0, 150.0, 40.0, 0.0),
        );
    }
    assert!(green, "p50 line at x = {x}");
}

#[test]
fn a_histogram_of_nothing_is_refused() {
    let err = write_histogram(&temp("none.png"), "x", &[f64::NAN]).unwrap_err();
    assert!(matches!(err, PlotError::NoData { .. }), "{err:?}");
}

#[test]
fn tick_steps_are_one_two_or_five_times_a_power_of_ten() {
    assert_eq!(nice_step(10.0, 10.0), 1.0);
    assert_eq!(nice_step(18.0, 10.0), 2.0);
    assert!((nice_step(0.4, 10.0) - 0.05).abs() < 1e-12);
    assert_eq!(ticks(-1.2, 2.1, 1.0), vec![-1.0, 0.0, 1.0, 2.0]);
    assert_eq!(tick_label(0.5, 0.5), "0.5");
    assert_eq!(tick_label(-0.0, 1.0), "0");
}
