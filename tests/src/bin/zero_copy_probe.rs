//! A misbehaving-free test peer: publishes or subscribes one camera frame and reports, on
//! stdout, where the frame's bytes live (`file=... offset=...`), so the `zero_copy` test can
//! prove that the subscriber reads the publisher's shared-memory bytes in place.
//!
//! Usage: `zero-copy-probe publish|subscribe PREFIX SERVICE`

use std::alloc::{GlobalAlloc, Layout, System};
use std::io::{BufRead, Write};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use anyhow::{Context, Result, bail};
use ipc_types::msg::{CameraFrameHeader, Header, PixelEncoding};
use landing_tests::mapped_location;
use runtime::{Ipc, IpcPrefix, PeriodicWait};

/// Counts every allocation, so the test can assert that receiving and reading a frame
/// allocates nothing (a copy would need a buffer).
struct CountingAlloc;

static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

// SAFETY: forwards to the system allocator unchanged; only counts calls.
unsafe impl GlobalAlloc for CountingAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

const WIDTH: u32 = 1280;
const HEIGHT: u32 = 720;
const LEN: usize = (WIDTH * HEIGHT * 3) as usize;

fn pixel(i: usize) -> u8 {
    (i.wrapping_mul(31) % 253) as u8
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() != 4 {
        bail!("usage: zero-copy-probe publish|subscribe PREFIX SERVICE");
    }
    let prefix = IpcPrefix::new(&args[2])?;
    let service = &args[3];
    match args[1].as_str() {
        "publish" => publish(&prefix, service),
        "subscribe" => subscribe(&prefix, service),
        other => bail!("unknown mode `{other}` (allowed: publish, subscribe)"),
    }
}

fn publish(prefix: &IpcPrefix, service: &str) -> Result<()> {
    let ipc = Ipc::open("zc-pub", prefix)?;
    let mut publ = ipc.slice_publisher::<u8, CameraFrameHeader>(service, LEN)?;
    // A first frame lets the subscriber connect to this publisher's data segment (which
    // maps it and allocates bookkeeping once); the second is the one examined.
    let first = publ.loan_uninit(LEN)?.write_from_fn(|_| 0);
    publ.send(first)?;
    let mut sample = publ.loan_uninit(LEN)?;
    let at = mapped_location(sample.payload().as_ptr() as usize)
        .context("the loaned payload is not in a mapped file")?;
    *sample.user_header_mut() = CameraFrameHeader {
        msg: Header::captured_at(1),
        width: WIDTH,
        height: HEIGHT,
        stride: WIDTH * 3,
        encoding: PixelEncoding::Bgr8 as u32,
        ..Default::default()
    };
    // The "camera" writes its pixels straight into the loaned shared memory.
    let sample = sample.write_from_fn(pixel);
    publ.send(sample)?;
    println!("file={} offset={}", at.file.display(), at.offset);
    std::io::stdout().flush()?;
    // Stay alive until the test has what it needs.
    let mut line = String::new();
    let _ = std::io::stdin().lock().read_line(&mut line);
    Ok(())
}

fn subscribe(prefix: &IpcPrefix, service: &str) -> Result<()> {
    let ipc = Ipc::open("zc-sub", prefix)?;
    let sub = ipc.slice_subscriber::<u8, CameraFrameHeader>(service)?;
    println!("ready");
    std::io::stdout().flush()?;
    let mut waiter = PeriodicWait::new(Duration::from_micros(200), Duration::from_millis(1));

    let first = waiter.wait(sub.listener(), Duration::from_secs(20), || {
        sub.receive().ok().flatten()
    });
    if first.is_none() {
        bail!("no first frame arrived");
    }
    drop(first);

    let before = ALLOCATIONS.load(Ordering::SeqCst);
    let got = waiter.wait(sub.listener(), Duration::from_secs(20), || {
        sub.receive().ok().flatten()
    });
    let Some(sample) = got else {
        bail!("no frame arrived");
    };
    let payload = sample.payload();
    let mut mismatches = 0usize;
    for (i, b) in payload.iter().enumerate() {
        if *b != pixel(i) {
            mismatches += 1;
        }
    }
    let addr = payload.as_ptr() as usize;
    let len = payload.len();
    let after = ALLOCATIONS.load(Ordering::SeqCst);

    let at = mapped_location(addr).context("the received payload is not in a mapped file")?;
    println!(
        "file={} offset={} len={} allocations={} mismatches={}",
        at.file.display(),
        at.offset,
        len,
        after - before,
        mismatches
    );
    std::io::stdout().flush()?;
    Ok(())
}
