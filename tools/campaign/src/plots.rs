//! A campaign's figures, per scenario: where every run came down on the 84 cm board, the
//! touchdown error's cumulative distribution, and the speeds at first contact against the
//! referee's limits. (The worst runs' tracks are drawn by flying them again: a run's seed
//! flies it the same on every machine.)

use std::path::{Path, PathBuf};

use opencv::core::{Mat, Point, Scalar, Vector};
use opencv::{core, imgcodecs, imgproc};

use crate::record::RunRecord;
use crate::table::quantile;

/// Why a figure could not be written.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// OpenCV drawing or encoding.
    #[error("drawing {path}: {error}")]
    Draw {
        /// The figure.
        path: PathBuf,
        /// What OpenCV said.
        error: opencv::Error,
    },
    /// The file system.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What the OS said.
        error: std::io::Error,
    },
}

const SIZE: i32 = 720;
const MARGIN: i32 = 70;

fn colour_of(outcome: &str) -> Scalar {
    match outcome {
        "landed" => Scalar::new(60.0, 150.0, 40.0, 0.0),
        "crashed" | "hard_landing" => Scalar::new(30.0, 30.0, 200.0, 0.0),
        _ => Scalar::new(0.0, 140.0, 230.0, 0.0),
    }
}

fn black() -> Scalar {
    Scalar::new(0.0, 0.0, 0.0, 0.0)
}

fn grey() -> Scalar {
    Scalar::new(170.0, 170.0, 170.0, 0.0)
}

/// A square canvas mapping [lo, hi] x [lo, hi] (data units) onto the plot area.
struct Canvas {
    img: Mat,
    x: [f64; 2],
    y: [f64; 2],
}

impl Canvas {
    fn new(x: [f64; 2], y: [f64; 2]) -> opencv::Result<Self> {
        let img = Mat::new_rows_cols_with_default(
            SIZE,
            SIZE,
            core::CV_8UC3,
            Scalar::new(255.0, 255.0, 255.0, 0.0),
        )?;
        Ok(Self { img, x, y })
    }

    fn at(&self, x: f64, y: f64) -> Point {
        let span = f64::from(SIZE - 2 * MARGIN);
        let u = (x - self.x[0]) / (self.x[1] - self.x[0]);
        let v = (y - self.y[0]) / (self.y[1] - self.y[0]);
        Point::new(
            MARGIN + (u * span).round() as i32,
            SIZE - MARGIN - (v * span).round() as i32,
        )
    }

    fn text(&mut self, s: &str, at: Point, scale: f64) -> opencv::Result<()> {
        imgproc::put_text(
            &mut self.img,
            s,
            at,
            imgproc::FONT_HERSHEY_SIMPLEX,
            scale,
            black(),
            1,
            imgproc::LINE_AA,
            false,
        )
    }

    fn line(&mut self, a: [f64; 2], b: [f64; 2], c: Scalar, w: i32) -> opencv::Result<()> {
        let (p, q) = (self.at(a[0], a[1]), self.at(b[0], b[1]));
        imgproc::line(&mut self.img, p, q, c, w, imgproc::LINE_AA, 0)
    }

    fn dot(&mut self, x: f64, y: f64, c: Scalar) -> opencv::Result<()> {
        let p = self.at(x, y);
        imgproc::circle(&mut self.img, p, 4, c, -1, imgproc::LINE_AA, 0)
    }

    fn frame(&mut self, title: &str, xl: &str, yl: &str) -> opencv::Result<()> {
        let (x, y) = (self.x, self.y);
        for (a, b) in [([x[0], y[0]], [x[1], y[0]]), ([x[0], y[0]], [x[0], y[1]])] {
            self.line(a, b, black(), 1)?;
        }
        for k in 0..=4 {
            let f = f64::from(k) / 4.0;
            let (vx, vy) = (x[0] + (x[1] - x[0]) * f, y[0] + (y[1] - y[0]) * f);
            let px = self.at(vx, y[0]);
            self.text(&format!("{vx:.2}"), Point::new(px.x - 16, px.y + 20), 0.4)?;
            let py = self.at(x[0], vy);
            self.text(&format!("{vy:.2}"), Point::new(py.x - 50, py.y + 4), 0.4)?;
        }
        self.text(title, Point::new(MARGIN, 36), 0.6)?;
        self.text(xl, Point::new(SIZE / 2 - 60, SIZE - 22), 0.5)?;
        self.text(yl, Point::new(8, MARGIN - 12), 0.5)
    }

    fn write(&self, path: &Path) -> Result<(), PlotError> {
        let mut buf = Vector::<u8>::new();
        imgcodecs::imencode(".png", &self.img, &mut buf, &Vector::new()).map_err(|error| {
            PlotError::Draw {
                path: path.to_path_buf(),
                error,
            }
        })?;
        std::fs::write(path, buf.as_slice()).map_err(|error| PlotError::Io {
            path: path.to_path_buf(),
            error,
        })
    }
}

fn draw(path: &Path, f: impl FnOnce() -> opencv::Result<Canvas>) -> Result<(), PlotError> {
    f().map_err(|error| PlotError::Draw {
        path: path.to_path_buf(),
        error,
    })?
    .write(path)
}

/// Half the board's side, m (the 84 cm board).
const BOARD_HALF_M: f64 = 0.42;

/// Writes the scenario's figures into `dir`: `NAME-touchdowns.png`, `NAME-error-cdf.png`,
/// `NAME-contact.png`. Returns their paths.
pub fn write(dir: &Path, name: &str, runs: &[&RunRecord]) -> Result<Vec<PathBuf>, PlotError> {
    std::fs::create_dir_all(dir).map_err(|error| PlotError::Io {
        path: dir.to_path_buf(),
        error,
    })?;
    let n = runs.len();
    let touchdowns = dir.join(format!("{name}-touchdowns.png"));
    draw(&touchdowns, || {
        let h = BOARD_HALF_M * 1.25;
        let mut c = Canvas::new([-h, h], [-h, h])?;
        let b = BOARD_HALF_M;
        for (a, z) in [
            ([-b, -b], [b, -b]),
            ([b, -b], [b, b]),
            ([b, b], [-b, b]),
            ([-b, b], [-b, -b]),
        ] {
            c.line(a, z, grey(), 2)?;
        }
        c.line([-0.03, 0.0], [0.03, 0.0], grey(), 1)?;
        c.line([0.0, -0.03], [0.0, 0.03], grey(), 1)?;
        for r in runs {
            if let Some([x, y]) = r.touchdown_pad_m {
                c.dot(x, y, colour_of(&r.outcome))?;
            }
        }
        c.frame(
            &format!("{name}: {n} touchdowns on the 84 cm board"),
            "x along the vehicle's heading, m",
            "y left, m",
        )?;
        Ok(c)
    })?;
    let cdf = dir.join(format!("{name}-error-cdf.png"));
    let errors: Vec<f64> = runs
        .iter()
        .filter(|r| r.outcome == "landed")
        .filter_map(|r| r.touchdown_error_m)
        .collect();
    draw(&cdf, || {
        let top = quantile(&errors, 1.0).unwrap_or(0.1).max(0.05) * 1.1;
        let mut c = Canvas::new([0.0, top], [0.0, 1.0])?;
        let mut sorted = errors.clone();
        sorted.sort_by(f64::total_cmp);
        let m = sorted.len().max(1) as f64;
        let mut last = [0.0, 0.0];
        for (i, e) in sorted.iter().enumerate() {
            let p = [*e, (i + 1) as f64 / m];
            c.line(last, [*e, last[1]], colour_of("landed"), 2)?;
            c.line([*e, last[1]], p, colour_of("landed"), 2)?;
            last = p;
        }
        for (q, label) in [(0.5, "p50"), (0.95, "p95")] {
            if let Some(v) = quantile(&errors, q) {
                c.line([v, 0.0], [v, q], grey(), 1)?;
                let at = c.at(v, q);
                c.text(
                    &format!("{label} {:.1} cm", v * 100.0),
                    Point::new(at.x + 4, at.y - 4),
                    0.45,
                )?;
            }
        }
        c.frame(
            &format!("{name}: error of {} landed runs", errors.len()),
            "horizontal error from the pad centre, m",
            "fraction of runs",
        )?;
        Ok(c)
    })?;
    let contact = dir.join(format!("{name}-contact.png"));
    draw(&contact, || {
        let mut c = Canvas::new([0.0, 0.6], [0.0, 1.2])?;
        // The referee's limits: 1.0 m/s down, 0.5 m/s sideways.
        c.line([0.0, 1.0], [0.5, 1.0], colour_of("crashed"), 1)?;
        c.line([0.5, 0.0], [0.5, 1.0], colour_of("crashed"), 1)?;
        for r in runs {
            if let (Some(h), Some(v)) = (r.contact_horizontal_mps, r.contact_vertical_mps) {
                c.dot(h.min(0.6), v.min(1.2), colour_of(&r.outcome))?;
            }
        }
        c.frame(
            &format!("{name}: speed at first contact, {n} runs"),
            "sideways, m/s (limit 0.5)",
            "down, m/s (limit 1.0)",
        )?;
        Ok(c)
    })?;
    Ok(vec![touchdowns, cdf, contact])
}
