#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test
//! `landing pad print` as a user meets it: the PNG is the board at true scale, OpenCV's
//! detector finds every marker where pad.toml puts it, the SVG is in millimetres, and
//! mistakes are one line.

mod common;
use common::landing;
use std::path::PathBuf;
use std::process::Output;

use opencv::aruco;
use opencv::core::{Mat, Point2f, Vector};
use opencv::imgcodecs;
use opencv::prelude::*;
use optics::PadModel;

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).to_string()
}

fn pad_toml() -> String {
    concat!(env!("CARGO_MANIFEST_DIR"), "/../../deploy/config/pad.toml").to_string()
}

fn pad() -> PadModel {
    PadModel::load(pad_toml()).unwrap()
}

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("landing-pad-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Prints the shipped pad at `dpi` into a fresh directory; returns (PNG, SVG) paths.
fn print(name: &str, dpi: &str) -> (PathBuf, PathBuf) {
    let dir = temp_dir(name);
    let png = dir.join("pad.png");
    let o = landing(&[
        "pad",
        "print",
        "--out",
        png.to_str().unwrap(),
        "--dpi",
        dpi,
        "--pad",
        &pad_toml(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    (png, dir.join("pad.svg"))
}

/// The chunks of a PNG file as (type, data), checking each CRC (an independent,
/// table-driven CRC-32).
fn png_chunks(bytes: &[u8]) -> Vec<([u8; 4], Vec<u8>)> {
    let table: Vec<u32> = (0..256u32)
        .map(|n| {
            (0..8).fold(n, |c, _| {
                if c & 1 == 1 {
                    0xEDB8_8320 ^ (c >> 1)
                } else {
                    c >> 1
                }
            })
        })
        .collect();
    let crc = |b: &[u8]| {
        !b.iter().fold(0xFFFF_FFFFu32, |c, &x| {
            table[((c ^ u32::from(x)) & 0xff) as usize] ^ (c >> 8)
        })
    };
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    let mut chunks = Vec::new();
    let mut at = 8;
    while at < bytes.len() {
        let len = u32::from_be_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
        let kind: [u8; 4] = bytes[at + 4..at + 8].try_into().unwrap();
        let data = bytes[at + 8..at + 8 + len].to_vec();
        let stored = u32::from_be_bytes(bytes[at + 8 + len..at + 12 + len].try_into().unwrap());
        assert_eq!(crc(&bytes[at + 4..at + 8 + len]), stored, "CRC of {kind:?}");
        chunks.push((kind, data));
        at += len + 12;
    }
    chunks
}

fn be32(b: &[u8]) -> u32 {
    u32::from_be_bytes(b[..4].try_into().unwrap())
}

#[test]
fn the_printed_png_is_the_board_at_the_requested_dpi_with_the_dpi_in_its_phys_chunk() {
    let pad = pad();
    let (w_m, h_m) = (
        pad.board.max_m[0] - pad.board.min_m[0],
        pad.board.max_m[1] - pad.board.min_m[1],
    );
    for (k, dpi) in [300.0, 72.5].into_iter().enumerate() {
        let (png, _) = print(&format!("size{k}"), &dpi.to_string());
        let chunks = png_chunks(&std::fs::read(&png).unwrap());
        assert_eq!(&chunks[0].0, b"IHDR");
        let ihdr = &chunks[0].1;
        let expect_w = (w_m / 0.0254 * dpi).round() as u32;
        let expect_h = (h_m / 0.0254 * dpi).round() as u32;
        assert_eq!(
            (be32(&ihdr[0..]), be32(&ihdr[4..])),
            (expect_w, expect_h),
            "{dpi} dpi"
        );
        assert_eq!(&chunks[1].0, b"pHYs", "pHYs right after IHDR");
        let phys = &chunks[1].1;
        let ppm = (dpi / 0.0254).round() as u32;
        assert_eq!(phys.len(), 9);
        assert_eq!((be32(&phys[0..]), be32(&phys[4..]), phys[8]), (ppm, ppm, 1));
        assert_eq!(
            chunks.iter().filter(|(t, _)| t == b"pHYs").count(),
            1,
            "one pHYs"
        );
        assert_eq!(&chunks.last().unwrap().0, b"IEND");
        // The board is centred, so the pad origin is the image centre (to rounding).
        let origin_u = -pad.board.min_m[0] * dpi / 0.0254;
        assert!((origin_u - f64::from(expect_w) / 2.0).abs() <= 0.5);
    }
}

#[test]
fn opencvs_detector_finds_every_marker_of_the_png_where_pad_toml_puts_it() {
    let pad = pad();
    let dpi = 150.0;
    let (png, _) = print("detect", "150");
    let image = imgcodecs::imread(png.to_str().unwrap(), imgcodecs::IMREAD_GRAYSCALE).unwrap();
    let ppm = dpi / 0.0254;
    assert_eq!(
        (image.cols(), image.rows()),
        pad.texture_size(ppm),
        "the board at 150 dpi"
    );
    // Exactly the texture the simulator renders, black and white only.
    let texture = pad.render_texture(ppm).unwrap();
    assert_eq!(image.data_bytes().unwrap(), texture.data_bytes().unwrap());

    let dict =
        aruco::get_predefined_dictionary(aruco::PREDEFINED_DICTIONARY_NAME::DICT_ARUCO_ORIGINAL)
            .unwrap();
    let mut corners = Vector::<Vector<Point2f>>::new();
    let mut ids = Vector::<i32>::new();
    aruco::detect_markers_def(&image, &dict, &mut corners, &mut ids).unwrap();
    let mut found: Vec<u32> = ids.iter().map(|i| i as u32).collect();
    found.sort_unstable();
    let mut expect: Vec<u32> = pad.markers.iter().map(|m| m.id).collect();
    expect.sort_unstable();
    assert_eq!(found, expect);
    for (id, c) in ids.iter().zip(corners.iter()) {
        let m = pad.marker(id as u32).unwrap();
        let (u, v) = c.iter().fold((0.0, 0.0), |(u, v), p| {
            (u + f64::from(p.x) / 4.0, v + f64::from(p.y) / 4.0)
        });
        // The documented mapping: OpenCV pixel (c, r) is centred at u = c + 0.5,
        // v = r + 0.5 from the top-left corner; right = +x, up = +y.
        let x = pad.board.min_m[0] + (u + 0.5) / ppm;
        let y = pad.board.max_m[1] - (v + 0.5) / ppm;
        let err_px = [(x - m.centre_m[0]) * ppm, (y - m.centre_m[1]) * ppm];
        assert!(
            err_px[0].abs() <= 1.0 && err_px[1].abs() <= 1.0,
            "marker {id}: centre ({x}, {y}) vs {:?}: {err_px:?} px",
            m.centre_m
        );
        // The first corner is the marker's top-left: up is +y, right is +x.
        let tl = c.get(0).unwrap();
        assert!(f64::from(tl.x) < u && f64::from(tl.y) < v, "marker {id}");
    }
}

/// The value of attribute `name` in the first tag that has it.
fn attr<'a>(text: &'a str, name: &str) -> &'a str {
    let key = format!(" {name}=\"");
    let start = text.find(&key).unwrap_or_else(|| panic!("{name}")) + key.len();
    &text[start..start + text[start..].find('"').unwrap()]
}

#[test]
fn the_svg_is_the_board_in_millimetres_with_a_scale_bar_and_every_black_cell() {
    let pad = pad();
    let (_, svg_path) = print("svg", "50");
    let svg = std::fs::read_to_string(&svg_path).unwrap();
    assert!(svg.starts_with("<?xml"), "{}", &svg[..80]);
    assert!(svg.trim_end().ends_with("</svg>"));
    for tag in ["svg", "g", "text"] {
        assert_eq!(
            svg.matches(&format!("<{tag} ")).count() + svg.matches(&format!("<{tag}>")).count(),
            svg.matches(&format!("</{tag}>")).count(),
            "<{tag}> balanced"
        );
    }
    let root = &svg[svg.find("<svg").unwrap()..];
    let w_mm = (pad.board.max_m[0] - pad.board.min_m[0]) * 1000.0;
    let h_mm = (pad.board.max_m[1] - pad.board.min_m[1]) * 1000.0;
    let mm = |s: &str| -> f64 { s.trim_end_matches("mm").parse().unwrap() };
    assert!(attr(root, "width").ends_with("mm") && attr(root, "height").ends_with("mm"));
    assert!((mm(attr(root, "width")) - w_mm).abs() < 1e-6, "{root:.200}");
    let page_h = mm(attr(root, "height"));
    assert!(page_h > h_mm, "a strip below the board: {page_h}");
    let view: Vec<f64> = attr(root, "viewBox").split(' ').map(mm).collect();
    assert_eq!(view, [0.0, 0.0, mm(attr(root, "width")), page_h]);
    let board = &svg[svg.find("id=\"board\"").unwrap() - 6..];
    assert!((mm(attr(board, "width")) - w_mm).abs() < 1e-6);
    assert!((mm(attr(board, "height")) - h_mm).abs() < 1e-6);

    // The scale bar: 100 mm long, below the board; the caption says how to print.
    let bar = &svg[svg.find("<g id=\"scale-bar\"").unwrap()..];
    assert_eq!(attr(bar, "width"), "100");
    assert!(attr(bar, "y").parse::<f64>().unwrap() > h_mm);
    assert!(bar.contains(">10 cm"));
    let lower = svg.to_lowercase();
    assert!(lower.contains("print at 100%"));
    for m in &pad.markers {
        assert!(svg.contains(&m.id.to_string()));
        assert!(svg.contains(&format!("{:.0} mm", m.size_m * 1000.0)));
    }
    assert!(svg.contains("id=\"origin\""));

    // One rect per black cell, counted from OpenCV's own dictionary.
    let dict =
        aruco::get_predefined_dictionary(aruco::PREDEFINED_DICTIONARY_NAME::DICT_ARUCO_ORIGINAL)
            .unwrap();
    for m in &pad.markers {
        let mut bits = Mat::default();
        aruco::draw_marker(&dict, m.id as i32, 7, &mut bits, 1).unwrap();
        let black = bits
            .data_bytes()
            .unwrap()
            .iter()
            .filter(|&&b| b == 0)
            .count();
        let group = &svg[svg.find(&format!("<g id=\"marker-{}\">", m.id)).unwrap()..];
        let group = &group[..group.find("</g>").unwrap()];
        assert_eq!(
            group.matches("<rect class=\"cell\"").count(),
            black,
            "marker {}",
            m.id
        );
        // The top-left cell is border (black) at the marker's top-left corner.
        let x0: f64 = attr(group, "x").parse().unwrap();
        let y0: f64 = attr(group, "y").parse().unwrap();
        let left = (m.centre_m[0] - m.size_m / 2.0 - pad.board.min_m[0]) * 1000.0;
        let top = (pad.board.max_m[1] - m.centre_m[1] - m.size_m / 2.0) * 1000.0;
        assert!(
            (x0 - left).abs() < 1e-3 && (y0 - top).abs() < 1e-3,
            "marker {}",
            m.id
        );
    }
}

fn assert_one_line_exit_2(o: &Output, needle: &str) {
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    assert!(err.contains(needle), "{needle:?} in {err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn a_dpi_outside_50_to_1200_is_refused_in_one_line() {
    let dir = temp_dir("baddpi");
    let out = dir.join("pad.png");
    for dpi in ["0", "49.9", "1201", "-300", "NaN", "inf"] {
        let o = landing(&["pad", "print", "--out", out.to_str().unwrap(), "--dpi", dpi]);
        assert_one_line_exit_2(
            &o,
            &format!("error: --dpi {dpi} is not allowed (allowed: 50 to 1200)"),
        );
        assert!(!out.exists());
    }
}

#[test]
fn an_unwritable_out_path_is_one_line_naming_it() {
    for out in ["/nonexistent-dir/pad.png", "/proc/pad.png"] {
        let o = landing(&[
            "pad",
            "print",
            "--out",
            out,
            "--dpi",
            "50",
            "--pad",
            &pad_toml(),
        ]);
        assert_one_line_exit_2(&o, &format!("cannot write {out}"));
    }
    let dir = temp_dir("badsvg");
    let out = dir.join("pad.png");
    let o = landing(&[
        "pad",
        "print",
        "--out",
        out.to_str().unwrap(),
        "--svg",
        "/nonexistent-dir/pad.svg",
        "--dpi",
        "50",
        "--pad",
        &pad_toml(),
    ]);
    assert_one_line_exit_2(&o, "cannot write /nonexistent-dir/pad.svg");
}

#[test]
fn a_bad_pad_file_is_one_line_naming_the_file_and_the_key() {
    let dir = temp_dir("badpad");
    let text = std::fs::read_to_string(pad_toml()).unwrap();
    let out = dir.join("pad.png");
    for (name, bad, needle) in [
        (
            "offcentre.toml",
            text.replacen("min_m = [-0.42, -0.42]", "min_m = [-0.24, -0.24]", 1),
            "board.max_m[0] = 0.42: must be -board.min_m[0] (0.24)",
        ),
        (
            "syntax.toml",
            text.replacen("size_m = 0.025", "size_m = ", 1),
            "line ",
        ),
    ] {
        let path = dir.join(name);
        std::fs::write(&path, bad).unwrap();
        let o = landing(&[
            "pad",
            "print",
            "--out",
            out.to_str().unwrap(),
            "--dpi",
            "50",
            "--pad",
            path.to_str().unwrap(),
        ]);
        assert_one_line_exit_2(&o, needle);
        assert!(
            stderr(&o).contains(path.to_str().unwrap()),
            "{}",
            stderr(&o)
        );
    }
    let o = landing(&[
        "pad",
        "print",
        "--out",
        out.to_str().unwrap(),
        "--dpi",
        "50",
        "--deploy-dir",
        "/nonexistent-deploy",
    ]);
    assert_one_line_exit_2(&o, "/nonexistent-deploy/config/pad.toml");
}

#[test]
fn the_help_documents_the_size_the_orientation_the_origin_and_the_svg() {
    let o = landing(&["pad", "print", "--help"]);
    assert!(o.status.success());
    let help = String::from_utf8_lossy(&o.stdout);
    for needle in [
        "--out",
        "--dpi",
        "--svg",
        "--pad",
        "--deploy-dir",
        "50 to 1200",
        "pHYs",
        "image up is pad +y",
        "image centre is the",
        "scale",
        "millimetres",
    ] {
        assert!(help.contains(needle), "{needle:?} in {help}");
    }
}
