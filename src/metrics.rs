//! Image error: multi-scale RMSE (Clasen et al. 2010, §4).
//!
//! RMSE of the difference image at every power-of-two resolution (full, ½, ¼, …
//! down to 1 pixel), averaged over the levels: single-pixel noise counts at the
//! fine levels, large-scale differences (a missing crown, a colour shift) at the
//! coarse ones. Computed in one pass along a z-curve (Fig. 8): in Morton order
//! every aligned 2^k × 2^k block is a contiguous run, so one running sum per
//! level yields every block mean as the scan passes it. Images of any size are
//! scanned over the enclosing power-of-two square; blocks cut by an edge average
//! the sub-blocks they hold (the same as halving with `div_ceil`, see
//! [`multiscale_rmse_pyramid`], the straightforward per-resolution computation).

/// Multi-scale RMSE between two RGBA8 images of `width`×`height`, on the RGB
/// channels, on a 0–1 scale (0 identical, 1 black vs white everywhere).
///
/// # Panics
/// If either image is not `width · height · 4` bytes.
// (`#[inline]` here and below: the bake calls these thousands of times; inline
// functions are compiled in the calling crate, so a debug build of the
// optimised bake tool runs them optimised too.)
#[must_use]
#[inline]
pub fn multiscale_rmse(a: &[u8], b: &[u8], width: u32, height: u32) -> f64 {
    let n = (width as usize) * (height as usize);
    assert_eq!(a.len(), n * 4, "image a has the wrong size");
    assert_eq!(b.len(), n * 4, "image b has the wrong size");
    multiscale_rmse_with::<3>(width, height, |i| {
        std::array::from_fn(|c| (f64::from(a[i * 4 + c]) - f64::from(b[i * 4 + c])) / 255.0)
    })
}

/// Spreads the low 16 bits of `v` to the even bits.
#[inline]
fn part1by1(v: u32) -> u32 {
    let mut x = v & 0xffff;
    x = (x | (x << 8)) & 0x00ff_00ff;
    x = (x | (x << 4)) & 0x0f0f_0f0f;
    x = (x | (x << 2)) & 0x3333_3333;
    (x | (x << 1)) & 0x5555_5555
}

/// Inverse of [`part1by1`].
#[inline]
fn compact1by1(v: u32) -> u32 {
    let mut x = v & 0x5555_5555;
    x = (x | (x >> 1)) & 0x3333_3333;
    x = (x | (x >> 2)) & 0x0f0f_0f0f;
    x = (x | (x >> 4)) & 0x00ff_00ff;
    (x | (x >> 8)) & 0xffff
}

/// Morton (z-curve) index of pixel (x, y).
#[must_use]
#[inline]
pub fn morton(x: u32, y: u32) -> u32 {
    part1by1(x) | (part1by1(y) << 1)
}

/// Multi-scale RMSE of a `C`-channel difference image given per pixel (row-major
/// index → difference per channel, each in [-1, 1]), in one z-curve pass.
///
/// # Panics
/// If a side exceeds 65,536 pixels.
#[must_use]
pub fn multiscale_rmse_with<const C: usize>(width: u32, height: u32, diff: impl Fn(usize) -> [f64; C]) -> f64 {
    if width == 0 || height == 0 {
        return 0.0;
    }
    assert!(width <= 1 << 16 && height <= 1 << 16, "image too large for the z-curve");
    let side = width.max(height).next_power_of_two();
    let levels = side.trailing_zeros() as usize + 1;
    // Per level: running sum of the present sub-block means and their count,
    // and the sum of squared block means and the block count.
    let mut acc = vec![([0.0f64; C], 0u32); levels];
    let mut sse = vec![0.0f64; levels];
    let mut blocks = vec![0u64; levels];
    let total = u64::from(side) * u64::from(side);
    let mut code: u64 = 0;
    while code < total {
        let x = compact1by1(code as u32);
        let y = compact1by1((code >> 1) as u32);
        if x >= width || y >= height {
            // Outside the image: skip the largest aligned block starting here. Its
            // corner (the block's smallest x and y) is outside, so all of it is.
            let mut span = 1u64;
            while code.is_multiple_of(span * 4) && span * 4 <= total {
                span *= 4;
            }
            let end = code + span;
            close_blocks(&mut acc, &mut sse, &mut blocks, end);
            code = end;
            continue;
        }
        let d = diff((y * width + x) as usize);
        let e = &mut acc[0];
        for (sum, v) in e.0.iter_mut().zip(d) {
            *sum += v;
        }
        e.1 += 1;
        close_blocks(&mut acc, &mut sse, &mut blocks, code + 1);
        code += 1;
    }
    (0..levels).map(|k| (sse[k] / (blocks[k].max(1) as f64 * C as f64)).sqrt()).sum::<f64>() / levels as f64
}

/// Closes the blocks that end at `end` (every level k with `end` a multiple of
/// 4^k): the level-k block mean is squared into that level's error and handed
/// to the parent level.
fn close_blocks<const C: usize>(acc: &mut [([f64; C], u32)], sse: &mut [f64], blocks: &mut [u64], end: u64) {
    let levels = acc.len();
    let mut k = 0;
    loop {
        let (sum, count) = acc[k];
        if count > 0 {
            let mean = sum.map(|v| v / f64::from(count));
            // Level 0 "blocks" are pixels: their sums are single values.
            sse[k] += mean.iter().map(|v| v * v).sum::<f64>();
            blocks[k] += 1;
            if k + 1 < levels {
                let p = &mut acc[k + 1];
                for (sum, v) in p.0.iter_mut().zip(mean) {
                    *sum += v;
                }
                p.1 += 1;
            }
        }
        acc[k] = ([0.0; C], 0);
        k += 1;
        if k >= levels || !end.is_multiple_of(1u64 << (2 * k)) {
            break;
        }
    }
}

/// The straightforward per-resolution computation (a box pyramid, halving each
/// side with `div_ceil`): the reference [`multiscale_rmse`] is tested against.
#[must_use]
pub fn multiscale_rmse_pyramid(a: &[u8], b: &[u8], width: u32, height: u32) -> f64 {
    let n = (width as usize) * (height as usize);
    assert_eq!(a.len(), n * 4, "image a has the wrong size");
    assert_eq!(b.len(), n * 4, "image b has the wrong size");
    if n == 0 {
        return 0.0;
    }
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

/// Whether an RGBA8 pixel is foliage: its green stands out over red and blue
/// by 8 levels or 12 % of the green, whichever is less, and at least 3 (shaded foliage is
/// dark, and the trees' own occlusion darkens it further; sky, ground and
/// haze are not green).
#[must_use]
pub fn is_foliage(p: &[u8]) -> bool {
    let margin = (f32::from(p[1]) * 0.12).clamp(3.0, 8.0);
    f32::from(p[1]) > f32::from(p[0]) + margin && f32::from(p[1]) > f32::from(p[2]) + margin
}

/// The agreement of two images' foliage masks ([`is_foliage`], RGBA8 of the
/// same size): intersection over union, and each image's foliage pixels.
/// Two images without foliage agree (1).
#[must_use]
pub fn foliage_iou(a: &[u8], b: &[u8]) -> (f64, usize, usize) {
    let (mut both, mut either, mut na, mut nb) = (0usize, 0usize, 0usize, 0usize);
    for (pa, pb) in a.chunks_exact(4).zip(b.chunks_exact(4)) {
        let (fa, fb) = (is_foliage(pa), is_foliage(pb));
        both += usize::from(fa && fb);
        either += usize::from(fa || fb);
        na += usize::from(fa);
        nb += usize::from(fb);
    }
    (if either == 0 { 1.0 } else { both as f64 / either as f64 }, na, nb)
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

    #[test]
    fn z_curve_equals_the_per_resolution_pyramid() {
        let mut seed = 12345u32;
        let mut next = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 24) as u8
        };
        for (w, h) in [(1, 1), (2, 2), (8, 8), (64, 64), (7, 5), (960 / 8, 540 / 8), (3, 17), (33, 1), (100, 37)] {
            let n = (w * h * 4) as usize;
            let a: Vec<u8> = (0..n).map(|_| next()).collect();
            let b: Vec<u8> = (0..n).map(|i| if i % 7 == 0 { next() } else { a[i] }).collect();
            let z = multiscale_rmse(&a, &b, w, h);
            let p = multiscale_rmse_pyramid(&a, &b, w, h);
            assert!((z - p).abs() < 1e-12, "{w}×{h}: z-curve {z} vs pyramid {p}");
            assert!(z > 0.0);
        }
    }

    #[test]
    fn morton_interleaves_bits() {
        assert_eq!(morton(0, 0), 0);
        assert_eq!(morton(1, 0), 1);
        assert_eq!(morton(0, 1), 2);
        assert_eq!(morton(3, 3), 15);
        assert_eq!(morton(4, 0), 16);
        for (x, y) in [(5, 9), (1000, 77), (65535, 1)] {
            let m = morton(x, y);
            assert_eq!((compact1by1(m), compact1by1(m >> 1)), (x, y));
        }
    }
}
