//! Tests of reading recorded maps back.

use ipc_types::msg::{CellState, Header, OccupancyMapHeader};
use stage::Message;

use super::*;

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
    let dir = std::env::temp_dir().join(format!("landing-maps-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("maps.mcap");
    let mut rec = recorder::Recorder::create(&path).unwrap();
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
    read_recording(&path, |m| maps.take(m).map(|_| ())).unwrap();
    assert_eq!(maps.grids, 3);
    let got: Vec<(u64, Option<Vec<u8>>)> = maps
        .maps
        .into_iter()
        .map(|m| (m.header.msg.seq, m.cells))
        .collect();
    assert_eq!(got, vec![(1, Some(ca)), (2, Some(cb)), (3, Some(cc))]);
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}
