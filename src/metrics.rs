//! Image error: multi-scale RMSE (seed 002 §4).
//!
//! RMSE of the difference image at every power-of-two resolution (full, ½, ¼, …
//! down to 1 pixel), averaged over the levels: single-pixel noise counts at the
//! fine levels, large-scale differences (a missing crown, a colour shift) at the
//! coarse ones. The paper scans the difference along a z-curve so every aligned
//! 2^k block is contiguous; the box pyramid here computes the same block means.

/// Multi-scale RMSE between two RGBA8 images of `width`×`height`, on the RGB
/// channels, on a 0–1 scale (0 identical, 1 black vs white everywhere).
///
/// # Panics
/// If either image is not `width · height · 4` bytes.
#[must_use]
pub fn multiscale_rmse(a: &[u8], b: &[u8], width: u32, height: u32) -> f64 {
    let n = (width as usize) * (height as usize);
    assert_eq!(a.len(), n * 4, "image a has the wrong size");
    assert_eq!(b.len(), n * 4, "image b has the wrong size");
    if n == 0 {
        return 0.0;
    }
    // Difference image, per pixel and channel, in [-1, 1].
    let mut diff: Vec<[f64; 3]> = a
        .chunks_exact(4)
        .zip(b.chunks_exact(4))
        .map(|(p, q)| std::array::from_fn(|c| (f64::from(p[c]) - f64::from(q[c])) / 255.0))
        .collect();
    let (mut w, mut h) = (width as usize, height as usize);
    let mut sum = 0.0;
    let mut levels = 0;
    loop {
        let mse: f64 = diff.iter().map(|d| d.iter().map(|v| v * v).sum::<f64>() / 3.0).sum::<f64>() / diff.len() as f64;
        sum += mse.sqrt();
        levels += 1;
        if w == 1 && h == 1 {
            break;
        }
        // Halve, averaging the 2×2 blocks (blocks cut by an odd edge average what they hold).
        let (nw, nh) = (w.div_ceil(2), h.div_ceil(2));
        let mut next = vec![[0.0; 3]; nw * nh];
        for y in 0..nh {
            for x in 0..nw {
                let mut acc = [0.0; 3];
                let mut count = 0.0;
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let (sx, sy) = (2 * x + dx, 2 * y + dy);
                    if sx < w && sy < h {
                        let d = diff[sy * w + sx];
                        for c in 0..3 {
                            acc[c] += d[c];
                        }
                        count += 1.0;
                    }
                }
                next[y * nw + x] = acc.map(|v| v / count);
            }
        }
        diff = next;
        w = nw;
        h = nh;
    }
    sum / f64::from(levels)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identical_images_have_zero_error() {
        let img = vec![77u8; 8 * 6 * 4];
        assert_eq!(multiscale_rmse(&img, &img, 8, 6), 0.0);
    }

    #[test]
    fn black_vs_white_is_one() {
        let black = vec![0u8; 4 * 4 * 4];
        let white = vec![255u8; 4 * 4 * 4];
        assert!((multiscale_rmse(&black, &white, 4, 4) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn noise_counts_less_than_a_shift() {
        // A checkerboard ±d has full RMSE d at level 0 but cancels at coarser levels;
        // a uniform shift d keeps d at every level.
        let base = vec![128u8; 8 * 8 * 4];
        let checker: Vec<u8> = (0..64)
            .flat_map(|i| {
                let v = if (i % 8 + i / 8) % 2 == 0 { 138 } else { 118 };
                [v, v, v, 255]
            })
            .collect();
        let shifted = vec![138u8; 8 * 8 * 4];
        let e_noise = multiscale_rmse(&base, &checker, 8, 8);
        let e_shift = multiscale_rmse(&base, &shifted, 8, 8);
        assert!(e_noise < e_shift * 0.5, "noise {e_noise} shift {e_shift}");
    }
}
