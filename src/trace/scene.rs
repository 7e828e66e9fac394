//! The tracer's two levels (Dietrich et al. 2005, §4.1): each species' BVH
//! ([`Bvh`], in model space) once, and a top-level hierarchy over the trees —
//! instances that place a species with the raster path's own transform
//! (`shaders/mesh.wgsl`: model xy scaled by scale × crown aspect, z by scale,
//! turned by yaw about +Z, then moved to the tree's position). A ray that
//! enters a tree's box is carried into the species' model space and walked
//! there; its parameter `t` is the same in both spaces (the map is affine and
//! the direction is not renormalised).
//!
//! [`TraceScene::intersect`] is the twin of `trace_scene` in `shaders/trace_scene.wgsl`.

use glam::Vec3;

use super::bvh::{build_nodes, mesh_surfaces, mesh_triangles, walk, Bvh, BvhNode, GpuTriangle};
use super::{Hit, Ray};
use crate::format::pack::{kind, Pack};

/// A tree as the tracer places it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Instance {
    /// Where the trunk's base stands (the scene's frame, metres).
    pub position: Vec3,
    /// Turn about +Z, radians.
    pub yaw: f32,
    /// Height scale of the species model.
    pub scale: f32,
    /// Horizontal over vertical scale (1 without crown data).
    pub aspect: f32,
    /// Index into the scene's species.
    pub species: u32,
    /// The tree's tint as the raster gives it (`variation_tint` in
    /// `shaders/light.wgsl`): its variation + 1, 0 for none (the terrain).
    pub tint: u8,
}

/// An instance as the GPU reads it. Must match `TraceInstance` in `shaders/trace_scene.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuInstance {
    /// Where the trunk's base stands.
    pub position: [f32; 3],
    /// Turn about +Z, radians.
    pub yaw: f32,
    /// Model xy → scene: scale × aspect.
    pub scale_xy: f32,
    /// Model z → scene: scale.
    pub scale_z: f32,
    /// Index into the species table (bits 0–23) and the tree's tint (24–31,
    /// [`Instance::tint`]): [`Self::species_index`], [`Self::tint`].
    pub species: u32,
    /// The instance's index in the list it was built from.
    pub id: u32,
}

/// Where a species' hierarchy and materials start in the concatenated
/// arrays, and how its texture coordinates dequantise. Must match
/// `TraceSpecies` in `shaders/trace_scene.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuSpeciesBvh {
    /// First node.
    pub node_base: u32,
    /// First triangle.
    pub tri_base: u32,
    /// Nodes (0: a species without triangles; its trees are never hit).
    pub node_count: u32,
    /// First material.
    pub material_base: u32,
    /// Texture coordinates: `uv_min + q / 65535 · uv_extent` (as `mesh.wgsl`).
    pub uv_min: [f32; 2],
    /// See `uv_min`.
    pub uv_extent: [f32; 2],
}

/// A material as the tracer reads it. Must match `TraceMaterial` in
/// `shaders/trace_scene.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuTraceMaterial {
    /// Linear RGBA factor (× the texture).
    pub base_color: [f32; 4],
    /// A hit whose alpha is below this is passed through (leaf cards).
    pub alpha_cutoff: f32,
    /// First texel of its texture's full-resolution layer in the texel
    /// array (RGBA8, one u32 each, rows of `size`), or `NO_TEXTURE`.
    pub texel_base: u32,
    /// The texture's side in texels (0 untextured).
    pub size: u32,
    /// 0 leaf, 1 branch (`MaterialKind`).
    pub kind: u32,
}

/// `GpuTraceMaterial::texel_base` of an untextured material.
pub const NO_TEXTURE: u32 = u32::MAX;

/// One species as the tracer holds it: its hierarchy in model space, its
/// materials and their textures' full-resolution texels.
#[derive(Debug, Clone, Default)]
pub struct TraceSpecies {
    /// The hierarchy over the full mesh.
    pub bvh: Bvh,
    /// Materials (`texel_base` into `texels`).
    pub materials: Vec<GpuTraceMaterial>,
    /// The material textures' mip 0, every layer, RGBA8 as u32 (r low);
    /// shared by a species' variants (uploaded once).
    pub texels: std::sync::Arc<Vec<u32>>,
    /// Texture coordinates' dequantisation: minimum.
    pub uv_min: [f32; 2],
    /// Texture coordinates' dequantisation: extent.
    pub uv_extent: [f32; 2],
}

impl TraceSpecies {
    /// A species drawn by `bvh` alone: one opaque untextured material.
    #[must_use]
    pub fn opaque(bvh: Bvh) -> Self {
        let material = GpuTraceMaterial { base_color: [1.0; 4], texel_base: NO_TEXTURE, ..Default::default() };
        Self { bvh, materials: vec![material], texels: Default::default(), uv_min: [0.0; 2], uv_extent: [1.0; 2] }
    }

    /// The species of a decoded pack: its full mesh (level 0), materials and
    /// material textures at full resolution.
    ///
    /// # Errors
    /// See [`Self::of_pack_variants`].
    pub fn of_pack(pack: &Pack<'_>) -> Result<Self, String> {
        Ok(Self::of_pack_variants(pack, |v, _| v == 0)?.swap_remove(0).unwrap_or_default())
    }

    /// The shapes of a decoded pack's full mesh (level 0) that `wanted(variant,
    /// extra shapes the level has)` asks for: variant 0 its own vertices, 1… the library's other shapes
    /// of the tree (`MVAR`; a tree draws [`variant_of`](crate::format::mesh::variant_of)
    /// `(variation, variants)`, as the raster's `mesh.wgsl` does). Each its
    /// own BVH; the materials and textures (at full resolution) shared.
    ///
    /// # Errors
    /// A pack without a mesh, or whose material textures are block-encoded
    /// (trace the plain pack).
    pub fn of_pack_variants(pack: &Pack<'_>, wanted: impl Fn(u32, u32) -> bool) -> Result<Vec<Option<Self>>, String> {
        use crate::format::mesh::VariantVertex;
        let meta = &pack.meta;
        let level = meta.mesh_levels.first().ok_or_else(|| format!("{}: no mesh to trace", meta.name))?;
        let (vertices, indices) = (pack.mesh_vertices(0), pack.mesh_indices(0));
        let shapes: Vec<VariantVertex> =
            pack.section(kind::MESH_VARIANTS, 0).map(bytemuck::pod_collect_to_vec).unwrap_or_default();
        let n = vertices.len();
        let extra = shapes.len().checked_div(n).map_or(0, |k| (level.variants as usize).min(k));
        let surfaces = mesh_surfaces(&vertices, &indices);
        let bvh_of = |v: usize| {
            if v == 0 {
                return Bvh::build_with(&mesh_triangles(level, &vertices, &indices), &surfaces);
            }
            let mut moved = vertices.clone();
            for (m, w) in moved.iter_mut().zip(&shapes[(v - 1) * n..v * n]) {
                m.position = w.position;
            }
            Bvh::build_with(&mesh_triangles(level, &moved, &indices), &surfaces)
        };
        let mut texels = Vec::new();
        let mut layer_base = Vec::new();
        if let Some(t) = &meta.material_texture {
            if let Some(e) = t.encoding {
                return Err(format!("{}: its textures are {} blocks; trace the plain pack", meta.name, e.name()));
            }
            let bytes = pack.section(kind::MATERIAL_TEXTURES, 0).unwrap_or_default();
            let layer_bytes = (t.size as usize).pow(2) * 4;
            for l in 0..t.layers as usize {
                layer_base.push(texels.len() as u32);
                let layer = bytes
                    .get(l * layer_bytes..(l + 1) * layer_bytes)
                    .ok_or_else(|| format!("{}: texture layer {l} missing", meta.name))?;
                texels.extend(layer.chunks_exact(4).map(|p| u32::from_le_bytes([p[0], p[1], p[2], p[3]])));
            }
        }
        let size = meta.material_texture.map_or(0, |t| t.size);
        let materials: Vec<GpuTraceMaterial> = meta
            .materials
            .iter()
            .map(|m| {
                let base = m.texture_layer.and_then(|l| layer_base.get(l as usize).copied());
                GpuTraceMaterial {
                    base_color: m.base_color,
                    alpha_cutoff: m.alpha_cutoff,
                    texel_base: base.unwrap_or(NO_TEXTURE),
                    size: if base.is_some() { size } else { 0 },
                    kind: match m.kind {
                        crate::format::mesh::MaterialKind::Branch => 1,
                        _ => 0,
                    },
                }
            })
            .collect();
        let uv_extent = [level.uv_max[0] - level.uv_min[0], level.uv_max[1] - level.uv_min[1]];
        let texels = std::sync::Arc::new(texels);
        Ok((0..=extra)
            .map(|v| {
                wanted(v as u32, extra as u32).then(|| Self {
                    bvh: bvh_of(v),
                    materials: materials.clone(),
                    texels: texels.clone(),
                    uv_min: level.uv_min,
                    uv_extent,
                })
            })
            .collect())
    }

    /// A hit's texture coordinate on `tri` at barycentric (u, v), dequantised
    /// as `mesh.wgsl` does. Twin: `trace_uv` in `shaders/trace_scene.wgsl`.
    #[must_use]
    pub fn uv(&self, tri: &GpuTriangle, u: f32, v: f32) -> [f32; 2] {
        let corner = |q: u32| {
            [
                self.uv_min[0] + (q & 0xffff) as f32 / 65535.0 * self.uv_extent[0],
                self.uv_min[1] + (q >> 16) as f32 / 65535.0 * self.uv_extent[1],
            ]
        };
        let (a, b, c) = (corner(tri.uv[0]), corner(tri.uv[1]), corner(tri.uv[2]));
        let w = 1.0 - u - v;
        [w * a[0] + u * b[0] + v * c[0], w * a[1] + u * b[1] + v * c[1]]
    }

    /// Whether a hit on `tri` at (u, v) is kept: the material's alpha (× its
    /// texture's, bilinear at full resolution, repeating, as the raster
    /// reference samples it) at least its cutoff. Twin: `trace_keeps` in
    /// `shaders/trace_scene.wgsl`.
    #[must_use]
    pub fn keeps(&self, tri: &GpuTriangle, u: f32, v: f32) -> bool {
        let Some(m) = self.materials.get(tri.material as usize) else { return true };
        let mut alpha = m.base_color[3] * (tri.color >> 24) as f32 / 255.0;
        if m.texel_base != NO_TEXTURE && m.size > 0 {
            alpha *= texel_alpha(&self.texels, m.texel_base, m.size, self.uv(tri, u, v));
        }
        alpha >= m.alpha_cutoff
    }

    /// The nearest kept hit of a model-space ray.
    #[must_use]
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        self.bvh.intersect_where(ray, |t, u, v| self.keeps(t, u, v))
    }
}

/// Alpha (0–1) of a texture layer (`size`² RGBA8 texels from `base`) at `uv`,
/// bilinear between the four nearest texel centres, repeating at the edges.
/// Twin: `texel_alpha` in `shaders/trace_scene.wgsl`.
#[must_use]
pub fn texel_alpha(texels: &[u32], base: u32, size: u32, uv: [f32; 2]) -> f32 {
    let n = size as i32;
    // Wrapped first (repeating), so the texel indices stay small whatever the uv.
    let x = (uv[0] - uv[0].floor()) * size as f32 - 0.5;
    let y = (uv[1] - uv[1].floor()) * size as f32 - 0.5;
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let a = |dx: i32, dy: i32| {
        let tx = (x0 as i32 + dx).rem_euclid(n);
        let ty = (y0 as i32 + dy).rem_euclid(n);
        let t = texels.get((base + (ty * n + tx) as u32) as usize).copied().unwrap_or(0);
        (t >> 24) as f32 / 255.0
    };
    let top = a(0, 0) + (a(1, 0) - a(0, 0)) * fx;
    let bottom = a(0, 1) + (a(1, 1) - a(0, 1)) * fx;
    top + (bottom - top) * fy
}

/// The nearest hit in a scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SceneHit {
    /// The instance hit (its index in the list the scene was built from).
    pub instance: u32,
    /// Its place in [`TraceScene::instances`].
    pub slot: u32,
    /// The hit on its species' mesh.
    pub hit: Hit,
}

/// Both levels, in the arrays the GPU reads.
#[derive(Debug, Clone, Default)]
pub struct TraceScene {
    /// Per species its hierarchy (model space), materials and textures.
    pub species: Vec<TraceSpecies>,
    /// The top level over the instances; a leaf's `first..first + count` index `instances`.
    pub top: Vec<BvhNode>,
    /// The instances in the top level's leaf order.
    pub instances: Vec<GpuInstance>,
}

impl GpuInstance {
    /// `inst` as the GPU reads it, with its index `id`.
    #[must_use]
    pub fn of(inst: &Instance, id: u32) -> Self {
        Self {
            position: inst.position.into(),
            yaw: inst.yaw,
            scale_xy: inst.scale * inst.aspect,
            scale_z: inst.scale,
            species: (inst.species & 0xff_ffff) | (u32::from(inst.tint) << 24),
            id,
        }
    }

    /// Its species' index.
    #[must_use]
    pub fn species_index(&self) -> u32 {
        self.species & 0xff_ffff
    }

    /// Its tint (variation + 1; 0 none).
    #[must_use]
    pub fn tint(&self) -> u32 {
        self.species >> 24
    }

    /// A scene-space ray carried into the species' model space: the same `t`
    /// reaches the same point. Twin: `to_model` in `shaders/trace_scene.wgsl`.
    #[must_use]
    pub fn to_model(&self, ray: &Ray) -> Ray {
        let (s, c) = self.yaw.sin_cos();
        let inv_scale = Vec3::new(1.0 / self.scale_xy, 1.0 / self.scale_xy, 1.0 / self.scale_z);
        // The inverse turn (by −yaw), then the inverse scale.
        let unturn = |v: Vec3| Vec3::new(c * v.x + s * v.y, -s * v.x + c * v.y, v.z) * inv_scale;
        Ray { origin: unturn(ray.origin - Vec3::from(self.position)), dir: unturn(ray.dir), t_max: ray.t_max }
    }

    /// A model-space point placed in the scene (the raster path's transform).
    #[must_use]
    pub fn to_scene(&self, p: Vec3) -> Vec3 {
        let (s, c) = self.yaw.sin_cos();
        let v = Vec3::new(p.x * self.scale_xy, p.y * self.scale_xy, p.z * self.scale_z);
        Vec3::new(c * v.x - s * v.y, s * v.x + c * v.y, v.z) + Vec3::from(self.position)
    }
}

impl TraceScene {
    /// The trees of `instances` ready for the GPU's top-level build
    /// (`render::top_level`): the instances of a species index past the list,
    /// of a species without nodes, or with a non-finite or non-positive
    /// transform left out, the rest in their order; `top` empty (the CPU's
    /// walk then meets nothing: [`Self::build`] builds its own).
    #[must_use]
    pub fn place(species: Vec<TraceSpecies>, instances: &[Instance]) -> Self {
        let instances = instances
            .iter()
            .enumerate()
            .filter(|(_, inst)| {
                let g = GpuInstance::of(inst, 0);
                let has_nodes = species.get(inst.species as usize).is_some_and(|s| !s.bvh.nodes.is_empty());
                // (A scale past 10,000 — a hostile tile's — would place corners at infinity.)
                let scaled = g.scale_xy > 0.0 && g.scale_z > 0.0 && g.scale_xy < 1e4 && g.scale_z < 1e4;
                has_nodes && inst.position.is_finite() && inst.yaw.is_finite() && scaled
            })
            .map(|(i, inst)| GpuInstance::of(inst, i as u32))
            .collect();
        Self { species, top: Vec::new(), instances }
    }

    /// The trees the GPU's top level is built over and whether the ground
    /// stands beside them: the last instance is the ground where it has no
    /// tint (the terrain, `load`) and trees precede it. `None`: no instances.
    #[must_use]
    pub fn top_level_trees(&self) -> Option<(u32, bool)> {
        let n = self.instances.len() as u32;
        let ground = n > 1 && self.instances.last().is_some_and(|i| i.tint() == 0);
        (n > 0).then_some((n - u32::from(ground), ground))
    }

    /// [`Self::place`] with the top level built on the CPU (the binned
    /// surface area heuristic over the trees' placed boxes): the twin the
    /// tests walk beside the GPU's build.
    #[must_use]
    pub fn build(species: Vec<TraceSpecies>, instances: &[Instance]) -> Self {
        Self::place(species, instances).with_cpu_top()
    }

    /// The scene with its top level built on the CPU by the binned surface
    /// area heuristic (its instances in the leaves' order): [`Self::build`]'s
    /// second half, and `sylva render --path-trace --top-level cpu`.
    #[must_use]
    pub fn with_cpu_top(self) -> Self {
        let boxes: Vec<(Vec3, Vec3)> = self.instances.iter().map(|g| self.placed_box(g)).collect();
        let (top, order) = build_nodes(&boxes);
        let instances = order.iter().map(|&i| self.instances[i as usize]).collect();
        Self { species: self.species, top, instances }
    }

    /// A tree's species box placed: the box around its eight corners. Twin:
    /// `placed_box` in `shaders/top_level.wgsl`.
    #[must_use]
    pub fn placed_box(&self, g: &GpuInstance) -> (Vec3, Vec3) {
        let root = self.species[g.species_index() as usize].bvh.nodes[0];
        let (lo, hi) = (Vec3::from(root.min), Vec3::from(root.max));
        let (mut min, mut max) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for k in 0..8 {
            let corner = Vec3::new(
                if k & 1 == 0 { lo.x } else { hi.x },
                if k & 2 == 0 { lo.y } else { hi.y },
                if k & 4 == 0 { lo.z } else { hi.z },
            );
            let p = g.to_scene(corner);
            min = min.min(p);
            max = max.max(p);
        }
        (min, max)
    }

    /// The nearest hit of a scene-space `ray`: the top level walked front to
    /// back, each tree entered walked in its species' model space.
    /// Twin: `trace_scene` in `shaders/trace_scene.wgsl`.
    #[must_use]
    pub fn intersect(&self, ray: &Ray) -> Option<SceneHit> {
        let mut best = None;
        walk(&self.top, ray, |first, count, closest| {
            let mut nearer = None;
            for (k, inst) in self.instances[first as usize..(first + count) as usize].iter().enumerate() {
                let mut model = inst.to_model(ray);
                model.t_max = nearer.unwrap_or(closest);
                if let Some(hit) = self.species[inst.species_index() as usize].intersect(&model) {
                    nearer = Some(hit.t);
                    best = Some(SceneHit { instance: inst.id, slot: first + k as u32, hit });
                }
            }
            nearer
        });
        best
    }

    /// Bytes of everything the GPU reads ([`Self::arrays`] and the
    /// instances), counted without concatenating anything.
    #[must_use]
    pub fn gpu_bytes(&self) -> u64 {
        let mut last: Option<&std::sync::Arc<Vec<u32>>> = None;
        let species: usize = self
            .species
            .iter()
            .map(|s| {
                // (A variant's texels are its species', which it follows.)
                let shared = last.is_some_and(|t| std::sync::Arc::ptr_eq(t, &s.texels));
                last = Some(&s.texels);
                let texels = if shared { 0 } else { s.texels.len() * 4 };
                std::mem::size_of_val(&s.bvh.nodes[..])
                    + std::mem::size_of_val(&s.bvh.triangles[..])
                    + std::mem::size_of_val(&s.materials[..])
                    + texels
            })
            .sum();
        // (An unbuilt top level: the nodes the GPU's build makes, 2n − 1 for
        // n instances with or without the ground beside the trees.)
        let top = if self.top.is_empty() { (2 * self.instances.len()).saturating_sub(1) } else { self.top.len() };
        (species + top * std::mem::size_of::<BvhNode>() + std::mem::size_of_val(&self.instances[..])) as u64
    }

    /// Everything the GPU reads, concatenated: the species' nodes then the
    /// top level's (from `top_base`), their triangles, the species table,
    /// materials (texel bases made global) and texels.
    #[must_use]
    pub fn arrays(&self) -> TraceArrays {
        let mut a = TraceArrays::default();
        // Texels uploaded once for a species and its variants (which follow it).
        let mut shared: Option<(&std::sync::Arc<Vec<u32>>, u32)> = None;
        for s in &self.species {
            a.species.push(GpuSpeciesBvh {
                node_base: a.nodes.len() as u32,
                tri_base: a.triangles.len() as u32,
                node_count: s.bvh.nodes.len() as u32,
                material_base: a.materials.len() as u32,
                uv_min: s.uv_min,
                uv_extent: s.uv_extent,
            });
            let texel_base = match shared.filter(|(t, _)| std::sync::Arc::ptr_eq(t, &s.texels)) {
                Some((_, base)) => base,
                None => {
                    let base = a.texels.len() as u32;
                    a.texels.extend_from_slice(&s.texels);
                    base
                }
            };
            shared = Some((&s.texels, texel_base));
            a.materials.extend(s.materials.iter().map(|m| GpuTraceMaterial {
                texel_base: if m.texel_base == NO_TEXTURE { NO_TEXTURE } else { m.texel_base + texel_base },
                ..*m
            }));
            a.nodes.extend_from_slice(&s.bvh.nodes);
            a.triangles.extend_from_slice(&s.bvh.triangles);
        }
        a.top_base = a.nodes.len() as u32;
        a.nodes.extend_from_slice(&self.top);
        a
    }
}

/// A scene's arrays as the GPU binds them (`TraceScene::arrays`).
#[derive(Debug, Clone, Default)]
pub struct TraceArrays {
    /// Every species' nodes, then the top level's.
    pub nodes: Vec<BvhNode>,
    /// Where the top level starts in `nodes`.
    pub top_base: u32,
    /// Every species' triangles.
    pub triangles: Vec<GpuTriangle>,
    /// Per species its offsets.
    pub species: Vec<GpuSpeciesBvh>,
    /// Every species' materials.
    pub materials: Vec<GpuTraceMaterial>,
    /// Every species' texels.
    pub texels: Vec<u32>,
}

/// A pack's bytes with one more shape of its full mesh (`MVAR`, variant 1):
/// the tree at half its height (z quantised to half). For tests.
#[cfg(test)]
pub(crate) fn with_a_squat_variant(bytes: &[u8]) -> Vec<u8> {
    use crate::format::mesh::VariantVertex;
    use crate::format::pack::{decode_pack, encode_pack, Section};
    let pack = decode_pack("a pack", bytes).unwrap();
    let squat: Vec<VariantVertex> = pack
        .mesh_vertices(0)
        .iter()
        .map(|v| VariantVertex { position: [v.position[0], v.position[1], v.position[2] / 2], normal_oct: [0, 0] })
        .collect();
    let mut meta = pack.meta.clone();
    meta.mesh_levels[0].variants = 1;
    let mut sections: Vec<Section> = pack
        .sections
        .iter()
        .filter(|(e, _)| e.kind != kind::META)
        .map(|(e, d)| Section { kind: e.kind, index: e.index, count: e.count, stride: e.stride, data: d.to_vec() })
        .collect();
    sections.push(Section {
        kind: kind::MESH_VARIANTS,
        index: 0,
        count: squat.len() as u32,
        stride: 8,
        data: bytemuck::cast_slice(&squat).to_vec(),
    });
    encode_pack(&meta, &sections)
}

#[cfg(test)]
mod tests {
    use super::super::Triangle;
    use super::*;

    /// A unit "tree": one upright triangle in the xz plane, 1 m wide, 2 m tall.
    fn tree() -> Bvh {
        Bvh::build(&[Triangle::new(Vec3::new(-0.5, 0.0, 0.0), Vec3::new(0.5, 0.0, 0.0), Vec3::new(0.0, 0.0, 2.0))])
    }

    #[test]
    fn a_ray_meets_a_placed_tree_where_the_raster_path_draws_it() {
        let inst =
            Instance { position: Vec3::new(10.0, 5.0, 1.0), yaw: 0.3, scale: 2.0, aspect: 1.5, species: 0, tint: 0 };
        let scene = TraceScene::build(vec![TraceSpecies::opaque(tree())], &[inst]);
        // The model point (0.1, 0, 1) placed as mesh.wgsl places it.
        let g = scene.instances[0];
        let target = g.to_scene(Vec3::new(0.1, 0.0, 1.0));
        let origin = target + Vec3::new(-3.0, -7.0, 0.5);
        let hit = scene.intersect(&Ray { origin, dir: target - origin, t_max: 2.0 }).expect("hit");
        assert_eq!(hit.instance, 0);
        assert!((hit.hit.t - 1.0).abs() < 1e-5, "t {}", hit.hit.t);
        // Beside the crown (model x 0.6 > its half width 0.5 at that height): a miss.
        let beside = g.to_scene(Vec3::new(0.6, 0.0, 1.0));
        assert!(scene.intersect(&Ray { origin, dir: beside - origin, t_max: 2.0 }).is_none());
    }

    /// A library species' other shapes (`MVAR`) traced as the raster draws
    /// them: each its own BVH, materials and textures shared (uploaded once),
    /// a tree of a variation taking the shape `variant_of` gives it.
    #[test]
    fn a_species_variants_are_traced_each_with_its_own_shape() {
        use crate::format::mesh::variant_of;
        use crate::format::pack::decode_pack;
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/forest-small/species/beech.pack");
        let bytes = with_a_squat_variant(&std::fs::read(path).expect("fixture pack (make fixtures)"));
        let pack = decode_pack("squat beech", &bytes).unwrap();
        let shapes = TraceSpecies::of_pack_variants(&pack, |_, extra| extra == 1).unwrap();
        assert_eq!(shapes.len(), 2);
        let (own, squat) = (shapes[0].clone().unwrap(), shapes[1].clone().unwrap());
        let height = |s: &TraceSpecies| s.bvh.nodes[0].max[2] - s.bvh.nodes[0].min[2];
        assert!((height(&squat) / height(&own) - 0.5).abs() < 0.05, "{} vs {}", height(&squat), height(&own));
        assert!(std::sync::Arc::ptr_eq(&own.texels, &squat.texels) && !own.texels.is_empty());
        assert_eq!(own.materials, squat.materials);
        // Only the shapes asked for are built.
        let some = TraceSpecies::of_pack_variants(&pack, |v, _| v == 1).unwrap();
        assert!(some[0].is_none() && some[1].is_some());
        // A tree of variation 15 draws variant 0, of 16 variant 1.
        assert_eq!((variant_of(15, 1), variant_of(16, 1)), (0, 1));
        let trees: Vec<Instance> = [0, 1]
            .iter()
            .map(|&v| Instance {
                position: Vec3::new(10.0 * v as f32, 0.0, 0.0),
                yaw: 0.0,
                scale: 1.0,
                aspect: 1.0,
                species: v,
                tint: 16 + v as u8,
            })
            .collect();
        let scene = TraceScene::build(vec![own.clone(), squat], &trees);
        let a = scene.arrays();
        // The texels once; both shapes' materials reading them.
        assert_eq!(a.texels.len(), own.texels.len());
        assert_eq!(a.materials.len(), 2 * own.materials.len());
        assert_eq!(a.materials[..own.materials.len()], a.materials[own.materials.len()..]);
        assert_eq!(scene.gpu_bytes() as usize, {
            let b = |s: &TraceSpecies| {
                std::mem::size_of_val(&s.bvh.nodes[..])
                    + std::mem::size_of_val(&s.bvh.triangles[..])
                    + std::mem::size_of_val(&s.materials[..])
            };
            scene.species.iter().map(b).sum::<usize>()
                + own.texels.len() * 4
                + std::mem::size_of_val(&scene.top[..])
                + std::mem::size_of_val(&scene.instances[..])
        });
        // A ray at three quarters of the tree's height meets the tall one, passes over the squat one.
        let z = own.bvh.nodes[0].max[2] * 0.75;
        let across = |x: f32| Ray { origin: Vec3::new(x, -30.0, z), dir: Vec3::Y, t_max: 60.0 };
        let hits = (0..40).filter(|k| scene.intersect(&across(-1.0 + *k as f32 * 0.05)).is_some()).count();
        let squat_hits = (0..40).filter(|k| scene.intersect(&across(9.0 + *k as f32 * 0.05)).is_some()).count();
        assert!(hits > 5 && squat_hits == 0, "tall {hits}, squat {squat_hits}");
    }

    #[test]
    fn the_nearest_of_many_trees_is_found_as_a_scan_finds_it() {
        let mut rng = super::super::Xorshift32(0x2545_f491);
        let mut unit = move || rng.unit();
        let trees: Vec<Instance> = (0..400)
            .map(|i| Instance {
                tint: 0,
                position: Vec3::new(unit() * 60.0, unit() * 60.0, unit()),
                yaw: unit() * std::f32::consts::TAU,
                scale: 0.5 + unit() * 3.0,
                aspect: 0.7 + unit() * 0.6,
                species: i % 2,
            })
            .collect();
        let scene = TraceScene::build(vec![TraceSpecies::opaque(tree()), TraceSpecies::opaque(tree())], &trees);
        assert_eq!(scene.instances.len(), 400);
        let mut hits = 0;
        let one = tree();
        for _ in 0..1000 {
            let origin = Vec3::new(unit() * 80.0 - 10.0, unit() * 80.0 - 10.0, 0.5 + unit() * 4.0);
            let target = Vec3::new(unit() * 60.0, unit() * 60.0, unit() * 3.0);
            let ray = Ray { origin, dir: target - origin, t_max: 3.0 };
            // The scan: every tree, in its model space.
            let mut scan: Option<(f32, u32)> = None;
            for (i, t) in trees.iter().enumerate() {
                let mut m = GpuInstance::of(t, i as u32).to_model(&ray);
                m.t_max = scan.map_or(ray.t_max, |s| s.0);
                if let Some(h) = one.intersect(&m) {
                    scan = Some((h.t, i as u32));
                }
            }
            let found = scene.intersect(&ray).map(|h| (h.hit.t, h.instance));
            assert_eq!(found, scan, "{ray:?}");
            hits += usize::from(found.is_some());
        }
        assert!(hits > 50, "{hits} of 1000 rays hit a tree");
    }

    #[test]
    fn bad_instances_are_left_out() {
        let ok = Instance { position: Vec3::ZERO, yaw: 0.0, scale: 1.0, aspect: 1.0, species: 0, tint: 0 };
        let scene = TraceScene::build(
            vec![TraceSpecies::opaque(tree())],
            &[
                ok,
                Instance { species: 7, ..ok },
                Instance { scale: 0.0, ..ok },
                Instance { position: Vec3::new(f32::NAN, 0.0, 0.0), ..ok },
                Instance { aspect: f32::INFINITY, ..ok },
            ],
        );
        assert_eq!(scene.instances.iter().map(|i| i.id).collect::<Vec<_>>(), vec![0]);
        assert!(TraceScene::build(vec![TraceSpecies::opaque(tree())], &[])
            .intersect(&Ray { origin: Vec3::ZERO, dir: Vec3::X, t_max: 1.0 })
            .is_none());
    }

    #[test]
    fn a_leaf_card_is_hit_where_its_texture_is_opaque_and_passed_where_not() {
        use super::super::bvh::TriangleSurface;
        // A 1 × 1 card in the xz plane, uv = (x, z); a 4² texture whose left
        // half is opaque, right half clear.
        let card = [
            Triangle::new(Vec3::ZERO, Vec3::X, Vec3::new(1.0, 0.0, 1.0)),
            Triangle::new(Vec3::ZERO, Vec3::new(1.0, 0.0, 1.0), Vec3::Z),
        ];
        let q = |u: f32, v: f32| (u * 65535.0) as u32 | (((v * 65535.0) as u32) << 16);
        let surfaces = [
            TriangleSurface { material: 0, uv: [q(0.0, 0.0), q(1.0, 0.0), q(1.0, 1.0)], color: u32::MAX },
            TriangleSurface { material: 0, uv: [q(0.0, 0.0), q(1.0, 1.0), q(0.0, 1.0)], color: u32::MAX },
        ];
        let texels: Vec<u32> = (0..16).map(|i| if i % 4 < 2 { 0xff00_ff00 } else { 0x0000_ff00 }).collect();
        let species = TraceSpecies {
            bvh: Bvh::build_with(&card, &surfaces),
            materials: vec![GpuTraceMaterial {
                base_color: [1.0; 4],
                alpha_cutoff: 0.5,
                texel_base: 0,
                size: 4,
                kind: 0,
            }],
            texels: texels.into(),
            uv_min: [0.0; 2],
            uv_extent: [1.0; 2],
        };
        let at = |x: f32| Ray { origin: Vec3::new(x, -1.0, 0.5), dir: Vec3::Y, t_max: 10.0 };
        assert!(species.intersect(&at(0.2)).is_some(), "opaque half");
        assert!(species.intersect(&at(0.8)).is_none(), "clear half");
        assert!(species.bvh.intersect(&at(0.8)).is_some(), "the card itself is there");
        assert!((texel_alpha(&species.texels, 0, 4, [0.5, 0.5]) - 0.5).abs() < 1e-6, "bilinear at the edge");
    }
}
