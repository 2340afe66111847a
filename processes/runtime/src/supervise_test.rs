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
fn a_process_that_failed_unreaped_is_dying_and_one_that_exited_cleanly_is_not() {
    assert!(
        !process_is_dying(std::process::id()),
        "this test is running"
    );
    let mut sleeper = std::process::Command::new("sleep")
        .arg("30")
        .spawn()
        .unwrap();
    assert!(!process_is_dying(sleeper.id()), "a sleeping process");
    // Not reaped: zombies until `wait`, their nodes (had they any) still listed alive.
    let zombie = |program: &str| {
        let child = std::process::Command::new(program).spawn().unwrap();
        let stat = format!("/proc/{}/stat", child.id());
        let start = std::time::Instant::now();
        while !std::fs::read_to_string(&stat).unwrap().contains(") Z ") {
            assert!(
                start.elapsed().as_secs() < 20,
                "`{program}` never became a zombie"
            );
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        child
    };
    let mut failed = zombie("false");
    assert!(process_is_dying(failed.id()), "exited 1, not reaped");
    let mut clean = zombie("true");
    assert!(
        !process_is_dying(clean.id()),
        "exited 0: a clean stop, not a death"
    );
    let gone = failed.id();
    failed.wait().unwrap();
    clean.wait().unwrap();
    assert!(!process_is_dying(gone), "reaped: the node list decides");
    // SIGKILL: dying from the signal on, a zombie with a signal status after.
    sleeper.kill().unwrap();
    assert!(process_is_dying(sleeper.id()), "killed, not reaped");
    sleeper.wait().unwrap();
    assert!(!process_is_dying(u32::MAX), "no such process");
}
