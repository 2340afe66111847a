//! A camera frame published by one OS process is read by another in place, from the very
//! shared-memory bytes the publisher wrote, with no allocation on the receiving path.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test

use std::collections::HashMap;
use std::io::{BufRead, BufReader, Write};
use std::process::{Command, Stdio};

use runtime::IpcPrefix;

fn fields(line: &str) -> HashMap<String, String> {
    line.split_whitespace()
        .filter_map(|kv| kv.split_once('='))
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect()
}

#[test]
fn a_frame_is_read_in_place_from_the_publishers_shared_memory() {
    let exe = env!("CARGO_BIN_EXE_zero-copy-probe");
    let prefix = IpcPrefix::unique("zerocopy");
    let service = "test/zero_copy/frame";

    let mut sub = Command::new(exe)
        .args(["subscribe", prefix.as_str(), service])
        .stdout(Stdio::piped())
        .spawn()
        .expect("start subscriber");
    let mut sub_out = BufReader::new(sub.stdout.take().expect("stdout"));
    let mut line = String::new();
    sub_out.read_line(&mut line).expect("subscriber ready");
    assert_eq!(line.trim(), "ready");

    let mut publ = Command::new(exe)
        .args(["publish", prefix.as_str(), service])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("start publisher");
    let mut pub_out = BufReader::new(publ.stdout.take().expect("stdout"));
    let mut pub_line = String::new();
    pub_out.read_line(&mut pub_line).expect("publisher report");

    let mut sub_line = String::new();
    sub_out.read_line(&mut sub_line).expect("subscriber report");
    let _ = publ.stdin.take().map(|mut s| s.write_all(b"done\n"));
    assert!(sub.wait().expect("subscriber exit").success());
    assert!(publ.wait().expect("publisher exit").success());

    let p = fields(&pub_line);
    let s = fields(&sub_line);
    assert!(
        p["file"].starts_with("/dev/shm/"),
        "publisher wrote into {}",
        p["file"]
    );
    assert_eq!(
        s["file"], p["file"],
        "subscriber reads the publisher's segment"
    );
    assert_eq!(s["offset"], p["offset"], "at the very same bytes");
    assert_eq!(s["len"], (1280 * 720 * 3).to_string());
    assert_eq!(s["mismatches"], "0", "the pixels are the ones written");
    assert_eq!(
        s["allocations"], "0",
        "receiving and reading the frame allocated nothing"
    );
}
