use std::collections::HashSet;

use super::*;

fn walk(from: [f32; 3], to: [f32; 3]) -> Vec<[i32; 3]> {
    let d = Dda::new(from, to);
    let mut v = vec![d.start()];
    v.extend(d.map(|s| s.voxel));
    v
}

fn floor3(p: [f32; 3]) -> [i32; 3] {
    [
        p[0].floor() as i32,
        p[1].floor() as i32,
        p[2].floor() as i32,
    ]
}

#[test]
fn a_walk_starts_in_the_first_voxel_ends_in_the_last_and_moves_one_face_at_a_time() {
    let cases = [
        ([0.5, 0.5, 0.5], [10.2, 3.7, 1.1]),
        ([10.2, 3.7, 1.1], [0.5, 0.5, 0.5]),
        ([5.0, 5.0, 5.0], [5.9, 5.1, 5.2]),
        ([3.3, 8.8, 2.5], [-4.2, 0.1, 7.9]),
        ([1.0, 1.0, 1.0], [4.0, 4.0, 4.0]),
        ([2.5, 2.5, 2.5], [2.5, 9.5, 2.5]),
    ];
    for (from, to) in cases {
        let v = walk(from, to);
        assert_eq!(v[0], floor3(from));
        assert_eq!(*v.last().unwrap(), floor3(to));
        for w in v.windows(2) {
            let moved: i32 = (0..3).map(|i| (w[1][i] - w[0][i]).abs()).sum();
            assert_eq!(moved, 1, "{from:?} -> {to:?}: {:?} -> {:?}", w[0], w[1]);
        }
        let manhattan: i32 = (0..3)
            .map(|i| (floor3(to)[i] - floor3(from)[i]).abs())
            .sum();
        assert_eq!(v.len() as i32, manhattan + 1);
    }
}

#[test]
fn every_voxel_the_segment_passes_through_is_visited() {
    let mut seed = 7u64;
    let mut rnd = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((seed >> 33) as f32 / (1u64 << 31) as f32) * 20.0 - 10.0
    };
    for _ in 0..200 {
        let from = [rnd(), rnd(), rnd()];
        let to = [rnd(), rnd(), rnd()];
        let visited: HashSet<[i32; 3]> = walk(from, to).into_iter().collect();
        // Dense samples, away from voxel corners where the segment only grazes an edge.
        for k in 0..=2000 {
            let t = k as f32 / 2000.0;
            let p = [
                from[0] + (to[0] - from[0]) * t,
                from[1] + (to[1] - from[1]) * t,
                from[2] + (to[2] - from[2]) * t,
            ];
            let near_face = p.iter().any(|c| (c - c.round()).abs() < 1e-3);
            if !near_face {
                assert!(
                    visited.contains(&floor3(p)),
                    "{from:?} -> {to:?} misses {p:?}"
                );
            }
        }
    }
}

#[test]
fn steps_carry_the_change_of_a_linear_index() {
    let strides = [1isize, 10, 100];
    let (from, to) = ([0.5f32, 8.5, 3.5], [6.2f32, 2.7, 0.1]);
    let d = Dda::with_strides(from, to, strides);
    let lin = |v: [i32; 3]| v[0] as isize + 10 * v[1] as isize + 100 * v[2] as isize;
    let mut idx = lin(d.start());
    for s in d {
        idx += s.offset;
        assert_eq!(idx, lin(s.voxel));
        assert_eq!(s.offset, s.dir as isize * strides[s.axis]);
    }
}

#[test]
fn a_segment_inside_one_voxel_has_no_step() {
    let d = Dda::new([3.1, 3.2, 3.3], [3.9, 3.8, 3.7]);
    assert_eq!(d.remaining(), 0);
    assert_eq!(d.count(), 0);
}
