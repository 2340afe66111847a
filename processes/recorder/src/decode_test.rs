//! Tests of reading recorded messages back.

use std::path::{Path, PathBuf};

use ipc_types::msg::{
    CellState, FsmStatus, Header, MAX_CONTROL_POINTS, OccupancyMapHeader, PadObservation, Text,
    Trajectory, VehicleState,
};
use serde_json::Value;
use stage::Message;

use super::*;
use crate::Recorder;

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("landing-decode-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// A value with every byte after its header all-ones: NaN in every float, the largest
/// value in every integer, a text that is no UTF-8 (what a corrupt fault publishes).
fn all_ones<T: Copy + Default>() -> T {
    let mut v = T::default();
    let start = std::mem::size_of::<Header>();
    // SAFETY: the message types are `#[repr(C)]` plain data starting with their header,
    // holding only integers, floats and bytes: any bit pattern is a valid value; the
    // bytes written lie within `v`.
    unsafe {
        let p = (&mut v as *mut T).cast::<u8>();
        std::ptr::write_bytes(p.add(start), 0xFF, std::mem::size_of::<T>() - start);
    }
    v
}

/// One message of every recorded payload kind, each on a topic of its kind: all-ones
/// and default (frame and map headers: default; all-ones ones are pictures of nothing).
macro_rules! every_kind {
    (
        structs: [$($(#[$sd:meta])* $s:ident($st:ty => $so:ty) = $sn:literal,)*],
        truth: [$($(#[$td:meta])* $t:ident($tt:ty => $to:ty) = $tn:literal,)*],
        slices: [$($(#[$cd:meta])* $c:ident($ch:ty, [$ce:ty]) = $cn:literal,)*],
        $($rest:tt)*
    ) => {
        fn every_kind() -> Vec<(&'static str, OwnedMessage)> {
            let on = |p: Payload| {
                topics::TABLE
                    .iter()
                    .find(|t| t.payload == p && t.service.is_some())
                    .map(|t| t.name)
                    .unwrap()
            };
            vec![
                $(
                    (on(Payload::$s), OwnedMessage::$s(all_ones::<$st>().into())),
                    (on(Payload::$s), OwnedMessage::$s(<$st>::default().into())),
                )*
                $(
                    (on(Payload::$t), OwnedMessage::$t(all_ones::<$tt>().into())),
                    (on(Payload::$t), OwnedMessage::$t(<$tt>::default().into())),
                )*
                $((on(Payload::$c), OwnedMessage::$c(<$ch>::default(), vec![])),)*
            ]
        }

        /// Records `d` as it was read, on `topic` at `t` (a header with no slice).
        fn rerecord(
            rec: &mut Recorder,
            topic: &str,
            t: u64,
            d: &Decoded,
        ) -> Result<(), crate::RecordError> {
            match d {
                Decoded::Message(m) => rec.record(topic, t, &m.as_message()),
                $(Decoded::Header(SliceHeader::$c(h)) => {
                    rec.record(topic, t, &Message::$c(h, &[]))
                })*
            }
        }
    };
}
ipc_types::for_each_payload!(every_kind);

/// The JSON messages of a recording, in order: (channel, bytes).
fn json_messages(path: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = vec![];
    read_recording(path, |m| {
        if m.encoding == "json" {
            out.push((m.topic.to_string(), m.data.to_vec()));
        }
        Ok(())
    })
    .unwrap();
    out
}

#[test]
fn every_recorded_kind_reads_back_into_what_records_the_same_json() {
    let first = temp("every-kind.mcap");
    let mut rec = Recorder::create(&first).unwrap();
    let sent = every_kind();
    for (i, (topic, m)) in sent.iter().enumerate() {
        rec.record(topic, i as u64, &m.as_message()).unwrap();
    }
    rec.finish().unwrap();

    // Read back and recorded again, each message is written the same, byte for byte:
    // every field read as written (NaN as NaN, the largest integers exact).
    let again = temp("every-kind-again.mcap");
    let mut rec = Recorder::create(&again).unwrap();
    let mut n = 0;
    read_recording(&first, |m| {
        let Some((topic, d)) = m.stack()? else {
            return Ok(());
        };
        rerecord(&mut rec, topic, m.log_time, &d)?;
        n += 1;
        Ok(())
    })
    .unwrap();
    rec.finish().unwrap();
    assert_eq!(n, sent.len(), "every kind read back");
    let (a, b) = (json_messages(&first), json_messages(&again));
    assert_eq!(a.len(), sent.len());
    assert_eq!(a, b);
}

#[test]
fn a_null_reads_back_as_nan_and_long_arrays_and_text_keep_every_item() {
    let path = temp("nan.mcap");
    let mut rec = Recorder::create(&path).unwrap();
    let state = VehicleState {
        msg: Header {
            seq: 7,
            ..Header::default()
        },
        velocity: [0.5, f64::NAN, f64::INFINITY],
        ..VehicleState::default()
    };
    let mut obs = PadObservation::default();
    obs.covariance[35] = f64::NAN;
    obs.covariance[34] = 0.1 + 0.2;
    let mut traj = Trajectory {
        count: MAX_CONTROL_POINTS as u32,
        ..Trajectory::default()
    };
    traj.control_points[MAX_CONTROL_POINTS - 1] = [1.0, f64::NAN, -0.0];
    let status = FsmStatus {
        reason: Text::new("pad lost for 2.0 s"),
        ..FsmStatus::default()
    };
    rec.record("vehicle/state", 1, &Message::VehicleState(&state))
        .unwrap();
    rec.record("pad/observation", 2, &Message::PadObservation(&obs))
        .unwrap();
    rec.record("planner/trajectory", 3, &Message::Trajectory(&traj))
        .unwrap();
    rec.record("fsm/status", 4, &Message::FsmStatus(&status))
        .unwrap();
    rec.finish().unwrap();

    let mut seen = 0;
    read_recording(&path, |m| {
        match m.topic {
            "/vehicle/state" => {
                let s: VehicleState = m.decode()?;
                assert_eq!(s.velocity[0], 0.5);
                assert!(s.velocity[1].is_nan() && s.velocity[2].is_nan());
                assert_eq!(m.header()?.seq, 7);
            }
            "/pad/observation" => {
                let o: PadObservation = m.decode()?;
                assert!(o.covariance[35].is_nan());
                assert_eq!(o.covariance[34].to_bits(), (0.1f64 + 0.2).to_bits());
            }
            "/planner/trajectory" => {
                let t: Trajectory = m.decode()?;
                let p = t.control_points[MAX_CONTROL_POINTS - 1];
                assert_eq!(p[0], 1.0);
                assert!(p[1].is_nan());
                assert_eq!(p[2].to_bits(), (-0.0f64).to_bits());
            }
            "/fsm/status" => {
                let s: FsmStatus = m.decode()?;
                assert_eq!(s.reason.as_str(), "pad lost for 2.0 s");
            }
            _ => return Ok(()),
        }
        seen += 1;
        Ok(())
    })
    .unwrap();
    assert_eq!(seen, 4);
}

#[test]
fn fields_a_message_gained_later_read_as_their_default_from_older_recordings() {
    let mut v = serde_json::to_value(VehicleState::default()).unwrap();
    let link = v["link"].as_object_mut().unwrap();
    for k in [
        "signed",
        "reserved",
        "wrong_address",
        "unknown_id",
        "replayed",
    ] {
        link.remove(k);
    }
    let s: VehicleState = from_json(&serde_json::to_vec(&v).unwrap()).unwrap();
    assert_eq!(s, VehicleState::default());
    let mut v = serde_json::to_value(OccupancyMapHeader::default()).unwrap();
    v.as_object_mut().unwrap().remove("state_ns");
    let h: OccupancyMapHeader = from_json(&serde_json::to_vec(&v).unwrap()).unwrap();
    assert_eq!(h.state_ns, 0);
    // A field every version has is not made up.
    let mut v = serde_json::to_value(VehicleState::default()).unwrap();
    v.as_object_mut().unwrap().remove("armed");
    assert!(from_json::<VehicleState>(&serde_json::to_vec(&v).unwrap()).is_err());
    assert!(from_json::<VehicleState>(b"{} trailing").is_err());
    assert_eq!(
        from_json::<Value>(b"[1.5, null]").unwrap(),
        serde_json::json!([1.5, null])
    );
}

#[test]
fn a_channel_of_another_type_or_no_json_is_an_error_naming_both() {
    let path = temp("types.mcap");
    let mut rec = Recorder::create(&path).unwrap();
    rec.record("fsm/status", 1, &Message::FsmStatus(&FsmStatus::default()))
        .unwrap();
    rec.record(
        "vehicle/state",
        2,
        &Message::VehicleState(&VehicleState::default()),
    )
    .unwrap();
    rec.finish().unwrap();
    let mut errors = vec![];
    read_recording(&path, |m| {
        if m.topic == "/fsm/status" {
            errors.push(m.decode::<VehicleState>().unwrap_err().to_string());
        }
        Ok(())
    })
    .unwrap();
    assert_eq!(
        errors,
        ["/fsm/status: holds landing::FsmStatus/v2, not landing::VehicleState/v2"]
    );
    // The caller's error names the message it met, and says what went wrong.
    let e = read_recording(&path, |m| {
        if m.topic == "/vehicle/state" {
            m.decode::<FsmStatus>()?;
        }
        Ok(())
    })
    .unwrap_err();
    assert_eq!(e.to_string(), "message on /vehicle/state at 2 ns");
    let source = std::error::Error::source(&e).map(ToString::to_string);
    assert_eq!(
        source.as_deref(),
        Some("/vehicle/state: holds landing::VehicleState/v2, not landing::FsmStatus/v2")
    );
}

fn map(seq: u64) -> OccupancyMapHeader {
    OccupancyMapHeader {
        msg: Header {
            seq,
            capture_ns: seq * 1000,
            ..Header::default()
        },
        origin: [0.0, 0.0, 0.0],
        resolution: 0.5,
        dims: [4, 3, 2],
        ..OccupancyMapHeader::default()
    }
}

#[test]
fn two_maps_taken_in_one_recorder_round_keep_their_own_cells() {
    let path = temp("maps.mcap");
    let mut rec = Recorder::create(&path).unwrap();
    let cells = |state: CellState| vec![state as u8; 24];
    let (a, b, c) = (map(1), map(2), map(3));
    let (ca, cb, cc) = (
        cells(CellState::Free),
        cells(CellState::Occupied),
        cells(CellState::Unknown),
    );
    // The first two in one round: the same log time.
    rec.record("map/occupancy", 5_000, &Message::OccupancyMap(&a, &ca))
        .unwrap();
    rec.record("map/occupancy", 5_000, &Message::OccupancyMap(&b, &cb))
        .unwrap();
    rec.record("map/occupancy", 9_000, &Message::OccupancyMap(&c, &cc))
        .unwrap();
    rec.finish().unwrap();

    let mut maps = RecordedMaps::default();
    read_recording(&path, |m| maps.take(m).map(|_| ()).map_err(Into::into)).unwrap();
    assert_eq!(maps.grids, 3);
    let got: Vec<(u64, Option<Vec<u8>>)> = maps
        .maps
        .into_iter()
        .map(|m| (m.header.msg.seq, m.cells))
        .collect();
    assert_eq!(got, vec![(1, Some(ca)), (2, Some(cb)), (3, Some(cc))]);
}
