use super::*;

#[test]
fn a_processs_cpu_time_is_read_from_proc_and_grows_as_it_works() {
    let me = std::process::id();
    let before = process_cpu_ns(me).unwrap();
    // Work until the kernel has counted at least one more tick (10 ms at 100 Hz).
    let start = std::time::Instant::now();
    let mut x = 0u64;
    let after = loop {
        for i in 0..100_000u64 {
            x = x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(i);
        }
        let now = process_cpu_ns(me).unwrap();
        if now > before || start.elapsed().as_secs() > 20 {
            break now;
        }
    };
    std::hint::black_box(x);
    assert!(after > before, "{before} -> {after} ns after 20 s of work");
    assert_eq!(process_cpu_ns(u32::MAX), None, "no such process");
}
