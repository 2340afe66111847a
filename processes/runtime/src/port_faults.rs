//! Faults injected into a process's output ports, for fault tests: a delay before each
//! send, a fraction of the messages dropped, the payloads corrupted; on every output or
//! one topic (a world fault: the simulator's camera cut for two seconds), until cleared
//! or for a time. Ordered at run time through `landing/fault/inject` ([`FaultOrder`]),
//! which a process listens to only when started with `LANDING_FAULT_INJECTION=1`
//! (`landing run --processes --inject` sets it; a deployed stack does not). The stages
//! never know: it happens in the driver's ports.

use ipc_types::msg::{FaultOrder, Header, PortFault};

/// The variable that lets a process take fault orders.
pub const ENV: &str = "LANDING_FAULT_INJECTION";

/// Whether this process takes fault orders.
pub fn enabled() -> bool {
    std::env::var(ENV).is_ok_and(|v| v == "1")
}

/// The faults on one output topic, or on all (`topic` `None`).
#[derive(Debug, Clone, Default)]
struct Rule {
    topic: Option<String>,
    delay_ns: u64,
    drop: f64,
    corrupt: bool,
    blank: bool,
    /// When it ends (monotonic ns); `None`: until cleared.
    until_ns: Option<u64>,
}

/// The faults standing on this process's outputs, and what they did.
#[derive(Debug, Default, Clone)]
pub struct PortFaults {
    rules: Vec<Rule>,
    rng: u64,
    /// Messages dropped by the fault.
    pub dropped: u64,
    /// Messages corrupted.
    pub corrupted: u64,
    /// Messages delayed.
    pub delayed: u64,
    /// Images blanked.
    pub blanked: u64,
}

impl PortFaults {
    /// Takes `order`, given at `now_ns`, when it is for `process`; whether it was.
    pub fn apply(&mut self, process: &str, order: &FaultOrder, now_ns: u64) -> bool {
        if order.process.as_str() != process {
            return false;
        }
        let v = if order.value.is_finite() {
            order.value
        } else {
            0.0
        };
        let topic = Some(order.topic.as_str().to_string()).filter(|t| !t.is_empty());
        let Some(fault) = PortFault::from_raw(order.fault) else {
            return false;
        };
        if fault == PortFault::Clear {
            // Clearing every output clears every rule.
            self.rules.retain(|r| topic.is_some() && r.topic != topic);
            return true;
        }
        let until_ns = (order.for_s.is_finite() && order.for_s > 0.0)
            .then(|| now_ns.saturating_add((order.for_s.min(3600.0) * 1e9) as u64));
        let k = match self.rules.iter().position(|r| r.topic == topic) {
            Some(k) => k,
            None => {
                self.rules.push(Rule {
                    topic: topic.clone(),
                    ..Rule::default()
                });
                self.rules.len() - 1
            }
        };
        let r = &mut self.rules[k];
        r.until_ns = until_ns;
        match fault {
            PortFault::Delay => r.delay_ns = (v.clamp(0.0, 10_000.0) * 1e6) as u64,
            PortFault::Drop => r.drop = v.clamp(0.0, 1.0),
            PortFault::Corrupt => r.corrupt = true,
            PortFault::Blank => r.blank = true,
            PortFault::Clear => {}
        }
        tracing::warn!(
            fault = order.fault,
            value = v,
            topic = topic.as_deref().unwrap_or("every output"),
            for_s = order.for_s,
            "fault injected into the outputs"
        );
        true
    }

    /// The rules standing for `topic` at `now_ns` (ended ones removed), folded into one.
    fn standing(&mut self, topic: &str, now_ns: u64) -> Rule {
        self.rules
            .retain(|r| r.until_ns.is_none_or(|end| now_ns < end));
        self.rules
            .iter()
            .filter(|r| r.topic.as_deref().is_none_or(|t| t == topic))
            .fold(Rule::default(), |a, r| Rule {
                delay_ns: a.delay_ns.max(r.delay_ns),
                drop: a.drop.max(r.drop),
                corrupt: a.corrupt || r.corrupt,
                blank: a.blank || r.blank,
                ..Rule::default()
            })
    }

    /// Called before a message on `topic` goes out: `None` when it is to be dropped,
    /// otherwise how long it is to be held first, ns (the caller waits: it keeps the
    /// process's heartbeat going meanwhile, for late data is not a hung process).
    pub fn admit(&mut self, topic: &str) -> Option<u64> {
        if self.rules.is_empty() {
            return Some(0);
        }
        let Rule { delay_ns, drop, .. } = self.standing(topic, crate::monotonic_ns());
        if drop > 0.0 {
            // xorshift64*: no dependency, and a drop pattern that does not repeat.
            if self.rng == 0 {
                self.rng = crate::monotonic_ns() | 1;
            }
            self.rng ^= self.rng >> 12;
            self.rng ^= self.rng << 25;
            self.rng ^= self.rng >> 27;
            let r =
                (self.rng.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64;
            if r < drop {
                self.dropped += 1;
                return None;
            }
        }
        if delay_ns > 0 {
            self.delayed += 1;
        }
        Some(delay_ns)
    }

    /// Paints `pixels` (an image on `topic`) one mid-grey, when blanking `topic`.
    pub fn blank(&mut self, topic: &str, pixels: &mut [u8]) {
        if self.rules.is_empty() {
            return;
        }
        let blanked = self.standing(topic, crate::monotonic_ns()).blank;
        if blanked {
            self.blanked += 1;
            pixels.fill(0x80);
        }
    }

    /// Overwrites what follows the [`Header`] at the start of `v` with all-ones bytes,
    /// when corrupting `topic`.
    pub fn corrupt<T: Copy>(&mut self, topic: &str, v: &mut T) {
        if self.rules.is_empty() || !self.standing(topic, crate::monotonic_ns()).corrupt {
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
