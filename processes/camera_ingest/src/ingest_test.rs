use ipc_types::msg::{CameraFrameHeader, Header, PixelEncoding, Stage};
use optics::CameraCalibration;

use super::*;

const W: u32 = 64;
const H: u32 = 48;

fn calibration() -> CameraCalibration {
    CameraCalibration::new(W, H, 50.0, 50.0, 32.0, 24.0, [0.0; 5]).unwrap()
}

fn header(width: u32, height: u32, stride: u32, encoding: u32) -> CameraFrameHeader {
    let mut msg = Header::captured_at(123_456_789);
    msg.seq = 7;
    msg.push_stage(Stage::Sensor, 123_456_789, 123_999_999);
    CameraFrameHeader {
        msg,
        width,
        height,
        stride,
        encoding,
        camera_id: 0,
        undistorted: 0,
        exposure_ns: 2_000_000,
    }
}

fn mono(stride: u32) -> (CameraFrameHeader, Vec<u8>) {
    let h = header(W, H, stride, PixelEncoding::Mono8 as u32);
    let pixels = (0..stride * H).map(|i| (i * 7 % 251) as u8).collect();
    (h, pixels)
}

#[test]
fn a_good_frame_is_copied_with_its_capture_time_kept() {
    let mut ingest = Ingest::new(calibration(), false).unwrap();
    let (h, pixels) = mono(W);
    let admitted = ingest.admit(&h, pixels.len()).unwrap();
    assert_eq!(admitted.out_len, (W * H) as usize);
    let mut out = vec![0u8; admitted.out_len];
    let published = ingest.write(&admitted, &pixels, &mut out).unwrap();
    ingest.sent();

    assert_eq!(out, pixels);
    assert_eq!(published.msg.capture_ns, 123_456_789);
    assert_eq!(
        published.msg.seq, 0,
        "the publisher stamps its own sequence"
    );
    assert_eq!(
        published.msg.stages(),
        h.msg.stages(),
        "upstream stamps kept"
    );
    assert_eq!((published.width, published.height), (W, H));
    assert_eq!(published.stride, W);
    assert_eq!(published.encoding, PixelEncoding::Mono8 as u32);
    assert_eq!(published.exposure_ns, 2_000_000);
    assert_eq!(published.undistorted, 0);
    assert_eq!(ingest.counters().published, 1);
    assert_eq!(ingest.counters().dropped(), 0);
}

#[test]
fn a_frame_with_padded_rows_is_published_with_tight_rows() {
    let mut ingest = Ingest::new(calibration(), false).unwrap();
    let h = header(W, H, W * 3 + 8, PixelEncoding::Bgr8 as u32);
    let pixels: Vec<u8> = (0..h.stride * H).map(|i| (i % 256) as u8).collect();
    let admitted = ingest.admit(&h, pixels.len()).unwrap();
    let mut out = vec![0u8; admitted.out_len];
    let published = ingest.write(&admitted, &pixels, &mut out).unwrap();
    assert_eq!(published.stride, W * 3);
    for r in 0..H as usize {
        let row = (W * 3) as usize;
        let src = &pixels[r * h.stride as usize..][..row];
        assert_eq!(&out[r * row..][..row], src, "row {r}");
    }
}

#[test]
fn a_header_inconsistent_with_its_payload_is_counted_and_skipped() {
    let mono8 = PixelEncoding::Mono8 as u32;
    let full = (W * H) as usize;
    let cases = [
        ("zero width", header(0, H, W, mono8), full),
        ("zero height", header(W, 0, W, mono8), full),
        ("unknown encoding", header(W, H, W, 99), full),
        (
            "stride shorter than a row",
            header(W, H, W - 1, mono8),
            full,
        ),
        ("payload too short", header(W, H, W, mono8), full - 1),
        (
            "payload too long",
            header(W, H, W, mono8),
            full + W as usize,
        ),
        ("empty payload", header(W, H, W, mono8), 0),
    ];
    let mut ingest = Ingest::new(calibration(), false).unwrap();
    for (what, h, len) in cases {
        let result = ingest.admit(&h, len);
        assert!(
            matches!(
                result,
                Err(Rejection::BadHeader { .. } | Rejection::PayloadLength { .. })
            ),
            "{what}: {result:?}"
        );
    }
    assert_eq!(ingest.counters().dropped_bad_header, cases.len() as u64);
    assert_eq!(ingest.counters().published, 0);

    // A good frame after the bad ones still goes through.
    let (h, pixels) = mono(W);
    assert!(ingest.admit(&h, pixels.len()).is_ok());
}

#[test]
fn a_frame_of_another_size_than_the_calibration_is_counted_and_skipped() {
    let mut ingest = Ingest::new(calibration(), false).unwrap();
    let h = header(W * 2, H * 2, W * 2, PixelEncoding::Mono8 as u32);
    let result = ingest.admit(&h, (W * H * 4) as usize);
    assert_eq!(
        result,
        Err(Rejection::Size {
            width: W * 2,
            height: H * 2,
            want_width: W,
            want_height: H
        })
    );
    assert_eq!(ingest.counters().dropped_size, 1);
    assert_eq!(
        result.unwrap_err().to_string(),
        "frame is 128x96, the calibration is 64x48"
    );
}

#[test]
fn an_output_buffer_of_the_wrong_length_is_an_error_not_a_panic() {
    let mut ingest = Ingest::new(calibration(), false).unwrap();
    let (h, pixels) = mono(W);
    let admitted = ingest.admit(&h, pixels.len()).unwrap();
    let mut out = vec![0u8; 10];
    assert!(matches!(
        ingest.write(&admitted, &pixels, &mut out),
        Err(IngestError::OutputLength { got: 10, .. })
    ));
    assert!(matches!(
        ingest.write(&admitted, &pixels[..5], &mut vec![0u8; admitted.out_len]),
        Err(IngestError::InputLength { got: 5, .. })
    ));
    assert_eq!(ingest.counters().dropped_error, 2);
}

#[test]
fn losses_reported_by_the_caller_are_counted() {
    let mut ingest = Ingest::new(calibration(), false).unwrap();
    ingest.record(Dropped::NoBuffer);
    ingest.record(Dropped::SendFailed);
    ingest.record(Dropped::SendFailed);
    let c = ingest.counters();
    assert_eq!(c.dropped_no_buffer, 1);
    assert_eq!(c.dropped_error, 2);
    assert_eq!(c.dropped(), 3);
}

#[test]
fn an_undistorting_ingest_marks_its_frames_undistorted() {
    let distorted =
        CameraCalibration::new(W, H, 50.0, 50.0, 32.0, 24.0, [-0.3, 0.05, 0.0, 0.0, 0.0]).unwrap();
    let mut ingest = Ingest::new(distorted, true).unwrap();
    assert!(ingest.undistorts());
    let (h, pixels) = mono(W);
    let admitted = ingest.admit(&h, pixels.len()).unwrap();
    assert!(admitted.remap);
    let mut out = vec![0u8; admitted.out_len];
    let published = ingest.write(&admitted, &pixels, &mut out).unwrap();
    assert_eq!(published.undistorted, 1);
    assert_ne!(out, pixels, "the pixels went through the maps");
}

#[test]
fn a_frame_undistorted_upstream_is_not_undistorted_twice() {
    let distorted =
        CameraCalibration::new(W, H, 50.0, 50.0, 32.0, 24.0, [-0.3, 0.05, 0.0, 0.0, 0.0]).unwrap();
    let mut ingest = Ingest::new(distorted, true).unwrap();
    let (mut h, pixels) = mono(W);
    h.undistorted = 1;
    let admitted = ingest.admit(&h, pixels.len()).unwrap();
    assert!(!admitted.remap);
    let mut out = vec![0u8; admitted.out_len];
    let published = ingest.write(&admitted, &pixels, &mut out).unwrap();
    assert_eq!(published.undistorted, 1);
    assert_eq!(out, pixels);
}
