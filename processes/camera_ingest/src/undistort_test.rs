use nalgebra::Point2;
use optics::CameraCalibration;

use super::*;

const W: u32 = 320;
const H: u32 = 240;

fn lens() -> CameraCalibration {
    CameraCalibration::new(
        W,
        H,
        200.0,
        200.0,
        160.0,
        120.0,
        [-0.25, 0.05, 0.001, -0.001, 0.0],
    )
    .unwrap()
}

/// The image the distorted camera sees of a scene whose ideal (pinhole) image is
/// `ideal(u, v)`: each distorted pixel looks up where its ray lands in the pinhole image.
fn distorted_image(cal: &CameraCalibration, ideal: impl Fn(f64, f64) -> f64) -> Vec<u8> {
    let mut img = vec![0u8; (W * H) as usize];
    for v in 0..H {
        for u in 0..W {
            let n = cal.undistort_pixel(&Point2::new(f64::from(u), f64::from(v)));
            let (iu, iv) = (cal.fx * n.x + cal.cx, cal.fy * n.y + cal.cy);
            img[(v * W + u) as usize] = ideal(iu, iv).round().clamp(0.0, 255.0) as u8;
        }
    }
    img
}

fn blob(cu: f64, cv: f64) -> impl Fn(f64, f64) -> f64 {
    move |u, v| 255.0 * (-((u - cu).powi(2) + (v - cv).powi(2)) / (2.0 * 1.5 * 1.5)).exp()
}

/// Intensity-weighted centroid of the window of half-size `r` around (u, v).
fn centroid(img: &[u8], u: f64, v: f64, r: i64) -> (f64, f64) {
    let (mut sw, mut su, mut sv) = (0.0, 0.0, 0.0);
    for y in (v as i64 - r)..=(v as i64 + r) {
        for x in (u as i64 - r)..=(u as i64 + r) {
            let w = f64::from(img[(y * i64::from(W) + x) as usize]);
            sw += w;
            su += w * x as f64;
            sv += w * y as f64;
        }
    }
    (su / sw, sv / sw)
}

#[test]
fn undistortion_moves_a_point_to_where_the_pinhole_model_puts_it() {
    let cal = lens();
    // A point well off-axis, where this lens moves it by several pixels.
    let ideal = (250.0, 190.0);
    let seen = cal
        .project(&nalgebra::Point3::new(
            (ideal.0 - cal.cx) / cal.fx,
            (ideal.1 - cal.cy) / cal.fy,
            1.0,
        ))
        .unwrap();
    assert!(
        (seen.x - ideal.0).hypot(seen.y - ideal.1) > 5.0,
        "the lens moves the point noticeably: {seen:?}"
    );
    let input = distorted_image(&cal, blob(ideal.0, ideal.1));
    let (du, dv) = centroid(&input, seen.x, seen.y, 6);
    assert!(
        (du - seen.x).hypot(dv - seen.y) < 0.5,
        "rendered at {du},{dv}"
    );

    let mut out = vec![0u8; input.len()];
    Undistorter::new(&cal)
        .unwrap()
        .remap_into(&input, 1, &mut out)
        .unwrap();
    let (u, v) = centroid(&out, ideal.0, ideal.1, 6);
    let err = (u - ideal.0).hypot(v - ideal.1);
    assert!(
        err < 0.25,
        "undistorted point at ({u:.2}, {v:.2}), off by {err:.2} px"
    );
}

#[test]
fn an_undistorted_image_line_is_straight() {
    let cal = lens();
    // A vertical line near the left edge: the lens bows it.
    let line_u = 40.0;
    let line = move |u: f64, _v: f64| 255.0 * (-((u - line_u).powi(2)) / (2.0 * 1.2 * 1.2)).exp();
    let input = distorted_image(&cal, line);
    let column = |img: &[u8], v: u32| -> f64 {
        let row = &img[(v * W) as usize..][..W as usize];
        let (mut sw, mut su) = (0.0, 0.0);
        for (u, &p) in row.iter().enumerate().take(80) {
            sw += f64::from(p);
            su += f64::from(p) * u as f64;
        }
        su / sw
    };
    let rows = [30, 60, 120, 180, 210];
    let spread = |img: &[u8]| {
        let cols: Vec<f64> = rows.iter().map(|&v| column(img, v)).collect();
        let lo = cols.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = cols.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        (hi - lo, cols)
    };
    let (bowed, _) = spread(&input);
    assert!(bowed > 3.0, "the distorted line bows by {bowed:.2} px");

    let mut out = vec![0u8; input.len()];
    Undistorter::new(&cal)
        .unwrap()
        .remap_into(&input, 1, &mut out)
        .unwrap();
    let (straight, cols) = spread(&out);
    assert!(straight < 0.3, "undistorted line columns {cols:?}");
    assert!((cols[2] - line_u).abs() < 0.3, "{cols:?}");
}

#[test]
fn colour_frames_are_undistorted_channel_by_channel() {
    let cal = lens();
    let grey = distorted_image(&cal, blob(250.0, 190.0));
    let bgr: Vec<u8> = grey.iter().flat_map(|&p| [p, p / 2, 255 - p]).collect();
    let mut out = vec![0u8; bgr.len()];
    let u = Undistorter::new(&cal).unwrap();
    u.remap_into(&bgr, 3, &mut out).unwrap();
    let mut out_grey = vec![0u8; grey.len()];
    u.remap_into(&grey, 1, &mut out_grey).unwrap();
    let blue: Vec<u8> = out.chunks(3).map(|p| p[0]).collect();
    assert_eq!(blue, out_grey);
}

#[test]
fn a_buffer_of_the_wrong_length_is_an_error() {
    let u = Undistorter::new(&lens()).unwrap();
    let input = vec![0u8; (W * H) as usize];
    let mut out = vec![0u8; 10];
    assert!(u.remap_into(&input, 1, &mut out).is_err());
    assert!(
        u.remap_into(&input, 2, &mut vec![0u8; input.len()])
            .is_err()
    );
}
