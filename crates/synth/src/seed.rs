//! Stable per-output seeds.
//!
//! The seed of one output is a hash of (recipe seed, clip name, op index, copy
//! index): FNV-1a over the bytes, then the SplitMix64 finaliser. Both are fixed
//! algorithms (unlike `std`'s `DefaultHasher`), so seeds are the same on every
//! platform and release, and an output does not depend on which other clips or
//! jobs ran before it.

use rand::SeedableRng;

use crate::SynthRng;

fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Seed of output `copy` of op `op_index` for clip `clip`.
pub fn output_seed(recipe_seed: u64, clip: &str, op_index: usize, copy: u32) -> u64 {
    const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
    const PRIME: u64 = 0x0000_0100_0000_01b3;
    let mut h = OFFSET;
    let mut eat = |bytes: &[u8]| {
        for b in bytes {
            h ^= u64::from(*b);
            h = h.wrapping_mul(PRIME);
        }
    };
    eat(&recipe_seed.to_le_bytes());
    eat(&(clip.len() as u64).to_le_bytes());
    eat(clip.as_bytes());
    eat(&(op_index as u64).to_le_bytes());
    eat(&u64::from(copy).to_le_bytes());
    splitmix64(h)
}

/// The generator for one output.
pub fn rng_from_seed(seed: u64) -> SynthRng {
    SynthRng::seed_from_u64(seed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seeds_differ_by_every_input_and_are_stable() {
        let a = output_seed(1, "clip", 0, 0);
        assert_eq!(a, output_seed(1, "clip", 0, 0));
        let others = [
            output_seed(2, "clip", 0, 0),
            output_seed(1, "clip2", 0, 0),
            output_seed(1, "clip", 1, 0),
            output_seed(1, "clip", 0, 1),
        ];
        for o in others {
            assert_ne!(a, o);
        }
        // Pinned value: changing the derivation would silently change every
        // published augmentation, so it must be a deliberate decision.
        assert_eq!(output_seed(0, "", 0, 0), 13_287_522_180_219_829_913);
    }
}
