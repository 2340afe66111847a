//! Helpers for the workspace-level tests: a toy stage added through the graph (`toy`),
//! stack binaries as child processes (`process`),
//! the whole stack started as `landing run --processes` starts it (`stack`), stop tests
//! under load (`stop`), misbehaving stages for fault tests (`misbehaving`), and where a pointer lives in this process's memory map, so a test
//! can prove that a payload is read in place from shared memory.

pub mod misbehaving;
pub mod process;
pub mod stack;
pub mod stop;
pub mod toy;

use std::path::PathBuf;

/// The file mapping that holds an address, and the address's offset in that file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MappedLocation {
    /// The mapped file (for iceoryx2 data segments, a file under /dev/shm).
    pub file: PathBuf,
    /// Offset of the address from the start of the file.
    pub offset: u64,
}

/// Looks `addr` up in /proc/self/maps; `None` when it is in anonymous memory (heap,
/// stack), which is where a copy would live.
pub fn mapped_location(addr: usize) -> Option<MappedLocation> {
    let maps = std::fs::read_to_string("/proc/self/maps").ok()?;
    for line in maps.lines() {
        let mut parts = line.split_whitespace();
        let range = parts.next()?;
        let _perms = parts.next()?;
        let offset = u64::from_str_radix(parts.next()?, 16).ok()?;
        let _dev = parts.next()?;
        let _inode = parts.next()?;
        let path: Vec<&str> = parts.collect();
        let (lo, hi) = range.split_once('-')?;
        let lo = usize::from_str_radix(lo, 16).ok()?;
        let hi = usize::from_str_radix(hi, 16).ok()?;
        if (lo..hi).contains(&addr) {
            let path = path.join(" ");
            if !path.starts_with('/') {
                return None;
            }
            return Some(MappedLocation {
                file: PathBuf::from(path.trim_end_matches(" (deleted)")),
                offset: offset + (addr - lo) as u64,
            });
        }
    }
    None
}

#[cfg(test)]
#[path = "lib_test.rs"]
mod tests;
