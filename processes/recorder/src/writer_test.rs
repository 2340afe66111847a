//! Tests of the writer: JSON channels, their schemas, and reading them back.

use std::collections::{BTreeMap, HashMap};

use iceoryx2::prelude::ZeroCopySend;
use ipc_types::msg::{
    CameraFrameHeader, DepthFrameHeader, FsmStatus, Header, LinkOutcome, LinkRequest,
    OccupancyMapHeader, PadObservation, PlannerGoal, PlannerStats, Pose, SafetyCommand, Setpoint,
    Text, Trajectory, TruthEvent, VehicleState, WatchdogView,
};
use mcap::MessageStream;
use serde_json::Value;

use super::*;
use crate::read::info;
use crate::schema::schema_for;

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("landing-record-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap_or_default();
    dir.join(name)
}

fn header(seq: u64) -> Header {
    Header {
        seq,
        capture_ns: seq * 1000,
        ..Header::default()
    }
}

/// Writes one or more messages of every type the mission records; returns how many per
/// topic.
fn write_sample(path: &Path) -> BTreeMap<&'static str, u64> {
    let mut rec = match Recorder::create(path) {
        Ok(r) => r,
        Err(e) => panic!("{e}"),
    };
    let mut counts = BTreeMap::new();
    let mut put = |topic: &'static str, n: u64| *counts.entry(topic).or_insert(0) += n;
    let mut obs = PadObservation {
        msg: header(1),
        world_from_pad: Pose {
            translation: [1.5, -2.0, 0.4],
            rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
        },
        marker_count: 2,
        world_valid: 1,
        ..PadObservation::default()
    };
    obs.covariance[7] = 0.25;
    obs.marker_ids[1] = 68;
    let results = [
        rec.write_message("/pad/observation", 1_000_000_000, &obs),
        rec.write_message(
            "/fsm/status",
            1_000_000_000,
            &FsmStatus {
                msg: header(1),
                state: 4,
                reason: Text::new("pad seen"),
                ..FsmStatus::default()
            },
        ),
        rec.write_message(
            "/planner/trajectory",
            1_100_000_000,
            &Trajectory {
                count: 4,
                control_points: {
                    let mut c = [[0.0; 3]; ipc_types::msg::MAX_CONTROL_POINTS];
                    c[3] = [1.0, 2.0, 3.0];
                    c
                },
                ..Trajectory::default()
            },
        ),
        rec.write_message("/planner/stats", 1_100_000_000, &PlannerStats::default()),
        rec.write_message("/planner/goal", 1_050_000_000, &PlannerGoal::default()),
        rec.write_message("/fsm/setpoint", 1_120_000_000, &Setpoint::default()),
        rec.write_message(
            "/sim/truth",
            3_000_000_000,
            &TruthEvent {
                kind: 1,
                on_pad: 1,
                reason: Text::new(""),
                ..TruthEvent::default()
            },
        ),
    ];
    for r in results {
        assert!(r.is_ok(), "{r:?}");
    }
    put("/pad/observation", 1);
    put("/fsm/status", 1);
    put("/planner/trajectory", 1);
    put("/planner/stats", 1);
    put("/planner/goal", 1);
    put("/fsm/setpoint", 1);
    put("/sim/truth", 1);
    for i in 0..50u64 {
        let mut s = VehicleState {
            msg: header(i + 1),
            ..VehicleState::default()
        };
        s.velocity = [f64::from(i as u32) * 0.1, f64::NAN, 0.0];
        let r = rec.write_message("/vehicle/state", 500_000_000 + i * 20_000_000, &s);
        assert!(r.is_ok(), "{r:?}");
    }
    put("/vehicle/state", 50);
    assert_eq!(rec.message_count(), 57);
    match rec.finish() {
        Ok(n) => assert_eq!(n, 57),
        Err(e) => panic!("{e}"),
    }
    counts
}

fn decode(data: &[u8]) -> Value {
    serde_json::from_slice(data).unwrap_or(Value::Null)
}

#[test]
fn a_recording_reads_back_with_every_topic_count_schema_and_field() {
    let path = temp("roundtrip.mcap");
    let want = write_sample(&path);
    let buf = std::fs::read(&path).unwrap_or_default();
    let mut got: BTreeMap<String, u64> = BTreeMap::new();
    let mut seen_cov = false;
    let mut seen_reason = false;
    let mut seen_point = false;
    let mut last_seq: HashMap<String, u32> = HashMap::new();
    let stream = match MessageStream::new(&buf) {
        Ok(s) => s,
        Err(e) => panic!("{e}"),
    };
    for m in stream {
        let m = match m {
            Ok(m) => m,
            Err(e) => panic!("{e}"),
        };
        let topic = m.channel.topic.clone();
        *got.entry(topic.clone()).or_insert(0) += 1;
        assert_eq!(m.channel.message_encoding, "json");
        let schema = m.channel.schema.clone();
        let Some(schema) = schema else {
            panic!("{topic} has no schema")
        };
        assert_eq!(schema.encoding, "jsonschema");
        assert!(schema.name.starts_with("landing::"), "{}", schema.name);
        let prev = last_seq.insert(topic.clone(), m.sequence).unwrap_or(0);
        assert_eq!(m.sequence, prev + 1, "{topic}: sequence numbers count up");
        let v = decode(&m.data);
        match topic.as_str() {
            "/pad/observation" => {
                assert_eq!(schema.name, "landing::PadObservation/v1");
                assert_eq!(v["covariance"].as_array().map(Vec::len), Some(36));
                assert_eq!(v["covariance"][7], 0.25);
                assert_eq!(v["world_from_pad"]["translation"][0], 1.5);
                assert_eq!(v["marker_ids"][1], 68);
                assert_eq!(v["msg"]["capture_ns"], 1000);
                seen_cov = true;
            }
            "/fsm/status" => {
                assert_eq!(v["reason"], "pad seen");
                assert_eq!(v["state"], 4);
                seen_reason = true;
            }
            "/planner/trajectory" => {
                assert_eq!(v["control_points"][3]["z"], 3.0);
                seen_point = true;
            }
            "/vehicle/state" => {
                // JSON has no NaN.
                assert!(v["velocity"][1].is_null());
            }
            _ => {}
        }
    }
    let want: BTreeMap<String, u64> = want.into_iter().map(|(k, v)| (k.to_string(), v)).collect();
    assert_eq!(got, want);
    assert!(seen_cov && seen_reason && seen_point);
}

#[test]
fn schemas_describe_the_json_with_types_and_array_lengths() {
    let s = match schema_for::<PadObservation>() {
        Ok(s) => s,
        Err(e) => panic!("{e}"),
    };
    assert_eq!(s["title"], "landing::PadObservation/v1");
    assert_eq!(s["type"], "object");
    let p = &s["properties"];
    assert_eq!(p["covariance"]["type"], "array");
    assert_eq!(p["covariance"]["items"]["type"], "number");
    assert_eq!(p["covariance"]["maxItems"], 36);
    assert_eq!(p["marker_count"]["type"], "integer");
    assert_eq!(p["msg"]["properties"]["seq"]["type"], "integer");
    assert_eq!(
        p["msg"]["properties"]["stages"]["items"]["properties"]["exit_ns"]["type"],
        "integer"
    );
    let f = match schema_for::<FsmStatus>() {
        Ok(s) => s,
        Err(e) => panic!("{e}"),
    };
    assert_eq!(f["properties"]["reason"]["type"], "string");
}

/// Every type a viewer may meet: only types Foxglove's JSON Schema reader knows
/// (objects, arrays of scalars or objects, scalars; no null, no arrays of arrays).
fn assert_plain_types(v: &Value, at: &str) {
    let t = v["type"].as_str().unwrap_or("");
    assert!(
        ["object", "array", "number", "integer", "string", "boolean"].contains(&t),
        "{at}: type {:?}",
        v["type"]
    );
    if let Some(props) = v["properties"].as_object() {
        for (k, p) in props {
            assert_plain_types(p, &format!("{at}.{k}"));
        }
    }
    if t == "array" {
        let item = v["items"]["type"].as_str().unwrap_or("");
        assert_ne!(
            item, "array",
            "{at}: arrays of arrays are not read by Foxglove"
        );
        assert_plain_types(&v["items"], &format!("{at}[]"));
    }
}

macro_rules! check_names {
    ($($t:ty),*) => {$(
        // SAFETY: only reads the name the derive put there; no layout is relied on.
        let name = unsafe { <$t as ZeroCopySend>::type_name() };
        assert_eq!(<$t as Recordable>::SCHEMA_NAME, name);
        match schema_for::<$t>() {
            Ok(s) => assert_plain_types(&s, name),
            Err(e) => panic!("{e}"),
        }
    )*};
}

#[test]
fn schema_names_are_the_versioned_type_names_of_the_messages() {
    check_names!(
        PadObservation,
        VehicleState,
        Trajectory,
        PlannerStats,
        PlannerGoal,
        Setpoint,
        FsmStatus,
        TruthEvent,
        LinkRequest,
        LinkOutcome,
        SafetyCommand,
        WatchdogView,
        OccupancyMapHeader,
        CameraFrameHeader,
        DepthFrameHeader
    );
}

#[test]
fn info_reports_topics_counts_and_time_range() {
    let path = temp("info.mcap");
    let want = write_sample(&path);
    eprintln!("wrote {}", path.display());
    let i = match info(&path) {
        Ok(i) => i,
        Err(e) => panic!("{e}"),
    };
    assert!(i.complete);
    assert_eq!(i.message_count, 57);
    assert_eq!(i.time_range_ns, Some((500_000_000, 3_000_000_000)));
    let got: BTreeMap<&str, u64> = i
        .channels
        .iter()
        .map(|c| (c.topic.as_str(), c.count))
        .collect();
    assert_eq!(got, want);
    let text = i.to_string();
    assert!(text.contains("/vehicle/state"), "{text}");
    assert!(text.contains("landing::VehicleState/v2"), "{text}");
    assert!(text.contains("2.500 s"), "{text}");
}

#[test]
fn a_recording_cut_short_reads_as_not_finished_instead_of_failing() {
    let path = temp("cut.mcap");
    write_sample(&path);
    let buf = std::fs::read(&path).unwrap_or_default();
    let cut = temp("cut-short.mcap");
    std::fs::write(&cut, &buf[..buf.len() / 2]).unwrap_or_default();
    match info(&cut) {
        Ok(i) => {
            assert!(!i.complete);
            assert!(i.message_count <= 57);
            assert!(i.to_string().contains("NOT FINISHED"));
        }
        Err(e) => panic!("{e}"),
    }
}

#[test]
fn one_topic_takes_one_message_type() {
    let path = temp("types.mcap");
    let Ok(mut rec) = Recorder::create(&path) else {
        panic!("create")
    };
    assert!(rec.write_message("/t", 1, &Setpoint::default()).is_ok());
    let e = rec.write_message("/t", 2, &PlannerGoal::default());
    assert!(matches!(e, Err(RecordError::TopicType { .. })), "{e:?}");
}

#[test]
fn a_recording_in_a_missing_directory_is_an_error_naming_the_file() {
    let path = temp("no/such/dir/x.mcap");
    match Recorder::create(&path) {
        Ok(_) => panic!("created in a missing directory"),
        Err(e) => assert!(e.to_string().contains("no/such/dir/x.mcap"), "{e}"),
    }
}
