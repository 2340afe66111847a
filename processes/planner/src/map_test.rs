use super::*;

fn v(x: f64, y: f64, z: f64) -> Vector3<f64> {
    Vector3::new(x, y, z)
}

#[test]
fn a_box_is_occupied_with_its_inflation_and_free_beyond() {
    let b = Aabb {
        min: v(2.0, 2.0, 0.0),
        max: v(3.0, 3.0, 2.0),
    };
    let m = GridMap::from_boxes(v(0.0, 0.0, 0.0), v(5.0, 5.0, 3.0), 0.15, 0.299, &[b]).unwrap();
    assert!(m.is_occupied(&v(2.5, 2.5, 1.0)));
    assert!(m.is_occupied(&v(1.8, 2.5, 1.0)));
    assert!(!m.is_occupied(&v(1.5, 2.5, 1.0)));
    // Every free cell centre is at least the inflation away from the box.
    for i in 0..50 {
        for j in 0..50 {
            let p = v(i as f64 * 0.1 + 0.05, j as f64 * 0.1 + 0.05, 1.0);
            if !m.is_occupied(&p) {
                assert!(b.distance(&p) >= 0.299 - 1e-9, "{p}");
            }
        }
    }
    assert!(!m.is_occupied(&v(-1.0, 2.5, 1.0)), "outside reads as free");
    assert!(!m.is_occupied(&v(f64::NAN, 2.5, 1.0)));
}

#[test]
fn bad_map_parameters_are_errors() {
    assert!(GridMap::new(v(0.0, 0.0, 0.0), v(1.0, 1.0, 1.0), 0.0, 0.3).is_err());
    assert!(GridMap::new(v(0.0, 0.0, 0.0), v(-1.0, 1.0, 1.0), 0.1, 0.3).is_err());
    assert!(GridMap::new(v(0.0, 0.0, 0.0), v(1e6, 1e6, 1e6), 0.1, 0.3).is_err());
}

#[test]
fn the_wire_view_treats_occupied_and_inflated_as_occupied_and_unknown_as_free() {
    let header = OccupancyMapHeader {
        origin: [0.0, 0.0, 0.0],
        resolution: 1.0,
        dims: [4, 1, 1],
        ..Default::default()
    };
    let cells = [0u8, 1, 2, 3];
    let view = CellView::new(&header, &cells).unwrap();
    assert!(!view.is_occupied(&v(0.5, 0.5, 0.5)));
    assert!(!view.is_occupied(&v(1.5, 0.5, 0.5)));
    assert!(view.is_occupied(&v(2.5, 0.5, 0.5)));
    assert!(view.is_occupied(&v(3.5, 0.5, 0.5)));
    assert!(
        CellView::new(&header, &cells[..3]).is_none(),
        "short payload"
    );
}
