//! The sampler's counter-based random numbers, twins of `kernels/softvk/include/probe.glsl`: every
//! random word is a hash of (seed, iteration, stream, sample index, draw), so any sample of any
//! iteration can be recomputed on its own, on the GPU or here, with the same bits.

/// The PCG hash (Jarzynski and Olano 2020, "Hash functions for GPU rendering"): a PCG step
/// followed by PCG's RXS-M-XS output permutation. A bijection of `u32`.
pub fn pcg_hash(v: u32) -> u32 {
    let state = v.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let word = ((state >> ((state >> 28) + 4)) ^ state).wrapping_mul(277_803_737);
    (word >> 22) ^ word
}

/// Stream of the probing rays.
pub const STREAM_RAYS: u32 = 0;
/// Stream of the anchors.
pub const STREAM_ANCHORS: u32 = 1;
/// Stream of the geometric regularizer's surface candidates.
pub const STREAM_CANDIDATES: u32 = 2;

/// The key of one stream of one iteration (computed on the host, pushed to the kernels).
pub fn stream_key(seed: u64, iteration: u32, stream: u32) -> u32 {
    let s = pcg_hash(pcg_hash(seed as u32) ^ (seed >> 32) as u32);
    pcg_hash(pcg_hash(s ^ iteration) ^ stream)
}

/// The `draw`-th random word (`draw < 8`) of sample `index` (`index < 2^29`) of a stream.
pub fn rand_u32(key: u32, index: u32, draw: u32) -> u32 {
    pcg_hash(key ^ pcg_hash(index.wrapping_mul(8).wrapping_add(draw)))
}

/// Uniform in [0, 1), exactly representable (24 bits).
pub fn unit_float(h: u32) -> f32 {
    (h >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// Uniform in (0, 1], for a logarithm.
pub fn unit_float_open0(h: u32) -> f32 {
    ((h >> 8) + 1) as f32 * (1.0 / 16_777_216.0)
}

/// `⌊h n / 2^32⌋`: an index uniform in [0, n) (`umulExtended`'s high word).
pub fn scale_u32(h: u32, n: u32) -> u32 {
    ((u64::from(h) * u64::from(n)) >> 32) as u32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pcg_hash_matches_the_reference_implementation() {
        // Printed by the C reference (uint32_t arithmetic) of Jarzynski and Olano's pcg_hash.
        assert_eq!(pcg_hash(0), 129_708_002);
        assert_eq!(pcg_hash(1), 2_831_084_092);
        assert_eq!(pcg_hash(0xFFFF_FFFF), 3_861_530_882);
    }

    #[test]
    fn pcg_hash_is_a_bijection_on_a_sample() {
        let mut seen = std::collections::HashSet::new();
        for v in 0..200_000u32 {
            assert!(seen.insert(pcg_hash(v.wrapping_mul(2_654_435_761))));
        }
    }

    #[test]
    fn unit_floats_stay_in_range() {
        assert_eq!(unit_float(0), 0.0);
        assert!(unit_float(u32::MAX) < 1.0);
        assert!(unit_float_open0(0) > 0.0);
        assert_eq!(unit_float_open0(u32::MAX), 1.0);
        assert_eq!(scale_u32(u32::MAX, 10), 9);
        assert_eq!(scale_u32(0, 10), 0);
    }

    #[test]
    fn streams_and_iterations_get_different_keys() {
        let keys = [
            stream_key(0, 0, STREAM_RAYS),
            stream_key(0, 0, STREAM_ANCHORS),
            stream_key(0, 1, STREAM_RAYS),
            stream_key(1, 0, STREAM_RAYS),
            stream_key(1 << 32, 0, STREAM_RAYS),
        ];
        for i in 0..keys.len() {
            for j in 0..i {
                assert_ne!(keys[i], keys[j], "{i} {j}");
            }
        }
    }
}
