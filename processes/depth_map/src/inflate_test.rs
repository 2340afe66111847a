use super::*;

/// Brute force: a cell is inflated when an occupied cell's box is within `r` cells of
/// its centre.
fn brute(occ: &[[usize; 3]], dims: [usize; 3], r: f64) -> BitGrid {
    let mut g = BitGrid::new(dims);
    let gap = |d: i64| (d.abs() as f64 - 0.5).max(0.0);
    for z in 0..dims[2] {
        for y in 0..dims[1] {
            for x in 0..dims[0] {
                let hit = occ.iter().any(|o| {
                    let d = [
                        x as i64 - o[0] as i64,
                        y as i64 - o[1] as i64,
                        z as i64 - o[2] as i64,
                    ];
                    d.iter().map(|&v| gap(v).powi(2)).sum::<f64>() <= r * r + 1e-9
                });
                g.set(x, y, z, hit);
            }
        }
    }
    g
}

#[test]
fn the_paper_radius_at_the_paper_resolution_inflates_81_cells() {
    let inf = Inflater::new([10, 10, 10], 0.299 / 0.15);
    assert_eq!(inf.kernel_cells(), 81);
}

#[test]
fn inflation_matches_the_brute_force_definition_across_word_boundaries_and_edges() {
    for (dims, r) in [
        ([70, 9, 7], 0.299 / 0.15),
        ([130, 5, 5], 3.4),
        ([64, 6, 6], 1.0),
        ([8, 8, 8], 0.0),
    ] {
        let occ = [
            [0, 0, 0],
            [63, 2, 3],
            [64, 4, 1],
            [dims[0] - 1, dims[1] - 1, dims[2] - 1],
            [dims[0] / 2, 3, 3],
        ];
        let mut bits = BitGrid::new(dims);
        for o in &occ {
            bits.set(o[0].min(dims[0] - 1), o[1], o[2], true);
        }
        let clipped: Vec<_> = occ
            .iter()
            .map(|o| [o[0].min(dims[0] - 1), o[1], o[2]])
            .collect();
        let mut inf = Inflater::new(dims, r);
        inf.run(&bits);
        let want = brute(&clipped, dims, r);
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    assert_eq!(
                        inf.inflated.get(x, y, z),
                        want.get(x, y, z),
                        "dims {dims:?} r {r} at ({x}, {y}, {z})"
                    );
                }
            }
        }
        // Nothing past a row's end.
        assert_eq!(inf.inflated.count(), want.count());
    }
}

#[test]
fn an_empty_grid_inflates_to_nothing_and_a_rerun_forgets_old_obstacles() {
    let dims = [20, 20, 20];
    let mut bits = BitGrid::new(dims);
    bits.set(10, 10, 10, true);
    let mut inf = Inflater::new(dims, 2.0);
    inf.run(&bits);
    assert!(inf.inflated.get(12, 10, 10));
    bits.clear();
    inf.run(&bits);
    assert_eq!(inf.inflated.count(), 0);
}
