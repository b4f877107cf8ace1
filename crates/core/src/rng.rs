//! Seeded generators, so a generated benchmark scene or workload (and every test drawn from
//! it) is the same on every run and machine: SplitMix64 (Steele, Lea, Flood 2014), tiny and
//! well mixed, for scenes; Knuth's MMIX linear congruential generator for the trained
//! networks' seeded weights and inputs.

/// The generator's state.
#[derive(Clone, Debug)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// A generator seeded with `seed`.
    pub fn new(seed: u64) -> Self {
        SplitMix64(seed)
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`, single precision.
    pub fn unit(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    /// Uniform in `[lo, hi)`, single precision.
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.unit()
    }

    /// A point uniform in the cube `[lo, hi)³`: x, then y, then z drawn by [`Self::range`].
    #[cfg(test)]
    pub(crate) fn in_cube(&mut self, lo: f32, hi: f32) -> glam::Vec3 {
        let x = self.range(lo, hi);
        let y = self.range(lo, hi);
        glam::Vec3::new(x, y, self.range(lo, hi))
    }
}

/// Knuth's MMIX linear congruential generator (`s ← 6364136223846793005·s +
/// 1442695040888963407`), the source of the networks' seeded weights, tables and inputs in
/// their tests and benchmark workloads.
#[derive(Clone, Debug)]
pub(crate) struct Mmix(u64);

impl Mmix {
    /// A generator seeded with `seed`.
    pub(crate) fn new(seed: u64) -> Self {
        Mmix(seed)
    }

    /// Uniform in `[0, 1)`, single precision: the top 24 bits of the next state.
    pub(crate) fn unit(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
}
