//! PX4's custom modes as HEARTBEAT carries them: main mode in bits 16-23, sub mode in
//! bits 24-31 (px4_custom_mode.h).

use ipc_types::msg::FlightMode;

/// PX4 main mode numbers.
const MAIN_MANUAL: u32 = 1;
const MAIN_ALTCTL: u32 = 2;
const MAIN_POSCTL: u32 = 3;
const MAIN_AUTO: u32 = 4;
const MAIN_ACRO: u32 = 5;
const MAIN_OFFBOARD: u32 = 6;
const MAIN_STABILIZED: u32 = 7;
/// AUTO sub modes.
const SUB_TAKEOFF: u32 = 2;
const SUB_LOITER: u32 = 3;
const SUB_MISSION: u32 = 4;
const SUB_RTL: u32 = 5;
const SUB_LAND: u32 = 6;
const SUB_PRECLAND: u32 = 9;

/// The stack's name for a PX4 custom mode.
pub fn flight_mode(custom_mode: u32) -> FlightMode {
    let main = (custom_mode >> 16) & 0xff;
    let sub = (custom_mode >> 24) & 0xff;
    match (main, sub) {
        (MAIN_OFFBOARD, _) => FlightMode::Offboard,
        (MAIN_AUTO, SUB_TAKEOFF) => FlightMode::Takeoff,
        (MAIN_AUTO, SUB_LOITER) => FlightMode::Hold,
        (MAIN_AUTO, SUB_LAND | SUB_PRECLAND) => FlightMode::Land,
        (MAIN_AUTO, SUB_RTL) => FlightMode::ReturnToLaunch,
        (MAIN_AUTO, SUB_MISSION) => FlightMode::Mission,
        (MAIN_MANUAL | MAIN_ALTCTL | MAIN_POSCTL | MAIN_ACRO | MAIN_STABILIZED, _) => {
            FlightMode::Manual
        }
        _ => FlightMode::Unknown,
    }
}

/// MAV_CMD_DO_SET_MODE parameters (base mode custom flag, main, sub) for OFFBOARD.
pub const OFFBOARD: (f32, f32, f32) = (1.0, MAIN_OFFBOARD as f32, 0.0);
