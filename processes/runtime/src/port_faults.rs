//! Faults injected into a process's output ports, for fault tests: a delay before each
//! send, a fraction of the messages dropped, the payloads corrupted. Ordered at run time
//! through `landing/fault/inject` ([`FaultOrder`]), which a process listens to only when
//! started with `LANDING_FAULT_INJECTION=1` (`landing run --processes --inject` sets it;
//! a deployed stack does not). The stages never know: it happens in the driver's ports.

use ipc_types::msg::{FaultOrder, Header, PortFault};

/// The variable that lets a process take fault orders.
pub const ENV: &str = "LANDING_FAULT_INJECTION";

/// Whether this process takes fault orders.
pub fn enabled() -> bool {
    std::env::var(ENV).is_ok_and(|v| v == "1")
}

/// The faults standing on this process's outputs, and what they did.
#[derive(Debug, Default, Clone)]
pub struct PortFaults {
    delay_ns: u64,
    drop: f64,
    corrupt: bool,
    rng: u64,
    /// Messages dropped by the fault.
    pub dropped: u64,
    /// Messages corrupted.
    pub corrupted: u64,
    /// Messages delayed.
    pub delayed: u64,
}

impl PortFaults {
    /// Takes `order` when it is for `process`; whether it was.
    pub fn apply(&mut self, process: &str, order: &FaultOrder) -> bool {
        if order.process.as_str() != process {
            return false;
        }
        let v = if order.value.is_finite() {
            order.value
        } else {
            0.0
        };
        match PortFault::from_raw(order.fault) {
            Some(PortFault::Clear) => {
                self.delay_ns = 0;
                self.drop = 0.0;
                self.corrupt = false;
            }
            Some(PortFault::Delay) => self.delay_ns = (v.clamp(0.0, 10_000.0) * 1e6) as u64,
            Some(PortFault::Drop) => self.drop = v.clamp(0.0, 1.0),
            Some(PortFault::Corrupt) => self.corrupt = true,
            None => return false,
        }
        tracing::warn!(
            fault = order.fault,
            value = v,
            "fault injected into the outputs"
        );
        true
    }

    /// Whether any fault stands.
    pub fn any(&self) -> bool {
        self.delay_ns > 0 || self.drop > 0.0 || self.corrupt
    }

    /// Called before a message goes out: `false` when it is to be dropped; otherwise
    /// waits the delay first.
    pub fn pass(&mut self) -> bool {
        if self.drop > 0.0 {
            // xorshift64*: no dependency, and a drop pattern that does not repeat.
            if self.rng == 0 {
                self.rng = crate::monotonic_ns() | 1;
            }
            self.rng ^= self.rng >> 12;
            self.rng ^= self.rng << 25;
            self.rng ^= self.rng >> 27;
            let r =
                (self.rng.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64;
            if r < self.drop {
                self.dropped += 1;
                return false;
            }
        }
        if self.delay_ns > 0 {
            self.delayed += 1;
            std::thread::sleep(std::time::Duration::from_nanos(self.delay_ns));
        }
        true
    }

    /// Overwrites what follows the [`Header`] at the start of `v` with all-ones bytes,
    /// when corrupting.
    pub fn corrupt<T: Copy>(&mut self, v: &mut T) {
        if !self.corrupt {
            return;
        }
        let start = std::mem::size_of::<Header>();
        let size = std::mem::size_of::<T>();
        if size <= start {
            return;
        }
        self.corrupted += 1;
        // SAFETY: every message type of ipc_types::msg is `#[repr(C)]` plain data that
        // starts with its `Header` and holds only integers and floats (enumerations are
        // raw integers, text is a length and bytes), so any bit pattern is a valid value;
        // the bytes written lie within `v`.
        unsafe {
            let p = (v as *mut T).cast::<u8>();
            std::ptr::write_bytes(p.add(start), 0xFF, size - start);
        }
    }
}
