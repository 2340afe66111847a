//! The seed of run `i` of a scenario: a function of the campaign's base seed, the
//! scenario's name and `i` only, so a run flies the same whatever worker, shard or job
//! count flies it, and two scenarios never share a sequence of seeds.

/// SplitMix64's finaliser: a bijection on u64 that spreads every input bit.
fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// FNV-1a of the scenario's name.
fn name_hash(name: &str) -> u64 {
    name.bytes().fold(0xCBF2_9CE4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01B3)
    })
}

/// The seed run `index` of `scenario` flies in a campaign of base seed `base`: from 1 to
/// 2^32 - 1, so the command that flies it again stays short to type.
pub fn derive(base: u64, scenario: &str, index: u64) -> u64 {
    let stream = mix(base ^ mix(name_hash(scenario)));
    let s = mix(stream.wrapping_add(index.wrapping_mul(0x9E37_79B9_7F4A_7C15)));
    (s % 0xFFFF_FFFF) + 1
}

#[cfg(test)]
#[path = "seed_test.rs"]
mod tests;
