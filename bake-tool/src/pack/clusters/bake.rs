//! The cluster levels of one pack: leaves → hierarchy, branches → lines, judged
//! by image error against the full mesh rendered through Sylva's own pipelines.

use std::collections::HashMap;

use anyhow::Result;
use glam::Vec3;
use sylva::format::cluster::{ClusterLevelMeta, ClusterMeta, Line, PackedEllipsoid, PackedLine};
use sylva::format::pack::{kind, AoFieldRef, MaterialKind, Section};
use sylva::format::Pack;
use sylva::metrics::multiscale_rmse;
use sylva::render::capture::{BillboardFrame, Shot, TreeDraw, TreeRenderer};
use sylva::render::cluster::ClusterGpu;
use sylva::render::mesh::MeshGpu;
use sylva::render::GpuContext;

use super::hierarchy::{build_levels, level_sizes, Candidate, HierarchyOptions, Judge};
use super::leaves::extract_leaves;
use super::lines::{simplify, skeleton, LineOptions};
use crate::input::gltf_import::ImportedModel;
use crate::pack::ao::AoField;

/// Background of the judging renders (the viewer's sky).
const BACKGROUND: [f64; 4] = [0.55, 0.68, 0.82, 1.0];

/// Views the judge compares: (elevation, azimuth) in degrees.
const VIEWS: [(f32, f32); 2] = [(0.0, 0.0), (40.0, 90.0)];

/// Judges candidates against the full mesh (level 0) of a mesh-only pack.
pub struct GpuJudge<'a> {
    ctx: &'a GpuContext,
    renderer: TreeRenderer,
    mesh: MeshGpu,
    frame: BillboardFrame,
    lo: Vec3,
    hi: Vec3,
    line_color: [f32; 3],
    /// The tree's `AOFD` section, when baked.
    ao: Option<Vec<u8>>,
    references: HashMap<u32, Vec<Vec<u8>>>,
    /// Renders made.
    pub renders: usize,
}

impl<'a> GpuJudge<'a> {
    /// A judge for the tree of `pack`.
    #[must_use]
    pub fn new(ctx: &'a GpuContext, pack: &Pack<'_>, line_color: [f32; 3], ao: &AoField) -> Self {
        let renderer = TreeRenderer::new(ctx);
        let mesh = MeshGpu::upload(&ctx.device, &ctx.queue, &renderer.mesh, pack);
        let (lo, hi) = (Vec3::from(pack.meta.bounds_min), Vec3::from(pack.meta.bounds_max));
        Self {
            ctx,
            renderer,
            mesh,
            frame: BillboardFrame::from_bounds(lo, hi),
            lo,
            hi,
            line_color,
            ao: (!ao.is_open()).then(|| ao.section_bytes()),
            references: HashMap::new(),
            renders: 0,
        }
    }

    fn image_size(&self, tree_px: u32) -> u32 {
        // The frame's quad is 2·half_height tall for a tree of height (hi − lo).z.
        let h = (self.hi.z - self.lo.z).max(1e-6);
        ((tree_px as f32 * 2.0 * self.frame.half_height / h).round() as u32).clamp(16, 512)
    }

    fn render(&self, what: &TreeDraw<'_>, size: u32) -> Vec<Vec<u8>> {
        VIEWS
            .iter()
            .map(|(e, a)| {
                let clip = self.frame.clip_from_model(e.to_radians(), a.to_radians());
                self.renderer.render(self.ctx, what, &Shot::square(clip, Vec3::ZERO, size), BACKGROUND)
            })
            .collect()
    }
}

impl Judge for GpuJudge<'_> {
    fn error(&mut self, c: &Candidate<'_>) -> f64 {
        let size = self.image_size(c.size_px);
        if !self.references.contains_key(&size) {
            let imgs = self.render(&TreeDraw::Mesh(&self.mesh, 0), size);
            self.renders += imgs.len();
            self.references.insert(size, imgs);
        }
        let gpu = ClusterGpu::from_level(
            &self.ctx.device,
            &self.ctx.queue,
            &self.renderer.cluster,
            c.ellipsoids,
            c.lines,
            (self.lo, self.hi),
            (c.noise_threshold, c.normal_blend),
            self.line_color,
            self.ao.as_deref().and_then(|b| AoFieldRef::parse(b).ok()),
        );
        let imgs = self.render(&TreeDraw::Cluster(&gpu, 0), size);
        self.renders += imgs.len();
        let refs = &self.references[&size];
        imgs.iter().zip(refs).map(|(a, b)| multiscale_rmse(a, b, size, size)).sum::<f64>() / imgs.len() as f64
    }
}

/// Mean linear albedo of the model's branch material(s), area-weighted.
#[must_use]
pub fn bark_color(model: &ImportedModel) -> [f32; 3] {
    let mut acc = Vec3::ZERO;
    let mut w = 0.0f32;
    for t in &model.triangles {
        let [a, b, c] = t.map(|i| model.vertices[i as usize]);
        let mat = &model.materials[usize::from(a.material)];
        if mat.kind != MaterialKind::Branch {
            continue;
        }
        let area = (b.position - a.position).cross(c.position - a.position).length() * 0.5;
        let tex = mat.texture.as_ref().map_or(Vec3::ONE, mean_texture_color);
        acc += tex * Vec3::from_slice(&mat.base_color[..3]) * Vec3::from_slice(&a.color[..3]) * area;
        w += area;
    }
    if w > 0.0 {
        (acc / w).to_array()
    } else {
        [0.25, 0.18, 0.12]
    }
}

fn mean_texture_color(img: &image::RgbaImage) -> Vec3 {
    let step = ((img.width() * img.height()) as usize / 4096).max(1);
    let (mut acc, mut n) = (Vec3::ZERO, 0.0f32);
    for p in img.pixels().step_by(step) {
        acc +=
            Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32).map(|v| sylva::format::cluster::srgb_to_linear(v / 255.0));
        n += 1.0;
    }
    acc / n.max(1.0)
}

/// What [`build_clusters`] made.
pub struct BuiltClusters {
    /// Metadata for `META.clusters`.
    pub meta: ClusterMeta,
    /// `ELPS` and `LINE` sections, and `AOFD` when the occlusion is baked.
    pub sections: Vec<Section>,
}

/// Builds the cluster levels of `model`, judged against the mesh of `mesh_pack`.
/// `None` when the model has no leaves.
///
/// # Errors
/// Never at present; reserved for GPU failures.
pub fn build_clusters(
    model: &ImportedModel,
    mesh_pack: &Pack<'_>,
    ctx: &GpuContext,
    opts: &HierarchyOptions,
    ao: &AoField,
    log: &mut dyn FnMut(&str),
) -> Result<Option<BuiltClusters>> {
    let started = std::time::Instant::now();
    let leaves = extract_leaves(model);
    if leaves.is_empty() {
        return Ok(None);
    }
    let (lo, hi) = (Vec3::from(mesh_pack.meta.bounds_min), Vec3::from(mesh_pack.meta.bounds_max));
    let sizes = level_sizes(leaves.len());
    let sk = skeleton(model);
    // One line level per ellipsoid level, each a quarter of the last.
    let targets: Vec<usize> = (0..sizes.len()).map(|k| (sk.len() >> (2 * (k + 1)).min(62)).max(1)).collect();
    let line_levels =
        if sk.is_empty() { Vec::new() } else { simplify(&sk, &targets, (lo, hi), &LineOptions::default()) };
    let lines: Vec<Vec<Line>> = line_levels.iter().map(|l| l.lines.clone()).collect();
    let line_color = bark_color(model);
    let mut judge = GpuJudge::new(ctx, mesh_pack, line_color, ao);
    let height = (hi.z - lo.z).max(1e-3);
    let levels = build_levels(&leaves, height, &lines, &mut judge, opts, &mut |k, n| {
        if k < n {
            log(&format!("    cluster level {}/{n}: {} ellipsoids", k + 1, sizes[k]));
        }
    });
    log(&format!(
        "    clusters: {} leaves, {} skeleton lines → {} levels in {:.1} s ({} judging renders)",
        leaves.len(),
        sk.len(),
        levels.len(),
        started.elapsed().as_secs_f64(),
        judge.renders
    ));
    let mut sections = Vec::new();
    for (k, l) in levels.iter().enumerate() {
        let data: Vec<u8> = l
            .ellipsoids
            .iter()
            .flat_map(|e| bytemuck::bytes_of(&PackedEllipsoid::encode(e, lo, hi)).to_vec())
            .collect();
        sections.push(Section {
            kind: kind::ELLIPSOIDS,
            index: k as u32,
            count: l.ellipsoids.len() as u32,
            stride: 24,
            data,
        });
    }
    let mut line_meta = Vec::new();
    for (k, l) in line_levels.iter().enumerate() {
        let data: Vec<u8> =
            l.lines.iter().flat_map(|x| bytemuck::bytes_of(&PackedLine::encode(x, lo, hi)).to_vec()).collect();
        sections.push(Section { kind: kind::LINES, index: k as u32, count: l.lines.len() as u32, stride: 16, data });
        line_meta.push(ClusterLevelMeta {
            count: l.lines.len() as u32,
            select_px: levels.get(k).map_or(0.0, |e| e.meta.select_px),
            error: l.error as f32,
            noise_threshold: 0.0,
            normal_blend: 0.0,
            pareto_error: None,
            pareto_cost: None,
        });
    }
    // The occlusion field ellipsoids and lines sample per pixel, with the cluster part.
    if !ao.is_open() {
        sections.push(Section { kind: kind::AO_FIELD, index: 0, count: 0, stride: 0, data: ao.section_bytes() });
    }
    Ok(Some(BuiltClusters {
        meta: ClusterMeta {
            ellipsoid_levels: levels.iter().map(|l| l.meta.clone()).collect(),
            line_levels: line_meta,
            line_color,
        },
        sections,
    }))
}
