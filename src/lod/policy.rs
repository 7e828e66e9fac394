//! The bake's LoD policy: which representation of a species is the
//! default at a size, chosen from the measured front of error against time.
//!
//! At bake time each candidate (a cluster level, the billboard cloud, a
//! simplified mesh level) and the far tier are rendered by the viewer's own
//! pipelines at the candidate's entry size (a cluster level and the cloud also
//! at the top of their band; the losing measurement is stored): the error is their multi-scale
//! RMSE against the full mesh, the time a model of the GPU time of drawing one
//! tree from the work the draw did (vertex and fragment shader invocations,
//! counted by a pipeline-statistics query) times per-invocation costs measured
//! on the reference device ([`COSTS`]). A timer would make bakes differ from
//! run to run (and a sharded bake from a single one); the counts do not on one
//! kind of device (another GPU may count helper invocations or vertex reuse
//! differently; a device without pipeline statistics stores no cost).
//!
//! The rule: the default is the representation with the smaller
//! `error × time^ALPHA`, `ALPHA = log2(1.1)`: a representation that costs twice
//! as much per tree must be at least 10 % more faithful (ten times as much:
//! 27 %); one that costs half as much may be up to 10 % less faithful. Where no
//! time was measured (a device without pipeline statistics, older packs), the
//! far tier is taken as half the cost.

use crate::format::cluster::ClusterLevelMeta;

/// Exponent of time in the policy's score `error × time^ALPHA`: `log2(1.1)`.
pub const ALPHA: f32 = 0.137_503_52;

/// What kind of draw a work count is from (their shaders differ in cost).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CostKind {
    /// A mesh level (alpha-tested leaves).
    Mesh,
    /// The billboard cloud (a list walk per fragment).
    Cloud,
    /// A cluster level (ray-cast ellipsoids and lines).
    Cluster,
    /// View-angle billboards (one texture fetch per fragment).
    Billboard,
    /// Multi-view impostors (three views with parallax per fragment).
    Impostor,
}

/// Per-invocation costs (ns per vertex, ns per fragment) of each kind on the
/// reference device: lavapipe (Mesa's CPU Vulkan) on 2 cores, fitted to wall
/// times of single-tree draws from 16 to 512 px of the Amsterdam (ez-tree) oak and pine
/// and the demo trees (`SYLVA_POLICY_CALIBRATE=1 sylva-bake …`, see
/// docs/BENCHMARKS.md, "Time in the policy"). Only their ratios matter to the
/// rule.
pub const COSTS: [(CostKind, f32, f32); 5] = [
    (CostKind::Mesh, 100.0, 35.0),
    (CostKind::Cloud, 100.0, 83.0),
    (CostKind::Cluster, 370.0, 45.0),
    (CostKind::Billboard, 0.0, 26.0),
    (CostKind::Impostor, 0.0, 92.0),
];

/// Modelled GPU time (µs) of a draw of `kind` that ran `vertices` vertex and
/// `fragments` fragment shader invocations.
#[must_use]
pub fn modelled_us(kind: CostKind, vertices: u64, fragments: u64) -> f32 {
    let (_, v, f) = COSTS.iter().find(|c| c.0 == kind).copied().unwrap_or((kind, 0.0, 0.0));
    ((vertices as f64 * f64::from(v) + fragments as f64 * f64::from(f)) * 1e-3) as f32
}

/// Whether the policy prefers a representation measured `error = [own, far]`,
/// `cost = [own, far]` (µs per tree) over the far tier at its entry size (see
/// the module's rule); `unmeasured` when there is no error measurement.
#[must_use]
pub fn policy_keeps(error: Option<[f32; 2]>, cost: Option<[f32; 2]>, unmeasured: bool) -> bool {
    let Some([own, far]) = error else { return unmeasured };
    let ratio = match cost {
        // (At most tenfold either way: a pack's numbers cannot force a decision.)
        Some([own_t, far_t]) if own_t > 0.0 && far_t > 0.0 => (own_t / far_t).clamp(0.1, 10.0),
        _ => 2.0,
    };
    own * ratio.powf(ALPHA) < far
}

/// The smallest projected height (px) from which the policy keeps cluster
/// levels below `mesh_floor`: levels are walked finest first, and the band
/// ends above the first level it drops (the far tier takes over there).
/// `mesh_floor` when it keeps none.
#[must_use]
pub fn policy_floor<'a>(levels: impl Iterator<Item = &'a ClusterLevelMeta>, mesh_floor: f32) -> f32 {
    let mut floor = mesh_floor;
    for l in levels {
        if l.select_px >= mesh_floor {
            continue;
        }
        if !policy_keeps(l.pareto_error, l.pareto_cost, true) {
            break;
        }
        floor = l.select_px;
    }
    floor
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rule_trades_error_for_time() {
        // Twice the cost: needs 10 % less error.
        assert!(policy_keeps(Some([0.0270, 0.03]), Some([2.0, 1.0]), false));
        assert!(!policy_keeps(Some([0.0275, 0.03]), Some([2.0, 1.0]), true));
        // Ten times the cost: 27 %.
        assert!(!policy_keeps(Some([0.023, 0.03]), Some([10.0, 1.0]), true));
        assert!(policy_keeps(Some([0.0215, 0.03]), Some([10.0, 1.0]), false));
        // Half the cost: may be slightly worse.
        assert!(policy_keeps(Some([0.032, 0.03]), Some([1.0, 2.0]), false));
        assert!(!policy_keeps(Some([0.034, 0.03]), Some([1.0, 2.0]), true));
        // Without a time: as if twice the cost; without an error: `unmeasured`.
        assert!(!policy_keeps(Some([0.0275, 0.03]), None, true));
        assert!(policy_keeps(Some([0.0270, 0.03]), None, false));
        assert!(policy_keeps(None, None, true) && !policy_keeps(None, Some([1.0, 1.0]), false));
        // Hostile numbers decide nothing by themselves.
        assert!(!policy_keeps(Some([0.05, 0.03]), Some([1e-30, 1e30]), true));
        assert!(!policy_keeps(Some([0.05, 0.03]), Some([f32::NAN, 1.0]), true));
    }

    #[test]
    fn the_model_weighs_each_kind_by_its_shader() {
        // 1000 impostor fragments cost more than 1000 billboard fragments.
        assert!(modelled_us(CostKind::Impostor, 6, 1000) > 3.0 * modelled_us(CostKind::Billboard, 6, 1000));
        // Vertices count for meshes and clusters.
        assert!(modelled_us(CostKind::Mesh, 10_000, 0) > 0.9);
        assert!((modelled_us(CostKind::Mesh, 0, 1000) - 35.0).abs() < 1e-3);
    }

    #[test]
    fn the_lod_policy_keeps_levels_only_where_they_beat_the_far_tier() {
        let level = |select_px: f32, e: Option<[f32; 2]>| ClusterLevelMeta {
            count: 1,
            select_px,
            error: 0.0,
            noise_threshold: 0.0,
            normal_blend: 0.0,
            pareto_error: e,
            pareto_cost: None,
        };
        // Finest first: 400 px is above the mesh floor (ignored), 100 and 60
        // beat the far tier, 30 does not: clusters from 60 px; below, the far tier.
        let levels = [
            level(400.0, Some([0.05, 0.01])),
            level(100.0, Some([0.01, 0.02])),
            level(60.0, Some([0.02, 0.03])),
            level(30.0, Some([0.04, 0.03])),
            level(15.0, Some([0.01, 0.03])),
        ];
        assert_eq!(policy_floor(levels.iter(), 120.0), 60.0);
        // The first level in the band dropped: none (the floor stays the mesh's).
        assert_eq!(policy_floor(levels[3..].iter(), 120.0), 120.0);
        // Unmeasured (older packs): every level.
        let old = [level(100.0, None), level(30.0, None)];
        assert_eq!(policy_floor(old.iter(), 120.0), 30.0);
        // Time counts: 20 % less error is not worth 10× the time (27 % is needed).
        let mut costly = level(60.0, Some([0.024, 0.03]));
        costly.pareto_cost = Some([10.0, 1.0]);
        assert_eq!(policy_floor([costly.clone()].iter(), 120.0), 120.0);
        costly.pareto_cost = Some([1.0, 1.0]);
        assert_eq!(policy_floor([costly].iter(), 120.0), 60.0);
    }
}
