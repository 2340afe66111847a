//! `landing pad print`: the landing pad as files to print at true scale, a PNG (its DPI
//! in a pHYs chunk, so a print dialog at 100% prints it actual size) and an SVG in
//! millimetres, both drawn from the same `PadModel` the simulator renders and the
//! detector's object points come from.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, anyhow, bail};
use clap::Args;
use opencv::core::{Mat, Vector};
use opencv::imgcodecs;
use opencv::prelude::*;
use optics::{MARKER_CELLS, Marker, PadError, PadModel, marker_cells};
use stack_config::deploy_dir;

/// Metres per inch: dots per inch to pixels per metre.
pub const METRES_PER_INCH: f64 = 0.0254;

/// Resolutions `--dpi` accepts: below 50 the smallest marker's cells are a few dots,
/// above 1200 no printer resolves more and the image passes 1.5 GB.
const DPI: std::ops::RangeInclusive<f64> = 50.0..=1200.0;

/// Height of the strip below the board in the SVG for the scale bar and caption, mm.
const STRIP_MM: f64 = 30.0;

/// Length of the SVG's scale bar, mm.
const SCALE_BAR_MM: f64 = 100.0;

/// Arguments of `landing pad print`.
#[derive(Debug, Args)]
pub struct PrintArgs {
    /// The PNG to write: exactly the board, edge to edge, black and white only.
    #[arg(long, value_name = "PNG")]
    out: PathBuf,
    /// Dots per inch of the print (50 to 1200); the PNG is round(board side / 25.4 mm
    /// * DPI) pixels a side and records the DPI in its pHYs chunk.
    #[arg(long, value_name = "DPI", allow_negative_numbers = true)]
    dpi: f64,
    /// The SVG to write (default: the --out path with the extension .svg).
    #[arg(long, value_name = "SVG")]
    svg: Option<PathBuf>,
    /// The pad layout (default: DEPLOY_DIR/config/pad.toml).
    #[arg(long, value_name = "FILE")]
    pad: Option<PathBuf>,
    /// The deploy directory (default: found above the current directory or executable).
    #[arg(long, value_name = "DIR")]
    deploy_dir: Option<PathBuf>,
}

/// Writes the PNG and the SVG and says where the pad origin is.
pub fn run(args: &PrintArgs) -> Result<()> {
    if !(args.dpi.is_finite() && DPI.contains(&args.dpi)) {
        bail!(
            "--dpi {} is not allowed (allowed: {} to {})",
            args.dpi,
            DPI.start(),
            DPI.end()
        );
    }
    let svg_path = args
        .svg
        .clone()
        .unwrap_or_else(|| args.out.with_extension("svg"));
    if svg_path == args.out {
        bail!(
            "--svg {} is also the PNG (--out): give the SVG another path",
            svg_path.display()
        );
    }
    let pad_path = args.pad.clone().unwrap_or_else(|| {
        args.deploy_dir
            .clone()
            .unwrap_or_else(deploy_dir)
            .join("config")
            .join("pad.toml")
    });
    let pad = PadModel::load(&pad_path).map_err(|e| match e {
        // Validation errors name the key but not the file.
        PadError::Invalid { .. } => anyhow!("pad file {}: {e}", pad_path.display()),
        other => anyhow!(other),
    })?;

    let ppm = args.dpi / METRES_PER_INCH;
    let texture = pad.render_texture(ppm)?;
    let png = encode_png(&texture, ppm)?;
    let svg = svg(&pad)?;
    write(&args.out, &png)?;
    write(&svg_path, svg.as_bytes())?;

    let [w_mm, h_mm] = board_mm(&pad);
    // From the top-left corner of the image (not from the first pixel's centre).
    let origin = [-pad.board.min_m[0] * ppm, pad.board.max_m[1] * ppm];
    println!(
        "{}: {} x {} px at {} dpi ({} x {} mm); the pad origin is {:.1} px right and {:.1} px \
         down from the top-left corner, the image centre",
        args.out.display(),
        texture.cols(),
        texture.rows(),
        args.dpi,
        num(w_mm),
        num(h_mm),
        origin[0],
        origin[1],
    );
    println!(
        "{}: {} x {} mm page (the board, then the scale bar and caption below it)",
        svg_path.display(),
        num(w_mm.max(min_page_width_mm())),
        num(h_mm + STRIP_MM)
    );
    Ok(())
}

fn write(path: &Path, bytes: &[u8]) -> Result<()> {
    std::fs::write(path, bytes).with_context(|| format!("cannot write {}", path.display()))
}

/// The board's width and height, mm.
fn board_mm(pad: &PadModel) -> [f64; 2] {
    [0, 1].map(|i| (pad.board.max_m[i] - pad.board.min_m[i]) * 1000.0)
}

/// A PNG of `texture`, one bit per pixel (it is black and white only), with a pHYs
/// chunk of `pixels_per_metre`.
fn encode_png(texture: &Mat, pixels_per_metre: f64) -> Result<Vec<u8>> {
    let params = Vector::<i32>::from_slice(&[imgcodecs::IMWRITE_PNG_BILEVEL, 1]);
    let mut buf = Vector::<u8>::new();
    if !imgcodecs::imencode(".png", texture, &mut buf, &params).context("encoding the PNG")? {
        bail!("encoding the PNG: OpenCV could not write it");
    }
    with_phys(buf.as_slice(), pixels_per_metre.round() as u32)
}

/// The PNG file signature.
const PNG_SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', b'\r', b'\n', 0x1a, b'\n'];

/// `png` with a pHYs chunk (`pixels_per_metre` both ways, unit: metre) right after
/// IHDR, replacing any pHYs already there. OpenCV writes none; print dialogs read it
/// to print at true size.
pub fn with_phys(png: &[u8], pixels_per_metre: u32) -> Result<Vec<u8>> {
    let bad = |why: &str| anyhow!("encoding the PNG: {why}");
    let body = png
        .strip_prefix(&PNG_SIGNATURE)
        .ok_or_else(|| bad("no PNG signature"))?;
    let mut out = Vec::with_capacity(png.len() + 21);
    out.extend_from_slice(&PNG_SIGNATURE);
    let mut rest = body;
    let mut first = true;
    while !rest.is_empty() {
        let len = rest
            .get(..4)
            .and_then(|b| b.try_into().ok())
            .map(u32::from_be_bytes)
            .ok_or_else(|| bad("truncated chunk"))? as usize;
        let chunk = rest.get(..len + 12).ok_or_else(|| bad("truncated chunk"))?;
        let kind = &chunk[4..8];
        if first && kind != b"IHDR" {
            return Err(bad("IHDR is not the first chunk"));
        }
        if kind != b"pHYs" {
            out.extend_from_slice(chunk);
        }
        if first {
            let mut data = [0u8; 9];
            data[..4].copy_from_slice(&pixels_per_metre.to_be_bytes());
            data[4..8].copy_from_slice(&pixels_per_metre.to_be_bytes());
            data[8] = 1; // unit: metre
            push_chunk(&mut out, b"pHYs", &data);
            first = false;
        }
        rest = &rest[len + 12..];
    }
    Ok(out)
}

fn push_chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
    out.extend_from_slice(&(data.len() as u32).to_be_bytes());
    let start = out.len();
    out.extend_from_slice(kind);
    out.extend_from_slice(data);
    let crc = crc32(&out[start..]);
    out.extend_from_slice(&crc.to_be_bytes());
}

/// CRC-32 (IEEE, reflected, as PNG and zlib use it), bit by bit: a chunk of 13 bytes
/// needs no table.
pub fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = 0xFFFF_FFFFu32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            let mask = (crc & 1).wrapping_neg();
            crc = (crc >> 1) ^ (0xEDB8_8320 & mask);
        }
    }
    !crc
}

/// Millimetres as SVG numbers: at most 4 decimals (0.1 um), no trailing zeros.
fn num(mm: f64) -> String {
    let s = format!("{mm:.4}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.into() }
}

fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// The page is at least this wide so the scale bar and its label fit beside a small
/// board, mm.
fn min_page_width_mm() -> f64 {
    SCALE_BAR_MM + 60.0
}

/// "43: 25 mm; 5, 6, 7, 8: 64 mm; ...": markers grouped by size in file order.
fn marker_list(markers: &[Marker]) -> String {
    let mut groups: Vec<(f64, Vec<u32>)> = Vec::new();
    for m in markers {
        match groups.iter_mut().find(|(size, _)| *size == m.size_m) {
            Some((_, ids)) => ids.push(m.id),
            None => groups.push((m.size_m, vec![m.id])),
        }
    }
    groups
        .iter()
        .map(|(size, ids)| {
            let ids: Vec<String> = ids.iter().map(u32::to_string).collect();
            format!("{}: {} mm", ids.join(", "), num(size * 1000.0))
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// The pad as an SVG page in millimetres: the board (image up = pad +y, right = pad
/// +x) with every black marker cell as a rect, a red cross at the pad origin, and a
/// strip below the board with a 10 cm scale bar and a caption.
fn svg(pad: &PadModel) -> Result<String> {
    let [min_x, max_y] = [pad.board.min_m[0], pad.board.max_m[1]];
    let [bw, bh] = board_mm(pad);
    let page_w = bw.max(min_page_width_mm());
    let page_h = bh + STRIP_MM;
    // Pad metres to page millimetres.
    let px = |x: f64| (x - min_x) * 1000.0;
    let py = |y: f64| (max_y - y) * 1000.0;
    let mut s = String::new();
    // `write!` into a String cannot fail; the results are ignored below for that reason.
    let _ = writeln!(
        s,
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n\
         <svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}mm\" height=\"{h}mm\" \
         viewBox=\"0 0 {w} {h}\">",
        w = num(page_w),
        h = num(page_h)
    );
    let _ = writeln!(s, "<title>Landing pad (print at 100%)</title>");
    let _ = writeln!(
        s,
        "<rect id=\"board\" x=\"0\" y=\"0\" width=\"{}\" height=\"{}\" fill=\"#fff\" \
         stroke=\"#bbb\" stroke-width=\"0.2\"/>",
        num(bw),
        num(bh)
    );
    let _ = writeln!(
        s,
        "<g id=\"markers\" fill=\"#000\" shape-rendering=\"crispEdges\">"
    );
    for m in &pad.markers {
        let cells = marker_cells(m.id)?;
        let cell = m.size_m / MARKER_CELLS as f64;
        let (left, top) = (
            m.centre_m[0] - m.size_m / 2.0,
            m.centre_m[1] + m.size_m / 2.0,
        );
        let _ = writeln!(s, "<g id=\"marker-{}\">", m.id);
        for (r, row) in cells.iter().enumerate() {
            for (c, _) in row.iter().enumerate().filter(|(_, black)| **black) {
                let (x0, x1) = (px(left + cell * c as f64), px(left + cell * (c + 1) as f64));
                let (y0, y1) = (py(top - cell * r as f64), py(top - cell * (r + 1) as f64));
                let _ = writeln!(
                    s,
                    "<rect class=\"cell\" x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\"/>",
                    num(x0),
                    num(y0),
                    num(x1 - x0),
                    num(y1 - y0)
                );
            }
        }
        let _ = writeln!(s, "</g>");
    }
    let _ = writeln!(s, "</g>");
    let (ox, oy, arm) = (px(0.0), py(0.0), 4.0);
    let _ = writeln!(
        s,
        "<g id=\"origin\" stroke=\"#e00000\" stroke-width=\"0.25\">\
         <line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\"/>\
         <line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\"/></g>",
        num(ox - arm),
        num(oy),
        num(ox + arm),
        num(oy),
        num(ox),
        num(oy - arm),
        num(ox),
        num(oy + arm)
    );
    // The strip below the board: scale bar with end and middle ticks, its label, and
    // the caption.
    let (bar_x, bar_y) = (10.0, bh + 6.0);
    let _ = writeln!(
        s,
        "<g id=\"scale-bar\"><rect x=\"{x}\" y=\"{y}\" width=\"{len}\" height=\"2\" fill=\"#000\"/>\
         <rect x=\"{x}\" y=\"{t}\" width=\"0.3\" height=\"6\" fill=\"#000\"/>\
         <rect x=\"{mid}\" y=\"{t}\" width=\"0.3\" height=\"6\" fill=\"#000\"/>\
         <rect x=\"{end}\" y=\"{t}\" width=\"0.3\" height=\"6\" fill=\"#000\"/>\
         <text x=\"{lx}\" y=\"{ly}\" font-family=\"sans-serif\" font-size=\"4\">10 cm \
         (measure it: print at 100%)</text></g>",
        x = num(bar_x),
        y = num(bar_y),
        len = num(SCALE_BAR_MM),
        t = num(bar_y - 2.0),
        mid = num(bar_x + SCALE_BAR_MM / 2.0 - 0.15),
        end = num(bar_x + SCALE_BAR_MM - 0.3),
        lx = num(bar_x + SCALE_BAR_MM + 4.0),
        ly = num(bar_y + 2.0),
    );
    let lines = [
        format!(
            "Landing pad, board {} x {} mm; ArUco ARUCO_ORIGINAL markers (ids: side) {}.",
            num(bw),
            num(bh),
            marker_list(&pad.markers)
        ),
        "Print at 100% (actual size, no fit to page). Image up = pad +y, right = pad +x \
         (heading); red cross = pad origin (landing point)."
            .to_string(),
    ];
    // Font size that fits the longest line across the page (about 0.6 em per character).
    let longest = lines.iter().map(|l| l.chars().count()).max().unwrap_or(1) as f64;
    let font = (3.5f64).min((page_w - 20.0) / (0.6 * longest));
    for (k, line) in lines.iter().enumerate() {
        let _ = writeln!(
            s,
            "<text id=\"caption-{k}\" x=\"{}\" y=\"{}\" font-family=\"sans-serif\" \
             font-size=\"{}\">{}</text>",
            num(bar_x),
            num(bh + 16.0 + 6.0 * k as f64),
            num(font),
            escape(line)
        );
    }
    let _ = writeln!(s, "</svg>");
    Ok(s)
}

#[cfg(test)]
#[path = "pad_print_test.rs"]
mod tests;
