//! Light from an equirectangular HDR environment (`sylva render --path-trace
//! --environment FILE.hdr`, issue 48), importance sampled: directions are
//! drawn in proportion to the map's luminance × sin θ, a piecewise-constant
//! 2D distribution (a marginal over rows and a conditional within each row),
//! the inversion method of Pharr, Jakob & Humphreys, *Physically Based
//! Rendering* (3rd ed., 2016), §13.6.7 and §14.2.4, combined with the
//! surfaces' own sampling by multiple importance sampling (Veach & Guibas
//! 1995, the power heuristic). GPU-free; `shaders/path_trace.wgsl` samples
//! the same arrays ([`Environment::gpu_array`]) the same way.
//!
//! The map's frame: row 0 is the zenith, the last row the nadir; column 0
//! faces south and the middle column north (azimuth clockwise from north:
//! east a quarter of the way from the middle), so the sun of a map made with
//! the camera facing north sits where it did.

use glam::Vec3;

/// Most texels a side the tracer keeps (a larger map is averaged down).
pub const MAX_WIDTH: u32 = 1024;

/// An environment's radiance and its sampling distribution.
#[derive(Debug, Clone, PartialEq)]
pub struct Environment {
    /// Columns (azimuth).
    pub width: u32,
    /// Rows (zenith angle).
    pub height: u32,
    /// Linear radiance per texel, row-major from the zenith.
    pub texels: Vec<[f32; 3]>,
    /// Cumulative weights over rows (`height + 1`, from 0 to 1).
    pub marginal: Vec<f32>,
    /// Per row the cumulative weights over its columns (`width + 1` each, 0 to 1).
    pub conditional: Vec<f32>,
    /// Σ of every texel's weight × (the map's texel count): the density's normaliser.
    pub total: f32,
}

/// The texel's weight: luminance (Rec. 709) × sin θ at the row's centre.
fn weight(c: [f32; 3], sin_theta: f32) -> f32 {
    (0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]).max(0.0) * sin_theta
}

impl Environment {
    /// An environment of `width`×`height` linear radiance texels (row 0 the zenith).
    ///
    /// # Errors
    /// A size that does not match the texels, an empty or a non-finite or negative map.
    pub fn new(width: u32, height: u32, texels: Vec<[f32; 3]>) -> Result<Self, String> {
        if width == 0 || height == 0 || texels.len() != (width as usize) * (height as usize) {
            return Err(format!("an environment of {width}×{height} texels holds {} values", texels.len()));
        }
        if let Some(i) = texels.iter().position(|t| t.iter().any(|c| !c.is_finite() || *c < 0.0)) {
            return Err(format!("texel {} (row {}) is not a finite non-negative radiance", i, i / width as usize));
        }
        let (w, h) = (width as usize, height as usize);
        let mut conditional = Vec::with_capacity(h * (w + 1));
        let mut rows = Vec::with_capacity(h);
        for j in 0..h {
            let sin_theta = ((j as f32 + 0.5) / h as f32 * std::f32::consts::PI).sin();
            let mut sum = 0.0f64;
            let start = conditional.len();
            conditional.push(0.0);
            for i in 0..w {
                sum += f64::from(weight(texels[j * w + i], sin_theta));
                conditional.push(sum as f32);
            }
            // (A black row: uniform within it.)
            for (i, c) in conditional[start..].iter_mut().enumerate() {
                *c = if sum > 0.0 { (f64::from(*c) / sum) as f32 } else { i as f32 / w as f32 };
            }
            rows.push(sum);
        }
        let all: f64 = rows.iter().sum();
        if all <= 0.0 {
            return Err("the environment is black: it lights nothing".into());
        }
        let mut marginal = Vec::with_capacity(h + 1);
        let mut acc = 0.0f64;
        marginal.push(0.0);
        for r in &rows {
            acc += r;
            marginal.push((acc / all) as f32);
        }
        let total = (all / (w * h) as f64) as f32;
        Ok(Self { width, height, texels, marginal, conditional, total })
    }

    /// Reads a Radiance `.hdr` (or any image the `image` crate reads as
    /// floating point), averaged down to at most [`MAX_WIDTH`] columns.
    ///
    /// # Errors
    /// A file that does not read or decode (within the `image` crate's
    /// 512 MiB allocation limit), or a map that is not 2:1-ish (named).
    #[cfg(not(target_arch = "wasm32"))]
    pub fn from_file(path: &std::path::Path) -> Result<Self, String> {
        let img = image::open(path).map_err(|e| format!("cannot read the environment {}: {e}", path.display()))?;
        let img = img.to_rgb32f();
        let (w, h) = img.dimensions();
        // (Equirectangular: twice as wide as tall, give or take a texel row.)
        if h < 2 || !(1.5..=2.5).contains(&(f64::from(w) / f64::from(h))) {
            return Err(format!("{}: {w}×{h} is not an equirectangular map (twice as wide as tall)", path.display()));
        }
        let f = w.div_ceil(MAX_WIDTH).max(1);
        let (nw, nh) = (w / f, (h / f).max(1));
        let mut texels = vec![[0.0f32; 3]; (nw * nh) as usize];
        for (j, row) in texels.chunks_exact_mut(nw as usize).enumerate() {
            for (i, t) in row.iter_mut().enumerate() {
                let mut sum = [0.0f32; 3];
                for y in 0..f {
                    for x in 0..f {
                        let p = img.get_pixel((i as u32 * f + x).min(w - 1), (j as u32 * f + y).min(h - 1)).0;
                        for k in 0..3 {
                            sum[k] += if p[k].is_finite() { p[k].max(0.0) } else { 0.0 };
                        }
                    }
                }
                *t = sum.map(|s| s / (f * f) as f32);
            }
        }
        Self::new(nw, nh, texels).map_err(|e| format!("{}: {e}", path.display()))
    }

    /// The map's (u, v) of a direction (unit): u the azimuth (0.5 north), v the zenith angle over π.
    #[must_use]
    pub fn uv(d: Vec3) -> [f32; 2] {
        let u = d.x.atan2(d.y) / std::f32::consts::TAU + 0.5;
        let v = d.z.clamp(-1.0, 1.0).acos() / std::f32::consts::PI;
        [u - u.floor(), v]
    }

    /// The direction of (u, v).
    #[must_use]
    pub fn direction([u, v]: [f32; 2]) -> Vec3 {
        let az = (u - 0.5) * std::f32::consts::TAU;
        let theta = v * std::f32::consts::PI;
        Vec3::new(theta.sin() * az.sin(), theta.sin() * az.cos(), theta.cos())
    }

    fn texel(&self, [u, v]: [f32; 2]) -> (usize, usize) {
        let i = ((u * self.width as f32) as usize).min(self.width as usize - 1);
        let j = ((v * self.height as f32) as usize).min(self.height as usize - 1);
        (i, j)
    }

    /// The radiance seen along `d` (unit; nearest texel).
    #[must_use]
    pub fn radiance(&self, d: Vec3) -> Vec3 {
        let (i, j) = self.texel(Self::uv(d));
        Vec3::from(self.texels[j * self.width as usize + i])
    }

    /// The density (per steradian) with which [`Self::sample`] draws `d`.
    #[must_use]
    pub fn pdf(&self, d: Vec3) -> f32 {
        let uv = Self::uv(d);
        let (i, j) = self.texel(uv);
        let sin_theta = (uv[1] * std::f32::consts::PI).sin();
        if sin_theta <= 0.0 {
            return 0.0;
        }
        let row_sin = ((j as f32 + 0.5) / self.height as f32 * std::f32::consts::PI).sin();
        let p_uv = weight(self.texels[j * self.width as usize + i], row_sin) / self.total;
        p_uv / (2.0 * std::f32::consts::PI * std::f32::consts::PI * sin_theta)
    }

    /// A direction drawn for `xi` (two uniform numbers in [0, 1)) and its density.
    #[must_use]
    pub fn sample(&self, xi: [f32; 2]) -> (Vec3, f32) {
        let (w, h) = (self.width as usize, self.height as usize);
        let j = find(&self.marginal, xi[0]).min(h - 1);
        let dv = (xi[0] - self.marginal[j]) / (self.marginal[j + 1] - self.marginal[j]).max(1e-30);
        let row = &self.conditional[j * (w + 1)..(j + 1) * (w + 1)];
        let i = find(row, xi[1]).min(w - 1);
        let du = (xi[1] - row[i]) / (row[i + 1] - row[i]).max(1e-30);
        let uv = [(i as f32 + du.clamp(0.0, 1.0)) / w as f32, (j as f32 + dv.clamp(0.0, 1.0)) / h as f32];
        let d = Self::direction(uv);
        (d, self.pdf(d))
    }

    /// The arrays as `shaders/path_trace.wgsl` reads them, one `f32` array:
    /// `[width, height, total, 0]` (the sizes as numbers), the texels as
    /// rgb + 0, the marginal, the conditionals.
    #[must_use]
    pub fn gpu_array(&self) -> Vec<f32> {
        let mut out = vec![self.width as f32, self.height as f32, self.total, 0.0];
        for t in &self.texels {
            out.extend_from_slice(&[t[0], t[1], t[2], 0.0]);
        }
        out.extend_from_slice(&self.marginal);
        out.extend_from_slice(&self.conditional);
        out
    }
}

/// The last index `k` with `cdf[k] <= x` (binary search; `cdf` ascending from 0).
fn find(cdf: &[f32], x: f32) -> usize {
    let (mut lo, mut hi) = (0usize, cdf.len() - 1);
    while lo + 1 < hi {
        let mid = (lo + hi) / 2;
        if cdf[mid] <= x {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trace::Xorshift32;

    /// A sky of 0.1 with one bright patch (a sun).
    fn patchy() -> Environment {
        let (w, h) = (64, 32);
        let texels = (0..w * h)
            .map(|k| {
                let (i, j) = (k % w, k / w);
                if (20..23).contains(&i) && (8..10).contains(&j) {
                    [500.0, 450.0, 400.0]
                } else {
                    [0.1, 0.12, 0.2]
                }
            })
            .collect();
        Environment::new(w as u32, h as u32, texels).unwrap()
    }

    #[test]
    fn directions_and_the_map_agree() {
        for d in [Vec3::Z, Vec3::Y, Vec3::X, -Vec3::Y, Vec3::new(0.3, -0.5, 0.2).normalize()] {
            let back = Environment::direction(Environment::uv(d));
            assert!((back - d).length() < 1e-5, "{d} → {back}");
        }
        // North in the middle of the map, east a quarter further, the zenith on row 0.
        assert!((Environment::uv(Vec3::Y)[0] - 0.5).abs() < 1e-6);
        assert!((Environment::uv(Vec3::X)[0] - 0.75).abs() < 1e-6);
        assert!(Environment::uv(Vec3::Z)[1].abs() < 1e-6);
    }

    #[test]
    fn the_density_integrates_to_one_and_sampling_follows_it() {
        let env = patchy();
        // ∫ pdf dω over the sphere, by uniform directions.
        let mut rng = Xorshift32(7);
        let n = 400_000;
        let mut integral = 0.0f64;
        for _ in 0..n {
            let z = rng.unit() * 2.0 - 1.0;
            let a = rng.unit() * std::f32::consts::TAU;
            let r = (1.0 - z * z).sqrt();
            integral += f64::from(env.pdf(Vec3::new(r * a.cos(), r * a.sin(), z)));
        }
        let integral = integral / f64::from(n) * 4.0 * std::f64::consts::PI;
        assert!((integral - 1.0).abs() < 0.02, "∫ pdf dω = {integral}");
        // Drawn directions land in the patch as often as its share of the weight says.
        let patch = |d: Vec3| {
            let uv = Environment::uv(d);
            let (i, j) = ((uv[0] * 64.0) as usize, (uv[1] * 32.0) as usize);
            (20..23).contains(&i) && (8..10).contains(&j)
        };
        let share: f64 = (0..64 * 32)
            .filter(|k| (20..23).contains(&(k % 64)) && (8..10).contains(&(k / 64)))
            .map(|k| {
                let j = k / 64;
                let s = ((j as f32 + 0.5) / 32.0 * std::f32::consts::PI).sin();
                f64::from(weight(env.texels[k], s))
            })
            .sum::<f64>()
            / (f64::from(env.total) * 64.0 * 32.0);
        let m = 100_000;
        let hits = (0..m).filter(|_| patch(env.sample([rng.unit(), rng.unit()]).0)).count();
        let seen = hits as f64 / f64::from(m);
        assert!((seen - share).abs() < 0.01, "patch drawn {seen}, weight share {share}");
        assert!(share > 0.9, "the patch holds most of the light: {share}");
        // Each draw's density is the density of its direction.
        for _ in 0..100 {
            let (d, p) = env.sample([rng.unit(), rng.unit()]);
            assert!((p - env.pdf(d)).abs() <= 1e-4 * p.max(1.0));
        }
    }

    #[test]
    fn a_radiance_file_reads_back_averaged_down_and_a_bad_one_is_named() {
        let dir = std::env::temp_dir().join(format!("sylva-env-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("sky.hdr");
        let (w, h) = (2048u32, 1024u32);
        let pixels: Vec<image::Rgb<f32>> = (0..w * h)
            .map(|k| if (k / w) < h / 2 { image::Rgb([2.0, 1.0, 0.5]) } else { image::Rgb([0.1, 0.1, 0.1]) })
            .collect();
        let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
        image::codecs::hdr::HdrEncoder::new(file).encode(&pixels, w as usize, h as usize).unwrap();
        let env = Environment::from_file(&path).unwrap();
        assert_eq!((env.width, env.height), (MAX_WIDTH, MAX_WIDTH / 2), "averaged down to {MAX_WIDTH} columns");
        let up = env.radiance(Vec3::new(0.0, 0.3, 0.9).normalize());
        assert!((up - Vec3::new(2.0, 1.0, 0.5)).abs().max_element() < 0.02, "{up}");
        let down = env.radiance(-Vec3::Z);
        assert!((down - Vec3::splat(0.1)).abs().max_element() < 0.01, "{down}");
        std::fs::write(dir.join("bad.hdr"), b"#?RADIANCE\nnot a map").unwrap();
        let err = Environment::from_file(&dir.join("bad.hdr")).unwrap_err();
        assert!(err.contains("bad.hdr"), "{err}");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn bad_maps_are_refused() {
        assert!(Environment::new(2, 1, vec![[0.0; 3]; 2]).unwrap_err().contains("black"));
        assert!(Environment::new(2, 1, vec![[f32::NAN, 0.0, 0.0], [1.0; 3]]).unwrap_err().contains("finite"));
        assert!(Environment::new(3, 1, vec![[1.0; 3]; 2]).is_err());
    }
}
