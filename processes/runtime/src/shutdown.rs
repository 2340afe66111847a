//! SIGTERM and SIGINT, remembered until the process asks.
//!
//! iceoryx2 0.10 keeps only the last signal it caught and also catches SIGCONT; systemd
//! and `timeout` send SIGTERM followed by SIGCONT, so a stop request could be overwritten
//! before a process looked (4 of 10 stops lost in a test of camera-ingest). So iceoryx2's
//! signal handling is disabled (node and wait set) and this handler, installed first
//! thing in `process_main`, sets a flag nothing else clears: a stop that arrives while a
//! process is still starting is kept, and honoured once its loop runs. It is installed without SA_RESTART so that a blocking wait
//! returns (EINTR) and the loop can look at the flag.

use std::sync::atomic::{AtomicBool, Ordering};

static REQUESTED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    // Async-signal-safe: one atomic store.
    REQUESTED.store(true, Ordering::SeqCst);
}

/// Installs the handler for SIGTERM and SIGINT (idempotent).
pub fn install() {
    for sig in [libc::SIGTERM, libc::SIGINT] {
        // SAFETY: a zeroed sigaction is a valid "no flags, empty mask" value; the handler
        // only stores to an atomic, which is async-signal-safe; sigaction with a valid
        // signal number and pointers has no other preconditions.
        unsafe {
            let mut action: libc::sigaction = std::mem::zeroed();
            action.sa_sigaction = on_signal as *const () as libc::sighandler_t;
            libc::sigemptyset(&mut action.sa_mask);
            action.sa_flags = 0;
            libc::sigaction(sig, &action, std::ptr::null_mut());
        }
    }
}

/// True once SIGTERM or SIGINT arrived.
pub fn requested() -> bool {
    REQUESTED.load(Ordering::SeqCst)
}
