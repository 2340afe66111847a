//! Tests of reading recordings back: damage is named by its offset, and what came
//! before it still counts.

use std::path::PathBuf;

use ipc_types::msg::{Header, Setpoint};

use super::*;
use crate::writer::{ChunkCompression, RecordOptions, Recorder};

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("landing-read-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap_or_default();
    dir.join(name)
}

/// Three seconds of setpoints at 50 Hz, flushed every second: several chunks. Returns
/// the file's bytes.
fn three_chunks(name: &str, compression: ChunkCompression) -> Vec<u8> {
    let path = temp(name);
    let options = RecordOptions {
        compression,
        ..RecordOptions::default()
    };
    let Ok(mut rec) = Recorder::with_options(&path, options) else {
        panic!("create {}", path.display())
    };
    for i in 0..150u64 {
        let sp = Setpoint {
            msg: Header {
                seq: i + 1,
                ..Header::default()
            },
            ..Setpoint::default()
        };
        let r = rec.write_message("/fsm/setpoint", i * 20_000_000, &sp);
        assert!(r.is_ok(), "{r:?}");
    }
    assert!(rec.finish().is_ok());
    std::fs::read(&path).unwrap_or_default()
}

/// Offsets of the top-level records with `opcode`.
fn records(buf: &[u8], opcode: u8) -> Vec<usize> {
    let mut pos = 8;
    let mut found = vec![];
    while pos + 9 <= buf.len() {
        let len = u64::from_le_bytes(buf[pos + 1..pos + 9].try_into().unwrap_or([0; 8]));
        if buf[pos] == opcode {
            found.push(pos);
        }
        pos += 9 + len as usize;
    }
    found
}

const CHUNK: u8 = 0x06;

fn read(buf: &[u8]) -> ReadSummary {
    match read_buffer(buf, &mut |_| {}) {
        Some(s) => s,
        None => panic!("not MCAP"),
    }
}

#[test]
fn a_finished_recording_reads_whole_and_complete() {
    for c in [
        ChunkCompression::Zstd,
        ChunkCompression::Lz4,
        ChunkCompression::None,
    ] {
        let buf = three_chunks(&format!("whole-{c:?}.mcap"), c);
        assert!(
            records(&buf, CHUNK).len() >= 3,
            "{c:?}: flushed every second"
        );
        let s = read(&buf);
        assert_eq!(s.messages, 150, "{c:?}");
        assert!(s.complete, "{c:?}");
        assert_eq!(s.broken, None, "{c:?}");
    }
}

#[test]
fn a_recording_cut_inside_a_chunk_names_the_chunk_and_keeps_the_chunks_before() {
    let buf = three_chunks("cut.mcap", ChunkCompression::Zstd);
    let chunks = records(&buf, CHUNK);
    let second = chunks[1];
    let cut = &buf[..second + 20];
    let mut before = 0;
    let _ = read_buffer(&buf[..second], &mut |_| before += 1);
    let s = read(cut);
    assert!(
        before >= 40,
        "the first second is in the first chunk: {before}"
    );
    assert_eq!(s.messages, before);
    assert!(!s.complete);
    let Some(b) = s.broken else {
        panic!("a cut inside a record is damage")
    };
    assert_eq!(b.offset, second as u64);
    assert_eq!(b.size, cut.len() as u64);
    assert!(b.reason.starts_with("truncated"), "{b}");
    assert!(b.to_string().contains(&format!("byte {second} of")), "{b}");
}

#[test]
fn a_recording_that_ends_between_records_is_unfinished_but_not_broken() {
    let buf = three_chunks("between.mcap", ChunkCompression::Zstd);
    let chunks = records(&buf, CHUNK);
    let s = read(&buf[..chunks[2]]);
    assert!(!s.complete);
    assert_eq!(s.broken, None);
    assert!(s.messages >= 80, "{}", s.messages);
}

#[test]
fn a_corrupted_chunk_names_its_offset_and_the_reading_stops_there() {
    let mut buf = three_chunks("corrupt.mcap", ChunkCompression::Zstd);
    let chunks = records(&buf, CHUNK);
    let second = chunks[1];
    // Into the compressed records, past the chunk's own header fields.
    for b in &mut buf[second + 80..second + 120] {
        *b ^= 0x5a;
    }
    let s = read(&buf);
    let Some(b) = s.broken else {
        panic!("damage went unseen")
    };
    assert_eq!(b.offset, second as u64, "{b}");
    assert!(b.reason.contains("chunk"), "{b}");
    assert!(s.messages >= 40 && s.messages < 150, "{}", s.messages);
}

#[test]
fn a_bad_opcode_is_named_with_its_offset() {
    let mut buf = three_chunks("opcode.mcap", ChunkCompression::Zstd);
    let third = records(&buf, CHUNK)[2];
    buf[third] = 0xee;
    let s = read(&buf);
    let Some(b) = s.broken else {
        panic!("damage went unseen")
    };
    assert_eq!(b.offset, third as u64);
    assert!(b.reason.contains("opcode 0xee"), "{b}");
}

#[test]
fn random_bytes_are_not_an_mcap_file() {
    let path = temp("random.mcap");
    let bytes: Vec<u8> = (0..4096u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    std::fs::write(&path, bytes).unwrap_or_default();
    match info(&path) {
        Err(e @ ReadError::NotMcap { .. }) => {
            assert!(e.to_string().contains("is not an MCAP file"), "{e}")
        }
        other => panic!("{other:?}"),
    }
    assert!(read_buffer(b"", &mut |_| {}).is_none());
}
