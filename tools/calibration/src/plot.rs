//! The calibration's figure: where in the image the fit saw corners (one colour per
//! view, the 8 x 6 coverage cells without a corner shaded), and each view's RMS
//! reprojection error as a bar, with the totals and the rejected views written under it.

use std::path::Path;

use opencv::core::{CV_8UC3, Mat, Point, Rect, Scalar, Vector};
use opencv::{imgcodecs, imgproc};

use crate::camera::Calibrated;

fn colour(i: usize) -> Scalar {
    const PALETTE: [(f64, f64, f64); 8] = [
        (31.0, 119.0, 180.0),
        (255.0, 127.0, 14.0),
        (44.0, 160.0, 44.0),
        (214.0, 39.0, 40.0),
        (148.0, 103.0, 189.0),
        (140.0, 86.0, 75.0),
        (227.0, 119.0, 194.0),
        (23.0, 190.0, 207.0),
    ];
    let (r, g, b) = PALETTE[i % PALETTE.len()];
    Scalar::new(b, g, r, 0.0)
}

fn text(img: &mut Mat, s: &str, at: Point, scale: f64) -> opencv::Result<()> {
    imgproc::put_text(
        img,
        s,
        at,
        imgproc::FONT_HERSHEY_SIMPLEX,
        scale,
        Scalar::all(20.0),
        1,
        imgproc::LINE_AA,
        false,
    )
}

/// Draws `c` into a PNG at `path`.
pub fn write(path: &Path, c: &Calibrated) -> opencv::Result<()> {
    let (w, h) = (c.calibration.width as i32, c.calibration.height as i32);
    let scale = 900.0 / f64::from(w.max(1));
    let (iw, ih) = (900, (f64::from(h) * scale).round() as i32);
    let bars_h = 220;
    let notes = 30 + 22 * (c.rejected.len().min(8) as i32 + 2);
    let (fw, fh) = (iw + 80, ih + bars_h + notes + 80);
    let mut img = Mat::new_rows_cols_with_default(fh, fw, CV_8UC3, Scalar::all(255.0))?;
    let origin = Point::new(40, 50);
    text(
        &mut img,
        "ChArUco corners used (one colour per view); grey: cells without a corner",
        Point::new(40, 30),
        0.55,
    )?;
    // Coverage cells.
    let mut seen = [[false; 8]; 6];
    for (x, y) in c.corners.iter().flatten() {
        let cx = (f64::from(*x) / f64::from(w) * 8.0).floor();
        let cy = (f64::from(*y) / f64::from(h) * 6.0).floor();
        if (0.0..8.0).contains(&cx) && (0.0..6.0).contains(&cy) {
            seen[cy as usize][cx as usize] = true;
        }
    }
    for (r, row) in seen.iter().enumerate() {
        for (k, s) in row.iter().enumerate() {
            let cell = Rect::new(
                origin.x + k as i32 * iw / 8,
                origin.y + r as i32 * ih / 6,
                iw / 8,
                ih / 6,
            );
            if !s {
                imgproc::rectangle(&mut img, cell, Scalar::all(215.0), -1, imgproc::LINE_8, 0)?;
            }
            imgproc::rectangle(&mut img, cell, Scalar::all(180.0), 1, imgproc::LINE_8, 0)?;
        }
    }
    imgproc::rectangle(
        &mut img,
        Rect::new(origin.x, origin.y, iw, ih),
        Scalar::all(0.0),
        1,
        imgproc::LINE_8,
        0,
    )?;
    for (i, view) in c.corners.iter().enumerate() {
        for (x, y) in view {
            let p = Point::new(
                origin.x + (f64::from(*x) * scale) as i32,
                origin.y + (f64::from(*y) * scale) as i32,
            );
            imgproc::circle(&mut img, p, 2, colour(i), -1, imgproc::LINE_AA, 0)?;
        }
    }
    // Per-view errors.
    let top = origin.y + ih + 40;
    let max = c
        .per_view_px
        .iter()
        .map(|(_, e)| *e)
        .filter(|e| e.is_finite())
        .fold(0.1f64, f64::max);
    text(
        &mut img,
        &format!("RMS reprojection error per view, px (max {max:.3})"),
        Point::new(40, top - 10),
        0.55,
    )?;
    let n = c.per_view_px.len().max(1) as i32;
    let bw = (iw / n).max(2);
    for (i, (_, e)) in c.per_view_px.iter().enumerate() {
        let bh = if e.is_finite() {
            (e / max * f64::from(bars_h - 40)) as i32
        } else {
            0
        };
        let r = Rect::new(
            origin.x + i as i32 * bw,
            top + bars_h - 40 - bh,
            (bw - 2).max(1),
            bh.max(1),
        );
        imgproc::rectangle(&mut img, r, colour(i), -1, imgproc::LINE_8, 0)?;
    }
    let k = &c.calibration;
    let mut y = top + bars_h;
    let summary = format!(
        "{} views used, {} rejected; RMS {:.3} px; coverage {:.0} %; fx {:.2} fy {:.2} cx {:.2} cy {:.2}",
        c.per_view_px.len(),
        c.rejected.len(),
        c.rms_px,
        c.coverage * 100.0,
        k.fx,
        k.fy,
        k.cx,
        k.cy
    );
    text(&mut img, &summary, Point::new(40, y), 0.5)?;
    for r in c.rejected.iter().take(8) {
        y += 22;
        text(
            &mut img,
            &format!("rejected {}: {}", r.name, r.why),
            Point::new(40, y),
            0.45,
        )?;
    }
    if c.rejected.len() > 8 {
        y += 22;
        text(
            &mut img,
            &format!("... and {} more", c.rejected.len() - 8),
            Point::new(40, y),
            0.45,
        )?;
    }
    imgcodecs::imwrite(&*path.to_string_lossy(), &img, &Vector::new()).map(|_| ())
}
