//! CPU twins of the structs the shaders read. Each names its WGSL twin.
//! The view, the species table and the representations, which the cull
//! shader and its CPU twin both read, are in [`crate::lod::shared`]; the
//! style bytes' bits in [`crate::scene::style`].

use bytemuck::{Pod, Zeroable};

pub use crate::lod::shared::{
    GpuSpecies, Repr, SkyUniform, ViewUniform, CLUSTER_TIERS, MAX_CASCADES, REPR_COUNT, SLOTS_PER_SPECIES,
};
pub use crate::scene::style::STYLE_HEADER_WORDS;

/// Byte stride of views in the view buffer (main view, then one per cascade):
/// the size rounded up to WebGPU's 256-byte storage offset alignment.
pub const VIEW_STRIDE: u64 = 1280;
const _: () = assert!(std::mem::size_of::<ViewUniform>() as u64 <= VIEW_STRIDE);

/// Per-draw constants, bound with a dynamic offset. Must match `DrawParams` in
/// `shaders/layout.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct DrawParams {
    /// x: first draw item, y: representation, z: species, w: billboard angles | azimuths << 16.
    pub ids: [u32; 4],
    /// Billboard centre (model space, scale 1) and half width.
    pub bb_center: [f32; 4],
    /// x: billboard half height, y: the billboards' variants; impostors: xyz
    /// the box's half extents, w the impostors' variants.
    pub bb_size: [f32; 4],
    /// Cluster levels: x first ellipsoid word, y ellipsoids, z first line word, w lines.
    pub cluster: [u32; 4],
    /// x: noise threshold, y: normal blend, z: log2 of the noise cube size; w unused.
    pub cluster_noise: [f32; 4],
    /// Quantisation box of cluster records: min xyz.
    pub bounds_min: [f32; 4],
    /// Quantisation box extent xyz.
    pub bounds_extent: [f32; 4],
    /// Linear RGB of the lines.
    pub line_color: [f32; 4],
    /// The tree's occlusion field box (model space at scale 1): min corner xyz;
    /// w how far out along the normal (model units) clusters look it up.
    pub ao_field_min: [f32; 4],
    /// Its size xyz.
    pub ao_field_size: [f32; 4],
    /// The species' season (`trees.wgsl`): xyz its leaves' autumn colour
    /// (linear RGB), w the state drawn ([`super::settings::Season::code`]:
    /// 0 leaf-on or evergreen, 1 autumn, 2 leaf-off; at a date 3 + the
    /// species' phase, [`super::settings::season_params_at`]).
    pub season: [f32; 4],
    /// Padding to the 256-byte dynamic-offset alignment.
    pub pad: [u32; 20],
}
const _: () = assert!(std::mem::size_of::<DrawParams>() == 256);

impl Default for DrawParams {
    fn default() -> Self {
        Zeroable::zeroed()
    }
}

/// The cull pass's counters. Must match the `control` words in `shaders/cull.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Pod, Zeroable)]
pub struct CullControl {
    /// Batches that passed the batch test (word 0).
    pub batches_visible: u32,
    /// Unused (words 1–3).
    pub unused: [u32; 3],
    /// Trees of visible batches tested one by one (word 4).
    pub instances_tested: u32,
    /// Draw items lost to a full segment (word 5).
    pub items_dropped: u32,
    /// Unused (words 6–7).
    pub unused_tail: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<CullControl>() == 32);

/// Where the styles start in the cull control buffer (bytes): the draw
/// passes bind it from here (group 2, binding 3). The control words come first.
pub const STYLE_OFFSET_BYTES: u64 = 256;
/// Bytes of the cull control buffer: the control words, then the styles'
/// header, then (with per-tree styles) a style byte per pool instance, then
/// (`growth`: a scene with a timeline) a growth byte per pool instance (read
/// at a date: `STYLE_DATED`).
#[must_use]
pub fn control_buffer_bytes(style_instances: u32, growth: bool) -> u64 {
    let per = if growth { 2 } else { 1 };
    STYLE_OFFSET_BYTES + u64::from(STYLE_HEADER_WORDS) * 4 + per * u64::from(style_instances).next_multiple_of(4)
}

/// Where the growth bytes start, in words from the styles' start (the
/// header's `STYLE_GROWTH_AT` word), for pools of `style_instances`.
#[must_use]
pub fn growth_words_at(style_instances: u32) -> u32 {
    STYLE_HEADER_WORDS + style_instances.div_ceil(4)
}

/// One draw slot's indirect arguments, written by the cull pass: the indexed
/// layout (`wgpu::util::DrawIndexedIndirectArgs`); non-indexed draws read the
/// first four words. Must match the 5-word slots of `args` in `shaders/cull.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Pod, Zeroable)]
pub struct DrawArgs {
    /// Indices (meshes) or vertices (billboards, clusters) per instance.
    pub count: u32,
    /// Instances (trees) drawn.
    pub instance_count: u32,
    /// First index or vertex.
    pub first: u32,
    /// Base vertex of an indexed draw; first instance of a non-indexed one.
    pub base_vertex_or_first_instance: u32,
    /// First instance of an indexed draw.
    pub first_instance: u32,
}
const _: () = assert!(std::mem::size_of::<DrawArgs>() == std::mem::size_of::<wgpu::util::DrawIndexedIndirectArgs>());

/// The indirect arguments `prepare_dispatch` writes (`dispatch_args` in
/// `shaders/cull.wgsl`): the cull_instances dispatch, then the batch-bounds
/// debug draw (24 vertices per visible batch).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Pod, Zeroable)]
pub struct CullDispatch {
    /// Workgroups x, y, z of cull_instances (words 0–2).
    pub groups: [u32; 3],
    /// Unused (word 3).
    pub unused: u32,
    /// The bounds overlay's non-indexed draw: vertex count, instance count, first
    /// vertex, first instance (words 4–7, `wgpu::util::DrawIndirectArgs`).
    pub bounds_draw: [u32; 4],
}
const _: () = assert!(std::mem::size_of::<CullDispatch>() == 8 * 4);
const _: () = assert!(std::mem::size_of::<[u32; 4]>() == std::mem::size_of::<wgpu::util::DrawIndirectArgs>());

impl CullDispatch {
    /// Byte offset of [`Self::bounds_draw`] (the bounds overlay's indirect draw).
    pub const BOUNDS_DRAW_OFFSET: u64 = std::mem::offset_of!(CullDispatch, bounds_draw) as u64;
}

/// Dequantisation of one mesh level. Must match `MeshParams` in `shaders/mesh.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct MeshUniform {
    /// Position of quantised 0 (xyz).
    pub pos_min: [f32; 4],
    /// Position span of quantised 0..65535 (xyz).
    pub pos_extent: [f32; 4],
    /// Texture coordinate of quantised 0.
    pub uv_min: [f32; 2],
    /// Texture coordinate span.
    pub uv_extent: [f32; 2],
    /// Billboard cloud: x the first cell word, y the first fragment word of
    /// its `CLDA` buffer (x = 16 × planes), zero for mesh levels. Mesh levels:
    /// z the other variants in the level's `variants` buffer (0: none), w its
    /// vertex count.
    pub cloud: [u32; 4],
}
const _: () = assert!(std::mem::size_of::<MeshUniform>() == 64);

/// A material. Must match `Material` in `shaders/mesh.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GpuMaterial {
    /// Linear RGBA factor.
    pub base_color: [f32; 4],
    /// Discard below this alpha.
    pub alpha_cutoff: f32,
    /// Texture layer or -1.
    pub layer: i32,
    /// 0 leaf, 1 branch.
    pub kind: u32,
    /// Share of the texture's full-resolution texels that pass `alpha_cutoff`
    /// (0 untextured): the keep probability of a leaf card seen at its
    /// texture's coarsest mips (adaptive transparency, `mesh.wgsl`).
    pub coverage: f32,
}
const _: () = assert!(std::mem::size_of::<GpuMaterial>() == 32);

/// What the fragment stage writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum RenderMode {
    /// Shaded colour.
    Lit = 0,
    /// Albedo + normal (billboard capture).
    Capture = 1,
    /// Depth only, alpha-tested (shadow casters; not a view's mode: cascades
    /// are drawn with [`RenderMode::Lit`] views and the shadow pipelines).
    Shadow = 2,
    /// The tree ids of picking (the id pass; not a view's mode either).
    Id = 3,
}
