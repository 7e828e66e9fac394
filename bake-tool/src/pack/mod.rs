//! Builds a species' LoD pack from an imported model: mesh levels (vertex-cache
//! optimised with meshoptimizer, quantised), material textures with alpha-aware
//! mips, and the view-angle billboard array rendered by Sylva's own mesh pass.

pub mod ao;
pub mod cloud;
pub mod clusters;

use anyhow::{Context, Result};
use glam::{Vec2, Vec3};
use sylva::format::cloud::{encode_cloud, CloudMeta};
use sylva::format::pack::{
    ao_to_snorm8, encode_pack, kind, BillboardMeta, DrawRange, ImpostorMeta, MaterialKind, MaterialMeta, MeshLevelMeta,
    MeshVertex, PackMeta, Section, TextureArrayMeta,
};
use sylva::render::capture::CapturePipelines;
use sylva::render::capture::{capture_billboards, capture_views, BillboardFrame};
use sylva::render::impostor;
use sylva::render::mips::{alpha_aware_mips, ColorEncoding};
use sylva::render::GpuContext;

use crate::input::gltf_import::{ImportedModel, ImportedVertex};
use crate::pack::ao::AoField;

/// Knobs of the pack bake.
#[derive(Debug, Clone)]
pub struct PackOptions {
    /// Side of the material texture array (power of two).
    pub texture_size: u32,
    /// Billboard elevation angles over 0–90°.
    pub billboard_angles: u32,
    /// Billboard azimuths.
    pub billboard_azimuths: u32,
    /// Billboard layer side (power of two).
    pub billboard_size: u32,
    /// Whether to add a simplified mesh level.
    pub simplified_level: bool,
    /// Whether to add clustered-ellipsoid and line levels (Clasen et al. 2010).
    pub clusters: bool,
    /// EM starts per cluster level.
    pub cluster_tries: usize,
    /// Whether to bake the tree's own ambient occlusion ([`crate::pack::ao`]).
    pub ao: bool,
    /// Which far-field representations to bake.
    pub far_tier: FarBake,
    /// Views per side of the impostors' hemi-octahedral grid.
    pub impostor_grid: u32,
    /// Impostor view side (power of two).
    pub impostor_size: u32,
    /// Planes of the billboard cloud (García et al. 2007); 0: no cloud.
    pub cloud_planes: u32,
}

/// The far-field representations a pack gets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum FarBake {
    /// Multi-view impostors only.
    Impostors,
    /// View-angle billboards only (Eichner 2024).
    Billboards,
    /// Both (the viewer draws the impostors; benchmarks compare them).
    Both,
}

impl FarBake {
    fn impostors(self) -> bool {
        self != FarBake::Billboards
    }
    fn billboards(self) -> bool {
        self != FarBake::Impostors
    }
}

impl Default for PackOptions {
    fn default() -> Self {
        Self {
            texture_size: 512,
            billboard_angles: 8,
            billboard_azimuths: 1,
            billboard_size: 128,
            simplified_level: true,
            clusters: true,
            cluster_tries: 4,
            ao: true,
            far_tier: FarBake::Both,
            impostor_grid: DEFAULT_IMPOSTOR_GRID,
            impostor_size: DEFAULT_IMPOSTOR_SIZE,
            cloud_planes: DEFAULT_CLOUD_PLANES,
        }
    }
}

/// Projected tree heights (pixels) above which each representation is selected.
/// Mesh LoD0 close up, the simplified mesh in the middle, billboards far away.
pub const SELECT_PX_MESH0: f32 = 360.0;
/// See [`SELECT_PX_MESH0`].
pub const SELECT_PX_MESH1: f32 = 120.0;

/// Projected tree height (pixels) above which the billboard cloud is drawn
/// (below the simplified mesh's threshold).
pub const SELECT_PX_CLOUD: f32 = 40.0;
/// Default planes of the billboard cloud: none (the viewer does not draw
/// clouds by default, see `Representations::default`); `--cloud-planes 64`
/// bakes one (the paper uses 60–260 for whole trees; ours carry no wood,
/// which stays geometry).
pub const DEFAULT_CLOUD_PLANES: u32 = 0;

/// Default views per side of the impostor grid (36 views over the hemisphere).
pub const DEFAULT_IMPOSTOR_GRID: u32 = 6;
/// Default impostor view side.
pub const DEFAULT_IMPOSTOR_SIZE: u32 = 128;

/// Alpha-test threshold of billboards (the viewer discards below it).
pub const BILLBOARD_ALPHA_CUTOFF: f32 = 0.5;

/// The bytes of a finished pack and its metadata.
pub struct BuiltPack {
    /// The encoded pack.
    pub bytes: Vec<u8>,
    /// Its metadata.
    pub meta: PackMeta,
    /// Billboard colour layers at full resolution (for `--debug-dump`).
    pub billboard_color: Vec<Vec<u8>>,
    /// Billboard normal layers at full resolution.
    pub billboard_normal: Vec<Vec<u8>>,
}

/// Builds the whole pack of `name` from `model`. `gpu` renders the billboards.
pub fn build_pack(
    name: &str,
    model: &ImportedModel,
    opts: &PackOptions,
    gpu: &GpuContext,
    pipelines: &CapturePipelines,
) -> Result<BuiltPack> {
    let (lo, hi) = model.bounds();
    let height = (hi.z - lo.z).max(1e-3);
    let (materials, texture_meta, texture_bytes) = build_materials(model, opts.texture_size);
    // The tree's own occlusion, one field for every level (mesh vertices, the
    // billboard capture through them, ellipsoids, lines).
    let started = std::time::Instant::now();
    let ao = if opts.ao { AoField::build(model) } else { AoField::open() };
    let vertex_ao: Vec<f32> = model.vertices.iter().map(|v| ao.at(v.position)).collect();
    if opts.ao {
        let (lo_v, hi_v) = vertex_ao.iter().fold((1.0f32, 0.0f32), |(a, b), v| (a.min(*v), b.max(*v)));
        eprintln!(
            "    ambient occlusion: sky visibility {lo_v:.2}–{hi_v:.2} at the vertices ({:.1} s)",
            started.elapsed().as_secs_f64()
        );
    }
    let mut levels = vec![build_mesh_level(model, SELECT_PX_MESH0, opts.ao.then_some(&vertex_ao[..]))];
    // The coarsest level's model and occlusion (the cloud's wood).
    let mut coarsest: Option<(ImportedModel, Vec<f32>)> = None;
    if opts.simplified_level {
        // Kept leaf cards keep their vertices' occlusion from where they were
        // before being enlarged (their corners now reach out into the open).
        let (simple, source) = simplify_model(model);
        if simple.triangles.len() < model.triangles.len() {
            let simple_ao: Vec<f32> = source.iter().map(|&i| vertex_ao[i as usize]).collect();
            levels.push(build_mesh_level(&simple, SELECT_PX_MESH1, opts.ao.then_some(&simple_ao[..])));
            coarsest = Some((simple, simple_ao));
        }
    }
    let mut sections = Vec::new();
    for (i, (_, vtx, idx)) in levels.iter().enumerate() {
        sections.push(records(kind::MESH_VERTICES, i as u32, vtx));
        sections.push(records(kind::MESH_INDICES, i as u32, idx));
    }
    if let Some(bytes) = texture_bytes {
        sections.push(Section { kind: kind::MATERIAL_TEXTURES, index: 0, count: 0, stride: 0, data: bytes });
    }
    let mut materials = materials;
    let cloud = (opts.cloud_planes > 0)
        .then(|| {
            let started = std::time::Instant::now();
            let (wood, wood_ao) = coarsest.as_ref().map_or((model, &vertex_ao[..]), |(m, a)| (m, &a[..]));
            let built = crate::pack::cloud::build_cloud(model, &vertex_ao, wood, wood_ao, opts.cloud_planes as usize)?;
            let (mut level, vtx, idx) =
                build_mesh_level(&built.model, SELECT_PX_CLOUD, opts.ao.then_some(&built.model_ao[..]));
            level.select_px = SELECT_PX_CLOUD;
            let material = materials.len() as u32;
            let cloud_material = built.model.materials.last().expect("the cloud material");
            materials.push(MaterialMeta {
                name: cloud_material.name.clone(),
                kind: MaterialKind::Cloud,
                base_color: cloud_material.base_color,
                alpha_cutoff: 0.0,
                double_sided: true,
                texture_layer: None,
            });
            let words = encode_cloud(&built.planes, &built.cells, &built.fragments);
            // Its coverage of the leaves, seen from the side (tested in crate::pack::cloud).
            let check = crate::pack::cloud::Cloud {
                planes: built.planes.clone(),
                cells: built.cells.clone(),
                fragments: built.fragments.clone(),
            };
            let (leaf_px, cloud_px, _) = crate::pack::cloud::view_coverage(model, &check, Vec3::X, 64);
            eprintln!(
                "    billboard cloud: {} planes, {} cells, {} list entries of {}/{} leaves, {:.2}× the leaves' \
                 coverage from the side ({} KiB, {:.1} s)",
                built.planes.len(),
                built.cells.len(),
                built.fragments.len(),
                built.leaves.0,
                built.leaves.1,
                cloud_px as f64 / leaf_px.max(1) as f64,
                (words.len() * 4 + vtx.len() * 20 + idx.len() * 4) / 1024,
                started.elapsed().as_secs_f64()
            );
            sections.push(records(kind::CLOUD_VERTICES, 0, &vtx));
            sections.push(records(kind::CLOUD_INDICES, 0, &idx));
            sections.push(records(kind::CLOUD_DATA, 0, &words));
            Some(CloudMeta {
                planes: built.planes.len() as u32,
                cells: built.cells.len() as u32,
                fragments: built.fragments.len() as u32,
                material,
                select_px: SELECT_PX_CLOUD,
                mesh: level,
                pareto_error: None,
                pareto_cost: None,
            })
        })
        .flatten();
    let mut meta = PackMeta {
        name: name.to_string(),
        height_m: height,
        bounds_min: lo.to_array(),
        bounds_max: hi.to_array(),
        materials,
        material_texture: texture_meta,
        mesh_levels: levels.iter().map(|(m, _, _)| m.clone()).collect(),
        billboards: None,
        clusters: None,
        impostors: None,
        cloud,
    };
    // Capture the billboards from the mesh-only pack, through the same decoder the viewer uses.
    let mesh_only = encode_pack(&meta, &sections);
    let decoded = sylva::format::decode_pack(name, &mesh_only).context("the mesh-only pack does not validate")?;
    let frame = BillboardFrame::from_bounds(lo, hi);
    let mut color_chains: Vec<Vec<Vec<u8>>> = Vec::new();
    let mut normal_chains: Vec<Vec<Vec<u8>>> = Vec::new();
    let tex = TextureArrayMeta {
        size: opts.billboard_size,
        layers: opts.billboard_angles * opts.billboard_azimuths,
        mips: opts.billboard_size.trailing_zeros() + 1,
    };
    if opts.far_tier.billboards() {
        let capture_size = opts.billboard_size * 2;
        let captured = capture_billboards(
            gpu,
            pipelines,
            &decoded,
            &frame,
            opts.billboard_angles,
            opts.billboard_azimuths,
            capture_size,
        );
        // Supersampled 2× capture: mip 1 of the alpha-aware chain is the stored mip 0,
        // so stored alpha is real coverage rather than a hard alpha test.
        color_chains = captured
            .color
            .iter()
            .map(|c| {
                alpha_aware_mips(c, c, capture_size, ColorEncoding::Srgb, Some(BILLBOARD_ALPHA_CUTOFF))[1..].to_vec()
            })
            .collect();
        normal_chains = captured
            .normal
            .iter()
            .zip(&captured.color)
            .map(|(n, c)| alpha_aware_mips(n, c, capture_size, ColorEncoding::Linear, None)[1..].to_vec())
            .collect();
        sections.push(Section {
            kind: kind::BILLBOARD_COLOR,
            index: 0,
            count: 0,
            stride: 0,
            data: mip_major(&color_chains, tex.mips),
        });
        sections.push(Section {
            kind: kind::BILLBOARD_NORMAL,
            index: 0,
            count: 0,
            stride: 0,
            data: mip_major(&normal_chains, tex.mips),
        });
        if opts.ao {
            // One byte per texel (the red channel), mips weighted by coverage like the normals'.
            let ao_chains: Vec<Vec<Vec<u8>>> = captured
                .ao
                .iter()
                .zip(&captured.color)
                .map(|(a, c)| {
                    alpha_aware_mips(a, c, capture_size, ColorEncoding::Linear, None)[1..]
                        .iter()
                        .map(|mip| mip.chunks_exact(4).map(|t| t[0]).collect())
                        .collect()
                })
                .collect();
            sections.push(Section {
                kind: kind::BILLBOARD_AO,
                index: 0,
                count: 0,
                stride: 0,
                data: mip_major(&ao_chains, tex.mips),
            });
        }
    }
    if opts.far_tier.impostors() {
        let (m, imp_sections) = build_impostors(gpu, pipelines, &decoded, lo, hi, opts);
        sections.extend(imp_sections);
        meta.impostors = Some(m);
    }
    if opts.clusters {
        let hopts =
            crate::pack::clusters::hierarchy::HierarchyOptions { tries: opts.cluster_tries, ..Default::default() };
        let mut log = |m: &str| eprintln!("{m}");
        if let Some(c) = crate::pack::clusters::bake::build_clusters(model, &decoded, gpu, &hopts, &ao, &mut log)? {
            sections.extend(c.sections);
            meta.clusters = Some(c.meta);
        }
    }
    meta.billboards = opts.far_tier.billboards().then(|| BillboardMeta {
        angles: opts.billboard_angles,
        azimuths: opts.billboard_azimuths,
        texture: tex,
        center: frame.center.to_array(),
        half_width: frame.half_width,
        half_height: frame.half_height,
        select_px: 0.0,
    });
    let mut bytes = encode_pack(&meta, &sections);
    // The LoD policy: which cluster levels and whether the cloud are default
    // tiers, from their error and the far tier's at their entry sizes.
    let (levels, cloud, mesh_policy) = {
        let decoded = sylva::format::decode_pack(name, &bytes).context("the finished pack does not validate")?;
        measure_policy(gpu, &decoded)
    };
    if levels.iter().any(Option::is_some) || cloud.is_some() || mesh_policy.iter().any(Option::is_some) {
        let mut report = Vec::new();
        for (l, p) in mesh_policy.iter().enumerate() {
            meta.mesh_levels[l + 1].policy_px = *p;
            if let Some(p) = p {
                report.push(if *p >= meta.mesh_levels[l].select_px {
                    format!("mesh level {} dropped (the far tier is preferred up to {:.0} px)", l + 1, p)
                } else {
                    format!("mesh level {} from {p:.0} px", l + 1)
                });
            }
        }
        if let Some(c) = meta.clusters.as_mut() {
            // (The band ends above the first level dropped: `policy_floor`.)
            for (l, m) in c.ellipsoid_levels.iter_mut().zip(&levels) {
                l.pareto_error = m.map(|m| m.error);
                l.pareto_cost = m.and_then(|m| m.cost);
                if let Some(m) = m {
                    let verdict = if Measured::keeps(Some(*m), true) { "wins" } else { "loses" };
                    report.push(format!("ellipsoids from {:.0} px: {m} {verdict}", l.select_px));
                }
            }
        }
        if let (Some(c), Some(m)) = (meta.cloud.as_mut(), cloud) {
            c.pareto_error = Some(m.error);
            c.pareto_cost = m.cost;
            let kept = Measured::keeps(Some(m), false);
            report.push(format!("cloud from {:.0} px: {m} {}", c.select_px, if kept { "kept" } else { "dropped" }));
        }
        eprintln!("    LoD policy (error / far tier's, in modelled µs per tree): {}", report.join(", "));
        bytes = encode_pack(&meta, &sections);
        sylva::format::decode_pack(name, &bytes).context("the finished pack does not validate")?;
    }
    Ok(BuiltPack {
        bytes,
        meta,
        billboard_color: color_chains.iter().map(|c| c[0].clone()).collect(),
        billboard_normal: normal_chains.iter().map(|c| c[0].clone()).collect(),
    })
}

/// A section of fixed-size records (`count` and `stride` from `items`).
fn records<T: bytemuck::Pod>(kind: [u8; 4], index: u32, items: &[T]) -> Section {
    Section {
        kind,
        index,
        count: items.len() as u32,
        stride: std::mem::size_of::<T>() as u32,
        data: bytemuck::cast_slice(items).to_vec(),
    }
}

/// One measurement of the LoD policy (`sylva::lod::policy`): a
/// representation's and the far tier's error and modelled time per tree.
#[derive(Debug, Clone, Copy)]
struct Measured {
    /// Multi-scale RMSE against the full mesh: [own, far tier].
    error: [f32; 2],
    /// Modelled GPU time per tree (µs): [own, far tier]; `None` where the
    /// device cannot count the work.
    cost: Option<[f32; 2]>,
    /// The tree's projected height (px) it was measured at.
    px: f32,
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
    fn keeps(m: Option<Self>, unmeasured: bool) -> bool {
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
fn measure_policy(
    gpu: &GpuContext,
    pack: &sylva::format::Pack<'_>,
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
    let impostor = ImpostorGpu::upload(dev, q, &r.impostor, pack);
    let billboard = if impostor.is_none() { BillboardGpu::upload(dev, q, &r.billboard, pack) } else { None };
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
            let (clip, eye) = preview_camera(lo, hi, view, size, size);
            r.full_res_alpha = true;
            let reference = r.render(gpu, &TreeDraw::Mesh(&mesh, 0), clip, eye, size, size, BACKGROUND);
            r.full_res_alpha = false;
            for (k, what) in [own, &far].into_iter().enumerate() {
                let img = r.render(gpu, what, clip, eye, size, size, BACKGROUND);
                sum[k] += sylva::metrics::multiscale_rmse(&img, &reference, size, size) / 2.0;
                let work = r.work(gpu, what, clip, eye, size, size);
                if let (Some(c), Some(w)) = (cost.as_mut(), work) {
                    c[k] += modelled_us(kind(what), w.vertices, w.fragments) / 2.0;
                } else {
                    cost = None;
                }
                if calibrate && view == PackView::Side {
                    let ms = r.wall_ms(gpu, what, clip, eye, size, size, 7);
                    let (v, f) = work.map_or((0, 0), |w| (w.vertices, w.fragments));
                    eprintln!(
                        "CALIBRATE {} {:?} px {px:.0} size {size} vertices {v} fragments {f} ms {ms:.4}",
                        ["own", "far"][k],
                        kind(what)
                    );
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

/// The multi-view impostors of a mesh-only pack: `grid`² orthographic views
/// over the upper hemisphere ([`impostor::capture_clip_from_model`]), each
/// framing the bounding sphere, rendered at twice the stored size through the
/// viewer's own mesh pass. Colour mips as the billboards' (alpha-aware, coverage
/// kept); the surface layer (normal, depth, occlusion and leaf flag) averaged
/// weighted by coverage.
fn build_impostors(
    gpu: &GpuContext,
    pipelines: &CapturePipelines,
    decoded: &sylva::format::Pack<'_>,
    lo: Vec3,
    hi: Vec3,
    opts: &PackOptions,
) -> (ImpostorMeta, Vec<Section>) {
    let grid = opts.impostor_grid;
    let center = (lo + hi) * 0.5;
    let radius = ((hi - lo) * 0.5).length().max(1e-3) * 1.01;
    let views: Vec<_> = (0..grid * grid).map(|l| impostor::capture_clip_from_model(center, radius, l, grid)).collect();
    let capture_size = opts.impostor_size * 2;
    let captured = capture_views(gpu, pipelines, decoded, &views, capture_size);
    let mut color_chains: Vec<Vec<Vec<u8>>> = Vec::new();
    let mut surface_chains = Vec::new();
    // Per stored mip: Σ coverage × |mean normal| and Σ coverage over all views.
    let mut spread = vec![(0.0f64, 0.0f64); opts.impostor_size.trailing_zeros() as usize + 1];
    for layer in 0..views.len() {
        let color = &captured.color[layer];
        color_chains.push(
            alpha_aware_mips(color, color, capture_size, ColorEncoding::Srgb, Some(BILLBOARD_ALPHA_CUTOFF))[1..]
                .to_vec(),
        );
        // Per texel: normal xyz, depth offset (−1 … 1), occlusion, leaf (0/1),
        // averaged as such down the mips and only then encoded: averaging
        // octahedral codes would bend normals near the fold (downward ones up).
        let surface: Vec<[f32; 6]> = (0..(capture_size * capture_size) as usize)
            .map(|i| {
                let n = &captured.normal[layer][i * 4..i * 4 + 4];
                if color[i * 4 + 3] == 0 {
                    // Background: the plane, open, weighted out of every mip.
                    return [0.0, 0.0, 1.0, 0.0, 1.0, 0.0];
                }
                let normal = Vec3::new(f32::from(n[0]), f32::from(n[1]), f32::from(n[2])) / 127.5 - Vec3::ONE;
                let depth = impostor::depth_to_offset(captured.depth[layer][i]);
                let ao = f32::from(captured.ao[layer][i * 4]) / 255.0;
                [normal.x, normal.y, normal.z, depth, ao, f32::from(u8::from(n[3] > 191))]
            })
            .collect();
        let encode = |t: &[f32; 6]| {
            let e = oct_encode(Vec3::new(t[0], t[1], t[2]).normalize_or(Vec3::Z));
            let unorm = |v: i8| ((f32::from(v) / 127.0 * 0.5 + 0.5) * 255.0).round() as u8;
            let depth = ((t[3] * 0.5 + 0.5).clamp(0.0, 1.0) * 255.0).round() as u8;
            [unorm(e[0]), unorm(e[1]), depth, impostor::pack_ao_leaf(t[4], t[5] >= 0.5)]
        };
        let mips = coverage_weighted_mips(surface, color, capture_size);
        for (l, level) in mips[1..].iter().enumerate() {
            let alpha = &color_chains[layer][l];
            for (i, t) in level.iter().enumerate() {
                let a = f64::from(alpha[i * 4 + 3]) / 255.0;
                spread[l].0 += a * f64::from(Vec3::new(t[0], t[1], t[2]).length().min(1.0));
                spread[l].1 += a;
            }
        }
        surface_chains
            .push(mips[1..].iter().map(|level| level.iter().flat_map(encode).collect()).collect::<Vec<Vec<u8>>>());
    }
    // How much the normals under a texel agree, per mip (1 at full resolution
    // on one leaf; less as texels cover more leaves): the viewer shades the
    // filtered normal with it (`shade_filtered`).
    let normal_length: Vec<f32> =
        spread.iter().map(|(w, n)| if *n > 0.0 { (w / n).clamp(0.0, 1.0) as f32 } else { 1.0 }).collect();
    let texture = TextureArrayMeta {
        size: opts.impostor_size,
        layers: grid * grid,
        mips: opts.impostor_size.trailing_zeros() + 1,
    };
    let sections = vec![
        Section {
            kind: kind::IMPOSTOR_COLOR,
            index: 0,
            count: 0,
            stride: 0,
            data: mip_major(&color_chains, texture.mips),
        },
        Section {
            kind: kind::IMPOSTOR_SURFACE,
            index: 0,
            count: 0,
            stride: 0,
            data: mip_major(&surface_chains, texture.mips),
        },
    ];
    (ImpostorMeta { grid, texture, center: center.to_array(), radius, normal_length }, sections)
}

/// Mip chain (mip 0 included) of a square layer of `N` floats per texel, all
/// averaged weighted by `color`'s alpha (coverage); where a 2×2 block has none,
/// by plain average.
fn coverage_weighted_mips<const N: usize>(layer: Vec<[f32; N]>, color: &[u8], size: u32) -> Vec<Vec<[f32; N]>> {
    let mut weights: Vec<f32> = color.chunks_exact(4).map(|t| f32::from(t[3])).collect();
    let mut chain = vec![layer];
    let mut s = size;
    while s > 1 {
        let h = s / 2;
        let texels = chain.last().expect("mip 0");
        let mut next = Vec::with_capacity((h * h) as usize);
        let mut next_w = Vec::with_capacity((h * h) as usize);
        for y in 0..h {
            for x in 0..h {
                let quad = [(0, 0), (1, 0), (0, 1), (1, 1)].map(|(dx, dy)| ((2 * y + dy) * s + 2 * x + dx) as usize);
                let w_sum: f32 = quad.iter().map(|&i| weights[i]).sum();
                let mut c = [0.0; N];
                for &i in &quad {
                    let w = if w_sum > 0.0 { weights[i] / w_sum } else { 0.25 };
                    for (k, v) in c.iter_mut().enumerate() {
                        *v += texels[i][k] * w;
                    }
                }
                next.push(c);
                next_w.push(w_sum * 0.25);
            }
        }
        weights = next_w;
        s = h;
        chain.push(next);
    }
    chain
}

/// Lays out per-layer mip chains mip-major (all layers of mip 0, then mip 1, …),
/// the order `queue.write_texture` takes for an array.
fn mip_major(chains: &[Vec<Vec<u8>>], mips: u32) -> Vec<u8> {
    let mut out = Vec::new();
    for m in 0..mips as usize {
        for chain in chains {
            out.extend_from_slice(&chain[m]);
        }
    }
    out
}

fn build_materials(model: &ImportedModel, size: u32) -> (Vec<MaterialMeta>, Option<TextureArrayMeta>, Option<Vec<u8>>) {
    // No larger than the largest source image: upscaling only costs bytes.
    let largest = model.materials.iter().filter_map(|m| m.texture.as_ref()).map(|t| t.width().max(t.height())).max();
    let size = size.max(1).next_power_of_two().min(largest.unwrap_or(1).next_power_of_two());
    let mut chains = Vec::new();
    let metas = model
        .materials
        .iter()
        .map(|m| {
            let layer = m.texture.as_ref().map(|img| {
                let resized = image::imageops::resize(img, size, size, image::imageops::FilterType::Triangle);
                let raw = resized.into_raw();
                let cutoff = (m.alpha_cutoff > 0.0).then_some(m.alpha_cutoff);
                chains.push(alpha_aware_mips(&raw, &raw, size, ColorEncoding::Srgb, cutoff));
                (chains.len() - 1) as u32
            });
            MaterialMeta {
                name: m.name.clone(),
                kind: m.kind,
                base_color: m.base_color,
                alpha_cutoff: m.alpha_cutoff,
                double_sided: m.double_sided,
                texture_layer: layer,
            }
        })
        .collect();
    if chains.is_empty() {
        return (metas, None, None);
    }
    let meta = TextureArrayMeta { size, layers: chains.len() as u32, mips: size.trailing_zeros() + 1 };
    let bytes = mip_major(&chains, meta.mips);
    (metas, Some(meta), Some(bytes))
}

/// Octahedral encoding of a unit vector into snorm8 x, y.
fn oct_encode(n: Vec3) -> [i8; 2] {
    let n = n / (n.x.abs() + n.y.abs() + n.z.abs()).max(1e-12);
    let (x, y) =
        if n.z >= 0.0 { (n.x, n.y) } else { ((1.0 - n.y.abs()) * n.x.signum(), (1.0 - n.x.abs()) * n.y.signum()) };
    [(x.clamp(-1.0, 1.0) * 127.0).round() as i8, (y.clamp(-1.0, 1.0) * 127.0).round() as i8]
}

/// One quantised, cache-optimised mesh level: metadata, vertices, indices.
/// `ao`: each vertex's own occlusion (sky visibility), when baked.
fn build_mesh_level(
    model: &ImportedModel,
    select_px: f32,
    ao: Option<&[f32]>,
) -> (MeshLevelMeta, Vec<MeshVertex>, Vec<u32>) {
    // Group triangles by material: one draw range per material.
    let mut order: Vec<usize> = (0..model.triangles.len()).collect();
    order.sort_by_key(|&t| model.vertices[model.triangles[t][0] as usize].material);
    let mut indices: Vec<u32> = Vec::with_capacity(order.len() * 3);
    let mut draws: Vec<DrawRange> = Vec::new();
    for &t in &order {
        let m = u32::from(model.vertices[model.triangles[t][0] as usize].material);
        match draws.last_mut() {
            Some(d) if d.material == m => d.index_count += 3,
            _ => draws.push(DrawRange { material: m, first_index: indices.len() as u32, index_count: 3 }),
        }
        indices.extend_from_slice(&model.triangles[t]);
    }
    // Vertex cache order within each material's range, then fetch order for all.
    for d in &draws {
        let range = d.first_index as usize..(d.first_index + d.index_count) as usize;
        let optimised = meshopt::optimize_vertex_cache(&indices[range.clone()], model.vertices.len());
        indices[range].copy_from_slice(&optimised);
    }
    let vertices: Vec<ImportedVertexPod> = model
        .vertices
        .iter()
        .enumerate()
        .map(|(i, v)| ImportedVertexPod { ao: ao.map_or(-1.0, |a| a[i]), ..ImportedVertexPod::from(v) })
        .collect();
    let vertices = meshopt::optimize_vertex_fetch(&mut indices, &vertices);
    let (mut pmin, mut pmax) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
    let (mut umin, mut umax) = (Vec2::splat(f32::MAX), Vec2::splat(f32::MIN));
    for v in &vertices {
        pmin = pmin.min(Vec3::from(v.position));
        pmax = pmax.max(Vec3::from(v.position));
        umin = umin.min(Vec2::from(v.uv));
        umax = umax.max(Vec2::from(v.uv));
    }
    if vertices.is_empty() {
        (pmin, pmax, umin, umax) = (Vec3::ZERO, Vec3::ONE, Vec2::ZERO, Vec2::ONE);
    }
    let pext = (pmax - pmin).max(Vec3::splat(1e-6));
    let uext = (umax - umin).max(Vec2::splat(1e-6));
    let q16 = |v: f32| (v.clamp(0.0, 1.0) * 65535.0).round() as u16;
    let packed: Vec<MeshVertex> = vertices
        .iter()
        .map(|v| {
            let p = (Vec3::from(v.position) - pmin) / pext;
            let uv = (Vec2::from(v.uv) - umin) / uext;
            let [ox, oy] = oct_encode(Vec3::from(v.normal));
            MeshVertex {
                position: [q16(p.x), q16(p.y), q16(p.z)],
                material: v.material as u16,
                normal_oct: [ox, oy, if v.ao < 0.0 { 0 } else { ao_to_snorm8(v.ao) }, 0],
                uv: [q16(uv.x), q16(uv.y)],
                color: v.color.map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8),
            }
        })
        .collect();
    let meta = MeshLevelMeta {
        vertex_count: packed.len() as u32,
        index_count: indices.len() as u32,
        pos_min: pmin.to_array(),
        pos_max: (pmin + pext).to_array(),
        uv_min: umin.to_array(),
        uv_max: (umin + uext).to_array(),
        draws,
        select_px,
        policy_px: None,
    };
    (meta, packed, indices)
}

/// `ImportedVertex` as plain data for meshopt's vertex fetch reordering.
#[derive(Debug, Clone, Copy, Default)]
struct ImportedVertexPod {
    position: [f32; 3],
    normal: [f32; 3],
    uv: [f32; 2],
    color: [f32; 4],
    material: u32,
    /// Own occlusion (sky visibility), negative when not baked.
    ao: f32,
}

impl From<&ImportedVertex> for ImportedVertexPod {
    fn from(v: &ImportedVertex) -> Self {
        Self {
            position: v.position.to_array(),
            normal: v.normal.to_array(),
            uv: v.uv.to_array(),
            color: v.color,
            material: u32::from(v.material),
            ao: -1.0,
        }
    }
}

/// The simplified mesh level: branches simplified to about a quarter of their
/// triangles by meshoptimizer (silhouette-preserving edge collapses), and one in
/// three leaf cards kept, each enlarged by √3 about its centre so the canopy
/// keeps its coverage (edge collapses would destroy alpha-tested cards). With
/// it, the index in `model` of each of its vertices.
pub fn simplify_model(model: &ImportedModel) -> (ImportedModel, Vec<u32>) {
    let is_leaf =
        |t: &[u32; 3]| model.materials[usize::from(model.vertices[t[0] as usize].material)].kind == MaterialKind::Leaf;
    let branch_idx: Vec<u32> = model.triangles.iter().filter(|t| !is_leaf(t)).flatten().copied().collect();
    let positions: Vec<[f32; 3]> = model.vertices.iter().map(|v| v.position.to_array()).collect();
    let mut out = ImportedModel {
        materials: model.materials.clone(),
        vertices: model.vertices.clone(),
        triangles: Vec::new(),
        notes: Vec::new(),
    };
    if !branch_idx.is_empty() {
        let adapter =
            meshopt::VertexDataAdapter::new(bytemuck::cast_slice(&positions), 12, 0).expect("12-byte positions");
        let target = (branch_idx.len() / 4 / 3 * 3).max(3);
        let simplified = meshopt::simplify(&branch_idx, &adapter, target, 0.02, meshopt::SimplifyOptions::None, None);
        out.triangles.extend(simplified.chunks_exact(3).map(|t| [t[0], t[1], t[2]]));
    }
    // Leaf cards = connected components of leaf triangles (union-find over shared vertices).
    let leaf_tris: Vec<[u32; 3]> = model.triangles.iter().filter(|t| is_leaf(t)).copied().collect();
    let mut parent: Vec<u32> = (0..model.vertices.len() as u32).collect();
    fn find(p: &mut [u32], mut x: u32) -> u32 {
        while p[x as usize] != x {
            p[x as usize] = p[p[x as usize] as usize];
            x = p[x as usize];
        }
        x
    }
    for t in &leaf_tris {
        let a = find(&mut parent, t[0]);
        for &v in &t[1..] {
            let b = find(&mut parent, v);
            parent[b as usize] = a;
        }
    }
    let mut card_of_root = std::collections::HashMap::new();
    let mut cards: Vec<Vec<[u32; 3]>> = Vec::new();
    for t in &leaf_tris {
        let root = find(&mut parent, t[0]);
        let id = *card_of_root.entry(root).or_insert_with(|| {
            cards.push(Vec::new());
            cards.len() - 1
        });
        cards[id].push(*t);
    }
    let grow = 3f32.sqrt();
    for (i, card) in cards.iter().enumerate() {
        if i % 3 != 0 {
            continue;
        }
        let mut verts: Vec<u32> = card.iter().flatten().copied().collect();
        verts.sort_unstable();
        verts.dedup();
        let centre = verts.iter().map(|&v| model.vertices[v as usize].position).sum::<Vec3>() / verts.len() as f32;
        for &v in &verts {
            let p = &mut out.vertices[v as usize].position;
            *p = centre + (*p - centre) * grow;
        }
        out.triangles.extend_from_slice(card);
    }
    // Drop unused vertices.
    let mut remap = vec![u32::MAX; out.vertices.len()];
    let mut vertices = Vec::new();
    let mut source = Vec::new();
    for t in &mut out.triangles {
        for i in t.iter_mut() {
            if remap[*i as usize] == u32::MAX {
                remap[*i as usize] = vertices.len() as u32;
                vertices.push(out.vertices[*i as usize]);
                source.push(*i);
            }
            *i = remap[*i as usize];
        }
    }
    out.vertices = vertices;
    (out, source)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn oct_encoding_round_trips_within_a_degree() {
        for n in [
            Vec3::X,
            -Vec3::Y,
            Vec3::Z,
            -Vec3::Z,
            Vec3::new(0.3, -0.5, -0.8).normalize(),
            Vec3::new(-0.7, 0.7, 0.1).normalize(),
        ] {
            let [x, y] = oct_encode(n);
            let e = Vec2::new(f32::from(x) / 127.0, f32::from(y) / 127.0);
            let mut d = Vec3::new(e.x, e.y, 1.0 - e.x.abs() - e.y.abs());
            let t = (-d.z).max(0.0);
            d.x += if d.x >= 0.0 { -t } else { t };
            d.y += if d.y >= 0.0 { -t } else { t };
            let d = d.normalize();
            assert!(d.dot(n) > 0.9995, "{n} -> {d}");
        }
    }
}
