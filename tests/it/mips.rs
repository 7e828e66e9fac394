//! Alpha-aware mipmaps with equalisation (Eichner 2024, alg. 3.2): coverage and colour
//! must survive down-sampling, where naive box filtering loses both.

use sylva::render::mips::{alpha_aware_mips, alpha_coverage, naive_mips, srgb_to_linear, ColorEncoding};

/// A 128² leaf-card texture: scattered leaf ellipses (opaque green) on transparent
/// black, the way exporters store alpha-masked foliage.
fn leaf_texture(size: u32) -> Vec<u8> {
    let mut img = vec![0u8; (size * size * 4) as usize];
    let leaves =
        [(30.0, 40.0, 24.0, 10.0), (84.0, 30.0, 28.0, 12.0), (60.0, 85.0, 32.0, 14.0), (104.0, 104.0, 18.0, 9.0)];
    for y in 0..size {
        for x in 0..size {
            let (fx, fy) = (x as f32 + 0.5, y as f32 + 0.5);
            let inside = leaves.iter().any(|&(cx, cy, a, b)| {
                let (u, v) = ((fx - cx) / a, (fy - cy) / b);
                u * u + v * v <= 1.0
            });
            if inside {
                let i = ((y * size + x) * 4) as usize;
                img[i..i + 4].copy_from_slice(&[70, 140, 40, 255]);
            }
        }
    }
    img
}

/// Mean linear green of the covered texels (alpha-weighted); None when nothing is covered.
fn covered_green(layer: &[u8]) -> Option<f64> {
    let (mut sum, mut w) = (0.0f64, 0.0f64);
    for t in layer.chunks_exact(4) {
        let a = f64::from(t[3]) / 255.0;
        sum += f64::from(srgb_to_linear(t[1])) * a;
        w += a;
    }
    (w > 0.0).then(|| sum / w)
}

#[test]
fn coverage_stays_within_a_few_percent_down_to_8x8() {
    let size = 128;
    let tex = leaf_texture(size);
    let base = alpha_coverage(&tex, 0.5);
    assert!(base > 0.1 && base < 0.6, "fixture coverage {base}");
    let aware = alpha_aware_mips(&tex, &tex, size, ColorEncoding::Srgb, Some(0.5));
    let naive = naive_mips(&tex, size);
    assert_eq!(aware.len(), 8, "128 → 1 is 8 levels");
    for (k, level) in aware.iter().enumerate() {
        let side = size >> k;
        if side < 8 {
            break;
        }
        let c = alpha_coverage(level, 0.5);
        // One texel of quantisation at the small levels, plus 3 %.
        let tolerance = 0.03 + 1.0 / f64::from(side * side);
        assert!((c - base).abs() <= tolerance, "mip {k} ({side}²): coverage {c:.3} vs base {base:.3}");
        // Equalisation keeps fully opaque texels at every level (alg. 3.2).
        assert!(level.chunks_exact(4).any(|t| t[3] == 255), "mip {k} has no opaque texel");
    }
    // The test can fail: naive box filtering thins the smallest mips out.
    let naive_worst = naive[4..=6].iter().map(|l| (alpha_coverage(l, 0.5) - base).abs()).fold(0.0, f64::max);
    assert!(naive_worst > 0.1, "naive mips kept coverage within {naive_worst:.3} of {base:.3}: fixture too easy");
}

#[test]
fn colours_do_not_darken_at_edges() {
    let size = 128;
    let tex = leaf_texture(size);
    let aware = alpha_aware_mips(&tex, &tex, size, ColorEncoding::Srgb, Some(0.5));
    let naive = naive_mips(&tex, size);
    let g0 = covered_green(&tex).unwrap();
    for (k, level) in aware.iter().enumerate().skip(1) {
        // The 1×1 level may be fully transparent (coverage below the cutoff).
        let Some(g) = covered_green(level) else { continue };
        assert!((g - g0).abs() / g0 < 0.02, "mip {k}: covered green {g:.4} vs {g0:.4}");
    }
    // Naive averaging mixes in the black of transparent texels: darker fringes.
    let darkest_naive = naive.iter().skip(2).filter_map(|l| covered_green(l)).fold(f64::MAX, f64::min);
    assert!(darkest_naive < g0 * 0.9, "naive mips did not darken ({darkest_naive} vs {g0})");
}

#[test]
fn opaque_textures_are_plain_averages() {
    let size = 16;
    let tex: Vec<u8> = (0..size * size).flat_map(|i| [(i % 256) as u8, 100, 50, 255]).collect();
    let mips = alpha_aware_mips(&tex, &tex, size, ColorEncoding::Linear, None);
    assert_eq!(mips.len(), 5);
    assert!(mips.iter().all(|l| l.chunks_exact(4).all(|t| t[3] == 255 && t[1] == 100 && t[2] == 50)));
}
