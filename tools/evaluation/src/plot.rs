//! Figures of a flight and of latency distributions, drawn with OpenCV into PNGs.
//!
//! [`write_plots`] draws what the paper's trajectory figures show: a top view (x-y) and
//! an oblique 3-D view of the UAV path (coloured by mission phase), the pad vehicle's
//! path, the obstacles and the touchdown with the pad outline. [`write_histogram`] draws
//! one latency distribution (per-process profiling) with its median and 99th percentile.
//! Plain OpenCV drawing keeps the tool free of a plotting stack.

use std::path::{Path, PathBuf};

use opencv::core::{self, Mat, Point, Rect, Scalar, Size, Vector};
use opencv::prelude::*;
use opencv::{imgcodecs, imgproc};
use thiserror::Error;

use crate::flight_log::{FlightLog, Touchdown};
use crate::stats::percentile;

/// Edge of the landing pad (the shipped 84 x 84 cm board), m: drawn around the touchdown.
pub const PAD_SIZE_M: f64 = 0.84;
/// Size of `top.png` and `3d.png`, pixels (width, height).
pub const FIGURE_SIZE: (i32, i32) = (1200, 900);
/// Size of a latency histogram, pixels (width, height).
pub const HISTOGRAM_SIZE: (i32, i32) = (900, 500);
/// File name of the top view in the plot directory.
pub const TOP_FILE: &str = "top.png";
/// File name of the 3-D view in the plot directory.
pub const ISO_FILE: &str = "3d.png";

/// Viewer azimuth of the 3-D view, degrees (matplotlib's default: from +x, -y).
const ISO_AZIMUTH_DEG: f64 = -60.0;
/// Viewer elevation of the 3-D view, degrees.
const ISO_ELEVATION_DEG: f64 = 28.0;
/// Heights are stretched until their range is at least this fraction of the horizontal
/// one, so that a 20 m track at 4 m height still shows its climb and descent (the axis
/// ticks stay in true metres).
const ISO_MIN_Z_FRACTION: f64 = 0.35;

/// Why a figure could not be written.
#[derive(Debug, Error)]
pub enum PlotError {
    /// The output directory is missing and cannot be made (or is a file).
    #[error("cannot create the plot directory {}: {error}", path.display())]
    CreateDir {
        /// The directory.
        path: PathBuf,
        /// What the OS said.
        error: std::io::Error,
    },
    /// Drawing or encoding failed, or the file cannot be written.
    #[error("cannot write {}: {reason}", path.display())]
    Write {
        /// The figure.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
    /// The input holds nothing to draw.
    #[error("nothing to plot in {}: {what}", path.display())]
    NoData {
        /// The figure that was asked for.
        path: PathBuf,
        /// What is missing.
        what: &'static str,
    },
}

/// Colours of the mission phases, in order of first appearance (BGR: matplotlib's "tab10").
const PHASE_BGR: [(f64, f64, f64); 9] = [
    (180.0, 119.0, 31.0),
    (14.0, 127.0, 255.0),
    (44.0, 160.0, 44.0),
    (40.0, 39.0, 214.0),
    (189.0, 103.0, 148.0),
    (75.0, 86.0, 140.0),
    (194.0, 119.0, 227.0),
    (207.0, 190.0, 23.0),
    (34.0, 189.0, 188.0),
];

fn bgr(c: (f64, f64, f64)) -> Scalar {
    Scalar::new(c.0, c.1, c.2, 0.0)
}

fn grey(v: f64) -> Scalar {
    Scalar::new(v, v, v, 0.0)
}

fn black() -> Scalar {
    grey(0.0)
}

/// Pad vehicle path colour.
fn ugv_colour() -> Scalar {
    grey(70.0)
}

/// Touchdown marker colour (magenta: not a phase colour).
fn touchdown_colour() -> Scalar {
    Scalar::new(200.0, 0.0, 200.0, 0.0)
}

/// Phase names in order of first appearance, each with its colour (the palette repeats
/// after nine phases).
fn phase_colours(log: &FlightLog) -> Vec<(String, Scalar)> {
    let mut out: Vec<(String, Scalar)> = Vec::new();
    for s in &log.samples {
        if !out.iter().any(|(n, _)| *n == s.phase) {
            let c = PHASE_BGR[out.len() % PHASE_BGR.len()];
            out.push((s.phase.clone(), bgr(c)));
        }
    }
    out
}

fn colour_of(phases: &[(String, Scalar)], name: &str) -> Scalar {
    phases
        .iter()
        .find(|(n, _)| n == name)
        .map(|(_, c)| *c)
        .unwrap_or_else(black)
}

/// A tick step of 1, 2 or 5 times a power of ten giving about `target` ticks over `span`.
fn nice_step(span: f64, target: f64) -> f64 {
    if !(span.is_finite() && span > 0.0) {
        return 1.0;
    }
    let raw = span / target.max(1.0);
    let mag = 10f64.powf(raw.log10().floor());
    let norm = raw / mag;
    let m = if norm <= 1.0 {
        1.0
    } else if norm <= 2.0 {
        2.0
    } else if norm <= 5.0 {
        5.0
    } else {
        10.0
    };
    m * mag
}

/// Multiples of `step` within `[lo, hi]`.
fn ticks(lo: f64, hi: f64, step: f64) -> Vec<f64> {
    let mut out = Vec::new();
    let mut k = (lo / step).ceil();
    while k * step <= hi + step * 1e-9 && out.len() < 200 {
        // -0.0 would print as "-0".
        out.push(k * step + 0.0);
        k += 1.0;
    }
    out
}

/// A tick label with as many decimals as the step needs.
fn tick_label(v: f64, step: f64) -> String {
    let decimals = if step >= 1.0 {
        0
    } else {
        (-step.log10().floor()) as usize
    };
    let v = if v.abs() < step * 1e-6 { 0.0 } else { v };
    format!("{v:.decimals$}")
}

fn px(x: f64, y: f64) -> Point {
    Point::new(x.round() as i32, y.round() as i32)
}

/// An image with the drawing calls this module needs.
struct Canvas {
    img: Mat,
}

const FONT: i32 = imgproc::FONT_HERSHEY_SIMPLEX;

impl Canvas {
    fn new(size: (i32, i32)) -> opencv::Result<Self> {
        let img = Mat::new_rows_cols_with_default(size.1, size.0, core::CV_8UC3, grey(255.0))?;
        Ok(Self { img })
    }

    fn line(&mut self, a: Point, b: Point, c: Scalar, thick: i32) -> opencv::Result<()> {
        imgproc::line(&mut self.img, a, b, c, thick, imgproc::LINE_AA, 0)
    }

    fn dashed(&mut self, a: Point, b: Point, c: Scalar, thick: i32) -> opencv::Result<()> {
        let (dx, dy) = (f64::from(b.x - a.x), f64::from(b.y - a.y));
        let len = dx.hypot(dy);
        let n = (len / 6.0).ceil().max(1.0) as i32;
        for i in (0..n).step_by(2) {
            let t0 = f64::from(i) / f64::from(n);
            let t1 = (f64::from(i) + 1.0) / f64::from(n);
            let p0 = px(f64::from(a.x) + dx * t0, f64::from(a.y) + dy * t0);
            let p1 = px(f64::from(a.x) + dx * t1, f64::from(a.y) + dy * t1);
            self.line(p0, p1, c, thick)?;
        }
        Ok(())
    }

    fn polyline(
        &mut self,
        pts: &[Point],
        closed: bool,
        c: Scalar,
        thick: i32,
    ) -> opencv::Result<()> {
        let v: Vector<Vector<Point>> = Vector::from_iter([Vector::from_slice(pts)]);
        imgproc::polylines(&mut self.img, &v, closed, c, thick, imgproc::LINE_AA, 0)
    }

    fn fill_poly(&mut self, pts: &[Point], c: Scalar) -> opencv::Result<()> {
        let v: Vector<Vector<Point>> = Vector::from_iter([Vector::from_slice(pts)]);
        imgproc::fill_poly(&mut self.img, &v, c, imgproc::LINE_AA, 0, Point::new(0, 0))
    }

    fn rect(&mut self, r: Rect, c: Scalar, thick: i32) -> opencv::Result<()> {
        imgproc::rectangle(&mut self.img, r, c, thick, imgproc::LINE_8, 0)
    }

    fn circle(&mut self, at: Point, r: i32, c: Scalar, thick: i32) -> opencv::Result<()> {
        imgproc::circle(&mut self.img, at, r, c, thick, imgproc::LINE_AA, 0)
    }

    fn text_size(s: &str, scale: f64) -> opencv::Result<Size> {
        let mut base = 0;
        imgproc::get_text_size(s, FONT, scale, 1, &mut base)
    }

    /// Text with its baseline-left at `at`, or aligned by `align` (0 left, 0.5 centre,
    /// 1 right).
    fn text(
        &mut self,
        s: &str,
        at: Point,
        scale: f64,
        c: Scalar,
        align: f64,
    ) -> opencv::Result<()> {
        let w = Self::text_size(s, scale)?.width;
        let x = at.x - (f64::from(w) * align).round() as i32;
        imgproc::put_text(
            &mut self.img,
            s,
            Point::new(x, at.y),
            FONT,
            scale,
            c,
            1,
            imgproc::LINE_AA,
            false,
        )
    }

    /// Text turned 90 degrees counter-clockwise (a vertical axis label), centred at `at`.
    fn text_vertical(&mut self, s: &str, at: Point, scale: f64) -> opencv::Result<()> {
        let size = Self::text_size(s, scale)?;
        let (w, h) = (size.width + 4, size.height + 8);
        let mut tmp = Canvas::new((w, h))?;
        tmp.text(s, Point::new(2, size.height + 2), scale, black(), 0.0)?;
        let mut rot = Mat::default();
        core::rotate(&tmp.img, &mut rot, core::ROTATE_90_COUNTERCLOCKWISE)?;
        let (x, y) = (at.x - h / 2, at.y - w / 2);
        if x < 0 || y < 0 || x + h > self.img.cols() || y + w > self.img.rows() {
            return Ok(());
        }
        let mut roi = Mat::roi_mut(&mut self.img, Rect::new(x, y, h, w))?;
        rot.copy_to(&mut roi)
    }

    /// A legend box at the top-left corner `at`: a swatch (line or marker) and a name per row.
    fn legend(&mut self, at: Point, rows: &[LegendRow]) -> opencv::Result<()> {
        let scale = 0.5;
        let row_h = 24;
        let mut w = 0;
        for r in rows {
            w = w.max(Self::text_size(&r.name, scale)?.width);
        }
        let box_w = w + 60;
        let box_h = row_h * rows.len() as i32 + 10;
        let frame = Rect::new(at.x, at.y, box_w, box_h);
        self.rect(frame, grey(255.0), imgproc::FILLED)?;
        self.rect(frame, grey(120.0), 1)?;
        for (i, r) in rows.iter().enumerate() {
            let y = at.y + 5 + row_h * i as i32 + row_h / 2;
            let (x0, x1) = (at.x + 8, at.x + 38);
            match r.swatch {
                Swatch::Line(c) => self.line(Point::new(x0, y), Point::new(x1, y), c, 3)?,
                Swatch::Fill(c) => {
                    self.rect(Rect::new(x0, y - 7, x1 - x0, 14), c, imgproc::FILLED)?;
                    self.rect(Rect::new(x0, y - 7, x1 - x0, 14), grey(110.0), 1)?;
                }
                Swatch::Marker(m) => m.draw(self, Point::new((x0 + x1) / 2, y))?,
            }
            self.text(&r.name, Point::new(x1 + 8, y + 5), scale, black(), 0.0)?;
        }
        Ok(())
    }

    fn write(&self, path: &Path) -> Result<(), PlotError> {
        let fail = |reason: String| PlotError::Write {
            path: path.to_path_buf(),
            reason,
        };
        let p = path
            .to_str()
            .ok_or_else(|| fail("not a UTF-8 path".to_string()))?;
        match imgcodecs::imwrite(p, &self.img, &Vector::new()) {
            Ok(true) => Ok(()),
            Ok(false) => Err(fail("OpenCV could not write the PNG".to_string())),
            Err(e) => Err(fail(e.to_string())),
        }
    }
}

/// The markers of the figures.
#[derive(Debug, Clone, Copy)]
enum Marker {
    /// A filled circle with a black rim (UAV start).
    Start(Scalar),
    /// A filled square with a black rim (pad vehicle start).
    Square(Scalar),
    /// A cross in a circle (touchdown).
    Touchdown,
}

impl Marker {
    fn draw(self, cv: &mut Canvas, at: Point) -> opencv::Result<()> {
        match self {
            Self::Start(c) => {
                cv.circle(at, 7, c, imgproc::FILLED)?;
                cv.circle(at, 7, black(), 2)
            }
            Self::Square(c) => {
                let r = Rect::new(at.x - 6, at.y - 6, 13, 13);
                cv.rect(r, c, imgproc::FILLED)?;
                cv.rect(r, black(), 2)
            }
            Self::Touchdown => {
                let c = touchdown_colour();
                cv.circle(at, 8, c, 2)?;
                cv.line(at + Point::new(-6, -6), at + Point::new(6, 6), c, 2)?;
                cv.line(at + Point::new(-6, 6), at + Point::new(6, -6), c, 2)
            }
        }
    }
}

#[derive(Debug, Clone, Copy)]
enum Swatch {
    Line(Scalar),
    Fill(Scalar),
    Marker(Marker),
}

struct LegendRow {
    swatch: Swatch,
    name: String,
}

/// The legend rows shared by both views.
fn legend_rows(log: &FlightLog, phases: &[(String, Scalar)]) -> Vec<LegendRow> {
    let mut rows: Vec<LegendRow> = phases
        .iter()
        .map(|(n, c)| LegendRow {
            swatch: Swatch::Line(*c),
            name: format!("UAV: {n}"),
        })
        .collect();
    let first = phases.first().map(|(_, c)| *c).unwrap_or_else(black);
    rows.push(LegendRow {
        swatch: Swatch::Marker(Marker::Start(first)),
        name: "UAV start".to_string(),
    });
    if log.samples.iter().any(|s| s.ugv_pad.is_some()) {
        rows.push(LegendRow {
            swatch: Swatch::Line(ugv_colour()),
            name: "UGV (pad centre)".to_string(),
        });
        rows.push(LegendRow {
            swatch: Swatch::Marker(Marker::Square(grey(200.0))),
            name: "UGV start".to_string(),
        });
    }
    if log.touchdown.is_some() {
        rows.push(LegendRow {
            swatch: Swatch::Marker(Marker::Touchdown),
            name: "touchdown + pad".to_string(),
        });
    }
    if !log.obstacles.is_empty() {
        rows.push(LegendRow {
            swatch: Swatch::Fill(grey(185.0)),
            name: "obstacle".to_string(),
        });
    }
    rows
}

/// The figure title: scenario, outcome (from the touchdown) and touchdown error.
fn title(log: &FlightLog) -> String {
    match &log.touchdown {
        Some(td) => format!(
            "{} (seed {}): {}, touchdown error {:.2} m, {:.2} m/s",
            log.scenario,
            log.seed,
            if td.on_pad {
                "on the pad"
            } else {
                "off the pad"
            },
            td.error_m,
            td.rel_speed_mps
        ),
        None => format!("{} (seed {}): no touchdown", log.scenario, log.seed),
    }
}

/// Corners of the pad square at touchdown, world x-y, turned to the pad vehicle's heading
/// when it was moving (the pad's +x is the carrier's heading).
fn pad_corners(log: &FlightLog, td: &Touchdown) -> [[f64; 2]; 4] {
    let heading = log
        .samples
        .iter()
        .rev()
        .find(|s| s.t_s <= td.t_s)
        .and_then(|s| s.ugv_velocity)
        .filter(|v| v[0].hypot(v[1]) > 0.05)
        .map(|v| v[1].atan2(v[0]))
        .unwrap_or(0.0);
    let (c, s) = (heading.cos(), heading.sin());
    let h = PAD_SIZE_M / 2.0;
    [[-h, -h], [h, -h], [h, h], [-h, h]]
        .map(|[x, y]| [td.pad[0] + c * x - s * y, td.pad[1] + s * x + c * y])
}

/// World x-y to pixels of the top view: equal scale on both axes.
#[derive(Debug, Clone, Copy)]
struct TopFrame {
    /// Plot area in pixels.
    area: Rect,
    /// World x at the left edge, y at the bottom edge, m.
    x0: f64,
    y0: f64,
    /// Pixels per metre.
    scale: f64,
}

impl TopFrame {
    /// The frame that shows `points` (x-y) in `area` with a margin, equal aspect.
    fn fit(points: &[[f64; 2]], area: Rect) -> Self {
        let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
        for p in points
            .iter()
            .filter(|p| p[0].is_finite() && p[1].is_finite())
        {
            for k in 0..2 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        if lo[0] > hi[0] {
            (lo, hi) = ([-1.0; 2], [1.0; 2]);
        }
        let span = [(hi[0] - lo[0]).max(2.0), (hi[1] - lo[1]).max(2.0)];
        let margin = 0.06;
        let scale = (f64::from(area.width) / (span[0] * (1.0 + 2.0 * margin)))
            .min(f64::from(area.height) / (span[1] * (1.0 + 2.0 * margin)));
        let cx = (lo[0] + hi[0]) / 2.0;
        let cy = (lo[1] + hi[1]) / 2.0;
        Self {
            area,
            x0: cx - f64::from(area.width) / scale / 2.0,
            y0: cy - f64::from(area.height) / scale / 2.0,
            scale,
        }
    }

    fn x_max(self) -> f64 {
        self.x0 + f64::from(self.area.width) / self.scale
    }

    fn y_max(self) -> f64 {
        self.y0 + f64::from(self.area.height) / self.scale
    }

    fn to_px(self, x: f64, y: f64) -> Point {
        px(
            f64::from(self.area.x) + (x - self.x0) * self.scale,
            f64::from(self.area.y + self.area.height) - (y - self.y0) * self.scale,
        )
    }
}

/// The points a figure of the flight must contain: the UAV's and the pad's paths, the
/// obstacles' corners and the pad's outline at touchdown (at the pad's height).
fn scene_points(log: &FlightLog) -> Vec<[f64; 3]> {
    let mut pts: Vec<[f64; 3]> = Vec::new();
    for s in &log.samples {
        pts.push(s.uav);
        pts.extend(s.ugv_pad);
    }
    for (lo, hi) in &log.obstacles {
        pts.push(*lo);
        pts.push(*hi);
    }
    if let Some(td) = &log.touchdown {
        pts.extend(pad_corners(log, td).map(|c| [c[0], c[1], td.pad[2]]));
    }
    pts
}

/// Everything the x-y extent of a figure must include.
fn xy_points(log: &FlightLog) -> Vec<[f64; 2]> {
    scene_points(log).iter().map(|p| [p[0], p[1]]).collect()
}

/// The pad vehicle's path, the pad at touchdown (filled with `pad_fill`, when given) and
/// the UAV's path, each segment in the colour of the phase it starts in, drawn through
/// `project`: the top view and the 3-D view differ only in it.
fn draw_paths(
    cv: &mut Canvas,
    log: &FlightLog,
    phases: &[(String, Scalar)],
    project: impl Fn([f64; 3]) -> Point,
    pad_fill: Option<Scalar>,
) -> opencv::Result<()> {
    let ugv: Vec<Point> = log
        .samples
        .iter()
        .filter_map(|s| s.ugv_pad.map(&project))
        .collect();
    if ugv.len() > 1 {
        cv.polyline(&ugv, false, ugv_colour(), 2)?;
    }
    if let Some(td) = &log.touchdown {
        let corners: Vec<Point> = pad_corners(log, td)
            .iter()
            .map(|c| project([c[0], c[1], td.pad[2]]))
            .collect();
        if let Some(fill) = pad_fill {
            cv.fill_poly(&corners, fill)?;
        }
        cv.polyline(&corners, true, black(), 2)?;
    }
    for w in log.samples.windows(2) {
        let c = colour_of(phases, &w[0].phase);
        cv.line(project(w[0].uav), project(w[1].uav), c, 2)?;
    }
    Ok(())
}

/// The top view's plot area inside [`FIGURE_SIZE`] (room for title, axes and legend).
fn top_area() -> Rect {
    Rect::new(90, 60, FIGURE_SIZE.0 - 90 - 260, FIGURE_SIZE.1 - 60 - 70)
}

fn draw_top(log: &FlightLog) -> opencv::Result<Canvas> {
    let mut cv = Canvas::new(FIGURE_SIZE)?;
    let area = top_area();
    let f = TopFrame::fit(&xy_points(log), area);
    let phases = phase_colours(log);

    // Grid and ticks.
    let step = nice_step((f.x_max() - f.x0).max(f.y_max() - f.y0), 10.0);
    for x in ticks(f.x0, f.x_max(), step) {
        let a = f.to_px(x, f.y0);
        let b = f.to_px(x, f.y_max());
        cv.line(a, b, grey(232.0), 1)?;
        cv.line(a, a + Point::new(0, 6), black(), 1)?;
        cv.text(
            &tick_label(x, step),
            a + Point::new(0, 22),
            0.45,
            black(),
            0.5,
        )?;
    }
    for y in ticks(f.y0, f.y_max(), step) {
        let a = f.to_px(f.x0, y);
        let b = f.to_px(f.x_max(), y);
        cv.line(a, b, grey(232.0), 1)?;
        cv.line(a, a - Point::new(6, 0), black(), 1)?;
        cv.text(
            &tick_label(y, step),
            a + Point::new(-10, 5),
            0.45,
            black(),
            1.0,
        )?;
    }
    cv.text(
        "x [m]",
        Point::new(area.x + area.width / 2, area.y + area.height + 52),
        0.55,
        black(),
        0.5,
    )?;
    cv.text_vertical("y [m]", Point::new(24, area.y + area.height / 2), 0.55)?;

    // Obstacles, filled.
    for (lo, hi) in &log.obstacles {
        let r = Rect::from_points(f.to_px(lo[0], hi[1]), f.to_px(hi[0], lo[1]));
        cv.rect(r, grey(185.0), imgproc::FILLED)?;
        cv.rect(r, grey(110.0), 1)?;
    }

    // Pad vehicle path, pad outline at touchdown, UAV path.
    draw_paths(&mut cv, log, &phases, |p| f.to_px(p[0], p[1]), None)?;

    // Markers on top.
    if let Some(p) = log.samples.iter().find_map(|s| s.ugv_pad) {
        Marker::Square(grey(200.0)).draw(&mut cv, f.to_px(p[0], p[1]))?;
    }
    if let Some(s) = log.samples.first() {
        let c = colour_of(&phases, &s.phase);
        Marker::Start(c).draw(&mut cv, f.to_px(s.uav[0], s.uav[1]))?;
    }
    if let Some(td) = &log.touchdown {
        Marker::Touchdown.draw(&mut cv, f.to_px(td.uav[0], td.uav[1]))?;
    }

    cv.rect(area, black(), 1)?;
    cv.text(&title(log), Point::new(area.x, 28), 0.65, black(), 0.0)?;
    cv.text(
        "top view (x-y), equal scale",
        Point::new(area.x, 50),
        0.45,
        grey(90.0),
        0.0,
    )?;
    let rows = legend_rows(log, &phases);
    cv.legend(Point::new(area.x + area.width + 15, area.y), &rows)?;
    Ok(cv)
}

/// World to pixels of the oblique (orthographic) 3-D view.
#[derive(Debug, Clone, Copy)]
struct IsoFrame {
    /// Screen-right and screen-up directions in the world (z already stretched).
    right: [f64; 3],
    up: [f64; 3],
    /// Height stretch (>= 1).
    z_scale: f64,
    /// Pixels per (stretched) metre, and the pixel of the projected origin.
    scale: f64,
    origin: (f64, f64),
}

impl IsoFrame {
    /// The view of the box `lo..hi` (which sets the height stretch) that fits `points`
    /// (what is drawn) into `area`.
    fn fit(lo: [f64; 3], hi: [f64; 3], points: &[[f64; 3]], area: Rect) -> Self {
        let az = ISO_AZIMUTH_DEG.to_radians();
        let el = ISO_ELEVATION_DEG.to_radians();
        let right = [-az.sin(), az.cos(), 0.0];
        let up = [-az.cos() * el.sin(), -az.sin() * el.sin(), el.cos()];
        let horiz = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        let zspan = (hi[2] - lo[2]).max(1e-6);
        let z_scale = (ISO_MIN_Z_FRACTION * horiz / zspan).max(1.0);
        let mut f = Self {
            right,
            up,
            z_scale,
            scale: 1.0,
            origin: (0.0, 0.0),
        };
        let (mut umin, mut umax, mut vmin, mut vmax) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for p in points.iter().filter(|p| p.iter().all(|v| v.is_finite())) {
            let (u, v) = f.project(*p);
            umin = umin.min(u);
            umax = umax.max(u);
            vmin = vmin.min(v);
            vmax = vmax.max(v);
        }
        if umin > umax {
            (umin, umax, vmin, vmax) = (-1.0, 1.0, -1.0, 1.0);
        }
        f.scale = (f64::from(area.width) / (umax - umin).max(1e-6))
            .min(f64::from(area.height) / (vmax - vmin).max(1e-6));
        let cx = f64::from(area.x) + f64::from(area.width) / 2.0;
        let cy = f64::from(area.y) + f64::from(area.height) / 2.0;
        f.origin = (
            cx - (umin + umax) / 2.0 * f.scale,
            cy + (vmin + vmax) / 2.0 * f.scale,
        );
        f
    }

    /// Screen coordinates before scaling (right, up).
    fn project(self, p: [f64; 3]) -> (f64, f64) {
        let q = [p[0], p[1], p[2] * self.z_scale];
        let dot = |a: [f64; 3]| a[0] * q[0] + a[1] * q[1] + a[2] * q[2];
        (dot(self.right), dot(self.up))
    }

    fn to_px(self, p: [f64; 3]) -> Point {
        let (u, v) = self.project(p);
        px(
            self.origin.0 + u * self.scale,
            self.origin.1 - v * self.scale,
        )
    }
}

/// The world box a 3-D figure shows (everything drawn, the ground included, padded) and
/// the points that must fit in the picture: the ground's corners, the top of the height
/// axis, the paths and the obstacles.
fn world_box(log: &FlightLog) -> ([f64; 3], [f64; 3], Vec<[f64; 3]>) {
    let (mut lo, mut hi) = ([f64::MAX; 3], [f64::MIN; 3]);
    let mut add = |p: [f64; 3]| {
        if p.iter().all(|v| v.is_finite()) {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
    };
    for p in scene_points(log) {
        add(p);
    }
    if lo[0] > hi[0] {
        (lo, hi) = ([-1.0, -1.0, 0.0], [1.0, 1.0, 1.0]);
    }
    for k in 0..2 {
        let pad = ((hi[k] - lo[k]) * 0.05).max(0.5);
        lo[k] -= pad;
        hi[k] += pad;
    }
    lo[2] = lo[2].min(0.0);
    hi[2] = hi[2].max(lo[2] + 1.0);
    let mut pts: Vec<[f64; 3]> = log.samples.iter().map(|s| s.uav).collect();
    pts.extend(log.samples.iter().filter_map(|s| s.ugv_pad));
    for (a, b) in &log.obstacles {
        for i in 0..8 {
            pts.push([
                if i & 1 == 0 { a[0] } else { b[0] },
                if i & 2 == 0 { a[1] } else { b[1] },
                if i & 4 == 0 { a[2] } else { b[2] },
            ]);
        }
    }
    for (x, y) in [
        (lo[0], lo[1]),
        (hi[0], lo[1]),
        (hi[0], hi[1]),
        (lo[0], hi[1]),
    ] {
        pts.push([x, y, lo[2]]);
    }
    pts.push([lo[0], lo[1], hi[2]]);
    (lo, hi, pts)
}

/// The 3-D view's plot area inside [`FIGURE_SIZE`].
fn iso_area() -> Rect {
    Rect::new(90, 75, FIGURE_SIZE.0 - 90 - 290, FIGURE_SIZE.1 - 75 - 95)
}

/// The twelve edges of a box, as corner index pairs (bit 0: x, bit 1: y, bit 2: z).
const BOX_EDGES: [(usize, usize); 12] = [
    (0, 1),
    (2, 3),
    (4, 5),
    (6, 7),
    (0, 2),
    (1, 3),
    (4, 6),
    (5, 7),
    (0, 4),
    (1, 5),
    (2, 6),
    (3, 7),
];

fn draw_iso(log: &FlightLog) -> opencv::Result<Canvas> {
    let mut cv = Canvas::new(FIGURE_SIZE)?;
    let area = iso_area();
    let (lo, hi, pts) = world_box(log);
    let f = IsoFrame::fit(lo, hi, &pts, area);
    let phases = phase_colours(log);
    let g = lo[2].min(0.0);

    // Ground grid with tick labels along the front edges (y = lo, x = hi).
    // One grid step for both axes (square cells), a finer one on a short axis.
    let xstep = nice_step((hi[0] - lo[0]).max(hi[1] - lo[1]), 10.0);
    let ystep = nice_step(hi[1] - lo[1], 4.0).min(xstep);
    let xs = ticks(lo[0], hi[0], xstep);
    let ys = ticks(lo[1], hi[1], ystep);
    for &x in &xs {
        cv.line(
            f.to_px([x, lo[1], g]),
            f.to_px([x, hi[1], g]),
            grey(225.0),
            1,
        )?;
        let a = f.to_px([x, lo[1], g]);
        cv.text(
            &tick_label(x, xstep),
            a + Point::new(-4, 20),
            0.42,
            black(),
            0.5,
        )?;
    }
    for &y in &ys {
        cv.line(
            f.to_px([lo[0], y, g]),
            f.to_px([hi[0], y, g]),
            grey(225.0),
            1,
        )?;
        let a = f.to_px([hi[0], y, g]);
        cv.text(
            &tick_label(y, ystep),
            a + Point::new(8, 14),
            0.42,
            black(),
            0.0,
        )?;
    }
    let ground = [
        f.to_px([lo[0], lo[1], g]),
        f.to_px([hi[0], lo[1], g]),
        f.to_px([hi[0], hi[1], g]),
        f.to_px([lo[0], hi[1], g]),
    ];
    cv.polyline(&ground, true, grey(150.0), 1)?;
    // Vertical axis at the left-front corner.
    let zstep = nice_step(hi[2] - g, 5.0);
    let base = f.to_px([lo[0], lo[1], g]);
    cv.line(base, f.to_px([lo[0], lo[1], hi[2]]), black(), 1)?;
    for z in ticks(g, hi[2], zstep) {
        let a = f.to_px([lo[0], lo[1], z]);
        cv.line(a, a - Point::new(6, 0), black(), 1)?;
        cv.text(
            &tick_label(z, zstep),
            a + Point::new(-10, 5),
            0.42,
            black(),
            1.0,
        )?;
    }
    let mid_x = f.to_px([(lo[0] + hi[0]) / 2.0, lo[1], g]);
    cv.text("x [m]", mid_x + Point::new(-20, 45), 0.55, black(), 0.5)?;
    let mid_y = f.to_px([hi[0], (lo[1] + hi[1]) / 2.0, g]);
    cv.text("y [m]", mid_y + Point::new(45, 35), 0.55, black(), 0.0)?;
    let top_z = f.to_px([lo[0], lo[1], hi[2]]);
    cv.text("z [m]", top_z + Point::new(0, -12), 0.55, black(), 0.5)?;

    // UAV shadow on the ground: where it flew over.
    let shadow: Vec<Point> = log
        .samples
        .iter()
        .map(|s| f.to_px([s.uav[0], s.uav[1], g]))
        .collect();
    if shadow.len() > 1 {
        cv.polyline(&shadow, false, grey(205.0), 1)?;
    }

    // Obstacles as wireframes.
    for (a, b) in &log.obstacles {
        let corner = |i: usize| {
            f.to_px([
                if i & 1 == 0 { a[0] } else { b[0] },
                if i & 2 == 0 { a[1] } else { b[1] },
                if i & 4 == 0 { a[2] } else { b[2] },
            ])
        };
        for (i, j) in BOX_EDGES {
            cv.line(corner(i), corner(j), grey(95.0), 2)?;
        }
    }

    // Pad vehicle path (pad centre height), the pad at touchdown, the UAV path in 3-D.
    draw_paths(&mut cv, log, &phases, |p| f.to_px(p), Some(grey(235.0)))?;

    if let Some(p) = log.samples.iter().find_map(|s| s.ugv_pad) {
        Marker::Square(grey(200.0)).draw(&mut cv, f.to_px(p))?;
    }
    if let Some(s) = log.samples.first() {
        Marker::Start(colour_of(&phases, &s.phase)).draw(&mut cv, f.to_px(s.uav))?;
    }
    if let Some(td) = &log.touchdown {
        Marker::Touchdown.draw(&mut cv, f.to_px(td.uav))?;
    }

    cv.text(&title(log), Point::new(40, 28), 0.65, black(), 0.0)?;
    let note = if f.z_scale > 1.01 {
        format!("3-D view, heights stretched x{:.1}", f.z_scale)
    } else {
        "3-D view".to_string()
    };
    cv.text(&note, Point::new(40, 50), 0.45, grey(90.0), 0.0)?;
    let rows = legend_rows(log, &phases);
    cv.legend(Point::new(FIGURE_SIZE.0 - 265, 70), &rows)?;
    Ok(cv)
}

/// Makes `dir` (and its parents) unless it exists.
fn ensure_dir(dir: &Path) -> Result<(), PlotError> {
    std::fs::create_dir_all(dir).map_err(|error| PlotError::CreateDir {
        path: dir.to_path_buf(),
        error,
    })
}

/// Writes `top.png` (x-y view) and `3d.png` (oblique view) of the flight into `dir`
/// (created if missing); returns their paths.
pub fn write_plots(dir: &Path, log: &FlightLog) -> Result<Vec<PathBuf>, PlotError> {
    let top_path = dir.join(TOP_FILE);
    if log.samples.is_empty() {
        return Err(PlotError::NoData {
            path: top_path,
            what: "the flight log has no samples",
        });
    }
    ensure_dir(dir)?;
    let fail = |path: &Path| {
        let path = path.to_path_buf();
        move |e: opencv::Error| PlotError::Write {
            path,
            reason: e.to_string(),
        }
    };
    draw_top(log).map_err(fail(&top_path))?.write(&top_path)?;
    let iso_path = dir.join(ISO_FILE);
    draw_iso(log).map_err(fail(&iso_path))?.write(&iso_path)?;
    Ok(vec![top_path, iso_path])
}

/// Bars of the histogram: linear bins from `lo` to `hi`; values above `hi` land in the
/// last bin (counted separately as overflow).
struct Bins {
    lo: f64,
    hi: f64,
    counts: Vec<u64>,
    overflow: u64,
}

/// How many bars a histogram has.
const HISTOGRAM_BINS: usize = 60;

fn bin(values: &[f64]) -> Bins {
    let p99 = percentile(values, 99.0);
    let max = values.iter().copied().fold(f64::MIN, f64::max);
    let min = values.iter().copied().fold(f64::MAX, f64::min);
    // A long tail would squeeze the body into a few bars: cut at 1.5 x p99 then.
    let hi_raw = if max > 3.0 * p99 && p99 > 0.0 {
        1.5 * p99
    } else {
        max
    };
    let span = (hi_raw - min).max(hi_raw.abs() * 0.1).max(1e-3);
    let step = nice_step(span, 8.0);
    let lo = if min >= 0.0 && min < span * 0.5 {
        0.0
    } else {
        (min / step).floor() * step
    };
    let hi = ((hi_raw / step).ceil() * step).max(lo + step);
    let mut counts = vec![0u64; HISTOGRAM_BINS];
    let mut overflow = 0;
    let width = (hi - lo) / HISTOGRAM_BINS as f64;
    for &v in values {
        let k = ((v - lo) / width).floor();
        let k = if k < 0.0 { 0 } else { k as usize };
        if v > hi {
            overflow += 1;
        }
        counts[k.min(HISTOGRAM_BINS - 1)] += 1;
    }
    Bins {
        lo,
        hi,
        counts,
        overflow,
    }
}

/// Writes a latency histogram of `values_ms` to `path` (PNG): linear bins, counts on a
/// log scale (tails stay visible), the median and 99th percentile marked; non-finite
/// values are left out. The parent directory is created if missing.
pub fn write_histogram(path: &Path, title: &str, values_ms: &[f64]) -> Result<(), PlotError> {
    let values: Vec<f64> = values_ms
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    if values.is_empty() {
        return Err(PlotError::NoData {
            path: path.to_path_buf(),
            what: "no finite values",
        });
    }
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        ensure_dir(dir)?;
    }
    draw_histogram(title, &values)
        .map_err(|e| PlotError::Write {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?
        .write(path)
}

/// Pixel geometry of a histogram: value to x, count to y (log).
struct HistFrame {
    area: Rect,
    lo: f64,
    hi: f64,
    /// log10 of the largest count (>= 1 decade shown).
    decades: f64,
}

/// Count 1 gets this fraction of a decade of height so that single values show.
const ONE_COUNT_DECADES: f64 = 0.3;

impl HistFrame {
    fn x(&self, v: f64) -> i32 {
        let t = (v - self.lo) / (self.hi - self.lo);
        (f64::from(self.area.x) + t * f64::from(self.area.width)).round() as i32
    }

    fn y(&self, count: f64) -> i32 {
        let bottom = f64::from(self.area.y + self.area.height);
        if count < 1.0 {
            return bottom as i32;
        }
        let h = (count.log10() + ONE_COUNT_DECADES) / (self.decades + ONE_COUNT_DECADES);
        (bottom - h * f64::from(self.area.height)).round() as i32
    }
}

/// Bar colour of the histogram.
fn bar_colour() -> Scalar {
    bgr(PHASE_BGR[0])
}

fn hist_area() -> Rect {
    Rect::new(
        80,
        60,
        HISTOGRAM_SIZE.0 - 80 - 30,
        HISTOGRAM_SIZE.1 - 60 - 70,
    )
}

fn draw_histogram(title: &str, values: &[f64]) -> opencv::Result<Canvas> {
    let mut cv = Canvas::new(HISTOGRAM_SIZE)?;
    let area = hist_area();
    let b = bin(values);
    let cmax = b.counts.iter().copied().max().unwrap_or(1).max(1) as f64;
    let f = HistFrame {
        area,
        lo: b.lo,
        hi: b.hi,
        decades: cmax.log10().ceil().max(1.0),
    };
    // Count grid: 1, 10, 100, ...
    let mut c = 1.0;
    while c <= 10f64.powf(f.decades) {
        let y = f.y(c);
        cv.line(
            Point::new(area.x, y),
            Point::new(area.x + area.width, y),
            grey(230.0),
            1,
        )?;
        cv.line(Point::new(area.x - 6, y), Point::new(area.x, y), black(), 1)?;
        cv.text(
            &format!("{c:.0}"),
            Point::new(area.x - 10, y + 5),
            0.42,
            black(),
            1.0,
        )?;
        c *= 10.0;
    }
    // Bars.
    let width = (b.hi - b.lo) / b.counts.len() as f64;
    for (k, &n) in b.counts.iter().enumerate() {
        if n == 0 {
            continue;
        }
        let x0 = f.x(b.lo + width * k as f64);
        let x1 = f.x(b.lo + width * (k + 1) as f64);
        let y = f.y(n as f64);
        let r = Rect::new(x0, y, (x1 - x0 - 1).max(1), area.y + area.height - y);
        cv.rect(r, bar_colour(), imgproc::FILLED)?;
    }
    // Value axis.
    let step = nice_step(b.hi - b.lo, 8.0);
    for v in ticks(b.lo, b.hi, step) {
        let x = f.x(v);
        let y = area.y + area.height;
        cv.line(Point::new(x, y), Point::new(x, y + 6), black(), 1)?;
        cv.text(
            &tick_label(v, step),
            Point::new(x, y + 22),
            0.42,
            black(),
            0.5,
        )?;
    }
    cv.rect(area, black(), 1)?;
    cv.text(
        "latency [ms]",
        Point::new(area.x + area.width / 2, area.y + area.height + 50),
        0.5,
        black(),
        0.5,
    )?;
    cv.text_vertical("count (log)", Point::new(22, area.y + area.height / 2), 0.5)?;

    // Percentiles.
    let p50 = percentile(values, 50.0);
    let p99 = percentile(values, 99.0);
    let marks = [
        (
            p50,
            format!("p50 {}", fmt_ms(p50)),
            Scalar::new(40.0, 150.0, 40.0, 0.0),
            0,
        ),
        (
            p99,
            format!("p99 {}", fmt_ms(p99)),
            Scalar::new(40.0, 40.0, 210.0, 0.0),
            1,
        ),
    ];
    for (v, label, colour, row) in marks {
        let x = f.x(v.clamp(b.lo, b.hi));
        cv.dashed(
            Point::new(x, area.y),
            Point::new(x, area.y + area.height),
            colour,
            2,
        )?;
        let y = area.y + 18 + 20 * row;
        let right = x > area.x + area.width - 120;
        let at = if right {
            Point::new(x - 6, y)
        } else {
            Point::new(x + 6, y)
        };
        cv.text(&label, at, 0.48, colour, if right { 1.0 } else { 0.0 })?;
    }

    let mean = values.iter().sum::<f64>() / values.len() as f64;
    let max = values.iter().copied().fold(f64::MIN, f64::max);
    cv.text(title, Point::new(area.x, 28), 0.6, black(), 0.0)?;
    let mut stats = format!(
        "n {}   mean {}   max {}",
        values.len(),
        fmt_ms(mean),
        fmt_ms(max)
    );
    if b.overflow > 0 {
        stats.push_str(&format!(
            "   ({} above {} in the last bar)",
            b.overflow,
            fmt_ms(b.hi)
        ));
    }
    cv.text(&stats, Point::new(area.x, 50), 0.45, grey(60.0), 0.0)?;
    Ok(cv)
}

/// Milliseconds with three significant digits or so.
fn fmt_ms(v: f64) -> String {
    let a = v.abs();
    if a >= 100.0 {
        format!("{v:.0} ms")
    } else if a >= 10.0 {
        format!("{v:.1} ms")
    } else if a >= 1.0 {
        format!("{v:.2} ms")
    } else {
        format!("{v:.3} ms")
    }
}

#[cfg(test)]
#[path = "plot_test.rs"]
mod tests;
