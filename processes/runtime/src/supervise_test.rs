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

/// Set in a child run of this test binary: the stack prefix under which it plays the
/// watched process.
const CHILD_PREFIX: &str = "SUPERVISE_TEST_VICTIM_PREFIX";

/// The watched process, run as a child: opens its node, beats once for every line on its
/// stdin and says `beat` when it has.
#[test]
fn a_watched_process_beats_for_every_line_it_is_given() {
    use std::io::{BufRead, Write};
    let Ok(prefix) = std::env::var(CHILD_PREFIX) else {
        return;
    };
    let prefix = IpcPrefix::new(&prefix).unwrap();
    let ipc = Ipc::open("victim", &prefix).unwrap();
    let mut heart = ipc.heartbeat(Duration::from_millis(250)).unwrap();
    for line in std::io::stdin().lock().lines() {
        line.unwrap();
        heart.beat().unwrap();
        let mut out = std::io::stdout().lock();
        writeln!(out, "beat").unwrap();
        out.flush().unwrap();
    }
}

struct Victim {
    child: std::process::Child,
    out: std::io::BufReader<std::process::ChildStdout>,
}

impl Victim {
    fn start(prefix: &str) -> Self {
        let mut child = std::process::Command::new(std::env::current_exe().unwrap())
            .args([
                "--exact",
                "supervise::tests::a_watched_process_beats_for_every_line_it_is_given",
                "--nocapture",
                "--test-threads=1",
                "-q",
            ])
            .env(CHILD_PREFIX, prefix)
            .stdin(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let out = std::io::BufReader::new(child.stdout.take().unwrap());
        Self { child, out }
    }

    /// One beat, sent when this returns.
    fn beat(&mut self) {
        use std::io::{BufRead, Write};
        let stdin = self.child.stdin.as_mut().unwrap();
        writeln!(stdin).unwrap();
        stdin.flush().unwrap();
        let mut line = String::new();
        loop {
            line.clear();
            assert_ne!(
                self.out.read_line(&mut line).unwrap(),
                0,
                "the victim ended"
            );
            if line.trim() == "beat" {
                return;
            }
        }
    }
}

/// The events the supervision source delivers in `waits` waits of 30 ms, on the clock
/// started at `start`; the first wait lists the nodes (their poll is due).
fn events(s: &mut Supervision, waits: usize, start: std::time::Instant) -> Vec<ProcessEventKind> {
    std::thread::sleep(Duration::from_millis(25));
    let clock = move || start.elapsed().as_nanos() as u64;
    let mut seen = Vec::new();
    for _ in 0..waits {
        s.wait(30_000_000, &clock, &mut |input, _| {
            if let Message::ProcessEvent(e) = input.msg {
                seen.extend(ProcessEventKind::from_raw(e.kind));
            }
            Ok(())
        })
        .unwrap();
    }
    seen.retain(|k| *k != ProcessEventKind::Cpu);
    seen
}

#[test]
fn a_beat_sent_before_a_death_and_read_after_it_is_not_a_restart_but_a_new_process_is() {
    use ProcessEventKind::{Beat, Died};
    let name = format!("sv{}_", std::process::id());
    let prefix = IpcPrefix::new(&name).unwrap();
    let mut s = Supervision::open(
        "dog",
        &prefix,
        &[("victim".to_string(), Duration::from_millis(250))],
        Duration::from_millis(20),
    )
    .unwrap();
    let start = std::time::Instant::now();
    let mut victim = Victim::start(&name);
    victim.beat();
    assert_eq!(
        events(&mut s, 3, start),
        vec![Beat],
        "listed alive, one beat"
    );
    // A beat waits unread in the listener; then the process is killed and reaped.
    victim.beat();
    victim.child.kill().unwrap();
    victim.child.wait().unwrap();
    assert_eq!(
        events(&mut s, 3, start),
        vec![Died],
        "the beat the dead process sent is not delivered after its death"
    );
    assert_eq!(s.stale_beats, 1);
    // Restarted: its first beat counts at once.
    let mut again = Victim::start(&name);
    again.beat();
    assert_eq!(events(&mut s, 1, start), vec![Beat]);
    again.child.kill().unwrap();
    again.child.wait().unwrap();
    assert_eq!(events(&mut s, 3, start), vec![Died]);
}
