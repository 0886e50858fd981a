//! The workspace's one seeded hash, splitmix64, and the generator that steps it. Every random
//! number in ptm is a hash of (texel, sample, light, seed) or a stream seeded by one, so output
//! is deterministic for any thread count; the bake's sample positions are among them, so this
//! function must never change (tests/farm.rs and the golden images depend on its values).

/// Weyl step of splitmix64: 2⁶⁴ over the golden ratio, odd.
pub const GOLDEN_GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

/// splitmix64 of `x`: the Weyl step added, then Stafford's "mix13" finaliser. A bijection of
/// u64 with full avalanche, so consecutive or XOR-ed keys give unrelated outputs.
pub fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(GOLDEN_GAMMA);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A hash's top 53 bits as a uniform f64 in [0, 1) (every value exactly representable).
pub fn unit_f64(h: u64) -> f64 {
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// The splitmix64 generator: the state advances by [`GOLDEN_GAMMA`] per draw and each output
/// is [`splitmix64`] of the state before the step (Steele, Lea and Flood's SplittableRandom).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SplitMix(pub u64);

impl SplitMix {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        let h = splitmix64(self.0);
        self.0 = self.0.wrapping_add(GOLDEN_GAMMA);
        h
    }

    /// Uniform in [0, 1) with 53 random bits.
    pub fn uniform(&mut self) -> f64 {
        unit_f64(self.next_u64())
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// An index in 0..n by the modulus (0 when n is 0); biased by under n/2⁶⁴.
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n.max(1) as u64) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_the_reference_splitmix64_stream() {
        // The first outputs of Vigna's splitmix64.c seeded with 0 and with 1234567.
        let mut r = SplitMix(0);
        assert_eq!(r.next_u64(), 0xE220_A839_7B1D_CDAF);
        assert_eq!(r.next_u64(), 0x6E78_9E6A_A1B9_65F4);
        let mut r = SplitMix(1_234_567);
        assert_eq!(r.next_u64(), 6_457_827_717_110_365_317);
        assert_eq!(r.next_u64(), 3_203_168_211_198_807_973);
        assert_eq!(splitmix64(0), 0xE220_A839_7B1D_CDAF);
    }

    #[test]
    fn unit_is_in_the_half_open_interval() {
        assert_eq!(unit_f64(0), 0.0);
        assert!(unit_f64(u64::MAX) < 1.0);
    }
}
