// The layouts every pass reads: the view, a batch, the species table, the
// representations, the draw params, the id pass's output. Each names its Rust twin
// (src/lod/shared.rs, src/render/gpu_data.rs). Composed first by src/render/shaders.rs.

// Must match `ViewUniform` in src/render/gpu_data.rs.
struct View {
    // Clip transform of eye-relative positions (rotation + projection only).
    clip_from_eye: mat4x4<f32>,
    // Eye position relative to the scene origin, split into a high and a low f32
    // part (relative-to-eye rendering: batch origin − eye_hi − eye_lo keeps
    // centimetres at UTM-sized coordinates). eye_hi.w: the mesh leaves' alpha
    // test: 1 at the textures' full resolution (the accuracy reference),
    // 2 adaptive transparency (hashed at the coarsest mips), 0 plain.
    // eye_lo.w: the progressive-refinement step shifting the cross-fade dither
    // (`fade_keeps`; 0 without refinement).
    eye_hi: vec4<f32>,
    eye_lo: vec4<f32>,
    // Frustum planes in eye-relative space, inside where dot(n, p) + d >= 0.
    // The far plane of the infinite projection is all zeros (always inside).
    frustum: array<vec4<f32>, 6>,
    // Unit vector towards the sun (xyz).
    sun_dir: vec4<f32>,
    // Sun colour (rgb) times intensity.
    sun_color: vec4<f32>,
    // Ambient colour (rgb).
    ambient: vec4<f32>,
    // x: pixels per metre at 1 m distance (viewport height / (2 tan(fov_y / 2)) × quality),
    // y: draw distance (m), z: transition band (fraction of a threshold),
    // w: culling mode (0 batches then trees, 1 trees only, 2 none) — the
    // baselines the benchmarks compare against.
    lod: vec4<f32>,
    // x: render mode (0 lit, 1 capture), y: batch slots to test, z: debug view
    // (0 off, 1 colour by representation), w: species count.
    params: vec4<u32>,
    // Inverse of clip_from_eye: per-pixel rays of the cluster pass.
    eye_from_clip: mat4x4<f32>,
    // x, y: viewport size (px); z: prefix-thinning threshold (px, 0 off);
    // w: 1 for an orthographic view sized in texels (a shadow cascade).
    viewport: vec4<f32>,
    // Per shadow cascade: clip transform of eye-relative positions.
    shadow_from_eye: array<mat4x4<f32>, 4>,
    // Per cascade: metres per shadow texel.
    shadow_texel: vec4<f32>,
    // x: cascades in use (0 off), y: map size, z: PCF radius (texels), w: fade-out distance (m).
    shadow: vec4<f32>,
    // The canopy cross-fade (`canopy_weight`): x, y: the projected
    // heights of a batch's tallest tree (px, × quality) below which its trees are all / begin to be
    // replaced by the canopy rasters (x = 0: no canopy); zw unused.
    canopy: vec4<f32>,
    // The sky and the air (`Sky` in sky_model.wgsl).
    sky: Sky,
};


// One batch of the resident pool. Must match `GpuBatch` in src/format/tile.rs
// (`instance_offset` is rebased to the instance pool on upload).
struct Batch {
    origin_m: vec3<f32>,
    instance_offset: u32,
    center_m: vec3<f32>,
    radius_m: f32,
    half_extent_m: vec3<f32>,
    instance_count: u32,
    species: u32,
    xy_step_m: f32,
    z_step_m: f32,
    scale_min: f32,
    scale_log2_step: f32,
    max_height_m: f32,
    // BATCH_DENSITY_ORDERED, BATCH_CROWN_ASPECT
    flags: u32,
    // Crown aspect range (BATCH_CROWN_ASPECT): bits 0–15 smallest aspect in
    // 1/8192, bits 16–31 log2 step in 1/65536.
    crown: u32,
};

// Per-species selection data. Must match `GpuSpecies` in src/render/gpu_data.rs.
// The per-representation fields are 8 entries as two vec4s: use the accessors.
struct Species {
    // Bounding sphere of the model at scale 1 (xyz centre, w radius).
    sphere: vec4<f32>,
    // x: model height; yzw unused.
    select: vec4<f32>,
    // Per representation: projected tree height (px) from which it is drawn.
    lower_px: array<vec4<f32>, 2>,
    // Draw-item segment base per representation.
    slot_base: array<vec4<u32>, 2>,
    // Segment capacity per representation (0: representation not ready).
    slot_cap: array<vec4<u32>, 2>,
    // Indices (meshes) or vertices (billboards, clusters) per instance.
    index_count: array<vec4<u32>, 2>,
};

fn species_lower(s: Species, r: u32) -> f32 { return s.lower_px[r >> 2u][r & 3u]; }
fn species_base(s: Species, r: u32) -> u32 { return s.slot_base[r >> 2u][r & 3u]; }
fn species_cap(s: Species, r: u32) -> u32 { return s.slot_cap[r >> 2u][r & 3u]; }
fn species_indices(s: Species, r: u32) -> u32 { return s.index_count[r >> 2u][r & 3u]; }

// Representations, in order of detail. A slot is species * REPR_COUNT + repr.
// 2 is the billboard cloud (García et al. 2007), 3–6 the cluster tiers (ellipsoids +
// lines of one level each, Clasen et al. 2010), 7 the far tier.
const REPR_MESH0: u32 = 0u;
const REPR_MESH1: u32 = 1u;
const REPR_CLOUD: u32 = 2u;
const REPR_CLUSTER0: u32 = 3u;
const REPR_BILLBOARD: u32 = 7u;
const REPR_COUNT: u32 = 8u;

// Per-draw constants (dynamic uniform offset). Must match `DrawParams` in src/render/gpu_data.rs.
struct DrawParams {
    // x: first draw item of the slot, y: representation, z: species, w: billboard angles.
    ids: vec4<u32>,
    // Billboard quad: centre (xyz, model space at scale 1), w: half width;
    // impostors: the bounding sphere (centre, radius).
    bb_center: vec4<f32>,
    // x: billboard half height, y: the billboards' variants, zw unused;
    // impostors: xyz the model box's half extents, w the impostors' variants.
    bb_size: vec4<f32>,
    // Cluster level: x first ellipsoid word, y ellipsoids, z first line word, w lines.
    cluster: vec4<u32>,
    // x: noise threshold, y: normal blend, z: log2 of the noise cube size.
    cluster_noise: vec4<f32>,
    // Quantisation box of cluster records (min, extent).
    bounds_min: vec4<f32>,
    bounds_extent: vec4<f32>,
    // Linear RGB of the lines.
    line_color: vec4<f32>,
    // The tree's occlusion field box (model space at scale 1): min corner
    // (xyz); w how far out along the normal clusters look it up.
    ao_field_min: vec4<f32>,
    ao_field_size: vec4<f32>,
    // The species' season: xyz its leaves' autumn colour (linear), w the
    // state (0 leaf-on or evergreen, 1 autumn, 2 leaf-off; at a date 3 + its
    // phase in its leaf calendar, 3–6; `trees.wgsl`).
    season: vec4<f32>,
};


// Batch flag: instances are density-ordered (every prefix an even thinning).
const BATCH_DENSITY_ORDERED: u32 = 1u;
// Batch flag: the top 5 bits of word 1 are the crown aspect, not the variation.
// Must match `BATCH_CROWN_ASPECT` in src/format/tile.rs.
const BATCH_CROWN_ASPECT: u32 = 2u;
// Must match `BATCH_DATED` in src/format/tile.rs: trees not standing at the
// scene's latest date, drawn only at a date (STYLE_DATED).
const BATCH_DATED: u32 = 8u;
// Fewest trees a thinned batch keeps, as a fraction (the largest boost is its root).
const THIN_MIN_FRACTION: f32 = 0.015625;
// Batch flag (GPU pools only): the batch holds a prefix of its trees, fetched
// by byte range; bits 8–31 of its flags are its whole count.
// Must match `BATCH_PARTIAL` and `PARTIAL_COUNT_SHIFT` in src/format/tile.rs.
const BATCH_PARTIAL: u32 = 4u;
const PARTIAL_COUNT_SHIFT: u32 = 8u;

// The id pass (picking, on demand): the pool instance + 1 of the tree a pixel
// shows, with that pixel's depth; 0 is no tree.
struct IdOut {
    @location(0) id: u32,
    @builtin(frag_depth) depth: f32,
};
