use super::*;

#[test]
fn the_voxel_grid_holds_every_cell_where_foxglove_reads_it() {
    let (nx, ny, nz) = (4u32, 3u32, 2u32);
    let h = OccupancyMapHeader {
        origin: [-1.0, 2.0, 0.5],
        resolution: 0.25,
        dims: [nx, ny, nz],
        ..OccupancyMapHeader::default()
    };
    let mut cells = vec![CellState::Free as u8; (nx * ny * nz) as usize];
    // The stack's layout: x fastest, then y, then z.
    let (x, y, z) = (3usize, 1usize, 1usize);
    cells[x + nx as usize * (y + ny as usize * z)] = CellState::Occupied as u8;
    let g = voxel_grid(&h, &cells).unwrap();
    // Foxglove's: z = i / slice_stride, y = (i % slice_stride) / row_stride,
    // x = (i % row_stride) / cell_stride.
    let i = g
        .data
        .iter()
        .position(|c| *c == CellState::Occupied as u8)
        .unwrap() as u32;
    assert_eq!(i / g.slice_stride, z as u32);
    assert_eq!((i % g.slice_stride) / g.row_stride, y as u32);
    assert_eq!((i % g.row_stride) / g.cell_stride, x as u32);
    assert_eq!((g.column_count, g.row_count), (nx, ny));
    assert_eq!(g.data.len(), cells.len());
    assert_eq!(g.fields[0].name, VOXEL_FIELD);
    let origin = g.pose.unwrap().position.unwrap();
    assert_eq!((origin.x, origin.y, origin.z), (-1.0, 2.0, 0.5));
    // A header bigger than its cells is left out, not read past.
    let big = OccupancyMapHeader {
        dims: [nx, ny, nz + 1],
        ..h
    };
    assert!(voxel_grid(&big, &cells).is_none());
}
