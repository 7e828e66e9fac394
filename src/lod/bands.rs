//! The representation choice: from what projected height (px) each of a
//! species' representations takes over, from what the species offers (its
//! pack's levels, or the part of them resident on the GPU), the
//! representations a frame allows and the bake's LoD policy.
//!
//! Two readers, one rule: `render::species` lays the bands out as the species
//! table's `lower_px` (read by the cull in `shaders/cull.wgsl` and
//! [`super::select`]), `render::reach` fetches only the pack parts a view's
//! trees can reach by them.
//!
//! Top to bottom: the full mesh from its `select_px`, the simplified mesh
//! (from its threshold, or higher where the policy moves it and a far tier
//! takes over below), the billboard cloud, then the cluster levels whose band
//! meets `[cluster floor, the lowest of those)`, then the far tier (impostors or
//! billboards) down to 0 px. Without a far tier the coarsest cluster level
//! reaches down to 0 px.

use super::policy::policy_floor;
use super::shared::CLUSTER_TIERS;
use crate::format::cluster::ClusterLevelMeta;

/// Representation families a frame may use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Representations {
    /// Mesh levels.
    pub meshes: bool,
    /// Clustered ellipsoids and lines.
    pub clusters: bool,
    /// Billboards.
    pub billboards: bool,
    /// Billboard clouds (García et al. 2007).
    pub clouds: bool,
}

impl Representations {
    /// Everything (Sylva's mixed pipeline).
    pub const ALL: Self = Self { meshes: true, clusters: true, billboards: true, clouds: true };
    /// Meshes only.
    pub const MESHES: Self = Self { meshes: true, clusters: false, billboards: false, clouds: false };
    /// Ellipsoids and lines only.
    pub const CLUSTERS: Self = Self { meshes: false, clusters: true, billboards: false, clouds: false };
    /// Billboards only.
    pub const BILLBOARDS: Self = Self { meshes: false, clusters: false, billboards: true, clouds: false };
    /// Billboard clouds only.
    pub const CLOUDS: Self = Self { meshes: false, clusters: false, billboards: false, clouds: true };
}

impl Default for Representations {
    /// Everything: which cluster levels and clouds a species draws by default
    /// is the bake's LoD policy (`RenderSettings::lod_policy`).
    fn default() -> Self {
        Self::ALL
    }
}

/// One mesh level as the choice sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshOffer {
    /// Projected height (px) from which the level is drawn.
    pub select_px: f32,
    /// Where the bake's policy starts it instead, if it measured one.
    pub policy_px: Option<f32>,
}

/// What a species offers: each present (or resident) representation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Offer {
    /// The full mesh (0) and the simplified one (1).
    pub meshes: [Option<MeshOffer>; 2],
    /// The billboard cloud: its `select_px` and whether the policy keeps it.
    pub cloud: Option<(f32, bool)>,
    /// Cluster levels (their metadata is passed to [`bands`] beside).
    pub clusters: bool,
    /// A far tier (impostors or billboards) in the pack, resident or not:
    /// while it loads, trees below the cluster band wait for it (the stream
    /// fetches it before anything finer).
    pub far: bool,
}

/// The bands of one species: each representation's lower bound (px), `None`
/// where it is not drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bands {
    /// Full mesh, simplified mesh.
    pub mesh: [Option<f32>; 2],
    /// The billboard cloud.
    pub cloud: Option<f32>,
    /// The coarsest drawn mesh level's lower bound (∞ without meshes).
    pub mesh_floor: f32,
    /// Where the representations above the clusters end: the cloud's lower
    /// bound, else `mesh_floor`.
    pub floor: f32,
    /// The cluster band `[min, floor)`, `None` without clusters. `min`: with a
    /// far tier `cluster_min_px`, raised to the policy's floor where the policy
    /// is on; without one 0.
    pub clusters: Option<f32>,
    /// The far tier, below everything.
    pub far: bool,
}

impl Bands {
    /// Whether cluster levels are drawn at all: a band that is not empty.
    #[must_use]
    pub fn has_clusters(&self) -> bool {
        self.clusters.is_some_and(|min| min < self.floor)
    }
}

/// The representation choice of a species offering `offer` under the frame's
/// `allow`, with the bake's policy on or off. With a far tier the cluster band
/// ends at `cluster_min_px` (or the policy's floor); `levels` are the cluster
/// levels' metadata, finest first.
#[must_use]
pub fn bands<'a>(
    offer: &Offer,
    allow: Representations,
    policy: bool,
    cluster_min_px: f32,
    levels: impl Iterator<Item = &'a ClusterLevelMeta>,
) -> Bands {
    let far = allow.billboards && offer.far;
    let [full, simple] = if allow.meshes { offer.meshes } else { [None, None] };
    let mesh0 = full.map(|m| m.select_px);
    // With a far tier to take over, the policy may start the simplified mesh
    // higher, or leave it out (where it would start above the full mesh).
    let mesh1 = simple
        .map(|m| match m.policy_px {
            Some(px) if policy && far => px.max(m.select_px),
            _ => m.select_px,
        })
        .filter(|&lower| mesh0.is_none_or(|m0| lower < m0));
    let cloud = offer.cloud.filter(|&(_, kept)| allow.clouds && (!policy || kept)).map(|(px, _)| px);
    let mesh_floor = mesh1.or(mesh0).unwrap_or(f32::INFINITY);
    let floor = cloud.unwrap_or(mesh_floor);
    let clusters = (allow.clusters && offer.clusters).then(|| {
        let min = if far { cluster_min_px } else { 0.0 };
        if policy && far {
            min.max(policy_floor(levels, floor))
        } else {
            min
        }
    });
    Bands { mesh: [mesh0, mesh1], cloud, mesh_floor, floor, clusters, far }
}

/// The cluster levels a band `[min_px, below_px)` draws as tiers: the finest
/// [`CLUSTER_TIERS`] levels whose size band `[select_px, finer level's
/// select_px)` meets it, as (level, lower bound px); the last reaches down to
/// `min_px`.
#[must_use]
pub fn cluster_tiers<'a>(
    levels: impl Iterator<Item = &'a ClusterLevelMeta>,
    min_px: f32,
    below_px: f32,
) -> Vec<(usize, f32)> {
    let mut out: Vec<(usize, f32)> = Vec::new();
    if min_px.partial_cmp(&below_px) != Some(std::cmp::Ordering::Less) {
        return out;
    }
    let mut upper = f32::INFINITY;
    for (i, l) in levels.enumerate() {
        let lower = l.select_px;
        if upper > min_px && lower < below_px && out.len() < CLUSTER_TIERS {
            out.push((i, lower.max(min_px)));
        }
        upper = lower;
    }
    if let Some(last) = out.last_mut() {
        last.1 = min_px;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn level(select_px: f32, pareto_error: Option<[f32; 2]>) -> ClusterLevelMeta {
        ClusterLevelMeta {
            count: 1,
            select_px,
            error: 0.0,
            noise_threshold: 0.0,
            normal_blend: 0.0,
            pareto_error,
            pareto_cost: None,
        }
    }

    #[test]
    fn tiers_cover_the_cluster_band() {
        let levels: Vec<_> = [2000.0, 900.0, 400.0, 180.0, 80.0, 35.0, 15.0].map(|px| level(px, None)).into();
        // Band [30, 120): level 4 [80, 180), level 5 [35, 80), level 6 [15, 35).
        let t = cluster_tiers(levels.iter(), 30.0, 120.0);
        assert_eq!(t, vec![(4, 80.0), (5, 35.0), (6, 30.0)]);
        assert!(cluster_tiers(levels.iter(), 200.0, 120.0).is_empty());
        // More usable levels than tiers: the finest four, the last reaching down.
        let t = cluster_tiers(levels.iter(), 1.0, 5000.0);
        assert_eq!(t, vec![(0, 2000.0), (1, 900.0), (2, 400.0), (3, 1.0)]);
    }

    fn oak() -> Offer {
        Offer {
            meshes: [
                Some(MeshOffer { select_px: 300.0, policy_px: None }),
                Some(MeshOffer { select_px: 120.0, policy_px: Some(200.0) }),
            ],
            cloud: Some((60.0, false)),
            clusters: true,
            far: true,
        }
    }

    #[test]
    fn every_representation_takes_its_band() {
        let levels = [level(100.0, None), level(50.0, None), level(20.0, None)];
        let b = bands(&oak(), Representations::ALL, false, 40.0, levels.iter());
        assert_eq!(b.mesh, [Some(300.0), Some(120.0)]);
        assert_eq!((b.cloud, b.mesh_floor, b.floor, b.clusters), (Some(60.0), 120.0, 60.0, Some(40.0)));
        assert!(b.far && b.has_clusters());
        // Without a far tier the clusters reach down to 0 px.
        let b =
            bands(&oak(), Representations { billboards: false, ..Representations::ALL }, false, 40.0, levels.iter());
        assert_eq!((b.clusters, b.far), (Some(0.0), false));
        let no_far = Offer { far: false, ..oak() };
        assert_eq!(bands(&no_far, Representations::ALL, false, 40.0, levels.iter()).clusters, Some(0.0));
        // Meshes only.
        let b = bands(&oak(), Representations::MESHES, false, 40.0, levels.iter());
        assert_eq!((b.mesh, b.cloud, b.clusters, b.far), ([Some(300.0), Some(120.0)], None, None, false));
    }

    #[test]
    fn the_policy_moves_and_drops_bands() {
        // The policy starts the simplified mesh at 200 px, drops the cloud (not
        // kept) and starts the clusters above the first level it drops.
        let levels = [level(100.0, Some([0.01, 0.02])), level(50.0, Some([0.03, 0.02])), level(20.0, None)];
        let b = bands(&oak(), Representations::ALL, true, 40.0, levels.iter());
        assert_eq!((b.mesh, b.cloud, b.floor), ([Some(300.0), Some(200.0)], None, 200.0));
        assert_eq!(b.clusters, Some(100.0));
        // A policy start above the full mesh leaves the simplified mesh out.
        let mut offer = oak();
        offer.meshes[1] = Some(MeshOffer { select_px: 120.0, policy_px: Some(400.0) });
        let b = bands(&offer, Representations::ALL, true, 40.0, levels.iter());
        assert_eq!((b.mesh, b.mesh_floor), ([Some(300.0), None], 300.0));
        // Without a far tier to take over the policy changes nothing.
        let b = bands(&Offer { far: false, ..offer }, Representations::ALL, true, 40.0, levels.iter());
        assert_eq!((b.mesh, b.clusters), ([Some(300.0), Some(120.0)], Some(0.0)));
        // Only the simplified mesh resident: it is drawn all the way up.
        offer.meshes[0] = None;
        let b = bands(&offer, Representations::ALL, true, 40.0, levels.iter());
        assert_eq!(b.mesh, [None, Some(400.0)]);
    }
}
