#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test
//! `landing mcap info` on a recording written by another writer (the mcap crate itself):
//! topics, counts and time range as text and JSON, and a one-line error for a file that
//! is not there.

mod common;
use common::landing;
use std::collections::BTreeMap;
use std::io::BufWriter;

fn write_recording(path: &std::path::Path) {
    let file = std::fs::File::create(path).unwrap();
    let mut w = mcap::Writer::new(BufWriter::new(file)).unwrap();
    let schema = w
        .add_schema(
            "landing::Setpoint/v1",
            "jsonschema",
            br#"{"type":"object","properties":{"valid":{"type":"integer"}}}"#,
        )
        .unwrap();
    let sp = w
        .add_channel(schema, "/fsm/setpoint", "json", &BTreeMap::new())
        .unwrap();
    let other = w
        .add_channel(schema, "/other", "json", &BTreeMap::new())
        .unwrap();
    for i in 0..20u32 {
        let header = mcap::records::MessageHeader {
            channel_id: if i % 4 == 0 { other } else { sp },
            sequence: i,
            log_time: 1_000_000_000 + u64::from(i) * 100_000_000,
            publish_time: 0,
        };
        w.write_to_known_channel(&header, br#"{"valid":1}"#)
            .unwrap();
    }
    w.finish().unwrap();
}

#[test]
fn mcap_info_prints_topics_counts_and_time_range() {
    let dir = std::env::temp_dir().join(format!("landing-mcap-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("rec.mcap");
    write_recording(&path);
    let o = landing(&["mcap", "info", path.to_str().unwrap()]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{out}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(out.contains("messages  20 on 2 topics"), "{out}");
    assert!(out.contains("1.000 s .. 2.900 s (1.900 s)"), "{out}");
    let line = out
        .lines()
        .find(|l| l.starts_with("/fsm/setpoint"))
        .unwrap();
    assert!(line.contains(" 15 "), "{line}");
    assert!(line.contains("landing::Setpoint/v1 (json)"), "{line}");

    let o = landing(&["mcap", "info", "--json", path.to_str().unwrap()]);
    assert!(o.status.success());
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["message_count"], 20);
    assert_eq!(v["complete"], true);
    assert_eq!(v["channels"][1]["topic"], "/other");
    assert_eq!(v["channels"][1]["count"], 5);
}

#[test]
fn mcap_info_on_a_missing_file_is_one_line_naming_it() {
    let o = landing(&["mcap", "info", "/nonexistent/rec.mcap"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains("/nonexistent/rec.mcap"), "{err}");
}
