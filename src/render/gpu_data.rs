//! CPU twins of the structs the shaders read. Each names its WGSL twin.

use bytemuck::{Pod, Zeroable};

/// Per-view constants. Must match `View` in `shaders/common.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct ViewUniform {
    /// Clip transform of eye-relative positions (rotation + projection only).
    pub clip_from_eye: [[f32; 4]; 4],
    /// Eye position relative to the scene origin, high f32 part (xyz); w the
    /// mesh leaves' alpha test: 1 at the textures' full resolution
    /// (`full_res_alpha`), 2 adaptive (`adaptive_alpha`), 0 plain.
    pub eye_hi: [f32; 4],
    /// Low f32 part: `eye_hi + eye_lo` is the f64 eye to ~1e-7 relative; w the
    /// refinement step shifting the dither and hash patterns (`refine_seed`).
    pub eye_lo: [f32; 4],
    /// Frustum planes in eye-relative space (inside: `n·p + d ≥ 0`); unused planes are zero.
    pub frustum: [[f32; 4]; 6],
    /// Unit vector towards the sun.
    pub sun_dir: [f32; 4],
    /// Sun colour × intensity.
    pub sun_color: [f32; 4],
    /// Ambient colour.
    pub ambient: [f32; 4],
    /// x: pixels per metre at 1 m (× quality), y: draw distance (m), z: transition band,
    /// w: culling mode (0 batches, 1 per tree, 2 none).
    pub lod: [f32; 4],
    /// x: [`RenderMode`], y: batch slots to test, z: debug view, w: species count.
    pub params: [u32; 4],
    /// Inverse of `clip_from_eye` (the cluster pass's per-pixel rays).
    pub eye_from_clip: [[f32; 4]; 4],
    /// x, y: viewport size in pixels; z: prefix-thinning threshold (px, 0 off);
    /// w: 1 for an orthographic view whose projected sizes do not shrink with
    /// distance (a shadow cascade: LoD by texel size), else 0.
    pub viewport: [f32; 4],
    /// Per shadow cascade: the cascade's clip transform of eye-relative
    /// positions (orthographic, reversed Z; texel-snapped).
    pub shadow_from_eye: [[[f32; 4]; 4]; MAX_CASCADES],
    /// Per cascade: metres per shadow texel.
    pub shadow_texel: [f32; 4],
    /// x: cascades in use (0: no shadows), y: shadow map size (texels), z: PCF
    /// kernel radius (texels: 0 one tap), w: distance (m) where shadows have faded out.
    pub shadow: [f32; 4],
    /// The canopy cross-fade (`canopy_weight`): x, y the projected heights of a
    /// batch's tallest tree (px × quality) below which its trees are all / begin to be replaced by the
    /// canopy rasters (x = 0: no canopy); zw unused.
    pub canopy: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<ViewUniform>() == 656);

/// Most shadow cascades a view carries.
pub const MAX_CASCADES: usize = 4;

/// Byte stride of views in the view buffer (main view, then one per cascade):
/// the size rounded up to WebGPU's 256-byte storage offset alignment.
pub const VIEW_STRIDE: u64 = 768;
const _: () = assert!(std::mem::size_of::<ViewUniform>() as u64 <= VIEW_STRIDE);

/// Per-species selection data. Must match `Species` in `shaders/common.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, Pod, Zeroable)]
pub struct GpuSpecies {
    /// Bounding sphere of the model at scale 1: centre xyz, radius w.
    pub sphere: [f32; 4],
    /// x: model height (m at scale 1); yzw unused.
    pub select: [f32; 4],
    /// Per representation: the projected tree height (px) from which it is drawn
    /// (the coarsest ready one reaches down to 0).
    pub lower_px: [f32; SLOTS_PER_SPECIES],
    /// First draw item of each representation's segment.
    pub slot_base: [u32; SLOTS_PER_SPECIES],
    /// Capacity of each segment (0: representation not ready, never selected).
    pub slot_cap: [u32; SLOTS_PER_SPECIES],
    /// Indices (meshes) or vertices (billboards, clusters) per instance.
    pub index_count: [u32; SLOTS_PER_SPECIES],
}
const _: () = assert!(std::mem::size_of::<GpuSpecies>() == 160);

/// Per-species array length of the representation fields (REPR_COUNT rounded up to vec4s).
pub const SLOTS_PER_SPECIES: usize = 8;

/// Per-draw constants, bound with a dynamic offset. Must match `DrawParams` in
/// `shaders/common.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct DrawParams {
    /// x: first draw item, y: representation, z: species, w: billboard angles | azimuths << 16.
    pub ids: [u32; 4],
    /// Billboard centre (model space, scale 1) and half width.
    pub bb_center: [f32; 4],
    /// x: billboard half height.
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
    /// Padding to the 256-byte dynamic-offset alignment.
    pub pad: [u32; 24],
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
/// Words of the styles' header: the palette (64 packed RGBA8 colours; entry 0
/// unused, a tree's own colour), then [`STYLE_FLAGS`], then spare words.
pub const STYLE_HEADER_WORDS: u32 = 128;
/// Header word: [`STYLE_TREES`] and [`STYLE_BY_SPECIES`] bits.
pub const STYLE_FLAGS: u32 = 64;
/// Flag: one style byte per pool instance follows the header (bits 0–5 the
/// palette entry, 0 the tree's own colour; [`STYLE_SELECTED`]; [`STYLE_HIDDEN`]).
pub const STYLE_TREES: u32 = 1;
/// Flag: a tree's palette entry is its model species + 1 (no per-tree data needed).
pub const STYLE_BY_SPECIES: u32 = 2;
/// Style byte bit: the tree is selected (highlighted at every level of detail).
pub const STYLE_SELECTED: u8 = 64;
/// Style byte bit: the tree is filtered out (the cull pass skips it).
pub const STYLE_HIDDEN: u8 = 128;

/// Bytes of the cull control buffer: the control words, then the styles'
/// header, then (with per-tree styles) a byte per pool instance.
#[must_use]
pub fn control_buffer_bytes(style_instances: u32) -> u64 {
    STYLE_OFFSET_BYTES + u64::from(STYLE_HEADER_WORDS) * 4 + u64::from(style_instances).next_multiple_of(4)
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

/// Representations a tree can be drawn with, finest first. A draw slot is
/// `species * REPR_COUNT + repr`. Must match `REPR_*` in `shaders/common.wgsl`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[repr(u32)]
pub enum Repr {
    /// Mesh level 0 (full detail).
    Mesh0 = 0,
    /// Mesh level 1 (simplified).
    Mesh1 = 1,
    /// The billboard cloud (seed 001): the coarsest level's wood and the
    /// leaves on planes.
    Cloud = 2,
    /// The finest cluster level in use (ellipsoids + lines, seed 002).
    Cluster0 = 3,
    /// The next cluster level.
    Cluster1 = 4,
    /// The next cluster level.
    Cluster2 = 5,
    /// The coarsest cluster level in use.
    Cluster3 = 6,
    /// View-angle billboards or multi-view impostors (the far tier).
    Billboard = 7,
}

/// Number of representations (draw slots per species).
pub const REPR_COUNT: u32 = 8;

/// Cluster levels a species can use at once (the levels whose projected size
/// band meets the cluster range).
pub const CLUSTER_TIERS: usize = 4;

impl Repr {
    /// All, finest first.
    pub const ALL: [Repr; 8] = [
        Repr::Mesh0,
        Repr::Mesh1,
        Repr::Cloud,
        Repr::Cluster0,
        Repr::Cluster1,
        Repr::Cluster2,
        Repr::Cluster3,
        Repr::Billboard,
    ];

    /// The cluster tiers.
    pub const CLUSTERS: [Repr; CLUSTER_TIERS] = [Repr::Cluster0, Repr::Cluster1, Repr::Cluster2, Repr::Cluster3];

    /// Name used in stats (`instances` keys): cluster tiers all count as `ellipsoid`.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Repr::Mesh0 => "mesh0",
            Repr::Mesh1 => "mesh1",
            Repr::Cloud => "cloud",
            Repr::Cluster0 | Repr::Cluster1 | Repr::Cluster2 | Repr::Cluster3 => "ellipsoid",
            Repr::Billboard => "billboard",
        }
    }

    /// The cluster tier (0–3) of a cluster representation.
    #[must_use]
    pub fn cluster_tier(self) -> Option<usize> {
        match self {
            Repr::Cluster0 => Some(0),
            Repr::Cluster1 => Some(1),
            Repr::Cluster2 => Some(2),
            Repr::Cluster3 => Some(3),
            _ => None,
        }
    }
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
    /// its `CLDA` buffer (x = 16 × planes); zw unused. Zero for mesh levels.
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
