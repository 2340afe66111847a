use opencv::core::{BORDER_REPLICATE, CV_8UC1, CV_16SC2, CV_16UC1, Mat, Scalar, Vec2s};
use opencv::imgproc;
use opencv::prelude::*;

use super::{Image, sample, sample_scalar};
use crate::rng::Pcg32;

/// What OpenCV's `remap` gives for these fixed-point points.
fn remap(image: &[u8], w: usize, h: usize, xy: &[[i16; 2]], fxy: &[u16]) -> Vec<u8> {
    let n = xy.len() as i32;
    let mut src =
        Mat::new_rows_cols_with_default(h as i32, w as i32, CV_8UC1, Scalar::all(0.0)).unwrap();
    src.data_bytes_mut().unwrap().copy_from_slice(image);
    let mut m1 = Mat::new_rows_cols_with_default(1, n, CV_16SC2, Scalar::all(0.0)).unwrap();
    for (d, s) in m1.data_typed_mut::<Vec2s>().unwrap().iter_mut().zip(xy) {
        *d = Vec2s::from(*s);
    }
    let mut m2 = Mat::new_rows_cols_with_default(1, n, CV_16UC1, Scalar::all(0.0)).unwrap();
    m2.data_typed_mut::<u16>().unwrap().copy_from_slice(fxy);
    let mut dst = Mat::default();
    imgproc::remap(
        &src,
        &mut dst,
        &m1,
        &m2,
        imgproc::INTER_LINEAR,
        BORDER_REPLICATE,
        Scalar::all(0.0),
    )
    .unwrap();
    dst.data_bytes().unwrap().to_vec()
}

/// The points as the sampler takes them: (x, y) in one word, the fraction in another.
fn words(xy: &[[i16; 2]], fxy: &[u16]) -> (Vec<u32>, Vec<u32>) {
    (
        xy.iter()
            .map(|&[x, y]| u32::from(x as u16) | u32::from(y as u16) << 16)
            .collect(),
        fxy.iter().map(|&f| u32::from(f)).collect(),
    )
}

#[test]
fn sampling_gives_the_bytes_opencvs_remap_gives() {
    let (w, h) = (301, 97);
    let mut rng = Pcg32::new(11);
    let texels: Vec<u8> = (0..w * h).map(|_| (rng.uniform() * 256.0) as u8).collect();
    let image = Image::new(&texels, w, h);
    // Every fraction index, at random in-range texels; then extremes of the texels
    // (0 and 255 everywhere a weight could overflow) at every fraction again.
    let mut xy = Vec::new();
    let mut fxy = Vec::new();
    for round in 0..20 {
        for f in 0..1024u16 {
            let x = (rng.uniform() * (w - 1) as f64) as i16;
            let y = (rng.uniform() * (h - 1) as f64) as i16;
            xy.push(if round == 0 { [0, 0] } else { [x, y] });
            fxy.push(f);
        }
    }
    let want = remap(&texels, w, h, &xy, &fxy);
    let (xy, fxy) = words(&xy, &fxy);
    let mut got = vec![0u8; xy.len()];
    sample(&image, &xy, &fxy, &mut got);
    let mut scalar = vec![0u8; xy.len()];
    sample_scalar(&image, &xy, &fxy, &mut scalar);
    let differ = |a: &[u8]| a.iter().zip(&want).filter(|(a, b)| a != b).count();
    assert_eq!(differ(&got), 0, "of {} points", want.len());
    assert_eq!(differ(&scalar), 0, "of {} points", want.len());

    let white = Image::new(&vec![255; w * h], w, h);
    let (at, all) = words(&[[5, 7]; 1024], &(0..1024).collect::<Vec<u16>>());
    let mut out = vec![0u8; 1024];
    sample(&white, &at, &all, &mut out);
    assert!(
        out.iter().all(|&v| v == 255),
        "a white image sampled to {out:?}"
    );
}

#[test]
fn points_off_the_image_are_clamped_never_read_outside_it() {
    let image = Image::new(&[9; 16 * 4], 16, 4);
    let xy = [
        [-5i16, -5],
        [i16::MAX, i16::MAX],
        [15, 3],
        [i16::MIN, 2],
        [3, i16::MAX],
        [0, 0],
        [14, 2],
        [1, 1],
        [20, 1],
    ];
    let fxy = [1023u16, 0, 512, 77, 1, 2, 3, 65535, 4];
    let mut out = [0u8; 9];
    let (xy, fxy) = words(&xy, &fxy);
    sample(&image, &xy, &fxy, &mut out);
    assert!(out.iter().all(|&v| v == 9), "{out:?}");
}
