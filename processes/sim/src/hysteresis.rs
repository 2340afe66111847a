//! PX4's boolean hysteresis (`lib/hysteresis/hysteresis.cpp`): a state that follows
//! its input only after the input has held for a while, so the land detector and the
//! hover thrust estimator do not flicker on one noisy sample.

/// A debounced boolean, as PX4's `systemlib::Hysteresis`.
///
/// A change is requested when the input first differs from the state; it happens once
/// the input has differed for the hysteresis time of the current state (0 by default:
/// at once). An input back at the state cancels the request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Hysteresis {
    state: bool,
    requested: bool,
    requested_at_ns: u64,
    time_from_true_ns: u64,
    time_from_false_ns: u64,
}

impl Hysteresis {
    /// Starts in `state`, switching at once both ways until times are set.
    pub fn new(state: bool) -> Self {
        Self {
            state,
            requested: state,
            requested_at_ns: 0,
            time_from_true_ns: 0,
            time_from_false_ns: 0,
        }
    }

    /// How long the input must differ before leaving `from_state`, ns.
    pub fn set_time_from(&mut self, from_state: bool, ns: u64) {
        if from_state {
            self.time_from_true_ns = ns;
        } else {
            self.time_from_false_ns = ns;
        }
    }

    /// Feeds the input at `now_ns` and switches if it has held long enough.
    pub fn set_state_and_update(&mut self, input: bool, now_ns: u64) {
        if input != self.state {
            if input != self.requested {
                self.requested = input;
                self.requested_at_ns = now_ns;
            }
        } else {
            self.requested = self.state;
        }
        self.update(now_ns);
    }

    /// Switches if a pending request has waited long enough.
    pub fn update(&mut self, now_ns: u64) {
        if self.requested == self.state {
            return;
        }
        let wait = if self.state {
            self.time_from_true_ns
        } else {
            self.time_from_false_ns
        };
        if now_ns >= self.requested_at_ns.saturating_add(wait) {
            self.state = self.requested;
        }
    }

    /// Forces the state (and drops any pending request), e.g. for a vehicle placed in
    /// the air by the simulator.
    pub fn force(&mut self, state: bool) {
        self.state = state;
        self.requested = state;
    }

    /// The debounced state.
    pub fn state(&self) -> bool {
        self.state
    }
}

#[cfg(test)]
#[path = "hysteresis_test.rs"]
mod tests;
