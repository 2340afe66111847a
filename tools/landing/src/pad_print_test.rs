//! Tests of `pad_print`: the PNG chunk arithmetic and the SVG's numbers.

use super::*;

#[test]
fn crc32_is_the_ieee_crc_png_uses() {
    assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    assert_eq!(crc32(b""), 0);
    // The CRC of the IEND chunk every PNG ends with.
    assert_eq!(crc32(b"IEND"), 0xAE42_6082);
}

fn chunk(kind: &[u8; 4], data: &[u8]) -> Vec<u8> {
    let mut v = Vec::new();
    push_chunk(&mut v, kind, data);
    v
}

#[test]
fn the_phys_chunk_goes_right_after_ihdr_and_replaces_an_old_one() {
    let ihdr = chunk(b"IHDR", &[0; 13]);
    let old = chunk(b"pHYs", &[0; 9]);
    let iend = chunk(b"IEND", &[]);
    let png = [&PNG_SIGNATURE[..], &ihdr, &old, &iend].concat();
    let out = with_phys(&png, 11811).unwrap();
    let mut data = [0u8; 9];
    data[..4].copy_from_slice(&11811u32.to_be_bytes());
    data[4..8].copy_from_slice(&11811u32.to_be_bytes());
    data[8] = 1;
    let expect = [&PNG_SIGNATURE[..], &ihdr, &chunk(b"pHYs", &data), &iend].concat();
    assert_eq!(out, expect);
    assert!(with_phys(b"not a png", 1).is_err());
    assert!(with_phys(&[&PNG_SIGNATURE[..], &iend].concat(), 1).is_err());
    assert!(with_phys(&[&PNG_SIGNATURE[..], &ihdr[..10]].concat(), 1).is_err());
}

#[test]
fn millimetres_print_without_float_noise() {
    assert_eq!(num(442.00000000000006), "442");
    assert_eq!(num(25.0 / 7.0), "3.5714");
    assert_eq!(num(-0.00001), "0");
    assert_eq!(num(840.0), "840");
}
