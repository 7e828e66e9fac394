// The bindings every tree pass (meshes, billboards, impostors, clusters)
// shares, declared once: the pools' batches, instances and the draw items the
// cull pass wrote (group 2; the styles at binding 3, `shaders/styles.wgsl`),
// and the draw's params (group 3, a dynamic offset per draw). Bound by
// `SharedLayouts::instance_group` and `draw_group` (src/render/layouts.rs).

@group(2) @binding(0) var<storage, read> batches: array<Batch>;
@group(2) @binding(1) var<storage, read> instances: array<vec2<u32>>;
@group(2) @binding(2) var<storage, read> items: array<vec2<u32>>;

@group(3) @binding(0) var<uniform> draw: DrawParams;

// The variant a tree of `variation` (0–31) draws of a level (or far tier) with
// `extra` other variants. Must match `variant_of` in src/format/mesh.rs.
fn variant_of(variation: u32, extra: u32) -> u32 {
    return ((variation + 17u) & 31u) % (extra + 1u);
}

// Seasons (`draw.season`, a deciduous species'; evergreens draw leaf-on):
// `w` 0 leaf-on, 1 autumn, 2 leaf-off (`--season`); at a date (`--date`) 3 +
// the stand's phase in its leaf calendar (0 bare, 1 in leaf, 2 in full colour,
// 3 bare again; src/phenology.rs). Within each change (leaf-out, colouring,
// fall) a tree starts after a delay of up to PHASE_SPREAD of the stand's
// change, by its variation, and goes through it in the rest: the stand turns
// over days, every tree done when the stand is (between changes all alike).
// Leaf-off: the passes drop their leaves (mesh leaf cards and cloud planes in
// the vertex stage, ellipsoids, the leaf texels of a far tier whose bare
// capture has not come). Twins in src/render/settings.rs (`tree_phase`).
const DATED: f32 = 2.75;
const PHASE_SPREAD: f32 = 0.6;
fn tree_phase(variation: f32) -> f32 {
    let p = clamp(draw.season.w - 3.0, 0.0, 3.0);
    let k = min(floor(p), 2.0);
    let delay = PHASE_SPREAD * fract(variation * 0.618034 + 0.3);
    return k + clamp((p - k - delay) / (1.0 - PHASE_SPREAD), 0.0, 1.0);
}
fn leaves_off(variation: f32) -> bool {
    if draw.season.w > DATED {
        let p = tree_phase(variation);
        return p < 0.5 || p >= 2.5;
    }
    return draw.season.w > 1.5;
}

// How far a tree of `variation` (0–31) has turned in autumn, 0.4–1: the trees
// of a stand turn at their own pace. Twin of `autumn_progress` in src/render/settings.rs.
fn autumn_progress(variation: f32) -> f32 {
    return 0.4 + 0.6 * fract(variation * 0.618034 + 0.3);
}

// A leaf's albedo in the season drawn: in autumn towards the species' autumn
// colour, keeping the light and dark of the leaf (its luminance against a
// typical leaf's), as far as the tree (`variation`) has turned. Twin of
// `autumn_albedo` in src/render/settings.rs (the canopy rasters' autumn).
const AUTUMN_LEAF_LUMINANCE: f32 = 0.08;
fn seasonal_leaf(albedo: vec3<f32>, variation: f32) -> vec3<f32> {
    var progress = autumn_progress(variation);
    if draw.season.w > DATED {
        progress = clamp(tree_phase(variation) - 1.0, 0.0, 1.0);
    } else if draw.season.w < 0.5 || draw.season.w > 1.5 {
        return albedo;
    }
    let l = dot(albedo, vec3<f32>(0.2126, 0.7152, 0.0722));
    let fall = draw.season.rgb * clamp(l / AUTUMN_LEAF_LUMINANCE, 0.3, 2.0);
    return mix(albedo, fall, progress);
}
