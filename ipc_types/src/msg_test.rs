//! Tests of `msg`.

use super::*;

#[test]
fn header_keeps_origin_and_newest_stages_when_full() {
    let mut h = Header::captured_at(5);
    for i in 0..(MAX_STAGES as u64 + 3) {
        h.push_stage(Stage::Bench, i, i + 1);
    }
    assert_eq!(h.stages().len(), MAX_STAGES);
    assert_eq!(h.stages()[0].enter_ns, 0);
    assert_eq!(h.stages()[MAX_STAGES - 1].enter_ns, MAX_STAGES as u64 + 2);
    assert_eq!(h.capture_ns, 5);
}

#[test]
fn frame_header_rejects_inconsistent_geometry() {
    let mut h = CameraFrameHeader {
        width: 640,
        height: 480,
        stride: 640,
        encoding: PixelEncoding::Mono8 as u32,
        ..Default::default()
    };
    assert_eq!(h.expected_len(), Some(640 * 480));
    h.encoding = PixelEncoding::Bgr8 as u32;
    assert_eq!(h.expected_len(), None, "stride shorter than a BGR row");
    h.encoding = 99;
    assert_eq!(h.expected_len(), None, "unknown encoding");
}

#[test]
fn text_cuts_at_a_character_boundary() {
    let long = "é".repeat(TEXT_LEN);
    let t = Text::new(&long);
    assert!(t.as_str().len() <= TEXT_LEN);
    assert!(t.as_str().chars().all(|c| c == 'é'));
}

#[test]
fn unknown_raw_values_decode_to_safe_defaults() {
    assert_eq!(SafetyAction::from_raw(77), SafetyAction::SafeLand);
    assert_eq!(GoalMode::from_raw(77), GoalMode::Stop);
    assert_eq!(CellState::from_raw(77), CellState::Unknown);
    assert_eq!(FlightMode::from_raw(77), FlightMode::Unknown);
    assert_eq!(PixelEncoding::from_raw(77), None);
}
