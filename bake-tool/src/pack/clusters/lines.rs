//! Branch lines (Clasen et al. 2010, §3.2): a line skeleton from the branch mesh and its
//! agglomerative simplification.
//!
//! Skeleton: every connected branch part (a tube in generated trees) is cut
//! along its principal axis into a few segments through the centroids of its
//! vertex slices, with radii from the slices' spread; a part's base (its thicker
//! end) hangs from the nearest segment of a larger part.
//!
//! Simplification: two merges, *straighten* (a line and its continuation → one
//! line) and *combine* (two lines with the same parent → their weighted average),
//! weights initialised by volume and summed on merge. Each step samples random
//! mergeable pairs and applies the one whose result has the lowest image error
//! against the full skeleton: multi-scale RMSE of capsule coverage rendered
//! orthographically from three sides.

use glam::{DMat3, DVec3, Vec2, Vec3};
use rayon::prelude::*;
use sylva::format::cluster::Line;
use sylva::format::pack::MaterialKind;

use super::em::{outer, symmetric_eigen};
use super::leaves::connected_parts;
use super::Rng;
use crate::input::gltf_import::ImportedModel;

/// A line of the skeleton being simplified.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SkeletonLine {
    /// The capsule.
    pub line: Line,
    /// Parent line.
    pub parent: Option<usize>,
    /// Whether it starts at its parent's end (a continuation, mergeable by straighten).
    pub continuation: bool,
    /// Merge weight (volume of the lines it stands for).
    pub weight: f64,
}

/// The line skeleton of `model`'s branch parts.
#[must_use]
pub fn skeleton(model: &ImportedModel) -> Vec<SkeletonLine> {
    let (lo, hi) = model.bounds();
    let size = f64::from((hi - lo).max_element().max(1e-6));
    let parts = connected_parts(model, MaterialKind::Branch);
    // Per part: ordered nodes (position, radius), base first.
    let mut chains: Vec<(f64, Vec<(DVec3, f64)>)> = Vec::new();
    for part in &parts {
        let mut pts: Vec<DVec3> = part
            .iter()
            .flat_map(|&t| model.triangles[t].map(|i| model.vertices[i as usize].position.as_dvec3()))
            .collect();
        pts.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)).then(a.z.total_cmp(&b.z)));
        pts.dedup();
        if pts.len() < 3 {
            continue;
        }
        let mean = pts.iter().sum::<DVec3>() / pts.len() as f64;
        let cov = pts.iter().fold(DMat3::ZERO, |c, p| c + outer(*p - mean, *p - mean)) * (1.0 / pts.len() as f64);
        let (_, axes) = symmetric_eigen(cov);
        let axis = axes.x_axis;
        let ts: Vec<f64> = pts.iter().map(|p| (*p - mean).dot(axis)).collect();
        let (t0, t1) = ts.iter().fold((f64::MAX, f64::MIN), |(a, b), t| (a.min(*t), b.max(*t)));
        let length = t1 - t0;
        if length < size * 1e-4 {
            continue;
        }
        let perp = |p: DVec3, c: DVec3| {
            let d = p - c;
            (d - axis * d.dot(axis)).length()
        };
        let r_mean = pts.iter().map(|p| perp(*p, mean)).sum::<f64>() / pts.len() as f64;
        let segments = ((length / (4.0 * r_mean.max(length / 60.0))).round() as usize).clamp(1, 6);
        let half = length / (2.0 * segments as f64);
        let mut nodes = Vec::with_capacity(segments + 1);
        for k in 0..=segments {
            let tk = t0 + length * k as f64 / segments as f64;
            let near: Vec<DVec3> =
                pts.iter().zip(&ts).filter(|(_, t)| (**t - tk).abs() <= half * 1.01).map(|(p, _)| *p).collect();
            if near.is_empty() {
                continue;
            }
            let c = near.iter().sum::<DVec3>() / near.len() as f64;
            let c = c + axis * (tk - (c - mean).dot(axis));
            let r = near.iter().map(|p| perp(*p, c)).sum::<f64>() / near.len() as f64;
            nodes.push((c, r.max(size * 1e-4)));
        }
        if nodes.len() < 2 {
            continue;
        }
        if nodes[0].1 < nodes[nodes.len() - 1].1 {
            nodes.reverse();
        }
        let volume = std::f64::consts::PI * r_mean * r_mean * length;
        chains.push((volume, nodes));
    }
    chains.sort_by(|a, b| b.0.total_cmp(&a.0));
    if let Some((_, trunk)) = chains.first_mut() {
        // The trunk grows upwards.
        if trunk[0].0.z > trunk[trunk.len() - 1].0.z {
            trunk.reverse();
        }
    }
    let mut out: Vec<SkeletonLine> = Vec::new();
    for (_, nodes) in chains {
        let parent = nearest_line(&out, nodes[0].0);
        for (k, w) in nodes.windows(2).enumerate() {
            let (a, b) = (w[0], w[1]);
            let line = Line { a: a.0.as_vec3(), b: b.0.as_vec3(), radius_a: a.1 as f32, radius_b: b.1 as f32 };
            out.push(SkeletonLine {
                line,
                parent: if k == 0 { parent } else { Some(out.len() - 1) },
                continuation: k > 0,
                weight: line_volume(&line),
            });
        }
    }
    out
}

fn line_volume(l: &Line) -> f64 {
    let r = f64::from(l.radius_a + l.radius_b) * 0.5;
    std::f64::consts::PI * r * r * f64::from(l.a.distance(l.b))
}

fn segment_distance(p: DVec3, a: DVec3, b: DVec3) -> (f64, f64) {
    let ab = b - a;
    let t = ((p - a).dot(ab) / ab.length_squared().max(1e-30)).clamp(0.0, 1.0);
    ((a + ab * t).distance(p), t)
}

fn nearest_line(lines: &[SkeletonLine], p: DVec3) -> Option<usize> {
    lines
        .iter()
        .enumerate()
        .map(|(i, l)| (segment_distance(p, l.line.a.as_dvec3(), l.line.b.as_dvec3()).0, i))
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|x| x.1)
}

/// Orthographic coverage images of capsules from three sides (x–z, y–z, x–y).
#[derive(Clone)]
pub struct CoverageRaster {
    size: u32,
    lo: Vec3,
    scale: f32,
    counts: Vec<u16>,
}

const VIEWS: usize = 3;

impl CoverageRaster {
    /// Empty images of `size`² per view over the bounds `lo..hi`.
    #[must_use]
    pub fn new(size: u32, lo: Vec3, hi: Vec3) -> Self {
        let scale = size as f32 / (hi - lo).max_element().max(1e-6) * 0.999;
        Self { size, lo, scale, counts: vec![0; VIEWS * (size * size) as usize] }
    }

    fn project(&self, p: Vec3, view: usize) -> Vec2 {
        let q = (p - self.lo) * self.scale;
        match view {
            0 => Vec2::new(q.x, q.z),
            1 => Vec2::new(q.y, q.z),
            _ => Vec2::new(q.x, q.y),
        }
    }

    /// Adds (`add`) or removes a capsule's coverage.
    pub fn draw(&mut self, l: &Line, add: bool) {
        let n = self.size as i32;
        for v in 0..VIEWS {
            let (a, b) = (self.project(l.a, v), self.project(l.b, v));
            let (ra, rb) = (l.radius_a * self.scale, l.radius_b * self.scale);
            let r = ra.max(rb).max(0.5);
            let lo = (a.min(b) - Vec2::splat(r)).floor();
            let hi = (a.max(b) + Vec2::splat(r)).ceil();
            let ab = b - a;
            let len2 = ab.length_squared().max(1e-12);
            for y in (lo.y as i32).max(0)..(hi.y as i32).min(n) {
                for x in (lo.x as i32).max(0)..(hi.x as i32).min(n) {
                    let p = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                    let t = ((p - a).dot(ab) / len2).clamp(0.0, 1.0);
                    // At least half a pixel wide, like the renderer's minimum line width.
                    let rt = (ra + (rb - ra) * t).max(0.5);
                    if (a + ab * t).distance_squared(p) <= rt * rt {
                        let i = v * (n * n) as usize + (y * n + x) as usize;
                        if add {
                            self.counts[i] += 1;
                        } else {
                            self.counts[i] -= 1;
                        }
                    }
                }
            }
        }
    }

    /// Coverage (0 or 1) per pixel of all views.
    #[must_use]
    pub fn coverage(&self) -> Vec<f32> {
        self.counts.iter().map(|&c| f32::from(u8::from(c > 0))).collect()
    }

    /// Multi-scale RMSE of this coverage against `reference`, mean over the views.
    #[must_use]
    pub fn error(&self, reference: &[f32]) -> f64 {
        let px = (self.size * self.size) as usize;
        (0..VIEWS)
            .map(|v| {
                let base = v * px;
                sylva::metrics::multiscale_rmse_with::<1>(self.size, self.size, |i| {
                    [f64::from(f32::from(u8::from(self.counts[base + i] > 0)) - reference[base + i])]
                })
            })
            .sum::<f64>()
            / VIEWS as f64
    }
}

/// Knobs of [`simplify`].
#[derive(Debug, Clone, Copy)]
pub struct LineOptions {
    /// Candidate pairs judged per merge step.
    pub candidates: usize,
    /// Side of each coverage image.
    pub raster_px: u32,
    /// Seed.
    pub seed: u64,
}

impl Default for LineOptions {
    fn default() -> Self {
        Self { candidates: 8, raster_px: 96, seed: 3 }
    }
}

/// A simplified line level and its image error against the full skeleton.
#[derive(Debug, Clone)]
pub struct LineLevel {
    /// The lines.
    pub lines: Vec<Line>,
    /// Multi-scale RMSE of its coverage against the full skeleton's (0–1).
    pub error: f64,
}

#[derive(Debug, Clone, Copy)]
enum Merge {
    Straighten(usize, usize),
    Combine(usize, usize),
}

fn merged(lines: &[SkeletonLine], m: Merge) -> SkeletonLine {
    match m {
        Merge::Straighten(a, b) => {
            let (x, y) = (lines[a], lines[b]);
            SkeletonLine {
                line: Line { a: x.line.a, b: y.line.b, radius_a: x.line.radius_a, radius_b: y.line.radius_b },
                parent: x.parent,
                continuation: x.continuation,
                weight: x.weight + y.weight,
            }
        }
        Merge::Combine(a, b) => {
            let (x, y) = (lines[a], lines[b]);
            let w = x.weight + y.weight;
            let (fx, fy) = ((x.weight / w) as f32, (y.weight / w) as f32);
            SkeletonLine {
                line: Line {
                    a: x.line.a * fx + y.line.a * fy,
                    b: x.line.b * fx + y.line.b * fy,
                    radius_a: x.line.radius_a * fx + y.line.radius_a * fy,
                    radius_b: x.line.radius_b * fx + y.line.radius_b * fy,
                },
                parent: x.parent,
                continuation: x.continuation || y.continuation,
                weight: w,
            }
        }
    }
}

/// Simplifies `skeleton` by merges until each of `targets` (line counts, descending)
/// is reached, returning one level per target (the full skeleton when a target
/// is at least its size).
#[must_use]
pub fn simplify(
    skeleton: &[SkeletonLine],
    targets: &[usize],
    bounds: (Vec3, Vec3),
    opts: &LineOptions,
) -> Vec<LineLevel> {
    let mut lines: Vec<SkeletonLine> = skeleton.to_vec();
    let mut alive = vec![true; lines.len()];
    let mut count = lines.len();
    let mut raster = CoverageRaster::new(opts.raster_px, bounds.0, bounds.1);
    for l in &lines {
        raster.draw(&l.line, true);
    }
    let reference = raster.coverage();
    let mut rng = Rng::new(opts.seed);
    let mut out = Vec::with_capacity(targets.len());
    let snapshot = |lines: &[SkeletonLine], alive: &[bool], raster: &CoverageRaster| LineLevel {
        lines: lines.iter().zip(alive).filter(|(_, a)| **a).map(|(l, _)| l.line).collect(),
        error: raster.error(&reference),
    };
    for &target in targets {
        while count > target.max(1) {
            let live: Vec<usize> = (0..lines.len()).filter(|&i| alive[i]).collect();
            // Sample mergeable pairs.
            let mut cands: Vec<Merge> = Vec::new();
            for _ in 0..opts.candidates * 8 {
                if cands.len() >= opts.candidates {
                    break;
                }
                let x = live[rng.below(live.len())];
                if rng.below(2) == 0 {
                    let kids: Vec<usize> =
                        live.iter().copied().filter(|&c| lines[c].parent == Some(x) && lines[c].continuation).collect();
                    if !kids.is_empty() {
                        cands.push(Merge::Straighten(x, kids[rng.below(kids.len())]));
                    }
                } else if let Some(p) = lines[x].parent {
                    let sibs: Vec<usize> =
                        live.iter().copied().filter(|&c| c != x && lines[c].parent == Some(p)).collect();
                    if !sibs.is_empty() {
                        cands.push(Merge::Combine(x, sibs[rng.below(sibs.len())]));
                    }
                }
            }
            if cands.is_empty() {
                // Forests of roots (no shared parent, no continuation): combine any two roots.
                let roots: Vec<usize> = live.iter().copied().filter(|&c| lines[c].parent.is_none()).collect();
                if roots.len() >= 2 {
                    cands.push(Merge::Combine(roots[0], roots[1]));
                } else {
                    // Only children of dead ends remain: straighten any line into its parent.
                    let c = live
                        .iter()
                        .copied()
                        .find(|&c| lines[c].parent.is_some())
                        .expect("a tree of ≥ 2 lines has a child");
                    cands.push(Merge::Straighten(lines[c].parent.expect("has a parent"), c));
                }
            }
            // Judge each candidate on its own copy of the raster.
            let judged: Vec<(f64, Merge)> = cands
                .par_iter()
                .map(|&m| {
                    let (a, b) = match m {
                        Merge::Straighten(a, b) | Merge::Combine(a, b) => (a, b),
                    };
                    let mut r = raster.clone();
                    r.draw(&lines[a].line, false);
                    r.draw(&lines[b].line, false);
                    r.draw(&merged(&lines, m).line, true);
                    (r.error(&reference), m)
                })
                .collect();
            let (_, best) = judged.into_iter().min_by(|x, y| x.0.total_cmp(&y.0)).expect("at least one candidate");
            let (a, b) = match best {
                Merge::Straighten(a, b) | Merge::Combine(a, b) => (a, b),
            };
            let m = merged(&lines, best);
            raster.draw(&lines[a].line, false);
            raster.draw(&lines[b].line, false);
            raster.draw(&m.line, true);
            lines[a] = m;
            alive[b] = false;
            for l in &mut lines {
                if l.parent == Some(b) {
                    l.parent = Some(a);
                }
            }
            count -= 1;
        }
        out.push(snapshot(&lines, &alive, &raster));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn branchy() -> Vec<SkeletonLine> {
        // A trunk of 3 segments with 6 side branches of 2 segments.
        let mut out = Vec::new();
        let push = |a: Vec3, b: Vec3, r: f32, parent: Option<usize>, cont: bool, out: &mut Vec<SkeletonLine>| {
            let line = Line { a, b, radius_a: r, radius_b: r * 0.8 };
            out.push(SkeletonLine { line, parent, continuation: cont, weight: line_volume(&line) });
            out.len() - 1
        };
        let mut prev = None;
        for k in 0..3 {
            let z = k as f32 * 3.0;
            prev = Some(push(Vec3::new(0.0, 0.0, z), Vec3::new(0.0, 0.0, z + 3.0), 0.4, prev, k > 0, &mut out));
        }
        for s in 0..6 {
            let parent = Some(s / 2);
            let z = s as f32 * 1.5 + 0.5;
            let dir = Vec3::new((s as f32).cos(), (s as f32).sin(), 0.5).normalize();
            let a = Vec3::new(0.0, 0.0, z);
            let m = push(a, a + dir * 2.0, 0.15, parent, false, &mut out);
            push(a + dir * 2.0, a + dir * 4.0, 0.1, Some(m), true, &mut out);
        }
        out
    }

    #[test]
    fn simplification_reaches_every_target_and_error_grows() {
        let sk = branchy();
        assert_eq!(sk.len(), 15);
        let bounds = (Vec3::new(-5.0, -5.0, 0.0), Vec3::new(5.0, 5.0, 10.0));
        let levels = simplify(&sk, &[15, 8, 3, 1], bounds, &LineOptions::default());
        assert_eq!(levels.iter().map(|l| l.lines.len()).collect::<Vec<_>>(), vec![15, 8, 3, 1]);
        assert_eq!(levels[0].error, 0.0);
        for w in levels.windows(2) {
            assert!(w[1].error >= w[0].error - 1e-9, "{} then {}", w[0].error, w[1].error);
        }
        assert!(levels[3].error > 0.0 && levels[3].error < 0.5);
        for l in levels.iter().flat_map(|l| &l.lines) {
            assert!(l.a.is_finite() && l.b.is_finite() && l.radius_a > 0.0 && l.radius_b > 0.0);
        }
    }

    #[test]
    fn raster_add_remove_is_exact() {
        let mut r = CoverageRaster::new(32, Vec3::ZERO, Vec3::splat(10.0));
        let l = Line { a: Vec3::new(1.0, 1.0, 1.0), b: Vec3::new(8.0, 5.0, 9.0), radius_a: 0.5, radius_b: 0.2 };
        let empty = r.coverage();
        r.draw(&l, true);
        assert!(r.coverage().iter().sum::<f32>() > 20.0);
        assert!(r.error(&empty) > 0.0);
        r.draw(&l, false);
        assert_eq!(r.error(&empty), 0.0);
    }
}
