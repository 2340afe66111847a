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
        assert_eq!(
            d.push(std::slice::from_ref(b), 0, &mut Guard::open(), &mut out),
            0
        );
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
    let errors = d.push(&stream, 0, &mut Guard::open(), &mut out);
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
    d.push(&stream, 0, &mut Guard::open(), &mut out);
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
    d.push(&stream, 0, &mut Guard::open(), &mut out);
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
    d.push(&stream, 0, &mut Guard::open(), &mut out);
    assert_eq!(seqs(&out), vec![0, 1]);
    assert_eq!(d.parse_errors(), 0);
    assert_eq!(d.unknown_messages(), 1);
}

#[test]
fn the_buffer_never_holds_more_than_one_partial_frame() {
    let mut d = StreamDecoder::new();
    let mut out = Vec::new();
    for _ in 0..100 {
        d.push(
            &[0xfd, 0xff, 0, 0, 0, 0, 0, 0, 0, 0, 7, 7, 7],
            0,
            &mut Guard::open(),
            &mut out,
        );
    }
    assert!(d.buf.len() <= MAX_FRAME, "{}", d.buf.len());
    assert!(out.is_empty());
}

fn heartbeat_from(sys: u8, comp: u8, seq: u8, guard: &mut Guard, now_ns: u64) -> Vec<u8> {
    let mut buf = Vec::new();
    let h = MavHeader {
        system_id: u32::from(sys),
        component_id: comp,
        sequence: seq,
    };
    guard
        .encode(
            &mut buf,
            h,
            &MavMessage::HEARTBEAT(HEARTBEAT_DATA::default()),
            now_ns,
        )
        .unwrap();
    buf
}

#[test]
fn a_guard_acts_only_on_its_peer_and_counts_the_others() {
    let mut send = Guard::open();
    let mut datagram = heartbeat_from(1, 1, 0, &mut send, 0);
    datagram.extend(heartbeat_from(7, 1, 1, &mut send, 0));
    datagram.extend(heartbeat_from(1, 190, 2, &mut send, 0));
    let mut guard = Guard::new(Some((1, 1)), None);
    let mut out = Vec::new();
    let errors = StreamDecoder::new().push_datagram(&datagram, 0, &mut guard, &mut out);
    assert_eq!(errors, 0);
    assert_eq!(seqs(&out), vec![0]);
    assert_eq!(guard.rejected().wrong_source, 2);
}

#[test]
fn a_signed_link_takes_signed_frames_and_counts_unsigned_foreign_and_replayed_ones() {
    use crate::signing::{Signer, SigningKey};
    let key = SigningKey::from_bytes([7; 32]);
    // 2026-11-26 as the sender's and receiver's clock.
    let unix = 1_795_000_000_000_000_000;
    let mut sender = Guard::new(None, Some(Signer::new(key.clone(), 1, unix)));
    let mut stranger = Guard::new(
        None,
        Some(Signer::new(SigningKey::from_bytes([8; 32]), 1, unix)),
    );
    let mut receiver = Guard::new(Some((1, 1)), Some(Signer::new(key, 0, unix)));
    let mut out = Vec::new();
    let mut d = StreamDecoder::new();

    let signed = heartbeat_from(1, 1, 0, &mut sender, 1_000);
    assert_eq!(signed.len(), frame(0).len() + 13);
    d.push_datagram(&signed, 2_000, &mut receiver, &mut out);
    assert_eq!(seqs(&out), vec![0]);

    // The same bytes again: not newer than the stream's last.
    d.push_datagram(&signed, 3_000, &mut receiver, &mut out);
    // Unsigned, and signed with another key.
    d.push_datagram(&frame(1), 3_000, &mut receiver, &mut out);
    let forged = heartbeat_from(1, 1, 2, &mut stranger, 3_000);
    d.push_datagram(&forged, 3_000, &mut receiver, &mut out);
    // A signed frame altered on the way (its checksum redone, as an attacker can).
    let mut altered = heartbeat_from(1, 1, 3, &mut sender, 4_000);
    altered[10] ^= 1;
    let n = altered.len() - 13;
    let crc = crate::raw::crc_accumulate(
        crate::raw::crc_accumulate(0xffff, &altered[1..n - 2]),
        &[<MavMessage as mavlink::Message>::extra_crc(0)],
    );
    altered[n - 2..n].copy_from_slice(&crc.to_le_bytes());
    d.push_datagram(&altered, 5_000, &mut receiver, &mut out);
    // A newer signed frame is taken.
    let next = heartbeat_from(1, 1, 4, &mut sender, 6_000);
    d.push_datagram(&next, 7_000, &mut receiver, &mut out);

    assert_eq!(seqs(&out), vec![0, 4]);
    let r = receiver.rejected();
    assert_eq!(
        (r.replayed, r.unsigned, r.bad_signature),
        (1, 1, 2),
        "{r:?}"
    );
}

#[test]
fn a_first_signed_frame_more_than_a_minute_old_is_refused_as_replayed() {
    use crate::signing::{Signer, SigningKey};
    let key = SigningKey::from_bytes([9; 32]);
    let unix = 1_795_000_000_000_000_000;
    let mut sender = Guard::new(None, Some(Signer::new(key.clone(), 1, unix)));
    let old = heartbeat_from(1, 1, 0, &mut sender, 0);
    // The receiver starts 61 s later (a restart, say) and meets the recorded frame.
    let mut receiver = Guard::new(None, Some(Signer::new(key, 0, unix)));
    let mut out = Vec::new();
    StreamDecoder::new().push_datagram(&old, 61_000_000_000, &mut receiver, &mut out);
    assert!(out.is_empty());
    assert_eq!(receiver.rejected().replayed, 1);
    // 59 s would do: the MAVLink rule, which a key change or a longer session defeats.
    let mut fresh = Guard::new(
        None,
        Some(Signer::new(SigningKey::from_bytes([9; 32]), 0, unix)),
    );
    StreamDecoder::new().push_datagram(&old, 59_000_000_000, &mut fresh, &mut out);
    assert_eq!(out.len(), 1);
}
