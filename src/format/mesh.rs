//! The mesh levels of a LoD pack (`MVTX`/`MIDX` sections, and the billboard
//! cloud's wood mesh): the quantised vertex, the materials and draw ranges, a
//! level's metadata and the checks of its sections. Layout: `docs/FORMAT.md`.

use serde::{Deserialize, Serialize};

use super::error::{finite, finite_all, Problem};

/// One mesh vertex, 20 bytes, quantised against its level's bounds.
///
/// Must match `MeshVertex` in `shaders/mesh.wgsl` (vertex attributes).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct MeshVertex {
    /// Position in 1/65535 steps of the level's `pos_min..pos_max`.
    pub position: [u16; 3],
    /// Index into the pack's materials.
    pub material: u16,
    /// Octahedral-encoded normal (snorm8 x, y); byte 2 the tree's own ambient
    /// occlusion (0 not baked, 1–127 sky visibility 0–1, see [`ao_from_snorm8`]);
    /// byte 3 reserved (0).
    pub normal_oct: [i8; 4],
    /// Texture coordinate in 1/65535 steps of the level's `uv_min..uv_max`.
    pub uv: [u16; 2],
    /// Vertex colour, linear RGBA8.
    pub color: [u8; 4],
}
const _: () = assert!(std::mem::size_of::<MeshVertex>() == 20);

/// Sky visibility (0–1) of a mesh vertex's occlusion byte: 0 is "not baked"
/// (open, 1), 1–127 map to 0–1. Must match `vertex_ao` in `shaders/mesh.wgsl`.
#[must_use]
pub fn ao_from_snorm8(v: i8) -> f32 {
    if v <= 0 {
        1.0
    } else {
        f32::from(v - 1) / 126.0
    }
}

/// The occlusion byte of a mesh vertex for sky visibility `v` (0–1): 1–127.
#[must_use]
pub fn ao_to_snorm8(v: f32) -> i8 {
    1 + (v.clamp(0.0, 1.0) * 126.0).round() as i8
}

/// Whether a material is foliage or wood; decides LoD treatment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MaterialKind {
    /// Leaves, needles, leaf cards.
    Leaf,
    /// Trunk and branches.
    Branch,
    /// The planes of a billboard cloud (García et al. 2007): their fragments draw the
    /// leaves listed in the cloud's cells (`META.cloud`).
    Cloud,
}

/// A material of the species.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialMeta {
    /// Name from the source model.
    pub name: String,
    /// Leaf or branch.
    pub kind: MaterialKind,
    /// Base colour factor (linear RGBA), multiplied with the texture.
    pub base_color: [f32; 4],
    /// Fragments with alpha below this are discarded (0 for opaque).
    pub alpha_cutoff: f32,
    /// Whether back faces are drawn.
    pub double_sided: bool,
    /// Layer of the material texture array, if textured.
    pub texture_layer: Option<u32>,
    /// Share of the layer's mip-0 texels the alpha test keeps, 0–1, where the
    /// texels are block-encoded (a BC7 variant: the viewer cannot count them);
    /// absent: the viewer counts them itself.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coverage: Option<f32>,
}

/// An indexed draw range of one material within a mesh level.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DrawRange {
    /// Material index.
    pub material: u32,
    /// First index in the level's index section.
    pub first_index: u32,
    /// Number of indices.
    pub index_count: u32,
}

/// One mesh level (0 = the full source mesh).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeshLevelMeta {
    /// Vertices in the `MVTX` section of this level.
    pub vertex_count: u32,
    /// Indices in the `MIDX` section of this level.
    pub index_count: u32,
    /// Dequantisation of positions: metres at scale 1, Z up, trunk base at the origin.
    pub pos_min: [f32; 3],
    /// Upper end of the position range.
    pub pos_max: [f32; 3],
    /// Dequantisation of texture coordinates.
    pub uv_min: [f32; 2],
    /// Upper end of the texture coordinate range.
    pub uv_max: [f32; 2],
    /// Draw ranges per material.
    pub draws: Vec<DrawRange>,
    /// This level is drawn while the tree's projected height is at least this many pixels.
    pub select_px: f32,
    /// The bake's LoD policy for a simplified level (`crate::lod::policy::policy_keeps`):
    /// the projected height from which it is more faithful than the far tier
    /// (the far tier is drawn below); at or above the finer level's threshold
    /// the level is not a default tier. Absent: `select_px`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub policy_px: Option<f32>,
    /// Other shapes of the level (the library's variants of a tree), in its
    /// `MVAR` section: [`VariantVertex`] × `vertex_count` per variant, variant 1
    /// first. A tree draws variant [`variant_of`]`(variation, variants)` (0: the
    /// `MVTX` vertices). At most [`MAX_VARIANTS`]; absent: none.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub variants: u32,
}

fn is_zero(v: &u32) -> bool {
    *v == 0
}

/// The variant a tree of `variation` (0–31, its tint's) draws of a level with
/// `extra` other variants: variation 15, the neutral one a single tree is
/// captured with, draws variant 0. Must match `variant_of` in `shaders/trees.wgsl`.
#[must_use]
pub fn variant_of(variation: u32, extra: u32) -> u32 {
    ((variation + 17) & 31) % (extra + 1)
}

/// Most extra shapes a mesh level may carry.
pub const MAX_VARIANTS: u32 = 7;

/// A vertex of another variant of a mesh level, 8 bytes: its position in the
/// level's quantisation and its octahedral normal; the rest (material, uv,
/// colour, occlusion) is the `MVTX` vertex's.
///
/// Must match the `variants` reads of `shaders/mesh.wgsl` (`vs_main`).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct VariantVertex {
    /// Position in 1/65535 steps of the level's `pos_min..pos_max`.
    pub position: [u16; 3],
    /// Octahedral-encoded normal (snorm8 x, y).
    pub normal_oct: [i8; 2],
}
const _: () = assert!(std::mem::size_of::<VariantVertex>() == 8);

/// A mesh level's floats are finite (checked whether its sections are held or not).
pub(super) fn mesh_meta_finite(what: &str, level: &MeshLevelMeta) -> Result<(), Problem> {
    finite_all(&format!("{what}.pos_min"), &level.pos_min)?;
    finite_all(&format!("{what}.pos_max"), &level.pos_max)?;
    finite_all(&format!("{what}.uv_min"), &level.uv_min)?;
    finite_all(&format!("{what}.uv_max"), &level.uv_max)?;
    finite(format!("{what}.select_px"), level.select_px.into())?;
    if let Some(p) = level.policy_px {
        finite(format!("{what}.policy_px"), p.into())?;
    }
    if level.variants > MAX_VARIANTS {
        return Err(Problem::OutOfRange {
            what: format!("{what}.variants"),
            value: level.variants.into(),
            allowed: format!("at most {MAX_VARIANTS}"),
        });
    }
    Ok(())
}

/// Checks a mesh level's `MVAR` section: exactly its variants' vertices.
pub(super) fn validate_variants(what: &str, level: &MeshLevelMeta, var: Option<&[u8]>) -> Result<(), Problem> {
    let want = u64::from(level.variants) * u64::from(level.vertex_count) * 8;
    match var {
        None if level.variants == 0 => Ok(()),
        None => Err(Problem::Invalid(format!("{what} declares {} variants but has no MVAR section", level.variants))),
        Some(v) if v.len() as u64 != want => Err(Problem::Invalid(format!(
            "{what} declares {} variants of {} vertices ({want} bytes), its MVAR section holds {} bytes",
            level.variants,
            level.vertex_count,
            v.len()
        ))),
        Some(_) => Ok(()),
    }
}

/// Checks one mesh level's sections against its metadata (`sections` names
/// the section kinds in messages).
pub(super) fn validate_mesh(
    what: &str,
    level: &MeshLevelMeta,
    vtx: Option<&[u8]>,
    idx: Option<&[u8]>,
    materials: usize,
    sections: &str,
) -> Result<(), Problem> {
    mesh_meta_finite(what, level)?;
    let (Some(vtx), Some(idx)) = (vtx, idx) else {
        return Err(Problem::Invalid(format!("{what} has no {sections}")));
    };
    if vtx.len() as u64 != u64::from(level.vertex_count) * 20 || idx.len() as u64 != u64::from(level.index_count) * 4 {
        return Err(Problem::Invalid(format!(
            "{what} declares {} vertices and {} indices, the sections hold {} and {} bytes",
            level.vertex_count,
            level.index_count,
            vtx.len(),
            idx.len()
        )));
    }
    for (d, draw) in level.draws.iter().enumerate() {
        let end = u64::from(draw.first_index) + u64::from(draw.index_count);
        if end > u64::from(level.index_count) || !draw.index_count.is_multiple_of(3) {
            return Err(Problem::Invalid(format!(
                "{what}.draws[{d}] covers indices {}..{end} of {} (or is not whole triangles)",
                draw.first_index, level.index_count
            )));
        }
        if draw.material as usize >= materials {
            return Err(Problem::OutOfRange {
                what: format!("{what}.draws[{d}].material"),
                value: draw.material.into(),
                allowed: format!("less than {} materials", materials),
            });
        }
    }
    // Indices must address existing vertices: the GPU would read out of bounds otherwise.
    let vertex_count = level.vertex_count;
    for (i, c) in idx.chunks_exact(4).enumerate() {
        let v = u32::from_le_bytes([c[0], c[1], c[2], c[3]]);
        if v >= vertex_count {
            return Err(Problem::OutOfRange {
                what: format!("{what} index[{i}]"),
                value: v.into(),
                allowed: format!("less than {vertex_count} vertices"),
            });
        }
    }
    for (i, c) in vtx.chunks_exact(20).enumerate() {
        let material = u16::from_le_bytes([c[6], c[7]]);
        if usize::from(material) >= materials {
            return Err(Problem::OutOfRange {
                what: format!("{what} vertex[{i}].material"),
                value: material.into(),
                allowed: format!("less than {} materials", materials),
            });
        }
    }
    Ok(())
}
