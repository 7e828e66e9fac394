//! Builds a species' LoD pack from an imported model: mesh levels (vertex-cache
//! optimised with meshoptimizer, quantised), material textures with alpha-aware
//! mips, and the view-angle billboard array rendered by Sylva's own mesh pass.

mod impostors;
mod mesh;
mod policy;

use impostors::*;
use mesh::*;
use policy::*;

pub mod ao;
pub mod cloud;
pub mod clusters;
pub mod textures;

use anyhow::{Context, Result};
use glam::Vec3;
use sylva::format::cloud::{encode_cloud, CloudMeta};
use sylva::format::pack::{
    encode_pack, kind, BillboardMeta, MaterialKind, MaterialMeta, PackMeta, SeasonMeta, Section, TextureArrayMeta,
};
use sylva::render::capture::CapturePipelines;
use sylva::render::capture::{capture_billboards, BillboardFrame, CapturedBillboards};
use sylva::render::mips::{alpha_aware_mips, ColorEncoding};
use sylva::render::GpuContext;

use crate::input::gltf_import::ImportedModel;
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
    /// Deciduous species get their seasons (autumn colour, the bare wood's
    /// far tiers); off: every species one state, leaf-on.
    pub seasons: bool,
    /// Write the packs as they are (version 1) instead of stored, each part
    /// deflated (version 2, `sylva::format::stored`): for viewers before
    /// issue 47 and the test fixture. Not a property of the pack's content
    /// (the pack cache keeps packs as they are, whichever is written).
    pub raw_packs: bool,
    /// Block-compressed variants written beside each pack ([`textures`]):
    /// BC7 and ETC2 by default. Not a property of the pack's content either.
    pub gpu_textures: Vec<sylva::format::pack::TexelEncoding>,
    /// Capture the far tiers (billboards, impostors) of every mesh variant,
    /// not variant 0's alone: a tree's far tier then shows its own shape (the
    /// far tiers' bytes × the variants).
    pub far_variants: bool,
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
            seasons: true,
            raw_packs: false,
            gpu_textures: vec![sylva::format::pack::TexelEncoding::Bc7, sylva::format::pack::TexelEncoding::Etc2],
            far_variants: false,
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
    log: &dyn Fn(&str),
) -> Result<BuiltPack> {
    // Variant 0's bounds frame the captures (billboards, impostors, which show
    // it; the others are stretched to its height and crown width); every
    // variant's bound the tree (culling, the occlusion field, the clusters).
    let (lo, hi) = model.own_bounds();
    let (all_lo, all_hi) = model.bounds();
    let height = (hi.z - lo.z).max(1e-3);
    let (materials, texture_meta, texture_bytes) = build_materials(model, opts.texture_size);
    // The tree's own occlusion, one field for every level (mesh vertices, the
    // billboard capture through them, ellipsoids, lines).
    let started = std::time::Instant::now();
    let ao = if opts.ao { AoField::build(model) } else { AoField::open() };
    let vertex_ao: Vec<f32> = model.vertices.iter().map(|v| ao.at(v.position)).collect();
    if opts.ao {
        let (lo_v, hi_v) = vertex_ao.iter().fold((1.0f32, 0.0f32), |(a, b), v| (a.min(*v), b.max(*v)));
        log(&format!(
            "    ambient occlusion: sky visibility {lo_v:.2}–{hi_v:.2} at the vertices ({:.1} s)",
            started.elapsed().as_secs_f64()
        ));
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
    for (i, (_, vtx, idx, variants)) in levels.iter().enumerate() {
        sections.push(records(kind::MESH_VERTICES, i as u32, vtx));
        sections.push(records(kind::MESH_INDICES, i as u32, idx));
        if !variants.is_empty() {
            sections.push(records(kind::MESH_VARIANTS, i as u32, variants));
        }
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
            let (mut level, vtx, idx, _) =
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
                coverage: None,
            });
            let words = encode_cloud(&built.planes, &built.cells, &built.fragments);
            // Its coverage of the leaves, seen from the side (tested in crate::pack::cloud).
            let check = crate::pack::cloud::Cloud {
                planes: built.planes.clone(),
                cells: built.cells.clone(),
                fragments: built.fragments.clone(),
            };
            let (leaf_px, cloud_px, _) = crate::pack::cloud::view_coverage(model, &check, Vec3::X, 64);
            log(&format!(
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
            ));
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
        bounds_min: all_lo.to_array(),
        bounds_max: all_hi.to_array(),
        materials,
        material_texture: texture_meta,
        mesh_levels: levels.iter().map(|(m, _, _, _)| m.clone()).collect(),
        billboards: None,
        clusters: None,
        impostors: None,
        cloud,
        season: None,
    };
    // Capture the billboards from the mesh-only pack, through the same decoder the viewer uses.
    let mesh_only = encode_pack(&meta, &sections);
    let decoded = sylva::format::decode_pack(name, &mesh_only).context("the mesh-only pack does not validate")?;
    // The far tiers of every mesh variant (`--far-tier-variants`), else variant 0's.
    let far_variants = if opts.far_variants { model.variants.len() as u32 + 1 } else { 1 };
    // Framed on variant 0's bounds, also when every variant is captured: the
    // others are stretched to its height and crown width (a crown reaching past
    // its box on one axis is cut there; framing on every variant's bounds made
    // no difference to the stands' error and cost 50 % more time, BENCHMARKS).
    let frame = BillboardFrame::from_bounds(lo, hi);
    let mut color_chains: Vec<Vec<Vec<u8>>> = Vec::new();
    let mut normal_chains: Vec<Vec<Vec<u8>>> = Vec::new();
    let tex = TextureArrayMeta::plain(
        opts.billboard_size,
        opts.billboard_angles * opts.billboard_azimuths * far_variants,
        opts.billboard_size.trailing_zeros() + 1,
    );
    // The far tiers' states: leaf-on, and a deciduous tree's bare wood
    // (section index 1), captured the same way with the leaves left out.
    let autumn = model.autumn.filter(|_| opts.seasons);
    let states: &[bool] = if autumn.is_some() { &[true, false] } else { &[true] };
    // Texels covered over every captured view, per state.
    let mut covered = [0u64; 2];
    for (state, &leaves) in states.iter().enumerate() {
        let index = state as u32;
        if opts.far_tier.billboards() {
            let capture_size = opts.billboard_size * 2;
            // Each variant's layers after the previous one's (variant 0's alone by default).
            let mut captured = CapturedBillboards::default();
            for variant in 0..far_variants {
                let c = capture_billboards(
                    gpu,
                    pipelines,
                    &decoded,
                    &frame,
                    opts.billboard_angles,
                    opts.billboard_azimuths,
                    capture_size,
                    leaves,
                    variant,
                );
                captured.append(c);
            }
            covered[state] += captured.color.iter().flat_map(|c| c.chunks_exact(4)).filter(|t| t[3] > 0).count() as u64;
            let (color, normal, built) = billboard_sections(&captured, capture_size, tex.mips, index, opts.ao);
            sections.extend(built);
            if leaves {
                (color_chains, normal_chains) = (color, normal);
            }
        }
        if opts.far_tier.impostors() {
            let (m, imp_sections, cover) =
                build_impostors(gpu, pipelines, &decoded, (lo, hi), opts, index, leaves, far_variants);
            sections.extend(imp_sections);
            if !opts.far_tier.billboards() {
                covered[state] += cover;
            }
            if leaves {
                meta.impostors = Some(m);
            }
        }
    }
    if let Some(autumn) = autumn {
        // (A capture without any wood: no bare far tier, leaf-off draws nothing far.)
        if covered[1] == 0 {
            sections.retain(|s| !(kind::FAR_TIERS.contains(&s.kind) && s.index == 1));
        }
        let bare_far = (opts.far_tier.billboards() || opts.far_tier.impostors()) && covered[1] > 0;
        let bare_cover = if covered[0] > 0 { (covered[1] as f64 / covered[0] as f64).min(1.0) as f32 } else { 0.0 };
        if bare_far {
            log(&format!(
                "    seasons: leaf-on, autumn, leaf-off (the bare wood covers {:.0} % of the leafy crown's far views)",
                bare_cover * 100.0
            ));
        }
        meta.season = Some(SeasonMeta { autumn, bare_far, bare_cover, genus: model.genus.clone() });
    }
    if opts.clusters {
        let hopts =
            crate::pack::clusters::hierarchy::HierarchyOptions { tries: opts.cluster_tries, ..Default::default() };
        let mut cluster_log = |m: &str| log(m);
        if let Some(c) =
            crate::pack::clusters::bake::build_clusters(model, &decoded, gpu, &hopts, &ao, &mut cluster_log)?
        {
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
        variants: (far_variants > 1).then_some(far_variants),
    });
    let mut bytes = encode_pack(&meta, &sections);
    // The LoD policy: which cluster levels and whether the cloud are default
    // tiers, from their error and the far tier's at their entry sizes.
    let (levels, cloud, mesh_policy) = {
        let decoded = sylva::format::decode_pack(name, &bytes).context("the finished pack does not validate")?;
        measure_policy(gpu, &decoded, log)
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
        log(&format!("    LoD policy (error / far tier's, in modelled µs per tree): {}", report.join(", ")));
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

/// The billboard sections of far-tier state `index` (0 leaf-on, 1 the bare
/// wood) from a capture at `capture_size` (twice the stored size): colour,
/// normal and (with `ao`) occlusion, and the colour and normal mip chains.
#[allow(clippy::type_complexity)]
fn billboard_sections(
    captured: &sylva::render::capture::CapturedBillboards,
    capture_size: u32,
    mips: u32,
    index: u32,
    ao: bool,
) -> (Vec<Vec<Vec<u8>>>, Vec<Vec<Vec<u8>>>, Vec<Section>) {
    // Supersampled 2× capture: mip 1 of the alpha-aware chain is the stored mip 0,
    // so stored alpha is real coverage rather than a hard alpha test.
    let color_chains: Vec<Vec<Vec<u8>>> = captured
        .color
        .iter()
        .map(|c| alpha_aware_mips(c, c, capture_size, ColorEncoding::Srgb, Some(BILLBOARD_ALPHA_CUTOFF))[1..].to_vec())
        .collect();
    let normal_chains: Vec<Vec<Vec<u8>>> = captured
        .normal
        .iter()
        .zip(&captured.color)
        .map(|(n, c)| alpha_aware_mips(n, c, capture_size, ColorEncoding::Linear, None)[1..].to_vec())
        .collect();
    let texture = |kind, data| Section { kind, index, count: 0, stride: 0, data };
    let mut sections = vec![
        texture(kind::BILLBOARD_COLOR, mip_major(&color_chains, mips)),
        texture(kind::BILLBOARD_NORMAL, mip_major(&normal_chains, mips)),
    ];
    if ao {
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
        sections.push(texture(kind::BILLBOARD_AO, mip_major(&ao_chains, mips)));
    }
    (color_chains, normal_chains, sections)
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

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec2;

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
