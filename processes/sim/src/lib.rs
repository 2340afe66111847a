//! The simulator core of the landing stack: a pure library.
//!
//! It stands in for the world and for PX4 so the whole mission can run on a
//! laptop: quadrotor rigid-body physics, a PX4-like cascaded controller, the
//! noise a visual-inertial estimator adds, the ground vehicle carrying the
//! landing pad, wind, and a [`world::World`] that ties them together and
//! records ground-truth events (touchdown, crash, collision); plus the two
//! simulated cameras: the downward pad camera ([`camera::DownCamera`]) and
//! the forward depth camera ([`depth::DepthCamera`]).
//!
//! Everything here is pure: inputs and time in, outputs out. There are no clock
//! reads, sleeps, threads, IPC or printing; the caller drives fixed-step
//! integration, so lockstep runs are deterministic for a given seed. The
//! `sim` binary puts the same stage ([`stage::SimStage`]) behind a UDP socket
//! on the wall clock. Reading a scenario file ([`scenario::load`]) is the one
//! I/O.
//!
//! Frames: world ENU (x east, y north, z up, origin at the take-off point),
//! body FLU (x forward, y left, z up); transforms are named by what they map
//! (`world_from_body * p_body = p_world`). SI units throughout.

pub mod autopilot;
pub mod autopilot_params;
mod bilinear;
pub mod camera;
pub mod depth;
pub mod estimator_noise;
pub mod geometry;
pub mod ground_vehicle;
pub mod hil;
pub mod hover_thrust;
pub mod hysteresis;
pub mod land_detector;
pub mod lockstep;
pub mod noise;
pub mod params;
pub mod px4;
pub mod quadrotor;
pub mod rng;
pub mod scenario;
pub mod stage;
pub mod vio;
pub mod wind;
pub mod world;
