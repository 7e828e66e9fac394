//! The mesh levels of a pack: materials and their texture array (coverage-
//! weighted mips), the quantised full level and the simplified one (meshopt).

use crate::input::gltf_import::{ImportedModel, ImportedVertex};
use glam::{Vec2, Vec3};
use sylva::format::pack::{
    ao_to_snorm8, DrawRange, MaterialKind, MaterialMeta, MeshLevelMeta, MeshVertex, TextureArrayMeta, VariantVertex,
};
use sylva::render::mips::{alpha_aware_mips, ColorEncoding};

/// Mip chain (mip 0 included) of a square layer of `N` floats per texel, all
/// averaged weighted by `color`'s alpha (coverage); where a 2×2 block has none,
/// by plain average.
pub(super) fn coverage_weighted_mips<const N: usize>(
    layer: Vec<[f32; N]>,
    color: &[u8],
    size: u32,
) -> Vec<Vec<[f32; N]>> {
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
pub(super) fn mip_major(chains: &[Vec<Vec<u8>>], mips: u32) -> Vec<u8> {
    let mut out = Vec::new();
    for m in 0..mips as usize {
        for chain in chains {
            out.extend_from_slice(&chain[m]);
        }
    }
    out
}

pub(super) fn build_materials(
    model: &ImportedModel,
    size: u32,
) -> (Vec<MaterialMeta>, Option<TextureArrayMeta>, Option<Vec<u8>>) {
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
                coverage: None,
            }
        })
        .collect();
    if chains.is_empty() {
        return (metas, None, None);
    }
    let meta = TextureArrayMeta::plain(size, chains.len() as u32, size.trailing_zeros() + 1);
    let bytes = mip_major(&chains, meta.mips);
    (metas, Some(meta), Some(bytes))
}

/// Octahedral encoding of a unit vector into snorm8 x, y.
pub(super) fn oct_encode(n: Vec3) -> [i8; 2] {
    let n = n / (n.x.abs() + n.y.abs() + n.z.abs()).max(1e-12);
    let (x, y) =
        if n.z >= 0.0 { (n.x, n.y) } else { ((1.0 - n.y.abs()) * n.x.signum(), (1.0 - n.x.abs()) * n.y.signum()) };
    [(x.clamp(-1.0, 1.0) * 127.0).round() as i8, (y.clamp(-1.0, 1.0) * 127.0).round() as i8]
}

/// One quantised, cache-optimised mesh level: metadata, vertices, indices.
/// `ao`: each vertex's own occlusion (sky visibility), when baked.
pub(super) fn build_mesh_level(
    model: &ImportedModel,
    select_px: f32,
    ao: Option<&[f32]>,
) -> (MeshLevelMeta, Vec<MeshVertex>, Vec<u32>, Vec<VariantVertex>) {
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
    // Vertex cache order within each material's range, then fetch order for all
    // (the variants' shapes reordered alike).
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
    // Vertices in the order the indices first use them (meshoptimizer's vertex
    // fetch order), unused ones dropped; one table for the vertices and shapes.
    let mut remap = vec![u32::MAX; vertices.len()];
    let mut used = 0usize;
    for &i in &indices {
        if remap[i as usize] == u32::MAX {
            remap[i as usize] = used as u32;
            used += 1;
        }
    }
    let indices: Vec<u32> = indices.iter().map(|&i| remap[i as usize]).collect();
    let vertices = {
        let mut out = vec![ImportedVertexPod::default(); used];
        for (i, &r) in remap.iter().enumerate() {
            if r != u32::MAX {
                out[r as usize] = vertices[i];
            }
        }
        out
    };
    let shapes: Vec<Vec<[Vec3; 2]>> = model
        .variants
        .iter()
        .map(|shape| {
            let mut out = vec![[Vec3::ZERO; 2]; used];
            for (i, &r) in remap.iter().enumerate() {
                if r != u32::MAX {
                    out[r as usize] = shape[i];
                }
            }
            out
        })
        .collect();
    let (mut pmin, mut pmax) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
    let (mut umin, mut umax) = (Vec2::splat(f32::MAX), Vec2::splat(f32::MIN));
    for v in &vertices {
        pmin = pmin.min(Vec3::from(v.position));
        pmax = pmax.max(Vec3::from(v.position));
        umin = umin.min(Vec2::from(v.uv));
        umax = umax.max(Vec2::from(v.uv));
    }
    for [p, _] in shapes.iter().flatten() {
        pmin = pmin.min(*p);
        pmax = pmax.max(*p);
    }
    if vertices.is_empty() {
        (pmin, pmax, umin, umax) = (Vec3::ZERO, Vec3::ONE, Vec2::ZERO, Vec2::ONE);
    }
    let pext = (pmax - pmin).max(Vec3::splat(1e-6));
    let uext = (umax - umin).max(Vec2::splat(1e-6));
    let q16 = |v: f32| (v.clamp(0.0, 1.0) * 65535.0).round() as u16;
    let quantise = |p: Vec3| {
        let p = (p - pmin) / pext;
        [q16(p.x), q16(p.y), q16(p.z)]
    };
    let packed: Vec<MeshVertex> = vertices
        .iter()
        .map(|v| {
            let uv = (Vec2::from(v.uv) - umin) / uext;
            let [ox, oy] = oct_encode(Vec3::from(v.normal));
            MeshVertex {
                position: quantise(Vec3::from(v.position)),
                material: v.material as u16,
                normal_oct: [ox, oy, if v.ao < 0.0 { 0 } else { ao_to_snorm8(v.ao) }, 0],
                uv: [q16(uv.x), q16(uv.y)],
                color: v.color.map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8),
            }
        })
        .collect();
    let variant_vertices: Vec<VariantVertex> = shapes
        .iter()
        .flatten()
        .map(|&[p, n]| VariantVertex { position: quantise(p), normal_oct: oct_encode(n) })
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
        variants: shapes.len() as u32,
    };
    (meta, packed, indices, variant_vertices)
}

/// `ImportedVertex` as plain data for meshopt's vertex fetch reordering.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct ImportedVertexPod {
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
        variants: Vec::new(),
        autumn: model.autumn,
        genus: model.genus.clone(),
    };
    // The variants' shapes, enlarged as the model's (the same cards: the same topology).
    let mut shapes: Vec<Vec<[Vec3; 2]>> = model.variants.clone();
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
    pub(super) fn find(p: &mut [u32], mut x: u32) -> u32 {
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
        for shape in &mut shapes {
            let centre = verts.iter().map(|&v| shape[v as usize][0]).sum::<Vec3>() / verts.len() as f32;
            for &v in &verts {
                let p = &mut shape[v as usize][0];
                *p = centre + (*p - centre) * grow;
            }
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
    out.variants = shapes.iter().map(|shape| source.iter().map(|&i| shape[i as usize]).collect()).collect();
    (out, source)
}
