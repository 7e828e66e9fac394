//! Clustered-ellipsoid and line levels of detail (seed 002, Clasen, Paar, Prohaska).
//!
//! - [`leaves`]: every leaf → one ellipsoid (uniform surface samples, alpha-tested
//!   against the leaf texture, then PCA).
//! - [`hierarchy`]: levels of n/4, n/16, … 1 clusters, each the best of several EM
//!   starts (alg. 1), as ellipsoids by weighted PCA, sized and noise-calibrated by
//!   image error against the full mesh rendered by Sylva's own pipelines.
//! - [`lines`]: a line skeleton from the branch mesh, simplified by agglomerative
//!   straighten/combine merges chosen by image error (§3.2).

pub mod bake;
pub mod em;
pub mod hierarchy;
pub mod leaves;
pub mod lines;

/// Small deterministic generator (SplitMix64): bakes must be reproducible.
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    /// Seeded.
    #[must_use]
    pub fn new(seed: u64) -> Self {
        Self(seed ^ 0x9e37_79b9_7f4a_7c15)
    }

    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    #[cfg(test)]
    pub fn f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in `0..n` (n > 0).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n.max(1) as u64) as usize
    }
}
