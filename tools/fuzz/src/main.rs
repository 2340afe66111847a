//! `landing-fuzz`: runs the fuzz targets (the `fuzz` library) for a bounded time on
//! stable Rust, in one process: it mutates the seeds (bytes, and text as text), keeps
//! inputs that reach an outcome not seen yet, and reports executions per target. A
//! panic, an input that runs longer than `--hang-ms`, or one that allocates more than
//! `--max-alloc-mb` at once is a failure: the input is saved (`--crash-dir`), the run
//! exits 1. Inputs kept in `tools/fuzz/regressions/TARGET/` are run first, every time.

use std::alloc::{GlobalAlloc, Layout, System};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use clap::Parser;
use fuzz::{State, TARGETS, Target};

/// The largest single allocation allowed, bytes (set from `--max-alloc-mb`).
static MAX_ALLOC: AtomicUsize = AtomicUsize::new(usize::MAX);
/// Allocations refused (over the bound), since the last look.
static TOO_BIG: AtomicU64 = AtomicU64::new(0);

/// The input being run, for the hang watchdog and for the allocator's last word.
static CURRENT: Mutex<(Vec<u8>, Option<Instant>)> = Mutex::new((Vec::new(), None));
/// Where the allocator saves the input that asked too much: a NUL-terminated path,
/// prepared before each target (the allocator itself must not allocate).
static OVERSIZE_PATH: Mutex<[u8; 512]> = Mutex::new([0; 512]);

/// Saves the current input to [`OVERSIZE_PATH`] without allocating.
fn save_oversize_input() {
    let (Ok(path), Ok(current)) = (OVERSIZE_PATH.try_lock(), CURRENT.try_lock()) else {
        return;
    };
    // SAFETY: `path` is NUL-terminated (set by `prepare_oversize_path`); the buffer
    // written is the locked input, valid for its length.
    unsafe {
        let fd = libc::open(
            path.as_ptr().cast(),
            libc::O_WRONLY | libc::O_CREAT | libc::O_TRUNC,
            0o644,
        );
        if fd >= 0 {
            let _ = libc::write(fd, current.0.as_ptr().cast(), current.0.len());
            libc::close(fd);
            let msg = b"landing-fuzz: an allocation over --max-alloc-mb; the input is saved beside the crashes as TARGET-oversize\n";
            let _ = libc::write(2, msg.as_ptr().cast(), msg.len());
        }
    }
}

fn prepare_oversize_path(dir: &Path, target: &str) {
    let _ = std::fs::create_dir_all(dir);
    let p = dir.join(format!("{target}-oversize"));
    let bytes = p.as_os_str().as_encoded_bytes();
    if let Ok(mut buf) = OVERSIZE_PATH.lock()
        && bytes.len() < buf.len()
    {
        buf.fill(0);
        buf[..bytes.len()].copy_from_slice(bytes);
    }
}

/// The system allocator, refusing any single allocation over [`MAX_ALLOC`]: an input
/// that makes a parser ask for gigabytes is found as a failure (the input saved, the
/// process aborted by Rust's allocation-failure handler), not as a dead machine.
struct Bounded;

// SAFETY: every call goes to the system allocator unchanged, or returns null (an
// allocation failure, which Rust turns into an abort the fuzzer reports).
unsafe impl GlobalAlloc for Bounded {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if layout.size() > MAX_ALLOC.load(Ordering::Relaxed) {
            TOO_BIG.fetch_add(1, Ordering::Relaxed);
            save_oversize_input();
            return std::ptr::null_mut();
        }
        // SAFETY: the caller's layout, passed on.
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: allocated by `System` above with this layout.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if new_size > MAX_ALLOC.load(Ordering::Relaxed) {
            TOO_BIG.fetch_add(1, Ordering::Relaxed);
            save_oversize_input();
            return std::ptr::null_mut();
        }
        // SAFETY: `ptr` was allocated by `System` with `layout`.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOC: Bounded = Bounded;

/// Fuzz the stack's parsers of untrusted input for a bounded time.
#[derive(Debug, Parser)]
#[command(name = "landing-fuzz", version, about)]
struct Args {
    /// Targets to run (default: all); `--list` names them.
    #[arg(long = "target")]
    targets: Vec<String>,
    /// List the targets and exit.
    #[arg(long)]
    list: bool,
    /// Seconds per target (0.1-86400).
    #[arg(long, default_value_t = 10.0)]
    seconds: f64,
    /// Seed of the mutations (default: from the clock); a run is repeatable with it.
    #[arg(long)]
    seed: Option<u64>,
    /// Longest time one input may run, ms (10-60000).
    #[arg(long, default_value_t = 2000)]
    hang_ms: u64,
    /// Largest single allocation allowed, MB (1-65536).
    #[arg(long, default_value_t = 512)]
    max_alloc_mb: usize,
    /// Where failing inputs are saved.
    #[arg(long, default_value = "target/fuzz-crashes")]
    crash_dir: PathBuf,
    /// The regression inputs (one directory per target).
    #[arg(long)]
    regressions: Option<PathBuf>,
    /// Print one JSON object per target instead of a line.
    #[arg(long)]
    json: bool,
}

/// A small xorshift generator.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// Values that find edges.
const INTERESTING: &[&[u8]] = &[
    b"0",
    b"-1",
    b"1e309",
    b"-1e309",
    b"nan",
    b"inf",
    b"18446744073709551616",
    b"4294967296",
    b"65536",
    b"0.0",
    b"\"\"",
    b"[]",
    b"{}",
    b"true",
    b"1e-320",
    b"-0",
    b"9999999999",
];

/// One mutation of `input` (using `other`, another corpus input, for splices).
fn mutate(rng: &mut Rng, input: &[u8], other: &[u8], text: bool, max_len: usize) -> Vec<u8> {
    let mut v = input.to_vec();
    for _ in 0..1 + rng.below(4) {
        let n = v.len();
        match rng.below(if text { 12 } else { 9 }) {
            0 if n > 0 => {
                let i = rng.below(n);
                v[i] ^= 1 << rng.below(8);
            }
            1 if n > 0 => {
                let i = rng.below(n);
                v[i] = rng.next() as u8;
            }
            2 if n > 0 => {
                let i = rng.below(n);
                v[i] = [0u8, 1, 0x7f, 0x80, 0xff, 0xfd, 0xfe][rng.below(7)];
            }
            3 => {
                let i = rng.below(n + 1);
                let k = 1 + rng.below(16);
                let bytes: Vec<u8> = (0..k).map(|_| rng.next() as u8).collect();
                v.splice(i..i, bytes);
            }
            4 if n > 0 => {
                let i = rng.below(n);
                let k = 1 + rng.below((n - i).min(64));
                v.drain(i..i + k);
            }
            5 if n > 0 => {
                let i = rng.below(n);
                let k = 1 + rng.below((n - i).min(64));
                let copy = v[i..i + k].to_vec();
                let at = rng.below(n + 1);
                v.splice(at..at, copy);
            }
            6 if !other.is_empty() => {
                // Splice: a piece of another input.
                let i = rng.below(other.len());
                let k = 1 + rng.below((other.len() - i).min(256));
                let at = rng.below(n + 1);
                v.splice(at..at, other[i..i + k].iter().copied());
            }
            7 if n > 0 => v.truncate(rng.below(n)),
            8 if n >= 2 => {
                // A little-endian integer field set to an edge.
                let i = rng.below(n - 1);
                let edge: u16 = [0, 1, 0x7fff, 0x8000, 0xffff, 640, 480][rng.below(7)];
                v[i..i + 2].copy_from_slice(&edge.to_le_bytes());
            }
            // Text: a number replaced by an edge value; a line dropped or repeated.
            9 => {
                let digits: Vec<usize> = (0..n).filter(|&i| v[i].is_ascii_digit()).collect();
                if let Some(&i) = digits.get(rng.below(digits.len())) {
                    let mut j = i;
                    while j < n && (v[j].is_ascii_digit() || v[j] == b'.') {
                        j += 1;
                    }
                    let with = INTERESTING[rng.below(INTERESTING.len())];
                    v.splice(i..j, with.iter().copied());
                }
            }
            10 | 11 => {
                let lines: Vec<usize> = std::iter::once(0)
                    .chain((0..n).filter(|&i| v[i] == b'\n').map(|i| i + 1))
                    .filter(|&i| i < n)
                    .collect();
                if let Some(&start) = lines.get(rng.below(lines.len())) {
                    let end = v[start..]
                        .iter()
                        .position(|&b| b == b'\n')
                        .map_or(n, |p| start + p + 1);
                    if rng.below(2) == 0 {
                        v.drain(start..end);
                    } else {
                        let line = v[start..end].to_vec();
                        let at = lines[rng.below(lines.len())];
                        v.splice(at..at, line);
                    }
                }
            }
            _ => {}
        }
    }
    v.truncate(max_len);
    if text && std::str::from_utf8(&v).is_err() {
        // A file the stack reads as text: invalid UTF-8 is refused before any parser
        // runs, so mutations stay text to reach the parsers.
        v = String::from_utf8_lossy(&v).into_owned().into_bytes();
    }
    v
}

/// What went wrong with one input.
enum Failure {
    Panic(String),
    TooBig,
}

/// Runs `input`; `current` holds it for the hang watchdog.
fn run_one(t: &Target, state: &mut State, input: &[u8]) -> Result<u64, Failure> {
    if let Ok(mut c) = CURRENT.lock() {
        c.0.clear();
        c.0.extend_from_slice(input);
        c.1 = Some(Instant::now());
    }
    TOO_BIG.store(0, Ordering::Relaxed);
    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| (t.run)(state, input)));
    if let Ok(mut c) = CURRENT.lock() {
        c.1 = None;
    }
    match r {
        Ok(_) if TOO_BIG.load(Ordering::Relaxed) > 0 => Err(Failure::TooBig),
        Ok(v) => Ok(v),
        Err(p) => Err(Failure::Panic(
            p.downcast_ref::<String>()
                .cloned()
                .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_default(),
        )),
    }
}

fn save(dir: &Path, target: &str, input: &[u8]) -> PathBuf {
    let _ = std::fs::create_dir_all(dir);
    let mut h = std::collections::hash_map::DefaultHasher::new();
    std::hash::Hash::hash(input, &mut h);
    let p = dir.join(format!("{target}-{:016x}", std::hash::Hasher::finish(&h)));
    let _ = std::fs::write(&p, input);
    p
}

/// One target's result.
struct Report {
    execs: u64,
    corpus: usize,
    outcomes: usize,
    regressions: usize,
    slowest_us: u64,
    failures: Vec<String>,
}

fn fuzz_target(
    t: &Target,
    args: &Args,
    rng: &mut Rng,
    deploy: &Path,
    regressions: &Path,
) -> Report {
    prepare_oversize_path(&args.crash_dir, t.name);
    let mut state = State::default();
    let mut corpus: Vec<Vec<u8>> = (t.seeds)(deploy);
    if corpus.is_empty() {
        corpus.push(Vec::new());
    }
    let mut kept = Vec::new();
    if let Ok(entries) = std::fs::read_dir(regressions.join(t.name)) {
        for e in entries.flatten() {
            if let Ok(b) = std::fs::read(e.path()) {
                kept.push(b);
            }
        }
    }
    let max_len = corpus.iter().map(Vec::len).max().unwrap_or(0).max(256) * 2;
    let mut seen = std::collections::HashSet::new();
    let mut report = Report {
        execs: 0,
        corpus: 0,
        outcomes: 0,
        regressions: kept.len(),
        slowest_us: 0,
        failures: Vec::new(),
    };
    let fail = |input: &[u8], why: String, report: &mut Report| {
        let p = save(&args.crash_dir, t.name, input);
        report
            .failures
            .push(format!("{why} (input saved to {})", p.display()));
    };
    // Seeds and regressions first, every one.
    for input in corpus.clone().iter().chain(kept.iter()) {
        match run_one(t, &mut state, input) {
            Ok(o) => {
                seen.insert(o);
            }
            Err(Failure::Panic(m)) => fail(input, format!("panic: {m}"), &mut report),
            Err(Failure::TooBig) => fail(input, "an allocation over the bound".into(), &mut report),
        }
        report.execs += 1;
    }
    let end = Instant::now() + Duration::from_secs_f64(args.seconds);
    while Instant::now() < end && report.failures.len() < 5 {
        for _ in 0..64 {
            let a = rng.below(corpus.len());
            let b = rng.below(corpus.len());
            let input = mutate(rng, &corpus[a], &corpus[b], t.text, max_len);
            let started = Instant::now();
            let r = run_one(t, &mut state, &input);
            report.slowest_us = report.slowest_us.max(started.elapsed().as_micros() as u64);
            report.execs += 1;
            match r {
                Ok(o) => {
                    // An outcome not seen yet: keep the input to mutate further.
                    if seen.insert(o) && corpus.len() < 4096 {
                        corpus.push(input);
                    }
                }
                Err(Failure::Panic(m)) => fail(&input, format!("panic: {m}"), &mut report),
                Err(Failure::TooBig) => {
                    fail(&input, "an allocation over the bound".into(), &mut report)
                }
            }
        }
    }
    report.corpus = corpus.len();
    report.outcomes = seen.len();
    report
}

fn main() -> std::process::ExitCode {
    match run() {
        Ok(true) => std::process::ExitCode::SUCCESS,
        Ok(false) => std::process::ExitCode::from(1),
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::from(2)
        }
    }
}

fn run() -> Result<bool> {
    let args = Args::parse();
    if args.list {
        for t in TARGETS {
            println!("{:<18} {}", t.name, t.about);
        }
        return Ok(true);
    }
    if !(args.seconds.is_finite() && (0.1..=86_400.0).contains(&args.seconds)) {
        bail!("--seconds {}: allowed 0.1 to 86400", args.seconds);
    }
    if !(10..=60_000).contains(&args.hang_ms) {
        bail!("--hang-ms {}: allowed 10 to 60000", args.hang_ms);
    }
    if !(1..=65_536).contains(&args.max_alloc_mb) {
        bail!("--max-alloc-mb {}: allowed 1 to 65536", args.max_alloc_mb);
    }
    let chosen: Vec<&Target> = if args.targets.is_empty() {
        TARGETS.iter().collect()
    } else {
        let names: Vec<&str> = TARGETS.iter().map(|t| t.name).collect();
        args.targets
            .iter()
            .map(|n| {
                fuzz::target(n).with_context(|| {
                    format!(
                        "--target {n}: no such target (allowed: {})",
                        names.join(", ")
                    )
                })
            })
            .collect::<Result<_>>()?
    };
    let deploy = stack_config::deploy_dir();
    let regressions = args
        .regressions
        .clone()
        .unwrap_or_else(|| deploy.join("../tools/fuzz/regressions"));
    MAX_ALLOC.store(args.max_alloc_mb << 20, Ordering::Relaxed);
    let seed = args.seed.unwrap_or_else(|| {
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(1, |d| d.as_nanos() as u64)
            | 1
    });
    // The hang watchdog: an input running longer than --hang-ms is saved, and the
    // process ends (a hung parser cannot be interrupted from outside).
    let hang = Duration::from_millis(args.hang_ms);
    let name: Arc<Mutex<&'static str>> = Arc::new(Mutex::new(""));
    {
        let (name, dir) = (name.clone(), args.crash_dir.clone());
        std::thread::spawn(move || {
            loop {
                std::thread::sleep(Duration::from_millis(50));
                let stuck = CURRENT
                    .lock()
                    .ok()
                    .and_then(|c| c.1.filter(|t| t.elapsed() > hang).map(|_| c.0.clone()));
                if let Some(input) = stuck {
                    let target = name.lock().map(|n| *n).unwrap_or("unknown");
                    let p = save(&dir, target, &input);
                    eprintln!(
                        "{target}: an input ran longer than {} ms (saved to {}): a hang",
                        hang.as_millis(),
                        p.display()
                    );
                    std::process::exit(1);
                }
            }
        });
    }
    // A panic is reported once, as a failure line; not with a backtrace per input.
    std::panic::set_hook(Box::new(|_| {}));
    eprintln!("landing-fuzz: seed {seed}, {} s per target", args.seconds);
    let mut rng = Rng(seed);
    let mut ok = true;
    for t in chosen {
        if let Ok(mut n) = name.lock() {
            *n = t.name;
        }
        let r = fuzz_target(t, &args, &mut rng, &deploy, &regressions);
        ok &= r.failures.is_empty();
        if args.json {
            println!(
                "{{\"target\":\"{}\",\"execs\":{},\"corpus\":{},\"outcomes\":{},\"regressions\":{},\"slowest_us\":{},\"failures\":{}}}",
                t.name,
                r.execs,
                r.corpus,
                r.outcomes,
                r.regressions,
                r.slowest_us,
                r.failures.len()
            );
        } else {
            println!(
                "{:<18} {:>9} execs  {:>5} corpus  {:>5} outcomes  {:>3} regressions  slowest {:>7} us  {} failures",
                t.name,
                r.execs,
                r.corpus,
                r.outcomes,
                r.regressions,
                r.slowest_us,
                r.failures.len()
            );
        }
        for f in &r.failures {
            eprintln!("{}: {f}", t.name);
        }
    }
    Ok(ok)
}
