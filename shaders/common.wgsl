// Shared structs and helpers of every Sylva pass. Prepended to each pass's WGSL
// by `src/render/shaders.rs`, so the structs here exist once.

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
    // x: billboard half height, yzw unused; impostors: xyz the model box's half extents.
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
};

// A decoded tree, eye-relative.
struct Tree {
    pos: vec3<f32>,
    yaw: f32,
    // Height scale of the species model.
    scale: f32,
    variation: f32,
    // Horizontal over vertical scale (crown width relative to the model's; 1 without crown data).
    aspect: f32,
};

// A model-space offset of `tree` scaled to the tree: xy by scale × aspect, z by scale.
fn tree_scaled(v: vec3<f32>, tree: Tree) -> vec3<f32> {
    return vec3<f32>(v.xy * (tree.scale * tree.aspect), v.z * tree.scale);
}

// An eye-space offset stretched horizontally by the tree's crown aspect.
fn crown_stretch(v: vec3<f32>, tree: Tree) -> vec3<f32> {
    return vec3<f32>(v.xy * tree.aspect, v.z);
}

// Variation of an instance of a BATCH_CROWN_ASPECT batch: a hash of its
// position word. Must match `variation_of` in src/format/tile.rs.
fn variation_of(xy: u32) -> u32 {
    return (xy * 0x9E3779B1u) >> 27u;
}

// Eye-relative position of a batch-local point: (origin − eye_hi) − eye_lo + offset.
// Both origin and eye_hi are exact f32s, so the first difference is exact for
// nearby batches; see docs/ARCHITECTURE.md (precision).
fn eye_relative(origin_m: vec3<f32>, offset: vec3<f32>, view: View) -> vec3<f32> {
    return ((origin_m - view.eye_hi.xyz) - view.eye_lo.xyz) + offset;
}

// Decodes a PackedInstance (src/format/tile.rs) of `batch`.
fn unpack_instance(packed: vec2<u32>, batch: Batch, view: View) -> Tree {
    let x = f32(packed.x & 0xffffu);
    let y = f32(packed.x >> 16u);
    let z = f32(packed.y & 0x7ffu);
    let yaw_q = (packed.y >> 11u) & 0xffu;
    let scale_q = (packed.y >> 19u) & 0xffu;
    var t: Tree;
    t.pos = eye_relative(batch.origin_m, vec3<f32>(x * batch.xy_step_m, y * batch.xy_step_m, z * batch.z_step_m), view);
    t.yaw = f32(yaw_q) * (6.283185307 / 256.0);
    t.scale = batch.scale_min * exp2(f32(scale_q) * batch.scale_log2_step);
    let top = packed.y >> 27u;
    if (batch.flags & BATCH_CROWN_ASPECT) != 0u {
        let min = f32(batch.crown & 0xffffu) / 8192.0;
        let step = f32(batch.crown >> 16u) / 65536.0;
        t.aspect = min * exp2(f32(top) * step);
        t.variation = f32(variation_of(packed.x));
    } else {
        t.aspect = 1.0;
        t.variation = f32(top);
    }
    return t;
}

// Batch flag: instances are density-ordered (every prefix an even thinning).
const BATCH_DENSITY_ORDERED: u32 = 1u;
// Batch flag: the top 5 bits of word 1 are the crown aspect, not the variation.
// Must match `BATCH_CROWN_ASPECT` in src/format/tile.rs.
const BATCH_CROWN_ASPECT: u32 = 2u;
// Fewest trees a thinned batch keeps, as a fraction (the largest boost is its root).
const THIN_MIN_FRACTION: f32 = 0.015625;
// Batch flag (GPU pools only): the batch holds a prefix of its trees, fetched
// by byte range; bits 8–31 of its flags are its whole count.
// Must match `BATCH_PARTIAL` and `PARTIAL_COUNT_SHIFT` in src/format/tile.rs.
const BATCH_PARTIAL: u32 = 4u;
const PARTIAL_COUNT_SHIFT: u32 = 8u;

// The batch's whole tree count (`instance_count` holds what is resident).
fn whole_count(b: Batch) -> u32 {
    return select(b.instance_count, b.flags >> PARTIAL_COUNT_SHIFT, (b.flags & BATCH_PARTIAL) != 0u);
}

// Prefix thinning (Eichner 2024, ch. 7). A density-ordered batch whose tallest tree
// is below view.viewport.z px tall at the batch's nearest point draws only its
// first n·f trees, f = (h / T)² (at least 1/64, and at least one tree): about as
// many trees per screen area as at T px. The billboard pass scales the kept
// trees up to keep the canopy's coverage (`coverage_boost`). A batch holding
// a prefix of its trees (BATCH_PARTIAL: the rest not fetched yet) keeps at
// most those, drawn as bigger as the trees they stand in for. Returns (trees
// kept, fractional; n / kept, 1 when not thinned; trees kept were the whole
// batch held, fractional: n when not thinned).
// Must match `thinning` in src/lod/select.rs.
fn thinning(b: Batch, view: View) -> vec3<f32> {
    let n = f32(whole_count(b));
    let held = max(f32(b.instance_count), 1.0);
    let t = view.viewport.z;
    if (b.flags & BATCH_DENSITY_ORDERED) == 0u || t <= 0.0 || view.lod.w > 0.5 {
        return vec3<f32>(held, n / held, n);
    }
    let center = eye_relative(b.center_m, vec3<f32>(0.0), view);
    let d = max(length(max(abs(center) - b.half_extent_m, vec3<f32>(0.0))), 1e-3);
    let h = b.max_height_m * view.lod.x / d;
    if h >= t {
        return vec3<f32>(held, n / held, n);
    }
    let f = clamp((h * h) / (t * t), THIN_MIN_FRACTION, 1.0);
    let wanted = max(n * f, 1.0);
    let kept = min(wanted, held);
    return vec3<f32>(kept, n / kept, wanted);
}

// Scale of a thinned batch's kept trees so the canopy covers about what all its
// trees did: s = (n / kept)^THIN_BOOST_EXPONENT. An exponent of ½ keeps the
// summed tree area; calibrated by the image metric it over-covers by 10–18 %
// (evenly spread kept trees overlap less than the whole batch, whose tiny
// billboards also alpha-test away part of their area) and no boost under-covers
// by up to 50 %; 0.35 keeps coverage within ±6 % (docs/BENCHMARKS.md).
const THIN_BOOST_EXPONENT: f32 = 0.35;

fn coverage_boost(thin: vec3<f32>, b: Batch) -> f32 {
    let n = f32(whole_count(b));
    if thin.x >= n {
        return 1.0;
    }
    return pow(n / thin.x, THIN_BOOST_EXPONENT);
}

// Sphere against the frustum (eye-relative).
fn sphere_visible(center: vec3<f32>, radius: f32, view: View) -> bool {
    for (var i = 0u; i < 6u; i++) {
        let p = view.frustum[i];
        if dot(p.xyz, center) + p.w < -radius {
            return false;
        }
    }
    return true;
}

// Draw item: x = instance index in the pool, y = batch index (bits 0–22),
// side (bit 23), fade (bits 24–31). The fade keeps the pixels whose dither is
// ≥ fade (side 0) or < fade (side 1): the two sides of a transition together
// cover every pixel exactly once.
fn pack_item_y(batch: u32, side: u32, fade: f32) -> u32 {
    let f = u32(clamp(fade, 0.0, 1.0) * 255.0 + 0.5);
    return (batch & 0x7fffffu) | (side << 23u) | (f << 24u);
}

// 8×8 ordered dither threshold in (0, 1), stable in screen space.
fn dither8(p: vec2<f32>) -> f32 {
    let x = u32(p.x) & 7u;
    let y = u32(p.y) & 7u;
    let v = x ^ y;
    let m = ((v & 1u) << 5u) | ((y & 1u) << 4u) | ((v & 2u) << 2u) | ((y & 2u) << 1u) | ((v & 4u) >> 1u) | ((y & 4u) >> 2u);
    return (f32(m) + 0.5) / 64.0;
}

// Whether an item's pixel survives its cross-fade mask. `seed` (the view's
// eye_lo.w: the progressive-refinement step, 0 otherwise) shifts the dither
// pattern, so accumulated steps blend the two sides instead of keeping one.
fn fade_keeps(item_y: u32, frag: vec2<f32>, seed: f32) -> bool {
    let fade = f32(item_y >> 24u) / 255.0;
    let side = (item_y >> 23u) & 1u;
    let s = u32(seed);
    let d = dither8(frag + vec2<f32>(f32(s & 7u), f32((s * 5u + (s >> 3u) * 3u) & 7u)));
    return select(d >= fade, d < fade, side == 1u);
}

// How much of a tree of `h_px` projected pixels the canopy raster stands in
// for: 1 below view.canopy.x, 0 above view.canopy.y, linear between; 0 without
// a canopy and in orthographic views (shadow cascades draw trees). Must match
// `canopy_weight` in src/lod/select.rs.
fn canopy_weight(h_px: f32, view: View) -> f32 {
    if view.canopy.x <= 0.0 || view.viewport.w > 0.5 {
        return 0.0;
    }
    return clamp((view.canopy.y - h_px) / max(view.canopy.y - view.canopy.x, 1e-3), 0.0, 1.0);
}

// Whether the canopy stands in for tree `i` of the `count` the cull considers
// of its batch (it is not drawn): a share `canopy_weight(h)` of the batch's
// trees, with `h` its tallest tree projected at tree i's distance, taken from
// the tail of the batch's density order — tree i is kept while
// i + ½ < count · (1 − w(h)), count · (1 − w) trees rounded — so a batch needs
// only its first count · (1 − w(h)) trees at its nearest point, and the
// stream fetches no more. Written as
// (count − i − ½) · (hi − lo) ≤ count · (hi − h) with only multiplications
// and subtractions, which are exactly rounded on every GPU, so the CPU oracle
// agrees bit for bit. Must match `canopy_drops` in src/lod/select.rs.
fn canopy_drops(h_px: f32, i: u32, count: u32, view: View) -> bool {
    if view.canopy.x <= 0.0 || view.viewport.w > 0.5 {
        return false;
    }
    return (f32(count - i) - 0.5) * max(view.canopy.y - view.canopy.x, 1e-3) <= f32(count) * (view.canopy.y - h_px);
}

// Decodes an octahedral-encoded unit vector (snorm xy in [-1, 1]).
fn oct_decode(e: vec2<f32>) -> vec3<f32> {
    var n = vec3<f32>(e.x, e.y, 1.0 - abs(e.x) - abs(e.y));
    let t = max(-n.z, 0.0);
    n.x += select(t, -t, n.x >= 0.0);
    n.y += select(t, -t, n.y >= 0.0);
    return normalize(n);
}

// Rotation about +Z (up) by `yaw` radians.
fn rotate_z(v: vec3<f32>, yaw: f32) -> vec3<f32> {
    let c = cos(yaw);
    let s = sin(yaw);
    return vec3<f32>(c * v.x - s * v.y, s * v.x + c * v.y, v.z);
}

// One lighting model for every representation, so a tree keeps its colour when
// its LoD changes. Leaves also pass some light through (wrap term).
// Sky light: a hemisphere instead of a flat ambient term. Surfaces facing up
// see the sky (a little brighter and bluer than `view.ambient`), surfaces
// facing down the light the ground bounces back (darker, warmer), so the
// undersides of crowns and the shaded sides of trunks read. Leaves (thin,
// scattering, normals only roughly meaningful) lean half as far either way.
const SKY_TINT: vec3<f32> = vec3<f32>(1.1, 1.12, 1.18);
const GROUND_BOUNCE: vec3<f32> = vec3<f32>(0.62, 0.58, 0.5);

fn sky_light(n: vec3<f32>, is_leaf: bool, view: View) -> vec3<f32> {
    var up = 0.5 + 0.5 * clamp(n.z, -1.0, 1.0);
    if is_leaf {
        up = 0.5 + 0.25 * clamp(n.z, -1.0, 1.0);
    }
    return view.ambient.rgb * mix(GROUND_BOUNCE, SKY_TINT, up);
}

// Aerial perspective: light scattered by the air between the eye and a
// surface veils it towards the horizon's colour, more with distance and less
// high up (density falling by e every HAZE_HEIGHT_M above the scene origin).
// Visibility (3/β) about 50 km at the ground (a clear day). Not in the LoD
// debug colours.
const HAZE_PER_M: f32 = 1.0 / 16000.0;
const HAZE_HEIGHT_M: f32 = 1500.0;
// The sky's horizon colour (shaders/sky.wgsl): far things fade into it.
const HAZE_COLOR: vec3<f32> = vec3<f32>(0.62, 0.74, 0.86);

// How bright the sky is relative to day (the ambient light's luminance
// against the default's): the sky and the haze darken at dusk.
fn sky_scale(view: View) -> f32 {
    return clamp(dot(view.ambient.rgb, vec3<f32>(0.2126, 0.7152, 0.0722)) / 0.4573, 0.15, 1.5);
}

// `color` seen through the air at `rel` (metres from the eye, world axes).
fn haze_at(color: vec3<f32>, rel: vec3<f32>, view: View) -> vec3<f32> {
    if view.params.z == 1u {
        return color;
    }
    let eye_z = view.eye_hi.z + view.eye_lo.z;
    let h = max(eye_z + 0.5 * rel.z, 0.0);
    let f = 1.0 - exp(-length(rel) * HAZE_PER_M * exp(-h / HAZE_HEIGHT_M));
    return mix(color, HAZE_COLOR * sky_scale(view), f);
}

// `color` of the fragment at `frag` (@builtin(position): pixel and depth),
// its distance recovered through the inverse projection.
fn haze(color: vec3<f32>, frag: vec4<f32>, view: View) -> vec3<f32> {
    return haze_at(color, frag_rel(frag, view), view);
}

// Eye-relative position of the fragment at `frag` (@builtin(position): pixel
// and depth), through the inverse projection.
fn frag_rel(frag: vec4<f32>, view: View) -> vec3<f32> {
    let ndc = vec2<f32>(frag.x / view.viewport.x * 2.0 - 1.0, 1.0 - frag.y / view.viewport.y * 2.0);
    let p = view.eye_from_clip * vec4<f32>(ndc, frag.z, 1.0);
    return p.xyz / p.w;
}

// `sun` is the fraction of the sun that reaches the surface (shadows, 1 lit);
// `occlusion` the fraction of the sky its surroundings hide (`canopy_occlusion`).
fn shade(albedo: vec3<f32>, n: vec3<f32>, is_leaf: bool, view: View, sun: f32, occlusion: f32, ao: f32) -> vec3<f32> {
    let ndl = dot(n, view.sun_dir.xyz);
    var diffuse = max(ndl, 0.0);
    if is_leaf {
        diffuse = max(ndl, 0.0) * 0.75 + abs(ndl) * 0.25;
    }
    let sky = sky_light(n, is_leaf, view) * (1.0 - CANOPY_SKY_OCCLUSION * occlusion) * ao;
    return albedo * (sky + view.sun_color.rgb * (diffuse * sun));
}

// `shade` for a pre-filtered surface (a billboard's or an impostor's texel
// averages many leaves): `m` is the mean of the unit normals it covers, whose
// length r (≤ 1) says how much they agree. Shading the normalised mean lights
// a spread of leaves as one leaf turned towards it (a far crown read 5–15 %
// off its leaves); the mean of the shading is wanted. The sky term and the
// signed part of the sun's are linear in the normal, so the mean normal gives
// them exactly. For the mean |n·l|, the normals are taken as spread evenly in
// a cone about the mean (r = (1 + cos α) / 2): from |n̂·l| for one direction
// (r = 1) to ½ for a hemisphere (r = ½, as the leaves facing a viewer are),
// linearly in r.
fn shade_filtered(albedo: vec3<f32>, m: vec3<f32>, is_leaf: bool, view: View, sun: f32, occlusion: f32, ao: f32) -> vec3<f32> {
    let r = clamp(length(m), 1e-4, 1.0);
    let ndl = dot(m, view.sun_dir.xyz);
    let spread = clamp(2.0 * r - 1.0, 0.0, 1.0);
    let mean_abs = mix(0.5, abs(ndl) / r, spread);
    // max(x, 0) = (x + |x|) / 2; leaves: 0.75 max(x, 0) + 0.25 |x|.
    var diffuse = 0.5 * ndl + 0.5 * mean_abs;
    if is_leaf {
        diffuse = 0.375 * ndl + 0.625 * mean_abs;
    }
    let sky = sky_light(m, is_leaf, view) * (1.0 - CANOPY_SKY_OCCLUSION * occlusion) * ao;
    return albedo * (sky + view.sun_color.rgb * (max(diffuse, 0.0) * sun));
}

// A tree's own ambient occlusion, baked per species (bake-tool/src/pack/ao.rs): the
// sky a point inside its crown sees through the tree's leaves and wood, the
// same field sampled by every level of detail (mesh vertices, the billboard
// capture, ellipsoids, lines). `baked` is 1 where a pack has none; the view's
// ambient.w switches it on (1) or off (0).
fn own_ao(baked: f32, view: View) -> f32 {
    return mix(1.0, clamp(baked, 0.0, 1.0), view.ambient.w);
}

// Forest-scale occlusion, the same for every representation of a tree: in a
// dense stand the neighbours' crowns hide part of the sky and of the sun from
// a tree, the more the lower in its crown (its top stays open), so clearings,
// edges and thinned stands read lighter than closed canopy. The stand's
// density is its batch's (a tree's neighbours × crown area over the batch's
// footprint, crown radius a fifth of the tallest tree's height: a lone tree
// is open); within the shadow
// distance the shadow map replaces the sun term (`sun_visibility`).
const CANOPY_CROWN_RADIUS: f32 = 0.2;
// At full cover, the bottom of a crown loses this much of the sky and of the sun.
const CANOPY_SKY_OCCLUSION: f32 = 0.45;
const CANOPY_SUN_OCCLUSION: f32 = 0.6;

// Fraction of the ground around one of a batch's trees that its neighbours'
// crowns cover (0–1).
fn batch_cover(b: Batch) -> f32 {
    let footprint = 4.0 * max(b.half_extent_m.x * b.half_extent_m.y, 1.0);
    let r = CANOPY_CROWN_RADIUS * b.max_height_m;
    let neighbours = f32(max(b.instance_count, 1u) - 1u);
    return clamp(neighbours * 3.14159265 * r * r / footprint, 0.0, 1.0);
}

// Occlusion (0 open – 1 closed) of a point at `rel_height` (0 base – 1 top) of a tree of batch `b`.
fn canopy_occlusion(b: Batch, rel_height: f32) -> f32 {
    return batch_cover(b) * (1.0 - clamp(rel_height, 0.0, 1.0));
}

// The sun reaching a point with that occlusion where no shadow map covers it.
// (A tree's own ambient occlusion dims only its sky light: it is an average
// over the sky, and the shadow map, where it covers, knows which leaves the
// sun reaches — dimming the sun by it too would make shadows brighten trees.)
fn open_sun(occlusion: f32) -> f32 {
    return 1.0 - CANOPY_SUN_OCCLUSION * occlusion;
}

// Direction from `p` (eye-relative) towards the eye; in an orthographic view
// (a shadow cascade: the eye is the sun) the same for every point.
fn towards_eye(p: vec3<f32>, view: View) -> vec3<f32> {
    if view.viewport.w > 0.5 {
        let near = view.eye_from_clip * vec4<f32>(0.0, 0.0, 1.0, 1.0);
        let far = view.eye_from_clip * vec4<f32>(0.0, 0.0, 0.0, 1.0);
        return normalize(near.xyz / near.w - far.xyz / far.w);
    }
    return -p;
}

// Per-tree tint/variation (0–31) → a small brightness/hue change.
fn variation_tint(variation: f32) -> vec3<f32> {
    let v = variation / 31.0 - 0.5;
    return vec3<f32>(1.0 + 0.12 * v, 1.0 + 0.08 * v, 1.0 - 0.05 * v);
}

// Debug colour of a representation (Eichner 2024, Fig. 3.1 style).
fn repr_color(repr: u32) -> vec3<f32> {
    switch repr {
        case 0u: { return vec3<f32>(0.9, 0.2, 0.2); }
        case 1u: { return vec3<f32>(0.95, 0.8, 0.2); }
        case 2u: { return vec3<f32>(0.85, 0.3, 0.85); }
        case 3u: { return vec3<f32>(0.2, 0.85, 0.3); }
        case 4u: { return vec3<f32>(0.1, 0.65, 0.45); }
        case 5u: { return vec3<f32>(0.1, 0.5, 0.55); }
        case 6u: { return vec3<f32>(0.3, 0.4, 0.6); }
        default: { return vec3<f32>(0.2, 0.5, 0.95); }
    }
}

// IEEE half floats (low 16 bits first) → f32, decoded by hand:
// `unpack2x16float` needs a capability (SHADER_FLOAT16_IN_FLOAT32) that naga's
// WebGPU validation and some native backends do not grant.
fn half_to_f32(h: u32) -> f32 {
    let e = (h >> 10u) & 0x1fu;
    let m = f32(h & 0x3ffu);
    var v = (1.0 + m / 1024.0) * exp2(f32(e) - 15.0);
    if e == 0u {
        v = m * exp2(-24.0);
    } else if e == 31u {
        v = 65504.0;
    }
    return select(v, -v, (h & 0x8000u) != 0u);
}

fn unpack_halves(w: u32) -> vec2<f32> {
    return vec2<f32>(half_to_f32(w & 0xffffu), half_to_f32(w >> 16u));
}

// The id pass (picking, on demand): the pool instance + 1 of the tree a pixel
// shows, with that pixel's depth; 0 is no tree.
struct IdOut {
    @location(0) id: u32,
    @builtin(frag_depth) depth: f32,
};

// Styles, in the cull control buffer from byte 256 (the draw passes
// bind them from there): a header, the palette (64 packed RGBA8 colours,
// entry 0 unused) and the flags at word 64, then, with STYLE_TREES, a byte per
// pool instance: bits 0–5 its palette entry (0: its own colour), bit 6
// selected, bit 7 filtered out. Must match src/render/gpu_data.rs.
const STYLE_CONTROL_WORD: u32 = 64u;
const STYLE_HEADER_WORDS: u32 = 128u;
const STYLE_FLAGS: u32 = 64u;
const STYLE_TREES: u32 = 1u;
const STYLE_BY_SPECIES: u32 = 2u;
const STYLE_SELECTED: u32 = 64u;
const STYLE_HIDDEN: u32 = 128u;

// Byte `instance & 3` of a word of style bytes.
fn style_byte_of(word: u32, instance: u32) -> u32 {
    return (word >> ((instance & 3u) * 8u)) & 0xffu;
}

// The style byte of a tree: from the header's `flags` and (with STYLE_TREES)
// the `word` of style bytes holding pool instance `instance` of model species `species`.
fn style_of(flags: u32, word: u32, instance: u32, species: u32) -> u32 {
    var b = select(0u, style_byte_of(word, instance), (flags & STYLE_TREES) != 0u);
    if (flags & STYLE_BY_SPECIES) != 0u {
        b = (b & 0xc0u) | min(species + 1u, 63u);
    }
    return b;
}

// A style's colour (palette word `entry`, sRGB with its weight in alpha; 0:
// none) in place of a tree's albedo, keeping the light and dark of its texture.
fn styled_albedo(albedo: vec3<f32>, entry: u32) -> vec3<f32> {
    if entry == 0u {
        return albedo;
    }
    let c = unpack4x8unorm(entry);
    let l = dot(albedo, vec3<f32>(0.2126, 0.7152, 0.0722));
    let shade = clamp(l / 0.06, 0.45, 1.6);
    return mix(albedo, pow(c.rgb, vec3<f32>(2.2)) * 0.6 * shade, c.a);
}

// A selected tree's colour: tinted towards a bright yellow.
fn highlighted(color: vec3<f32>, style: u32) -> vec3<f32> {
    return select(color, mix(color, vec3<f32>(1.0, 0.82, 0.1), 0.55), (style & STYLE_SELECTED) != 0u);
}
