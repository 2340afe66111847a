#![allow(clippy::unwrap_used, clippy::expect_used)]

use mavlink::dialects::common::{HEARTBEAT_DATA, MavMessage};

use super::*;

fn frame(seq: u8) -> Vec<u8> {
    let mut buf = Vec::new();
    let h = MavHeader {
        system_id: 1,
        component_id: 1,
        sequence: seq,
    };
    encode(
        &mut buf,
        h,
        &MavMessage::HEARTBEAT(HEARTBEAT_DATA::default()),
    )
    .unwrap();
    buf
}

fn seqs(out: &[(MavHeader, MavMessage)]) -> Vec<u8> {
    out.iter().map(|(h, _)| h.sequence).collect()
}

#[test]
fn frames_split_across_reads_byte_by_byte_are_all_decoded() {
    let stream: Vec<u8> = (0..5).flat_map(frame).collect();
    let mut d = StreamDecoder::new();
    let mut out = Vec::new();
    for b in &stream {
        assert_eq!(d.push(std::slice::from_ref(b), &mut out), 0);
    }
    assert_eq!(seqs(&out), vec![0, 1, 2, 3, 4]);
    assert_eq!(d.parse_errors(), 0);
}

#[test]
fn garbage_between_frames_is_skipped_and_counted_once_per_run() {
    let mut stream = b"\x00\x11hello\xfd\xfe\x42".to_vec();
    stream.extend(frame(1));
    stream.extend([0x55; 40]);
    stream.extend(frame(2));
    stream.extend(frame(3));
    let mut d = StreamDecoder::new();
    let mut out = Vec::new();
    let errors = d.push(&stream, &mut out);
    assert_eq!(seqs(&out), vec![1, 2, 3]);
    assert_eq!(errors, 2);
    assert_eq!(d.parse_errors(), 2);
}

#[test]
fn a_frame_with_a_wrong_crc_is_counted_and_the_next_frame_still_decodes() {
    let mut bad = frame(1);
    let n = bad.len();
    bad[n - 1] ^= 0xff;
    let mut stream = frame(0);
    stream.extend(bad);
    stream.extend(frame(2));
    let mut d = StreamDecoder::new();
    let mut out = Vec::new();
    d.push(&stream, &mut out);
    assert_eq!(seqs(&out), vec![0, 2]);
    assert_eq!(d.parse_errors(), 1);
}

#[test]
fn a_cut_frame_followed_by_a_whole_one_loses_only_the_cut_one() {
    let cut = frame(1);
    let mut stream = frame(0);
    stream.extend(&cut[..cut.len() / 2]);
    stream.extend(frame(2));
    stream.extend(frame(3));
    let mut d = StreamDecoder::new();
    let mut out = Vec::new();
    d.push(&stream, &mut out);
    assert!(seqs(&out).ends_with(&[3]), "{:?}", seqs(&out));
    assert!(seqs(&out).starts_with(&[0]));
    assert_eq!(d.parse_errors(), 1);
}

#[test]
fn a_well_formed_frame_of_an_unknown_message_is_skipped_without_an_error() {
    // MAVLink 2, payload 3, message id 0xABCDEF (not in the common dialect).
    let mut unknown = vec![0xfd, 3, 0, 0, 9, 1, 1, 0xef, 0xcd, 0xab, 1, 2, 3];
    unknown.extend([0x12, 0x34]);
    let mut stream = frame(0);
    stream.extend(unknown);
    stream.extend(frame(1));
    let mut d = StreamDecoder::new();
    let mut out = Vec::new();
    d.push(&stream, &mut out);
    assert_eq!(seqs(&out), vec![0, 1]);
    assert_eq!(d.parse_errors(), 0);
    assert_eq!(d.unknown_messages(), 1);
}

#[test]
fn the_buffer_never_holds_more_than_one_partial_frame() {
    let mut d = StreamDecoder::new();
    let mut out = Vec::new();
    for _ in 0..100 {
        d.push(&[0xfd, 0xff, 0, 0, 0, 0, 0, 0, 0, 0, 7, 7, 7], &mut out);
    }
    assert!(d.buf.len() <= MAX_FRAME, "{}", d.buf.len());
    assert!(out.is_empty());
}
