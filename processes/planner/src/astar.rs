//! A* on the map's lattice: 26-connected, octile (3-D diagonal) heuristic.
//!
//! It guides the rebound only: its path decides which side of an obstacle a control
//! point is pushed to. Buffers are kept between searches and reset by a generation
//! counter, so a search costs what it expands, not the size of the map.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use nalgebra::Vector3;

use crate::map::OccupancyQuery;

/// An open-list entry packed in one word: the f-value's bits above the cell index. f is
/// finite and non-negative, so its bits order as the value does, and a heap of words
/// moves a third of the bytes a struct would.
#[inline]
fn open_key(f: f32, idx: u32) -> Reverse<u64> {
    Reverse(((f.to_bits() as u64) << 32) | idx as u64)
}

/// Per-cell search state, together so that a neighbour costs one cache line.
#[derive(Debug, Clone, Copy, Default)]
struct Node {
    /// The search that last touched the cell (the rest is stale when it differs).
    stamp: u32,
    g: f32,
    parent: u32,
    closed: bool,
}

/// The default heuristic weight: ties break toward the goal, far fewer expansions than
/// plain A* and the same path length to within 0.1%.
pub const TIE_BREAK: f32 = 1.0 + 1e-3;

/// Reusable A* search state.
#[derive(Debug, Clone, Default)]
pub struct AStar {
    nodes: Vec<Node>,
    heap: BinaryHeap<Reverse<u64>>,
    current: u32,
    /// Expansion limit per search (bounds the time on a maze).
    pub max_expansions: usize,

    /// Heuristic weight (>= 1): 1 + 1e-3 breaks ties toward the goal; larger values
    /// trade path length for far fewer expansions (weighted A*: at most `weight` times
    /// the shortest path).
    pub weight: f32,
    /// Cells expanded over all searches so far (a work counter for the statistics).
    pub expansions: u64,
}

/// Octile distance in 3-D between two cells, in cells.
#[inline]
fn octile(a: [i32; 3], b: [i32; 3]) -> f32 {
    let x = (a[0] - b[0]).abs();
    let y = (a[1] - b[1]).abs();
    let z = (a[2] - b[2]).abs();
    let lo = x.min(y).min(z) as f32;
    let hi = x.max(y).max(z) as f32;
    let mid = (x + y + z) as f32 - lo - hi;
    (3f32.sqrt() - 2f32.sqrt()) * lo + (2f32.sqrt() - 1.0) * mid + hi
}

/// The 26 neighbour offsets and their step lengths, in cells.
const NEIGHBOURS: [([i32; 3], f32); 26] = {
    let mut out = [([0i32; 3], 0f32); 26];
    let mut k = 0;
    let mut dz = -1;
    while dz <= 1 {
        let mut dy = -1;
        while dy <= 1 {
            let mut dx = -1;
            while dx <= 1 {
                let m = (dx * dx + dy * dy + dz * dz) as usize;
                if m != 0 {
                    let step = [0.0, 1.0, std::f32::consts::SQRT_2, 1.732_050_8][m];
                    out[k] = ([dx, dy, dz], step);
                    k += 1;
                }
                dx += 1;
            }
            dy += 1;
        }
        dz += 1;
    }
    out
};

impl AStar {
    /// A search state with a limit of `max_expansions` expanded cells per search.
    pub fn new(max_expansions: usize) -> Self {
        Self {
            max_expansions,
            weight: TIE_BREAK,
            ..Self::default()
        }
    }

    /// Shortest 26-connected path of free cells from `from` to `to`, written into `out`
    /// as points (`from`, cell centres, `to`). The start cell may be occupied (to leave
    /// the inflation); the goal cell must be free and both must be in the map. Returns
    /// false when there is no path within the expansion limit.
    pub fn search<M: OccupancyQuery + ?Sized>(
        &mut self,
        map: &M,
        from: &Vector3<f64>,
        to: &Vector3<f64>,
        out: &mut Vec<Vector3<f64>>,
    ) -> bool {
        out.clear();
        let res = map.resolution();
        let (lo, hi) = map.bounds();
        let mut dims = [0i32; 3];
        for i in 0..3 {
            dims[i] = (((hi[i] - lo[i]) / res).round() as i32).max(1);
        }
        let total = dims.iter().map(|&d| d as usize).product::<usize>();
        if total > u32::MAX as usize / 2 {
            return false;
        }
        let cell = |p: &Vector3<f64>| -> Option<[i32; 3]> {
            let mut c = [0i32; 3];
            for i in 0..3 {
                let f = ((p[i] - lo[i]) / res).floor();
                if !(f >= 0.0) || f >= dims[i] as f64 {
                    return None;
                }
                c[i] = f as i32;
            }
            Some(c)
        };
        let (Some(s), Some(t)) = (cell(from), cell(to)) else {
            return false;
        };
        let centre = |c: [i32; 3]| {
            Vector3::new(
                lo[0] + (c[0] as f64 + 0.5) * res,
                lo[1] + (c[1] as f64 + 0.5) * res,
                lo[2] + (c[2] as f64 + 0.5) * res,
            )
        };
        if map.is_occupied(&centre(t)) {
            return false;
        }
        let lin = |c: [i32; 3]| ((c[2] * dims[1] + c[1]) * dims[0] + c[0]) as u32;
        let unlin = |i: u32| {
            let i = i as i32;
            [
                i % dims[0],
                (i / dims[0]) % dims[1],
                i / (dims[0] * dims[1]),
            ]
        };
        if self.nodes.len() < total {
            self.nodes.resize(total, Node::default());
        }
        self.current = self.current.wrapping_add(1);
        if self.current == 0 {
            self.nodes.iter_mut().for_each(|n| n.stamp = 0);
            self.current = 1;
        }
        let cur = self.current;
        self.heap.clear();
        let si = lin(s);
        let ti = lin(t);
        self.nodes[si as usize] = Node {
            stamp: cur,
            g: 0.0,
            parent: si,
            closed: false,
        };
        // Linear offsets of the neighbours: away from the faces a neighbour is `idx + off`.
        let mut offsets = [0i64; 26];
        for (o, (d, _)) in offsets.iter_mut().zip(&NEIGHBOURS) {
            *o = (d[2] as i64 * dims[1] as i64 + d[1] as i64) * dims[0] as i64 + d[0] as i64;
        }
        // A slightly greedy heuristic: ties break toward the goal, far fewer expansions.
        let tie = self.weight;
        self.heap.push(open_key(octile(s, t) * tie, si));
        let mut expanded = 0usize;
        let mut found = false;
        while let Some(Reverse(key)) = self.heap.pop() {
            let idx = key as u32;
            let oi = idx as usize;
            let node = self.nodes[oi];
            // Lazy deletion: the first entry popped for a cell carries its best g (a
            // better g means a smaller f for the same cell); later ones find it closed.
            if node.closed {
                continue;
            }
            if idx == ti {
                found = true;
                break;
            }
            self.nodes[oi].closed = true;
            expanded += 1;
            if expanded > self.max_expansions {
                break;
            }
            let c = unlin(idx);
            let g = node.g;
            let interior = (0..3).all(|i| c[i] > 0 && c[i] < dims[i] - 1);
            for (k, &(d, step)) in NEIGHBOURS.iter().enumerate() {
                let nc = [c[0] + d[0], c[1] + d[1], c[2] + d[2]];
                if !interior && (0..3).any(|i| nc[i] < 0 || nc[i] >= dims[i]) {
                    continue;
                }
                let ni = (idx as i64 + offsets[k]) as u32;
                let nu = ni as usize;
                let n = &mut self.nodes[nu];
                let fresh = n.stamp != cur;
                if !fresh && n.closed {
                    continue;
                }
                let ng = g + step;
                if !fresh && ng >= n.g {
                    continue;
                }
                if fresh {
                    // Occupancy is asked once per cell per search.
                    n.stamp = cur;
                    n.closed = false;
                    if map.is_occupied(&centre(nc)) {
                        n.closed = true;
                        continue;
                    }
                }
                n.g = ng;
                n.parent = idx;
                self.heap.push(open_key(ng + octile(nc, t) * tie, ni));
            }
        }
        self.expansions += expanded as u64;
        if !found {
            return false;
        }
        let mut i = ti;
        out.push(*to);
        loop {
            let p = self.nodes[i as usize].parent;
            if p == i || out.len() > total {
                break;
            }
            if p != si {
                out.push(centre(unlin(p)));
            }
            i = p;
        }
        out.push(*from);
        out.reverse();
        true
    }
}
