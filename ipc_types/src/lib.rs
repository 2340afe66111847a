//! Messages, service names and the small runtime shared by every process of the landing
//! stack. No algorithm lives here: this crate is the bottom of the dependency graph.

pub mod msg;
pub mod runtime;
pub mod services;

pub use iceoryx2;
