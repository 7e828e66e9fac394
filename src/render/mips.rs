//! Alpha-aware mipmaps with alpha equalisation (Eichner 2024, §3.3.2, alg. 3.2).
//!
//! Colours are averaged weighted by alpha, so transparent texels (whose colour
//! is meaningless) do not darken edges; each level's alpha range is then mapped
//! linearly back to mip 0's range, so far trees keep fully opaque texels and
//! neither fade away nor blend into the ground. Colour averaging happens in
//! linear light (inputs are sRGB), which is what a GPU filter would do.

/// sRGB byte → linear.
#[must_use]
pub fn srgb_to_linear(c: u8) -> f32 {
    let c = f32::from(c) / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear → sRGB byte.
#[must_use]
pub fn linear_to_srgb(c: f32) -> u8 {
    let c = c.clamp(0.0, 1.0);
    let s = if c <= 0.003_130_8 { c * 12.92 } else { 1.055 * c.powf(1.0 / 2.4) - 0.055 };
    (s * 255.0 + 0.5) as u8
}

/// How the colour channels of a texture are encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ColorEncoding {
    /// sRGB colour: averaged in linear light.
    Srgb,
    /// Plain data (normals): averaged as stored.
    Linear,
}

/// One square RGBA layer with f32 channels.
struct Level {
    size: u32,
    rgba: Vec<[f32; 4]>,
}

/// Builds the full mip chain of a square `size`² RGBA8 layer (mip 0 included, down
/// to 1×1) with alpha-weighted colour averaging and alpha equalisation.
/// `weights` gives the alpha used for weighting and equalisation (pass the colour
/// layer's own bytes for colour; for a normal layer, its colour layer), so the
/// normal and colour chains of a billboard stay consistent. `cutoff` is the alpha
/// test threshold whose coverage the equalisation preserves; `None` keeps the
/// averaged alpha as it is (for data whose alpha is not coverage).
///
/// Returns one RGBA8 vector per mip level.
///
/// # Panics
/// If `size` is not a power of two or a layer's length is not `size² · 4`.
#[must_use]
pub fn alpha_aware_mips(
    layer: &[u8],
    weights: &[u8],
    size: u32,
    encoding: ColorEncoding,
    cutoff: Option<f32>,
) -> Vec<Vec<u8>> {
    assert!(size.is_power_of_two(), "mip chains need a power-of-two size, got {size}");
    let texels = (size * size) as usize;
    assert_eq!(layer.len(), texels * 4);
    assert_eq!(weights.len(), texels * 4);
    let decode = |c: u8| match encoding {
        ColorEncoding::Srgb => srgb_to_linear(c),
        ColorEncoding::Linear => f32::from(c) / 255.0,
    };
    let encode = |c: f32| match encoding {
        ColorEncoding::Srgb => linear_to_srgb(c),
        ColorEncoding::Linear => (c.clamp(0.0, 1.0) * 255.0 + 0.5) as u8,
    };
    // Working alpha (the weights) and the stored alpha of `layer`, per level.
    let mut levels = vec![Level {
        size,
        rgba: layer
            .chunks_exact(4)
            .map(|t| [decode(t[0]), decode(t[1]), decode(t[2]), f32::from(t[3]) / 255.0])
            .collect(),
    }];
    let mut alphas: Vec<Vec<f32>> = vec![weights.chunks_exact(4).map(|t| f32::from(t[3]) / 255.0).collect()];
    while levels.last().map_or(1, |l| l.size) > 1 {
        let prev = levels.last().expect("at least one level");
        let prev_alpha = alphas.last().expect("at least one level");
        let s = prev.size / 2;
        let mut rgba = Vec::with_capacity((s * s) as usize);
        let mut alpha = Vec::with_capacity((s * s) as usize);
        for y in 0..s {
            for x in 0..s {
                let idx = |dx: u32, dy: u32| ((2 * y + dy) * prev.size + 2 * x + dx) as usize;
                let quad = [idx(0, 0), idx(1, 0), idx(0, 1), idx(1, 1)];
                let alpha_sum: f32 = quad.iter().map(|&i| prev_alpha[i]).sum();
                let mut c = [0.0f32; 4];
                for &i in &quad {
                    // Alg. 3.2 line 6: colour weighted by alpha. All-transparent quads
                    // fall back to a plain average so they keep a defined colour.
                    let w = if alpha_sum > 0.0 { prev_alpha[i] / alpha_sum } else { 0.25 };
                    let t = prev.rgba[i];
                    c = [c[0] + t[0] * w, c[1] + t[1] * w, c[2] + t[2] * w, c[3] + t[3] * 0.25];
                }
                rgba.push(c);
                alpha.push(alpha_sum * 0.25);
            }
        }
        levels.push(Level { size: s, rgba });
        alphas.push(alpha);
    }
    // Alg. 3.2 lines 9–14: map each level's alpha range back to mip 0's. Sylva's
    // remap is piecewise linear through the level's coverage quantile, so beyond
    // restoring the range (opaque texels at every level) the fraction of texels
    // passing the alpha test stays that of mip 0: alpha-tested billboards neither
    // thin out nor thicken with distance.
    let alpha0: Vec<f32> = levels[0].rgba.iter().map(|t| t[3]).collect();
    let (lo0, hi0) = min_max(&alpha0);
    let coverage0 = cutoff.map(|c| alpha0.iter().filter(|&&a| a >= c).count() as f64 / alpha0.len() as f64);
    levels
        .iter()
        .enumerate()
        .map(|(k, l)| {
            let alpha: Vec<f32> = l.rgba.iter().map(|t| t[3]).collect();
            let remap = match (k, cutoff, coverage0) {
                (1.., Some(cutoff), Some(c0)) => Some(CoverageRemap::new(&alpha, c0, cutoff, lo0, hi0)),
                _ => None,
            };
            l.rgba
                .iter()
                .flat_map(|t| {
                    let a = remap.as_ref().map_or(t[3], |r| r.apply(t[3]));
                    [encode(t[0]), encode(t[1]), encode(t[2]), (a.clamp(0.0, 1.0) * 255.0).round() as u8]
                })
                .collect()
        })
        .collect()
}

fn min_max(v: &[f32]) -> (f32, f32) {
    v.iter().fold((f32::MAX, f32::MIN), |(lo, hi), &a| (lo.min(a), hi.max(a)))
}

/// Piecewise-linear alpha remap of one mip level: `[lo, t] → [lo0, cutoff)` and
/// `[t, hi] → [cutoff, hi0]`, where `t` splits the level's texels so that the
/// share at or above the cutoff equals mip 0's coverage.
struct CoverageRemap {
    lo: f32,
    t: f32,
    hi: f32,
    lo0: f32,
    hi0: f32,
    cutoff: f32,
}

impl CoverageRemap {
    fn new(alpha: &[f32], coverage0: f64, cutoff: f32, lo0: f32, hi0: f32) -> Self {
        let (lo, hi) = min_max(alpha);
        let mut sorted = alpha.to_vec();
        sorted.sort_by(|a, b| b.total_cmp(a));
        let n = sorted.len();
        let passing = ((coverage0 * n as f64).round() as usize).min(n);
        // Threshold between the last passing and the first failing texel.
        let t = match passing {
            0 => hi + 1.0,
            p if p == n => lo - 1.0,
            p => 0.5 * (sorted[p - 1] + sorted[p]),
        };
        Self { lo, t, hi, lo0, hi0, cutoff }
    }

    fn apply(&self, a: f32) -> f32 {
        // Largest value that still fails the test after 8-bit rounding.
        let below = self.cutoff - 0.6 / 255.0;
        if a >= self.t {
            let span = (self.hi - self.t.max(self.lo)).max(1e-9);
            self.cutoff.max(self.lo0)
                + (a - self.t.max(self.lo)) / span * (self.hi0 - self.cutoff.max(self.lo0)).max(0.0)
        } else {
            let span = (self.t.min(self.hi) - self.lo).max(1e-9);
            self.lo0 + (a - self.lo) / span * (below - self.lo0).max(0.0)
        }
    }
}

/// Fraction of texels of an RGBA8 layer whose alpha passes `cutoff` (0–1).
#[must_use]
pub fn alpha_coverage(layer: &[u8], cutoff: f32) -> f64 {
    let n = layer.len() / 4;
    let passing = layer.chunks_exact(4).filter(|t| f32::from(t[3]) / 255.0 >= cutoff).count();
    passing as f64 / n.max(1) as f64
}

/// Plain per-channel box-filtered mips, for comparison in tests and benchmarks.
#[must_use]
pub fn naive_mips(layer: &[u8], size: u32) -> Vec<Vec<u8>> {
    let mut out = vec![layer.to_vec()];
    let mut s = size;
    while s > 1 {
        let prev = out.last().expect("one level");
        let n = s / 2;
        let mut next = Vec::with_capacity((n * n * 4) as usize);
        for y in 0..n {
            for x in 0..n {
                for ch in 0..4 {
                    let at = |dx: u32, dy: u32| u32::from(prev[(((2 * y + dy) * s + 2 * x + dx) * 4 + ch) as usize]);
                    next.push(((at(0, 0) + at(1, 0) + at(0, 1) + at(1, 1) + 2) / 4) as u8);
                }
            }
        }
        out.push(next);
        s = n;
    }
    out
}
