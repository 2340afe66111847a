//! The messages of the landing stack: the payloads that cross a process boundary and the
//! service names they travel on. No algorithm and no runtime live here (the iceoryx2
//! node, ports and wait loop are the `runtime` crate's): this crate is the bottom of the
//! dependency graph, and every process, tool and test can depend on it.

pub mod msg;
pub mod payloads;
pub mod services;
pub mod topics;
