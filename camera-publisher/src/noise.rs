//! Deterministic pseudo-randomness for scenes, without a `rand` dependency.
//!
//! Scenes need cheap, reproducible noise and a few per-blob parameters, not statistical
//! quality: SplitMix64 turns a seed into well-mixed words and xorshift64* streams them.

/// SplitMix64's finaliser: mixes any 64-bit word (zero included) into a well-spread one.
pub(crate) fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A xorshift64* stream: one multiply and three shifts a word, enough to fill a frame
/// with noise at memory speed.
#[derive(Debug, Clone)]
pub(crate) struct XorShift64 {
    state: u64,
}

impl XorShift64 {
    /// A stream from any seed; the seed is mixed first, because xorshift must not start
    /// at zero and starts poorly from small seeds.
    pub(crate) fn new(seed: u64) -> Self {
        let state = mix(seed);
        Self { state: if state == 0 { 0x2545_F491_4F6C_DD1D } else { state } }
    }

    /// The next word.
    pub(crate) fn next_u64(&mut self) -> u64 {
        let mut x = self.state;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.state = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// A float uniform in `[0, 1)`.
    pub(crate) fn next_unit(&mut self) -> f64 {
        // The top 53 bits fill a double's mantissa exactly.
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_are_reproducible_and_seed_dependent() {
        let a: Vec<u64> = {
            let mut r = XorShift64::new(0);
            (0..4).map(|_| r.next_u64()).collect()
        };
        let b: Vec<u64> = {
            let mut r = XorShift64::new(0);
            (0..4).map(|_| r.next_u64()).collect()
        };
        let c: Vec<u64> = {
            let mut r = XorShift64::new(1);
            (0..4).map(|_| r.next_u64()).collect()
        };
        assert_eq!(a, b);
        assert_ne!(a, c);
        assert!(a.iter().all(|&w| w != 0));
    }

    #[test]
    fn unit_floats_stay_in_range() {
        let mut r = XorShift64::new(42);
        for _ in 0..10_000 {
            let u = r.next_unit();
            assert!((0.0..1.0).contains(&u));
        }
    }
}
