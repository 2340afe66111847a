//! Occupancy as bits, and inflation as a dilation of those bits.
//!
//! Each x-row of the window is a few `u64` words, so dilating along x is a handful of
//! shifts per word, and dilating along y and z is OR-ing whole rows. The kernel is the
//! set of cell offsets whose centre lies within the inflation radius of the occupied
//! cell's *box* (not its centre): with 0.15 m cells and 0.299 m, two cells along each
//! axis, the 5x5x5 cube without the cells two away along two or three axes (81 cells).
//! Written as "for each (dy, dz), the x-extent", the dilation of a whole window is a few
//! tens of passes over a few thousand words: tens of microseconds, with no bookkeeping
//! to keep consistent when cells change or the window moves.

/// A 3D grid of bits, x fastest; each (y, z) row is `words` whole `u64`s (the bits past
/// the row's end stay 0).
#[derive(Debug, Clone)]
pub(crate) struct BitGrid {
    dims: [usize; 3],
    words: usize,
    data: Vec<u64>,
}

impl BitGrid {
    /// All zero. Allocates once.
    pub(crate) fn new(dims: [usize; 3]) -> Self {
        let words = dims[0].div_ceil(64);
        Self {
            dims,
            words,
            data: vec![0; words * dims[1] * dims[2]],
        }
    }

    #[inline]
    fn row_start(&self, y: usize, z: usize) -> usize {
        (z * self.dims[1] + y) * self.words
    }

    #[inline]
    pub(crate) fn get(&self, x: usize, y: usize, z: usize) -> bool {
        let w = self.row_start(y, z) + x / 64;
        self.data.get(w).is_some_and(|v| v >> (x % 64) & 1 == 1)
    }

    #[inline]
    pub(crate) fn set(&mut self, x: usize, y: usize, z: usize, on: bool) {
        let w = self.row_start(y, z) + x / 64;
        if let Some(v) = self.data.get_mut(w) {
            let m = 1u64 << (x % 64);
            if on {
                *v |= m;
            } else {
                *v &= !m;
            }
        }
    }

    /// Calls `f(x, y, z)` for every set bit, in storage order.
    pub(crate) fn for_each_set(&self, f: &mut impl FnMut(usize, usize, usize)) {
        let ny = self.dims[1];
        for (r, row) in self.data.chunks_exact(self.words).enumerate() {
            let (y, z) = (r % ny, r / ny);
            for (w, &word) in row.iter().enumerate() {
                let mut bits = word;
                while bits != 0 {
                    let b = bits.trailing_zeros() as usize;
                    f(w * 64 + b, y, z);
                    bits &= bits - 1;
                }
            }
        }
    }

    pub(crate) fn clear(&mut self) {
        self.data.fill(0);
    }

    /// Number of set bits.
    #[cfg(test)]
    pub(crate) fn count(&self) -> usize {
        self.data.iter().map(|w| w.count_ones() as usize).sum()
    }

    /// The storage's address and capacity (to show that nothing reallocates).
    pub(crate) fn storage(&self) -> (usize, usize) {
        (self.data.as_ptr() as usize, self.data.capacity())
    }

    fn bytes(&self) -> usize {
        self.data.capacity() * 8
    }
}

/// Which offsets inflate: for each (dy, dz) column, the largest |dx|.
#[derive(Debug, Clone)]
struct Kernel {
    /// (dy, dz, index into the x-extents).
    columns: Vec<(i32, i32, usize)>,
    /// Distinct x-extents, cells.
    extents: Vec<usize>,
}

impl Kernel {
    /// The cells whose centre is within `radius` (cells) of the box of cell 0.
    fn new(radius: f64) -> Self {
        let r = radius.max(0.0);
        let reach = (r + 0.5).floor() as i32;
        // Distance from an offset's centre to the unit box around the origin, squared.
        let gap = |d: i32| (f64::from(d.abs()) - 0.5).max(0.0);
        let mut columns = Vec::new();
        let mut extents: Vec<usize> = Vec::new();
        for dz in -reach..=reach {
            for dy in -reach..=reach {
                let yz = gap(dy).powi(2) + gap(dz).powi(2);
                let mut ex = None;
                for dx in 0..=reach {
                    if yz + gap(dx).powi(2) <= r * r + 1e-9 {
                        ex = Some(dx as usize);
                    }
                }
                if let Some(e) = ex {
                    let k = match extents.iter().position(|&v| v == e) {
                        Some(k) => k,
                        None => {
                            extents.push(e);
                            extents.len() - 1
                        }
                    };
                    columns.push((dy, dz, k));
                }
            }
        }
        Self { columns, extents }
    }

    fn cells(&self) -> usize {
        self.columns
            .iter()
            .map(|&(_, _, k)| 2 * self.extents[k] + 1)
            .sum()
    }
}

/// Dilates an occupancy [`BitGrid`] into an inflation grid, with scratch allocated once.
#[derive(Debug, Clone)]
pub(crate) struct Inflater {
    kernel: Kernel,
    /// One x-dilated copy of the occupancy per distinct x-extent.
    dilated_x: Vec<BitGrid>,
    /// The result: cells within the radius of an occupied cell (occupied ones included).
    pub(crate) inflated: BitGrid,
}

impl Inflater {
    /// For a window of `dims` cells and a radius of `radius_cells`.
    pub(crate) fn new(dims: [usize; 3], radius_cells: f64) -> Self {
        let kernel = Kernel::new(radius_cells);
        let dilated_x = kernel.extents.iter().map(|_| BitGrid::new(dims)).collect();
        Self {
            kernel,
            dilated_x,
            inflated: BitGrid::new(dims),
        }
    }

    /// Cells in the kernel (81 for 0.299 m at 0.15 m).
    pub(crate) fn kernel_cells(&self) -> usize {
        self.kernel.cells()
    }

    /// Recomputes `inflated` from `occupied`.
    pub(crate) fn run(&mut self, occupied: &BitGrid) {
        let dims = occupied.dims;
        let words = occupied.words;
        let tail_mask = match dims[0] % 64 {
            0 => u64::MAX,
            r => (1u64 << r) - 1,
        };
        for (grid, &e) in self.dilated_x.iter_mut().zip(&self.kernel.extents) {
            for (src, dst) in occupied
                .data
                .chunks_exact(words)
                .zip(grid.data.chunks_exact_mut(words))
            {
                dilate_row(src, dst, e, tail_mask);
            }
        }
        self.inflated.clear();
        let (ny, nz) = (dims[1] as i32, dims[2] as i32);
        for &(dy, dz, k) in &self.kernel.columns {
            let Some(src) = self.dilated_x.get(k) else {
                continue;
            };
            let (y0, y1) = (0.max(-dy), ny.min(ny - dy));
            let (z0, z1) = (0.max(-dz), nz.min(nz - dz));
            if y0 >= y1 {
                continue;
            }
            // For one z, rows y0..y1 are one contiguous block in both grids.
            let len = (y1 - y0) as usize * words;
            for z in z0..z1 {
                let from = src.row_start((y0 + dy) as usize, (z + dz) as usize);
                let to = self.inflated.row_start(y0 as usize, z as usize);
                let (Some(s), Some(d)) = (
                    src.data.get(from..from + len),
                    self.inflated.data.get_mut(to..to + len),
                ) else {
                    continue;
                };
                for (d, s) in d.iter_mut().zip(s) {
                    *d |= *s;
                }
            }
        }
    }

    /// Calls `f(x, y, z)` for every inflated cell.
    pub(crate) fn for_each_inflated(&self, mut f: impl FnMut(usize, usize, usize)) {
        self.inflated.for_each_set(&mut f);
    }

    /// Bytes of scratch and result.
    pub(crate) fn bytes(&self) -> usize {
        self.inflated.bytes() + self.dilated_x.iter().map(BitGrid::bytes).sum::<usize>()
    }

    /// Addresses and capacities of every buffer.
    pub(crate) fn storage(&self, out: &mut Vec<(usize, usize)>) {
        out.push(self.inflated.storage());
        out.extend(self.dilated_x.iter().map(BitGrid::storage));
    }
}

/// `dst` = `src` dilated by `e` cells along x (bit i set if any bit within i-e..=i+e is).
#[inline]
fn dilate_row(src: &[u64], dst: &mut [u64], e: usize, tail_mask: u64) {
    dst.copy_from_slice(src);
    for s in 1..=e {
        let (q, r) = (s / 64, (s % 64) as u32);
        for (i, d) in dst.iter_mut().enumerate() {
            // Bits of src moved up by s (toward larger x) and down by s.
            let up = word_at(src, i as isize - q as isize) << r
                | if r == 0 {
                    0
                } else {
                    word_at(src, i as isize - q as isize - 1) >> (64 - r)
                };
            let down = word_at(src, i as isize + q as isize) >> r
                | if r == 0 {
                    0
                } else {
                    word_at(src, i as isize + q as isize + 1) << (64 - r)
                };
            *d |= up | down;
        }
    }
    if let Some(last) = dst.last_mut() {
        *last &= tail_mask;
    }
}

#[inline]
fn word_at(words: &[u64], i: isize) -> u64 {
    if i < 0 {
        0
    } else {
        words.get(i as usize).copied().unwrap_or(0)
    }
}

#[cfg(test)]
#[path = "inflate_test.rs"]
mod tests;
