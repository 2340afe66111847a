//! Tests of `lib`.

use super::*;

#[test]
fn heap_memory_is_not_a_mapped_file() {
    let v = vec![0u8; 1 << 20];
    assert_eq!(mapped_location(v.as_ptr() as usize), None);
}
