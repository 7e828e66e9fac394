//! The ellipsoid cluster hierarchy (Clasen et al. 2010, §3.1, alg. 1): for n = leaves/4,
//! leaves/16, … down to 1 cluster, run EM from several random starts, turn each
//! result's fuzzy assignments into ellipsoids by weighted PCA, drop the tiny
//! ones, calibrate their size, and keep the start whose image error against the
//! full mesh is lowest. The noise threshold is then calibrated the same way.

use glam::{DMat3, DVec3, Quat, Vec3};
use sylva::format::cluster::{ClusterLevelMeta, Ellipsoid, Line};

use super::em::{self, outer, EmOptions};
use super::leaves::Leaf;
use super::Rng;

/// Projected width (px) of a level's median ellipsoid when the level is selected (Clasen et al. 2010, §6).
pub const ELLIPSOID_TARGET_PX: f32 = 5.0;

/// Something that measures how a cluster level looks against the full tree.
pub trait Judge {
    /// Multi-scale RMSE (0–1) of `level` drawn at a tree height of `size_px`
    /// pixels against the full mesh at the same size.
    fn error(&mut self, level: &Candidate<'_>) -> f64;
}

/// A level to judge.
#[derive(Debug, Clone, Copy)]
pub struct Candidate<'a> {
    /// Ellipsoids.
    pub ellipsoids: &'a [Ellipsoid],
    /// Lines drawn with them.
    pub lines: &'a [Line],
    /// Alpha-noise threshold.
    pub noise_threshold: f32,
    /// Normal-noise blend.
    pub normal_blend: f32,
    /// Tree height in pixels.
    pub size_px: u32,
}

/// Knobs of [`build_levels`].
#[derive(Debug, Clone)]
pub struct HierarchyOptions {
    /// EM starts per level (the paper: more than 4 did not help).
    pub tries: usize,
    /// Seed of the random starts.
    pub seed: u64,
    /// Size factors tried by the calibration (× the PCA radii).
    pub scales: Vec<f32>,
    /// Noise thresholds tried (besides 0).
    pub thresholds: Vec<f32>,
    /// Normal-noise blends tried per level (the first is used while calibrating size and threshold).
    pub normal_blends: Vec<f32>,
    /// Size factors tried for the single-leaf ellipsoids.
    pub leaf_scales: Vec<f32>,
    /// EM settings.
    pub em: EmOptions,
    /// Render size bounds of the calibration images (px).
    pub min_size_px: u32,
    /// See `min_size_px`.
    pub max_size_px: u32,
}

impl Default for HierarchyOptions {
    fn default() -> Self {
        Self {
            tries: 4,
            seed: 1,
            scales: vec![0.55, 0.7, 0.85, 1.0, 1.2],
            thresholds: vec![0.25, 0.4],
            normal_blends: vec![0.35, 0.0, 0.7],
            leaf_scales: vec![0.6, 0.8, 1.0, 1.25],
            em: EmOptions::default(),
            min_size_px: 48,
            max_size_px: 192,
        }
    }
}

/// A finished level.
#[derive(Debug, Clone)]
pub struct BuiltLevel {
    /// Its ellipsoids (calibrated radii).
    pub ellipsoids: Vec<Ellipsoid>,
    /// Metadata (count, select_px, error, noise).
    pub meta: ClusterLevelMeta,
}

/// Cluster counts per level: n/4, n/16, … ending with 1.
#[must_use]
pub fn level_sizes(leaves: usize) -> Vec<usize> {
    let mut out = Vec::new();
    let mut n = leaves / 4;
    while n > 1 {
        out.push(n);
        n /= 4;
    }
    if leaves > 0 {
        out.push(1);
    }
    out
}

/// Surface area of an ellipsoid (Knud Thomsen's approximation, ≤ 1.1 % off).
#[must_use]
pub fn ellipsoid_area(r: Vec3) -> f32 {
    const P: f32 = 1.6075;
    let (a, b, c) = (r.x.powf(P), r.y.powf(P), r.z.powf(P));
    4.0 * std::f32::consts::PI * ((a * b + a * c + b * c) / 3.0).powf(1.0 / P)
}

/// Ellipsoid of a covariance: axes by PCA, semi-axes √5 σ (a solid ellipsoid's
/// variance is r²/5), the thinnest kept ≥ 5 % of the widest.
#[must_use]
pub fn ellipsoid_from_moments(center: DVec3, covariance: DMat3, color: Vec3, noise_level: f32) -> Ellipsoid {
    let (vals, vecs) = em::symmetric_eigen(covariance);
    let r = vals.max(DVec3::ZERO).map(|v| (5.0 * v).sqrt()).as_vec3();
    let widest = r.x.max(1e-6);
    let radii = r.max(Vec3::splat(widest * 0.05));
    let rotation = Quat::from_mat3(&vecs.as_mat3()).normalize();
    Ellipsoid { center: center.as_vec3(), rotation, radii, color, noise_level }
}

/// Weighted PCA of the leaves per component (Fig. 5): mean and covariance of the
/// leaf centres weighted by w_ij, plus each leaf's own extent.
#[must_use]
pub fn weighted_pca(leaves: &[Leaf], responsibilities: &[Vec<(u32, f32)>], components: usize) -> Vec<Ellipsoid> {
    let mut acc = vec![(0.0f64, DVec3::ZERO, DMat3::ZERO, Vec3::ZERO); components];
    for (leaf, r) in leaves.iter().zip(responsibilities) {
        for &(j, w) in r {
            let w = f64::from(w);
            let a = &mut acc[j as usize];
            a.0 += w;
            a.1 += leaf.center * w;
            a.2 += (outer(leaf.center, leaf.center) + leaf.covariance) * w;
            a.3 += leaf.color * w as f32;
        }
    }
    acc.into_iter()
        .filter(|a| a.0 > 1e-6)
        .map(|(w, s1, s2, col)| {
            let m = s1 / w;
            let cov = s2 * (1.0 / w) - outer(m, m);
            // l_j = 0.5 (1 + log2 Σ_i w_ij): the noise features ≈ the leaves it stands for.
            let level = (0.5 * (1.0 + w.max(1.0).log2())) as f32;
            ellipsoid_from_moments(m, cov, col / w as f32, level)
        })
        .collect()
}

/// Drops ellipsoids whose area is under 1 % of the largest (§3.1).
#[must_use]
pub fn drop_tiny(mut e: Vec<Ellipsoid>) -> Vec<Ellipsoid> {
    let largest = e.iter().map(|x| ellipsoid_area(x.radii)).fold(0.0f32, f32::max);
    e.retain(|x| ellipsoid_area(x.radii) >= 0.01 * largest);
    e
}

fn scaled(e: &[Ellipsoid], s: f32) -> Vec<Ellipsoid> {
    e.iter().map(|x| Ellipsoid { radii: x.radii * s, ..*x }).collect()
}

/// Median ellipsoid width 2√(r₁r₂) (m at scale 1).
#[must_use]
pub fn median_width(e: &[Ellipsoid]) -> f32 {
    let mut w: Vec<f32> = e.iter().map(|x| 2.0 * (x.radii.x * x.radii.y).sqrt()).collect();
    if w.is_empty() {
        return 0.0;
    }
    w.sort_by(f32::total_cmp);
    w[w.len() / 2]
}

/// Builds every level. `lines[k]` is drawn with level k while judging (the last
/// line level for levels beyond it). `progress(level, levels)` is called per level.
pub fn build_levels(
    leaves: &[Leaf],
    height_m: f32,
    lines: &[Vec<Line>],
    judge: &mut dyn Judge,
    opts: &HierarchyOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Vec<BuiltLevel> {
    if leaves.is_empty() {
        return Vec::new();
    }
    let empty: Vec<Line> = Vec::new();
    let blend = opts.normal_blends.first().copied().unwrap_or(0.0);
    // First the leaves as single ellipsoids, sized so they cover what the leaves
    // cover (§3.1); the calibrated extents feed every level's weighted PCA.
    let leaf_scale = {
        let base: Vec<Ellipsoid> =
            leaves.iter().map(|l| ellipsoid_from_moments(l.center, l.covariance, l.color, 0.0)).collect();
        let size_px = opts.max_size_px;
        let mut best = (f64::INFINITY, 1.0f32);
        for &s in &opts.leaf_scales {
            let e = scaled(&base, s);
            let lines = lines.first().unwrap_or(&empty);
            let c = Candidate { ellipsoids: &e, lines, noise_threshold: 0.0, normal_blend: blend, size_px };
            let err = judge.error(&c);
            if err < best.0 {
                best = (err, s);
            }
        }
        best.1
    };
    let scaled_leaves: Vec<Leaf> =
        leaves.iter().map(|l| Leaf { covariance: l.covariance * f64::from(leaf_scale * leaf_scale), ..*l }).collect();
    let leaves = &scaled_leaves[..];
    let points: Vec<DVec3> = leaves.iter().map(|l| l.center).collect();
    let sizes = level_sizes(leaves.len());
    let mut rng = Rng::new(opts.seed);
    let mut out = Vec::with_capacity(sizes.len());
    for (k, &n) in sizes.iter().enumerate() {
        progress(k, sizes.len());
        let level_lines = lines.get(k).or(lines.last()).unwrap_or(&empty);
        // (error, −log-likelihood as the tie-breaker, ellipsoids, threshold, size).
        let mut best: Option<(f64, f64, Vec<Ellipsoid>, f32, u32)> = None;
        for _ in 0..opts.tries.max(1) {
            // Random starts: distinct random leaves (the paper draws random points
            // in the box; starting on the data never leaves a component empty).
            let init: Vec<DVec3> = if n == 1 {
                vec![points.iter().sum::<DVec3>() / points.len() as f64]
            } else {
                let mut idx: Vec<usize> = (0..points.len()).collect();
                for i in 0..n {
                    let j = i + rng.below(idx.len() - i);
                    idx.swap(i, j);
                }
                idx[..n].iter().map(|&i| points[i]).collect()
            };
            let mixture = em::fit(&points, &init, &opts.em);
            let base = drop_tiny(weighted_pca(leaves, &mixture.responsibilities, mixture.means.len()));
            let width = median_width(&base);
            let size_px = calibration_size(height_m, width, opts);
            for &s in &opts.scales {
                let e = scaled(&base, s);
                let err = judge.error(&Candidate {
                    ellipsoids: &e,
                    lines: level_lines,
                    noise_threshold: 0.0,
                    normal_blend: blend,
                    size_px,
                });
                let key = (err, -mixture.log_likelihood);
                if best.as_ref().is_none_or(|b| key < (b.0, b.1)) {
                    best = Some((err, key.1, e, 0.0, size_px));
                }
            }
            if n == 1 {
                break; // one start is enough for one cluster
            }
        }
        let (mut err, _, mut ell, mut threshold, size_px) = best.expect("at least one start");
        // Noise: threshold t with a larger size compensating the holes (§3.1, Fig. 6).
        let base = ell.clone();
        for &t in &opts.thresholds {
            for s in [1.0, 1.12, 1.25] {
                let e = scaled(&base, s);
                let candidate =
                    Candidate { ellipsoids: &e, lines: level_lines, noise_threshold: t, normal_blend: blend, size_px };
                let x = judge.error(&candidate);
                if x < err {
                    (err, ell, threshold) = (x, e, t);
                }
            }
        }
        // Then the normal noise's blend, the same way.
        let mut normal_blend = blend;
        for &b in opts.normal_blends.iter().skip(1) {
            let candidate = Candidate {
                ellipsoids: &ell,
                lines: level_lines,
                noise_threshold: threshold,
                normal_blend: b,
                size_px,
            };
            let x = judge.error(&candidate);
            if x < err {
                (err, normal_blend) = (x, b);
            }
        }
        let width = median_width(&ell).max(1e-6);
        out.push(BuiltLevel {
            meta: ClusterLevelMeta {
                count: ell.len() as u32,
                select_px: ELLIPSOID_TARGET_PX * height_m / width,
                error: err as f32,
                noise_threshold: threshold,
                normal_blend,
                pareto_error: None,
                pareto_cost: None,
            },
            ellipsoids: ell,
        });
    }
    progress(sizes.len(), sizes.len());
    out
}

/// Tree height (px) at which a level with median ellipsoid width `width` is
/// selected, clamped to the calibration image bounds.
fn calibration_size(height_m: f32, width: f32, opts: &HierarchyOptions) -> u32 {
    let px = ELLIPSOID_TARGET_PX * height_m / width.max(1e-6);
    (px.round() as u32).clamp(opts.min_size_px, opts.max_size_px)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pack::clusters::Rng;

    #[test]
    fn level_sizes_quarter_down_to_one() {
        assert_eq!(level_sizes(2660), vec![665, 166, 41, 10, 2, 1]);
        assert_eq!(level_sizes(3), vec![1]);
        assert_eq!(level_sizes(1), vec![1]);
        assert!(level_sizes(0).is_empty());
    }

    #[test]
    fn weighted_pca_of_a_known_point_set() {
        // Points on a 3D cross: ±3 along a rotated x, ±1 along y, 0 along z.
        let r = DMat3::from_rotation_z(0.5);
        let mut leaves = Vec::new();
        for p in [DVec3::X * 3.0, -DVec3::X * 3.0, DVec3::Y, -DVec3::Y] {
            leaves.push(Leaf { center: r * p, covariance: DMat3::ZERO, area: 1.0, color: Vec3::ONE });
        }
        let resp = vec![vec![(0u32, 1.0f32)]; 4];
        let e = weighted_pca(&leaves, &resp, 1);
        assert_eq!(e.len(), 1);
        let e = e[0];
        // Variances 4.5 and 0.5 → semi-axes √(5·4.5), √(5·0.5).
        assert!((e.radii.x - (22.5f32).sqrt()).abs() < 1e-4, "{:?}", e.radii);
        assert!((e.radii.y - (2.5f32).sqrt()).abs() < 1e-4);
        assert!((e.radii.z - e.radii.x * 0.05).abs() < 1e-4, "flat clamped to 5 %");
        let axis = e.rotation * Vec3::X;
        assert!(axis.dot((r * DVec3::X).as_vec3()).abs() > 0.9999, "{axis:?}");
        // Half the weight on the right point halves its pull.
        let resp = vec![vec![(0u32, 0.5f32)], vec![(0, 1.0)], vec![(0, 1.0)], vec![(0, 1.0)]];
        let e = weighted_pca(&leaves, &resp, 1)[0];
        assert!(e.center.dot((r * DVec3::X).as_vec3()) < -0.3);
    }

    /// A CPU stand-in for the GPU judge: prefers a known total ellipsoid volume.
    struct VolumeJudge(f32);

    impl Judge for VolumeJudge {
        fn error(&mut self, c: &Candidate<'_>) -> f64 {
            let v: f32 = c.ellipsoids.iter().map(|e| e.radii.x * e.radii.y * e.radii.z).sum();
            f64::from((v * (1.0 - c.noise_threshold) - self.0).abs())
        }
    }

    fn leaf(center: DVec3) -> Leaf {
        let cov = DMat3::from_diagonal(DVec3::new(0.01, 0.01, 0.0));
        Leaf { center, covariance: cov, area: 0.1, color: Vec3::new(0.1, 0.4, 0.1) }
    }

    fn check(levels: &[BuiltLevel], leaves: usize) {
        assert_eq!(levels.len(), level_sizes(leaves).len());
        assert_eq!(levels.last().map(|l| l.ellipsoids.len()), Some(1), "ends with one cluster");
        for l in levels {
            assert!(!l.ellipsoids.is_empty());
            assert!(l.meta.select_px.is_finite() && l.meta.select_px > 0.0 && l.meta.error.is_finite());
            for e in &l.ellipsoids {
                assert!(e.center.is_finite() && e.radii.is_finite() && e.rotation.is_finite(), "{e:?}");
                assert!(e.radii.min_element() > 0.0 && e.noise_level.is_finite());
                assert!((e.rotation.length() - 1.0).abs() < 1e-3);
            }
        }
    }

    #[test]
    fn degenerate_leaf_sets_give_valid_ellipsoids() {
        let opts = HierarchyOptions { tries: 2, ..Default::default() };
        let cases: Vec<(&str, Vec<Leaf>)> = vec![
            ("single leaf", vec![leaf(DVec3::new(1.0, 2.0, 3.0))]),
            ("duplicates", vec![leaf(DVec3::splat(2.0)); 64]),
            ("collinear", (0..200).map(|i| leaf(DVec3::new(f64::from(i) * 0.1, 0.0, 5.0))).collect()),
            ("coplanar", (0..400).map(|i| leaf(DVec3::new(f64::from(i % 20), f64::from(i / 20), 7.0))).collect()),
        ];
        for (name, leaves) in cases {
            let levels = build_levels(&leaves, 10.0, &[], &mut VolumeJudge(1.0), &opts, &mut |_, _| {});
            check(&levels, leaves.len());
            println!("{name}: {:?}", levels.iter().map(|l| l.ellipsoids.len()).collect::<Vec<_>>());
        }
    }

    #[test]
    fn a_hundred_thousand_leaves() {
        let mut rng = Rng::new(5);
        // Clumps in a crown, like a big tree.
        let clumps: Vec<DVec3> = (0..300)
            .map(|_| DVec3::new(rng.f64() * 20.0 - 10.0, rng.f64() * 20.0 - 10.0, 8.0 + rng.f64() * 15.0))
            .collect();
        let leaves: Vec<Leaf> = (0..100_000)
            .map(|i| {
                let c = clumps[i % clumps.len()];
                leaf(c + DVec3::new(rng.f64() - 0.5, rng.f64() - 0.5, rng.f64() - 0.5) * 1.5)
            })
            .collect();
        let opts = HierarchyOptions {
            tries: 1,
            scales: vec![1.0],
            thresholds: vec![],
            normal_blends: vec![0.35],
            leaf_scales: vec![1.0],
            ..Default::default()
        };
        let levels = build_levels(&leaves, 25.0, &[], &mut VolumeJudge(50.0), &opts, &mut |_, _| {});
        check(&levels, leaves.len());
        assert!(levels[0].ellipsoids.len() > 20_000, "{}", levels[0].ellipsoids.len());
    }

    #[test]
    fn tiny_ellipsoids_are_dropped() {
        let mk = |r: f32| Ellipsoid {
            center: Vec3::ZERO,
            rotation: Quat::IDENTITY,
            radii: Vec3::splat(r),
            color: Vec3::ONE,
            noise_level: 0.0,
        };
        let kept = drop_tiny(vec![mk(1.0), mk(0.2), mk(0.05)]);
        assert_eq!(kept.len(), 2, "0.05² = 0.25 % of the area");
        assert!((ellipsoid_area(Vec3::ONE) - 4.0 * std::f32::consts::PI).abs() < 1e-3);
    }
}
