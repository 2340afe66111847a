use super::*;

#[test]
fn a_z16_frame_with_padded_rows_is_unpacked_row_by_row() {
    // 3 x 2 px, rows padded to 8 bytes.
    let bytes = [1, 0, 2, 0, 0, 1, 9, 9, 3, 0, 4, 0, 255, 255, 9, 9];
    let mut image = DepthImage::default();
    unpack_z16(&bytes, 3, 2, 8, &mut image).unwrap();
    assert_eq!((image.width, image.height), (3, 2));
    assert_eq!(image.depths, [1, 2, 256, 3, 4, 65535]);
    // The last row needs no padding; one byte short is an error, not a panic.
    unpack_z16(&bytes[..14], 3, 2, 8, &mut image).unwrap();
    assert!(matches!(
        unpack_z16(&bytes[..13], 3, 2, 8, &mut image),
        Err(V4l2Error::ShortBuffer { got: 13, want: 14 })
    ));
    assert!(unpack_z16(&bytes, 3, 2, 4, &mut image).is_err());
}
