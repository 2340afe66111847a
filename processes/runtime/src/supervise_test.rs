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

#[test]
fn a_process_that_exited_unreaped_is_dying_and_a_running_one_is_not() {
    assert!(
        !process_is_dying(std::process::id()),
        "this test is running"
    );
    let mut sleeper = std::process::Command::new("sleep")
        .arg("30")
        .spawn()
        .unwrap();
    assert!(!process_is_dying(sleeper.id()), "a sleeping process");
    let mut done = std::process::Command::new("true").spawn().unwrap();
    // Not reaped: a zombie until `wait`, its node (had it one) still listed alive.
    let start = std::time::Instant::now();
    while !process_is_dying(done.id()) {
        assert!(
            start.elapsed().as_secs() < 20,
            "`true` never became a zombie"
        );
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    let gone = done.id();
    done.wait().unwrap();
    assert!(!process_is_dying(gone), "reaped: the node list decides");
    sleeper.kill().unwrap();
    sleeper.wait().unwrap();
    assert!(!process_is_dying(u32::MAX), "no such process");
}
