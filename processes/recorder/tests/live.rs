#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test
//! The live view: `recorder --live` serves what it records over Foxglove's WebSocket
//! protocol; a plain WebSocket client (a ground station's Foxglove, in the field) sees
//! the channels advertised, subscribes and gets the messages as they are published.

use std::io::{BufRead, BufReader};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use ipc_types::msg::{Header, VehicleState};
use ipc_types::services;
use runtime::{Ipc, IpcPrefix, monotonic_ns};
use serde_json::Value;
use tungstenite::client::IntoClientRequest;
use tungstenite::{Message, WebSocket, stream::MaybeTlsStream};

fn deploy() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy")
}

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("landing-recorder-live-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// Starts `recorder --live` with no file, listening on a free loopback port; returns it
/// and the address it logged.
fn start_live(prefix: &IpcPrefix) -> (Child, String) {
    let config = temp("live.toml");
    std::fs::write(&config, "[recorder]\nlive_address = \"127.0.0.1:0\"\n").unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_recorder"))
        .args(["--ipc-prefix", prefix.as_str(), "--live", "--deploy-dir"])
        .arg(deploy())
        .arg("--config")
        .arg(&config)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Its log, read on a thread for the whole run (a full pipe would block it).
    let (tx, rx) = mpsc::channel();
    let stderr = child.stderr.take().unwrap();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    let deadline = Instant::now() + Duration::from_secs(20);
    while Instant::now() < deadline {
        let Ok(line) = rx.recv_timeout(Duration::from_millis(100)) else {
            continue;
        };
        if let Some(i) = line.find("ws://") {
            let addr: String = line[i + 5..]
                .chars()
                .take_while(|c| c.is_ascii_digit() || *c == '.' || *c == ':')
                .collect();
            return (child, addr);
        }
    }
    let _ = child.kill();
    let _ = child.wait();
    panic!("the recorder logged no live view address");
}

fn connect(addr: &str) -> WebSocket<MaybeTlsStream<TcpStream>> {
    let mut request = format!("ws://{addr}").into_client_request().unwrap();
    request
        .headers_mut()
        .insert("Sec-WebSocket-Protocol", "foxglove.sdk.v1".parse().unwrap());
    let (socket, response) = tungstenite::connect(request).unwrap();
    assert_eq!(
        response.headers().get("Sec-WebSocket-Protocol").unwrap(),
        "foxglove.sdk.v1"
    );
    socket
}

#[test]
fn a_ground_station_subscribes_to_the_live_view_and_gets_each_state_as_it_is_published() {
    let prefix = IpcPrefix::new(&format!("lt_live_{}", std::process::id())).unwrap();
    let (mut recorder, addr) = start_live(&prefix);
    assert!(addr.starts_with("127.0.0.1:"), "{addr}");

    let ipc = Ipc::open("recorder-live-test", &prefix).unwrap();
    let mut states = ipc
        .publisher::<VehicleState>(services::VEHICLE_STATE)
        .unwrap();
    let mut ws = connect(&addr);
    // Short reads: the test publishes between them.
    if let MaybeTlsStream::Plain(s) = ws.get_mut() {
        s.set_read_timeout(Some(Duration::from_millis(5))).unwrap();
    }

    // Publish at 50 Hz until the client has subscribed and seen ten states.
    let mut channel: Option<u64> = None;
    let mut subscribed = false;
    let mut seqs: Vec<u64> = vec![];
    let mut server_name = String::new();
    let start = Instant::now();
    let mut k = 0u64;
    while seqs.len() < 10 {
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "after 30 s: channel {channel:?}, states {seqs:?}"
        );
        k += 1;
        let s = VehicleState {
            msg: Header {
                seq: k,
                ..Header::captured_at(monotonic_ns())
            },
            ..VehicleState::default()
        };
        states.send(s.msg, &s).unwrap();
        std::thread::sleep(Duration::from_millis(20));
        // Everything the server sent meanwhile.
        loop {
            match ws.read() {
                Ok(Message::Text(t)) => {
                    let v: Value = serde_json::from_str(&t).unwrap();
                    match v["op"].as_str() {
                        Some("serverInfo") => server_name = v["name"].as_str().unwrap().into(),
                        Some("advertise") => {
                            for c in v["channels"].as_array().unwrap() {
                                if c["topic"] == "/vehicle/state" {
                                    assert_eq!(c["encoding"], "json");
                                    assert_eq!(c["schemaName"], "landing::VehicleState/v2");
                                    channel = c["id"].as_u64();
                                }
                            }
                        }
                        _ => {}
                    }
                }
                Ok(Message::Binary(b)) => {
                    // messageData: opcode 1, subscription id, log time, the message.
                    assert_eq!(b[0], 1);
                    assert_eq!(u32::from_le_bytes(b[1..5].try_into().unwrap()), 7);
                    let v: Value = serde_json::from_slice(&b[13..]).unwrap();
                    seqs.push(v["msg"]["seq"].as_u64().unwrap());
                }
                Ok(_) => {}
                Err(tungstenite::Error::Io(e))
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) =>
                {
                    break;
                }
                Err(e) => panic!("{e}"),
            }
        }
        if let (Some(id), false) = (channel, subscribed) {
            let sub = serde_json::json!({
                "op": "subscribe",
                "subscriptions": [{"id": 7, "channelId": id}],
            });
            ws.send(Message::Text(sub.to_string().into())).unwrap();
            subscribed = true;
        }
    }
    assert!(server_name.starts_with("landing"), "{server_name}");
    // In order, none skipped, each the one published.
    for w in seqs.windows(2) {
        assert_eq!(w[1], w[0] + 1, "{seqs:?}");
    }
    assert!(seqs[9] <= k, "{seqs:?} (published up to {k})");

    let _ = ws.close(None);
    unsafe { libc::kill(recorder.id() as i32, libc::SIGTERM) };
    let status = recorder.wait().unwrap();
    assert!(status.success(), "{status}");
}
