//! The LoD policy measured at bake time (`sylva::lod::policy`): each candidate
//! level and the far tier rendered by the viewer's pipelines at the candidate's
//! size, their image error against the full mesh and their modelled GPU time.

use glam::Vec3;
use sylva::render::GpuContext;

/// One measurement of the LoD policy (`sylva::lod::policy`): a
/// representation's and the far tier's error and modelled time per tree.
#[derive(Debug, Clone, Copy)]
pub(super) struct Measured {
    /// Multi-scale RMSE against the full mesh: [own, far tier].
    pub(super) error: [f32; 2],
    /// Modelled GPU time per tree (µs): [own, far tier]; `None` where the
    /// device cannot count the work.
    pub(super) cost: Option<[f32; 2]>,
    /// The tree's projected height (px) it was measured at.
    pub(super) px: f32,
}

impl std::fmt::Display for Measured {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let [own, far] = self.error;
        write!(f, "at {:.0} px {own:.4}/{far:.4}", self.px)?;
        if let Some([own, far]) = self.cost {
            write!(f, " in {own:.1}/{far:.1} µs")?;
        }
        Ok(())
    }
}

impl Measured {
    pub(super) fn keeps(m: Option<Self>, unmeasured: bool) -> bool {
        sylva::lod::policy::policy_keeps(m.map(|m| m.error), m.and_then(|m| m.cost), unmeasured)
    }
}

/// The LoD policy's measurements: per ellipsoid cluster level (finest first)
/// and for the billboard cloud, its multi-scale RMSE and the far tier's
/// (impostors, or billboards) against the full mesh (alpha-tested at full
/// resolution), all drawn by the viewer's pipelines with the tree `select_px`
/// tall (a cluster level or the cloud: also at the top of its band, up to the
/// meshes, and the measurement where it loses decides),
/// from the side and from 35° up (averaged), and the draws' modelled GPU time
/// from their work counts. `None` where the pack has no far tier. Also, per
/// simplified mesh level (1, 2, …), the policy's threshold.
#[allow(clippy::type_complexity)]
pub(super) fn measure_policy(
    gpu: &GpuContext,
    pack: &sylva::format::Pack<'_>,
    log: &dyn Fn(&str),
) -> (Vec<Option<Measured>>, Option<Measured>, Vec<Option<f32>>) {
    use sylva::lod::policy::{modelled_us, CostKind};
    use sylva::render::billboard::BillboardGpu;
    use sylva::render::capture::{preview_camera, PackView, TreeDraw, TreeRenderer};
    use sylva::render::cluster::ClusterGpu;
    use sylva::render::impostor::ImpostorGpu;
    use sylva::render::mesh::MeshGpu;
    const BACKGROUND: [f64; 4] = [0.55, 0.68, 0.82, 1.0];
    let levels = pack.meta.clusters.as_ref().map_or(0, |c| c.ellipsoid_levels.len());
    let mut r = TreeRenderer::new(gpu);
    let (dev, q) = (&gpu.device, &gpu.queue);
    let impostor = ImpostorGpu::upload(dev, q, 0, &r.impostor, pack);
    let billboard = if impostor.is_none() { BillboardGpu::upload(dev, q, 0, &r.billboard, pack) } else { None };
    let far = match (&impostor, &billboard) {
        (Some(i), _) => TreeDraw::Impostor(i),
        (None, Some(b)) => TreeDraw::Billboard(b),
        _ => return (vec![None; levels], None, Vec::new()),
    };
    let mesh = MeshGpu::upload(dev, q, &r.mesh, pack);
    if !mesh.has_level(0) {
        return (vec![None; levels], None, Vec::new());
    }
    let cluster = ClusterGpu::upload(dev, q, &r.cluster, pack);
    let (lo, hi) = (Vec3::from(pack.meta.bounds_min), Vec3::from(pack.meta.bounds_max));
    let radius = ((hi - lo) * 0.5).length().max(1e-3);
    let height = (hi.z - lo.z).max(1e-3);
    let kind = |what: &TreeDraw<'_>| match what {
        TreeDraw::Mesh(..) => CostKind::Mesh,
        TreeDraw::Cloud(..) => CostKind::Cloud,
        TreeDraw::Cluster(..) => CostKind::Cluster,
        TreeDraw::Billboard(..) => CostKind::Billboard,
        TreeDraw::Impostor(..) => CostKind::Impostor,
    };
    // With SYLVA_POLICY_CALIBRATE set, each draw's work counts and wall time
    // are printed (for fitting `sylva::lod::policy::COSTS`).
    let calibrate = std::env::var_os("SYLVA_POLICY_CALIBRATE").is_some();
    // `own` and the far tier with the tree `px` tall.
    let mut measure = |own: &TreeDraw<'_>, px: f32| -> Measured {
        let size = ((px * 2.0 * radius * 1.05 / height).round() as u32).clamp(16, 1024);
        let mut sum = [0.0f64; 2];
        let mut cost = Some([0.0f32; 2]);
        for view in [PackView::Side, PackView::Oblique] {
            let shot = preview_camera(lo, hi, view, [size, size]);
            r.full_res_alpha = true;
            let reference = r.render(gpu, &TreeDraw::Mesh(&mesh, 0), &shot, BACKGROUND);
            r.full_res_alpha = false;
            for (k, what) in [own, &far].into_iter().enumerate() {
                let img = r.render(gpu, what, &shot, BACKGROUND);
                sum[k] += sylva::metrics::multiscale_rmse(&img, &reference, size, size) / 2.0;
                let work = r.work(gpu, what, &shot);
                if let (Some(c), Some(w)) = (cost.as_mut(), work) {
                    c[k] += modelled_us(kind(what), w.vertices, w.fragments) / 2.0;
                } else {
                    cost = None;
                }
                if calibrate && view == PackView::Side {
                    let ms = r.wall_ms(gpu, what, &shot, 7);
                    let (v, f) = work.map_or((0, 0), |w| (w.vertices, w.fragments));
                    log(&format!(
                        "CALIBRATE {} {:?} px {px:.0} size {size} vertices {v} fragments {f} ms {ms:.4}",
                        ["own", "far"][k],
                        kind(what)
                    ));
                }
            }
        }
        // The size actually drawn (the image is clamped).
        Measured { error: sum.map(|e| e as f32), cost, px: size as f32 * height / (2.0 * radius * 1.05) }
    };
    if calibrate {
        for px in [24.0, 48.0, 96.0, 192.0, 384.0] {
            for l in 0..pack.meta.mesh_levels.len() {
                if mesh.has_level(l) {
                    measure(&TreeDraw::Mesh(&mesh, l), px);
                }
            }
            if let Some(c) = cluster.as_ref() {
                for l in 0..c.levels.len() {
                    measure(&TreeDraw::Cluster(c, l), px);
                }
            }
            if mesh.cloud.is_some() {
                measure(&TreeDraw::Cloud(&mesh), px);
            }
        }
    }
    let cloud_entry = pack
        .meta
        .cloud
        .as_ref()
        .filter(|_| mesh.cloud.is_some())
        .map(|c| measure(&TreeDraw::Cloud(&mesh), c.select_px));
    // Simplified mesh levels: from their threshold up to the finer level's, in
    // steps of 1.5×, the first size where the policy prefers the level to the
    // far tier.
    let mesh_levels = &pack.meta.mesh_levels;
    let mesh_policy: Vec<Option<f32>> = (1..mesh_levels.len())
        .map(|l| {
            if !mesh.has_level(l) {
                return None;
            }
            let (from, to) = (mesh_levels[l].select_px.max(1.0), mesh_levels[l - 1].select_px);
            let mut px = from;
            while px < to {
                if Measured::keeps(Some(measure(&TreeDraw::Mesh(&mesh, l), px)), true) {
                    return Some(px);
                }
                px *= 1.5;
            }
            Some(to)
        })
        .collect();
    // Cluster levels: each over its band, from its entry size up to the finer
    // level's (the finest: up to the lowest mesh level the policy keeps, or the
    // cloud), measured at both ends; the measurement where it loses decides.
    let mut top = mesh_levels.first().map_or(f32::INFINITY, |m| m.select_px);
    for (l, p) in mesh_policy.iter().enumerate() {
        let px = p.unwrap_or(mesh_levels[l + 1].select_px);
        if mesh.has_level(l + 1) && px < top {
            top = px;
        }
    }
    // The cloud, too, over its band up to the meshes.
    let cloud = cloud_entry.map(|at_entry| {
        let band_top = top / 1.05;
        if Measured::keeps(Some(at_entry), false) && band_top > at_entry.px * 1.2 {
            let at_top = measure(&TreeDraw::Cloud(&mesh), band_top);
            if !Measured::keeps(Some(at_top), false) {
                return at_top;
            }
        }
        at_entry
    });
    if let (Some(c), Some(m)) = (&pack.meta.cloud, cloud) {
        if Measured::keeps(Some(m), false) {
            top = top.min(c.select_px);
        }
    }
    let mut level_errors = Vec::with_capacity(levels);
    for l in 0..levels {
        let c = cluster.as_ref().filter(|c| l < c.levels.len());
        let Some((c, entry)) = c.zip(pack.meta.clusters.as_ref().map(|m| m.ellipsoid_levels[l].select_px)) else {
            level_errors.push(None);
            continue;
        };
        let at_entry = measure(&TreeDraw::Cluster(c, l), entry);
        let band_top = top / 1.05;
        level_errors.push(Some(if Measured::keeps(Some(at_entry), true) && band_top > entry * 1.2 {
            let at_top = measure(&TreeDraw::Cluster(c, l), band_top);
            if Measured::keeps(Some(at_top), true) {
                at_entry
            } else {
                at_top
            }
        } else {
            at_entry
        }));
        top = top.min(entry);
    }
    (level_errors, cloud, mesh_policy)
}
