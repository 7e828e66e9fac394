//! Deterministic random numbers (SplitMix64) and value noise: bakes must be
//! reproducible, so the demo layout, its ground and the cluster bake draw from
//! seeded generators.

/// A seeded SplitMix64 generator.
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    /// Seeded generator.
    #[must_use]
    pub fn new(seed: u64) -> Self {
        Self(seed ^ 0x9E37_79B9_7F4A_7C15)
    }

    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    /// Uniform in [0, 1), double precision.
    pub fn f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.f32()
    }

    /// Uniform in `0..n` (n > 0).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n.max(1) as u64) as usize
    }
}

/// A 64-bit mix of a value, for per-tree attributes derived from ids.
pub fn hash64(x: u64) -> u64 {
    Rng::new(x).next_u64()
}

/// Smooth value noise in [0, 1] with integer lattice at `1/scale`.
pub fn value_noise(seed: u64, x: f64, y: f64) -> f64 {
    let (xi, yi) = (x.floor(), y.floor());
    let (fx, fy) = (x - xi, y - yi);
    let h = |i: f64, j: f64| {
        (hash64(seed ^ ((i as i64 as u64).wrapping_mul(0x1F1F_1F1F) ^ (j as i64 as u64).wrapping_mul(0x007A_3D5B)))
            >> 11) as f64
            / (1u64 << 53) as f64
    };
    let s = |t: f64| t * t * (3.0 - 2.0 * t);
    let (sx, sy) = (s(fx), s(fy));
    let a = h(xi, yi) + (h(xi + 1.0, yi) - h(xi, yi)) * sx;
    let b = h(xi, yi + 1.0) + (h(xi + 1.0, yi + 1.0) - h(xi, yi + 1.0)) * sx;
    a + (b - a) * sy
}

/// Fractal noise, three octaves, period ~`scale` metres.
pub fn fbm(seed: u64, x: f64, y: f64, scale: f64) -> f64 {
    let mut sum = 0.0;
    let mut amp = 0.5;
    let mut f = 1.0 / scale;
    for o in 0..3 {
        sum += amp * value_noise(seed + o, x * f, y * f);
        amp *= 0.5;
        f *= 2.0;
    }
    sum / 0.875
}
