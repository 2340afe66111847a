//! A toy stage added to the pipeline through the graph and the stage interface alone:
//! `altitude-guard` reads the vehicle state and, the first time the vehicle is armed
//! above its ceiling, orders a safe landing on `safety/command`, as a geofence monitor
//! would. Its binary (`src/bin/altitude_guard.rs`) is the four lines every stage binary
//! is; the test `tests/toy_stage.rs` runs it in lockstep and as its own process.

use ipc_types::msg::{Header, SafetyAction, SafetyCommand, Text};
use ipc_types::topics;
use stage::{Counter, Input, Message, Outbox, Stage, StageError};

/// The `altitude-guard` node.
#[derive(Debug, Clone)]
pub struct AltitudeGuard {
    ceiling_m: f64,
    states: u64,
    orders: u64,
}

impl AltitudeGuard {
    /// Orders a safe landing when the armed vehicle is above `ceiling_m` (world z).
    pub fn new(ceiling_m: f64) -> Self {
        Self {
            ceiling_m,
            states: 0,
            orders: 0,
        }
    }
}

impl Stage for AltitudeGuard {
    fn name(&self) -> &'static str {
        "altitude-guard"
    }

    fn on_input(
        &mut self,
        now_ns: u64,
        input: Input<'_>,
        out: &mut dyn Outbox,
    ) -> Result<(), StageError> {
        let Message::VehicleState(v) = input.msg else {
            return Ok(());
        };
        self.states += 1;
        let z = v.world_from_body.translation[2];
        if self.orders == 0 && v.armed == 1 && z > self.ceiling_m {
            let mut msg = Header::derived_from(&v.msg);
            msg.push_stage(ipc_types::msg::Stage::Bench, now_ns, now_ns);
            let order = SafetyCommand {
                msg,
                action: SafetyAction::SafeLand as u32,
                reserved: 0,
                source: Text::new("altitude-guard"),
                reason: Text::new("above the ceiling"),
            };
            out.publish(topics::SAFETY_COMMAND, Message::SafetyCommand(&order))?;
            self.orders += 1;
        }
        Ok(())
    }

    fn counters(&self) -> Vec<Counter> {
        vec![("states", self.states), ("orders", self.orders)]
    }
}

/// The node to add to a graph (TOML) to run the guard with `ceiling_m`: it reads the
/// vehicle state (delayed: it closes the cycle px4-link -> vehicle/state -> guard ->
/// safety/command -> px4-link) and publishes safety orders.
pub fn graph_node(ceiling_m: f64) -> String {
    format!(
        r#"
[[node]]
name = "altitude-guard"
binary = "altitude-guard"
rate_hz = 50.0
trigger = "vehicle/state"
heartbeat_deadline_ms = 500
latency_ms = 0.0
inputs = [{{ topic = "vehicle/state", policy = "newest", depth = 4, delay = true }}]
outputs = ["safety/command"]
args = ["--ceiling-m", "{ceiling_m}"]
"#
    )
}
