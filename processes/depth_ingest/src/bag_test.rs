use std::io::Write;

use super::*;

/// A record: its header fields, then its data, each length-prefixed.
fn record(fields: &[(&str, &[u8])], data: &[u8]) -> Vec<u8> {
    let mut header = Vec::new();
    for (name, value) in fields {
        let field = [name.as_bytes(), b"=", value].concat();
        header.extend((field.len() as u32).to_le_bytes());
        header.extend(field);
    }
    let mut out = (header.len() as u32).to_le_bytes().to_vec();
    out.extend(header);
    out.extend((data.len() as u32).to_le_bytes());
    out.extend(data);
    out
}

fn string(s: &str) -> Vec<u8> {
    [(s.len() as u32).to_le_bytes().as_slice(), s.as_bytes()].concat()
}

fn ros_header(seq: u32, frame_id: &str) -> Vec<u8> {
    [
        seq.to_le_bytes().as_slice(),
        &7u32.to_le_bytes(),
        &500u32.to_le_bytes(),
        &string(frame_id),
    ]
    .concat()
}

fn connection(conn: u32, topic: &str) -> Vec<u8> {
    let data = record(&[("type", b"any"), ("md5sum", b"0")], &[]);
    record(
        &[
            ("op", &[0x07]),
            ("conn", &conn.to_le_bytes()),
            ("topic", topic.as_bytes()),
        ],
        &data[4..data.len() - 4],
    )
}

fn message(conn: u32, data: &[u8]) -> Vec<u8> {
    record(
        &[
            ("op", &[0x02]),
            ("conn", &conn.to_le_bytes()),
            ("time", &1u64.to_le_bytes()),
        ],
        data,
    )
}

fn camera_info(w: u32, h: u32) -> Vec<u8> {
    let mut m = ros_header(0, "");
    m.extend(h.to_le_bytes());
    m.extend(w.to_le_bytes());
    m.extend(string("Brown Conrady"));
    m.extend(5u32.to_le_bytes());
    m.extend([0.0f64; 5].iter().flat_map(|v| v.to_le_bytes()));
    let k = [380.0, 0.0, 2.0, 0.0, 381.0, 1.5, 0.0, 0.0, 1.0f64];
    m.extend(k.iter().flat_map(|v| v.to_le_bytes()));
    m.extend([0.0f64; 21].iter().flat_map(|v| v.to_le_bytes()));
    m.extend([0u8; 4 * 6 + 1]);
    m
}

fn image(seq: u32, w: u32, h: u32, depth: u16, units: Option<f32>) -> Vec<u8> {
    let mut m = ros_header(seq, "1");
    m.extend(h.to_le_bytes());
    m.extend(w.to_le_bytes());
    m.extend(string("mono16"));
    m.push(0);
    m.extend((w * 2).to_le_bytes());
    let pixels: Vec<u8> = (0..w * h).flat_map(|_| depth.to_le_bytes()).collect();
    m.extend((pixels.len() as u32).to_le_bytes());
    m.extend(pixels);
    if let Some(u) = units {
        m.extend(u.to_le_bytes());
    }
    m
}

/// A bag of `frames` 4x3 depth images (depth k+1 in frame k) in one chunk.
fn bag(compression: &str, frames: u16, with_info: bool) -> Vec<u8> {
    let mut inner = Vec::new();
    inner.extend(connection(0, "/device_0/sensor_0/Depth_0/info/camera_info"));
    inner.extend(connection(1, "/device_0/sensor_0/Depth_0/info"));
    inner.extend(connection(2, "/device_0/sensor_0/Depth_0/image/data"));
    inner.extend(connection(3, "/device_0/sensor_1/Color_0/image/data"));
    if with_info {
        inner.extend(message(0, &camera_info(4, 3)));
    }
    inner.extend(message(
        1,
        &[30u32.to_le_bytes().as_slice(), &string("mono16"), &[1]].concat(),
    ));
    for k in 0..frames {
        inner.extend(message(3, b"colour: skipped"));
        let units = (k == 0).then_some(0.0001f32);
        inner.extend(message(2, &image(u32::from(k) + 1, 4, 3, k + 1, units)));
    }
    let data = match compression {
        "lz4" => {
            let mut e = lz4::EncoderBuilder::new().build(Vec::new()).unwrap();
            e.write_all(&inner).unwrap();
            let (out, r) = e.finish();
            r.unwrap();
            out
        }
        _ => inner.clone(),
    };
    let mut out = b"#ROSBAG V2.0\n".to_vec();
    out.extend(record(
        &[
            ("op", &[0x03]),
            ("index_pos", &0u64.to_le_bytes()),
            ("conn_count", &4u32.to_le_bytes()),
            ("chunk_count", &1u32.to_le_bytes()),
        ],
        &[b' '; 16],
    ));
    out.extend(record(
        &[
            ("op", &[0x05]),
            ("compression", compression.as_bytes()),
            ("size", &(inner.len() as u32).to_le_bytes()),
        ],
        &data,
    ));
    out
}

fn write(name: &str, bytes: &[u8]) -> PathBuf {
    let path = std::env::temp_dir().join(format!("{name}_{}.bag", std::process::id()));
    std::fs::write(&path, bytes).unwrap();
    path
}

fn play(path: &Path) -> (DepthStreamInfo, Vec<DepthImage>) {
    let mut bag = RsBag::open(path).unwrap();
    let mut frames = Vec::new();
    let mut image = DepthImage::default();
    while bag.next_image(&mut image).unwrap().is_some() {
        frames.push(image.clone());
    }
    (bag.info(), frames)
}

#[test]
fn a_bag_plays_its_depth_frames_with_their_intrinsics_in_either_compression() {
    for compression in ["none", "lz4"] {
        let path = write(compression, &bag(compression, 3, true));
        let (info, frames) = play(&path);
        std::fs::remove_file(&path).unwrap();
        assert_eq!(
            (info.width, info.height, info.fps),
            (4, 3, 30),
            "{compression}"
        );
        let k = info.intrinsics;
        assert_eq!((k.fx, k.fy, k.cx, k.cy), (380.0, 381.0, 2.0, 1.5));
        assert!(
            (info.depth_scale_m - 0.0001).abs() < 1e-9,
            "the frame's own units"
        );
        assert_eq!(frames.len(), 3, "the colour stream is not depth");
        for (k, f) in frames.iter().enumerate() {
            assert_eq!((f.width, f.height), (4, 3));
            assert_eq!(f.depths, vec![k as u16 + 1; 12]);
        }
    }
}

#[test]
fn what_is_not_a_playable_depth_bag_is_one_error_naming_why() {
    let cases: [(&str, Vec<u8>, &str); 4] = [
        (
            "notbag",
            b"PK\x03\x04 a zip".to_vec(),
            "not a RealSense .bag",
        ),
        ("noinfo", bag("none", 2, false), "no depth stream"),
        (
            "bz2",
            bag("bz2", 2, true),
            "compressed with `bz2` (allowed: none, lz4)",
        ),
        (
            "cut",
            bag("lz4", 2, true)[..200].to_vec(),
            "damaged at byte",
        ),
    ];
    for (name, bytes, expected) in cases {
        let path = write(name, &bytes);
        let result = RsBag::open(&path);
        std::fs::remove_file(&path).unwrap();
        let Err(e) = result else {
            panic!("{name}: opened");
        };
        let line = e.to_string();
        assert!(line.contains(expected), "{name}: {line}");
        assert!(!line.contains('\n'), "one line: {line}");
    }
}

#[test]
fn every_truncation_of_a_bag_is_an_error_or_fewer_frames_never_a_panic() {
    let full = bag("none", 2, true);
    for cut in (0..full.len()).step_by(7) {
        let path = write("trunc", &full[..cut]);
        if let Ok(mut b) = RsBag::open(&path) {
            let mut image = DepthImage::default();
            while let Ok(Some(_)) = b.next_image(&mut image) {
                assert_eq!(image.depths.len(), 12);
            }
        }
        std::fs::remove_file(&path).unwrap();
    }
}

#[test]
fn a_recording_written_by_librealsense_itself_plays_its_three_frames() {
    // tests/fixtures: written by pyrealsense2 2.57's recorder (software device, LZ4):
    // 160x120, fx = fy = 380, a 5 m background and a 2 m box in the middle third.
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/fixtures/realsense-160x120-3-frames.bag");
    let (info, frames) = play(&path);
    assert_eq!((info.width, info.height), (160, 120));
    assert_eq!((info.intrinsics.fx, info.intrinsics.cx), (380.0, 80.0));
    assert!((info.depth_scale_m - 0.001).abs() < 1e-9);
    assert_eq!(frames.len(), 3);
    for f in &frames {
        assert_eq!(f.depths[60 * 160 + 80], 2000, "the box, 2 m");
        assert_eq!(f.depths[10 * 160 + 80], 5000, "the background, 5 m");
    }
}

#[test]
fn a_chunk_that_claims_more_than_64_mib_is_damage_not_an_allocation() {
    let mut bytes = bag("none", 1, true);
    // The chunk record's `size` field: its value follows "size=".
    let at = bytes.windows(5).position(|w| w == b"size=").unwrap() + 5;
    bytes[at..at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
    let path = write("huge", &bytes);
    let err = RsBag::open(&path).err().unwrap();
    std::fs::remove_file(&path).unwrap();
    assert!(err.to_string().contains("larger than 64 MiB"), "{err}");
}
