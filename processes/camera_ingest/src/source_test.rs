use std::path::PathBuf;

use opencv::core::{CV_8UC1, CV_8UC3, CV_16UC1, Mat, Scalar, Size, Vector};
use opencv::imgcodecs;
use opencv::prelude::*;
use opencv::videoio::{VideoWriter, VideoWriterTrait};

use super::*;
use runtime::capture::Pacer;

/// A fresh directory for one test, removed when dropped.
struct TempDir(PathBuf);

impl TempDir {
    fn new(name: &str) -> Self {
        let dir = std::env::temp_dir().join(format!(
            "camera_ingest_{name}_{}_{:?}",
            std::process::id(),
            std::thread::current().id()
        ));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        Self(dir)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn grey(value: u8) -> Mat {
    Mat::new_rows_cols_with_default(48, 64, CV_8UC1, Scalar::all(f64::from(value))).unwrap()
}

#[test]
fn source_names_parse_into_backends() {
    assert_eq!("sim".parse::<SourceSpec>().unwrap(), SourceSpec::Sim);
    assert_eq!(
        "v4l2:/dev/video2".parse::<SourceSpec>().unwrap(),
        SourceSpec::V4l2("/dev/video2".into())
    );
    let gst = "gst:nvarguscamerasrc ! video/x-raw(memory:NVMM),width=640,height=480 ! nvvidconv ! appsink";
    assert_eq!(
        gst.parse::<SourceSpec>().unwrap(),
        SourceSpec::Gst(gst["gst:".len()..].into())
    );
    assert_eq!(
        "file:/data/flight.avi".parse::<SourceSpec>().unwrap(),
        SourceSpec::File("/data/flight.avi".into())
    );
    assert_eq!(
        "file:rec/frames".parse::<SourceSpec>().unwrap().to_string(),
        "file:rec/frames"
    );
}

#[test]
fn an_unknown_source_is_one_line_naming_what_is_allowed() {
    for bad in ["usb:0", "/dev/video0", "v4l2:", "file:", "", "simulator"] {
        let e = bad.parse::<SourceSpec>().unwrap_err().to_string();
        assert!(e.starts_with(&format!("unknown --source `{bad}`")), "{e}");
        assert!(e.contains("allowed: sim, v4l2:/dev/videoN, gst:"), "{e}");
        assert!(!e.contains('\n'));
    }
}

#[test]
fn an_image_directory_is_read_in_name_order() {
    let dir = TempDir::new("order");
    // Written out of order; a note that is not an image is ignored.
    for (name, value) in [
        ("frame_10.png", 30u8),
        ("frame_02.png", 10),
        ("frame_05.png", 20),
    ] {
        assert!(imgcodecs::imwrite(dir.0.join(name), &grey(value), &Vector::new()).unwrap());
    }
    std::fs::write(dir.0.join("notes.txt"), "flight 3").unwrap();

    let FrameSource::Images(mut images) =
        FrameSource::for_spec(&SourceSpec::File(dir.0.clone()), None, None).unwrap()
    else {
        panic!("a directory plays as images");
    };
    let names: Vec<_> = images
        .files()
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, ["frame_02.png", "frame_05.png", "frame_10.png"]);
    let mut values = Vec::new();
    while let Some(image) = images.next_image() {
        let m = image.unwrap();
        assert_eq!((m.cols(), m.rows(), m.typ()), (64, 48, CV_8UC1));
        values.push(*m.at_2d::<u8>(0, 0).unwrap());
    }
    assert_eq!(values, [10, 20, 30]);

    images.rewind();
    assert_eq!(
        *images
            .next_image()
            .unwrap()
            .unwrap()
            .at_2d::<u8>(0, 0)
            .unwrap(),
        10
    );
}

#[test]
fn an_unreadable_image_in_a_directory_is_counted_and_skipped() {
    let dir = TempDir::new("unreadable");
    imgcodecs::imwrite(dir.0.join("a.png"), &grey(1), &Vector::new()).unwrap();
    std::fs::write(dir.0.join("b.png"), b"not a png at all").unwrap();
    imgcodecs::imwrite(dir.0.join("c.png"), &grey(3), &Vector::new()).unwrap();

    let mut images = ImageDir::open(&dir.0).unwrap();
    assert!(images.next_image().unwrap().is_ok());
    let e = images.next_image().unwrap().unwrap_err();
    assert!(
        matches!(&e, SourceError::Unreadable(p) if p.ends_with("b.png")),
        "{e}"
    );
    let third = images.next_image().unwrap().unwrap();
    assert_eq!(*third.at_2d::<u8>(0, 0).unwrap(), 3);
    assert!(images.next_image().is_none());
    assert_eq!(images.unreadable(), 1);
}

#[test]
fn a_missing_or_empty_directory_is_an_error_naming_it() {
    let dir = TempDir::new("empty");
    let e = ImageDir::open(&dir.0).unwrap_err().to_string();
    assert!(
        e.contains(&*dir.0.to_string_lossy()) && e.contains("no image files"),
        "{e}"
    );
    let missing = dir.0.join("nope");
    let e = FrameSource::for_spec(&SourceSpec::File(missing.clone()), None, None)
        .unwrap_err()
        .to_string();
    assert_eq!(e, format!("{}: not found", missing.display()));
}

#[test]
fn a_video_file_is_read_at_its_recorded_rate() {
    let dir = TempDir::new("video");
    let path = dir.0.join("flight.avi");
    let fourcc = VideoWriter::fourcc('M', 'J', 'P', 'G').unwrap();
    let mut writer = VideoWriter::new(&path, fourcc, 10.0, Size::new(64, 48), true).unwrap();
    assert!(writer.is_opened().unwrap(), "OpenCV can write MJPG AVI");
    for i in 0..12u8 {
        let frame = Mat::new_rows_cols_with_default(
            48,
            64,
            CV_8UC3,
            Scalar::new(f64::from(i) * 20.0, 100.0, 200.0, 0.0),
        )
        .unwrap();
        writer.write(&frame).unwrap();
    }
    writer.release().unwrap();

    let FrameSource::Video(mut video) =
        FrameSource::for_spec(&SourceSpec::File(path.clone()), None, None).unwrap()
    else {
        panic!("a file plays as a video");
    };
    assert!(!video.is_live());
    video.open().unwrap();
    let rate = video.declared_rate_hz().unwrap();
    assert!((rate - 10.0).abs() < 1e-6, "recorded at {rate} Hz");

    // Played through a pacer at that rate, on a simulated clock.
    let mut pacer = Pacer::from_rate_hz(rate).unwrap();
    let mut now = 0u64;
    let mut emitted = Vec::new();
    let mut frame = Mat::default();
    while video.grab().unwrap() {
        video.retrieve(&mut frame).unwrap();
        let header = header_for_mat(&frame, now, 0);
        assert_eq!(mat_bytes(&frame).len(), header.expected_len().unwrap());
        assert_eq!(
            (header.width, header.height, header.stride),
            (64, 48, 64 * 3)
        );
        emitted.push(now);
        pacer.emitted(now);
        now += 2_000_000; // decode + publish
        now += pacer.delay_ns(now);
    }
    assert_eq!(emitted.len(), 12, "every frame read, then the end");
    assert!(
        emitted.windows(2).all(|w| w[1] - w[0] == 100_000_000),
        "{emitted:?}"
    );
}

#[test]
fn a_missing_video_file_is_an_error_naming_it() {
    let mut v = VideoSource::file(std::path::Path::new("/nonexistent/flight.avi"));
    assert_eq!(
        v.open().unwrap_err().to_string(),
        "/nonexistent/flight.avi: not found"
    );
    assert!(matches!(v.grab(), Err(SourceError::ReadFailed(_))));
}

#[test]
fn opencv_images_are_described_by_a_header_the_ingest_checks() {
    let h = header_for_mat(&grey(0), 42, 3);
    assert_eq!((h.width, h.height, h.stride), (64, 48, 64));
    assert_eq!(h.encoding, ipc_types::msg::PixelEncoding::Mono8 as u32);
    assert_eq!((h.msg.capture_ns, h.camera_id), (42, 3));
    assert_eq!(h.expected_len(), Some(64 * 48));

    let deep = Mat::new_rows_cols_with_default(48, 64, CV_16UC1, Scalar::all(0.0)).unwrap();
    let h = header_for_mat(&deep, 0, 0);
    assert_eq!(
        h.expected_len(),
        None,
        "16-bit images are not camera frames"
    );
    let mut ingest = crate::Ingest::new(
        optics::CameraCalibration::new(64, 48, 50.0, 50.0, 32.0, 24.0, [0.0; 5]).unwrap(),
        false,
    )
    .unwrap();
    assert!(ingest.admit(&h, mat_bytes(&deep).len()).is_err());
    assert_eq!(ingest.counters().dropped_bad_header, 1);
}
