// Sun shadows in the lit passes (mesh, billboard, cluster, terrain): the
// cascaded shadow map drawn by src/render/shadow.rs. Composed after
// layout.wgsl and light.wgsl; each pass declares `view` at group 0 binding 0.

// One depth layer per cascade, reversed Z (nearer the sun is greater).
@group(0) @binding(1) var shadow_map: texture_depth_2d_array;
// Bilinear comparison: each tap is a 2×2 PCF; "greater-equal": lit where the
// receiver is at least as near the sun as the nearest caster.
@group(0) @binding(2) var shadow_sampler: sampler_comparison;

// Receiver offsets against acne, in shadow texels of the cascade: along the
// normal (turned to the sun) and towards the sun.
const SHADOW_NORMAL_OFFSET: f32 = 0.5;
const SHADOW_SUN_OFFSET: f32 = 2.0;
// Shadows fade out over the last fifth of the shadow distance.
const SHADOW_FADE_START: f32 = 0.8;

fn shadow_pcf(uv: vec2<f32>, layer: u32, depth: f32) -> f32 {
    let r = i32(view.shadow.z);
    let step = 1.0 / view.shadow.y;
    var sum = 0.0;
    for (var y = -r; y <= r; y++) {
        for (var x = -r; x <= r; x++) {
            let at = uv + vec2<f32>(f32(x), f32(y)) * step;
            sum += textureSampleCompareLevel(shadow_map, shadow_sampler, at, layer, depth);
        }
    }
    let taps = f32((2 * r + 1) * (2 * r + 1));
    return sum / taps;
}

// The sun's angular radius (0.2666 degrees, its mean apparent size; the path
// tracer's `SUN_ANGULAR_RADIUS`): its tangent, twice, is the penumbra's width
// per metre between an occluder and what it shades.
const SUN_TAN: f32 = 0.004653;
// Soft shadows: the blocker search's and the filter's reach (texels).
const SOFT_SEARCH_TEXELS: f32 = 6.0;
const SOFT_MAX_TEXELS: f32 = 6.0;

// Percentage-closer soft shadows (Fernando 2005, "Percentage-Closer Soft
// Shadows", §3): the mean depth of the texels nearer the sun than the
// receiver around it (the blockers), the penumbra's width from the sun's
// angular size and the blockers' distance (a directional light: 2 tan(r) per
// metre), then PCF over that width. In metres, not texels: a shadow keeps its
// softness where one cascade hands over to the next (no seam between
// cascades), never narrower than a texel nor wider than 12 of the cascade's.
fn shadow_soft(uv: vec2<f32>, layer: u32, depth: f32, texel_m: f32, depth_per_m: f32) -> f32 {
    let size = view.shadow.y;
    let last = i32(size) - 1;
    var sum = 0.0;
    var count = 0.0;
    // A 5 x 5 grid 0, 3 and 6 texels out: the receiver's own texel too, so a
    // blocker narrower than the grid's step over it is found.
    for (var y = -2; y <= 2; y++) {
        for (var x = -2; x <= 2; x++) {
            let o = vec2<f32>(f32(x), f32(y)) * (0.5 * SOFT_SEARCH_TEXELS);
            let t = clamp(vec2<i32>(floor(uv * size + o)), vec2<i32>(0), vec2<i32>(last));
            let d = textureLoad(shadow_map, t, i32(layer), 0);
            // Reversed Z: nearer the sun is greater.
            if d > depth {
                sum += d;
                count += 1.0;
            }
        }
    }
    if count == 0.0 {
        return 1.0;
    }
    let blocker_m = (sum / count - depth) / max(depth_per_m, 1e-9);
    // The filter's radius: half the penumbra's width (2 tan(r) per metre).
    let r = clamp(SUN_TAN * blocker_m / texel_m, 0.5, SOFT_MAX_TEXELS);
    var lit = 0.0;
    for (var y = 0; y < 4; y++) {
        for (var x = 0; x < 4; x++) {
            let o = (vec2<f32>(f32(x), f32(y)) - 1.5) / 1.5 * r;
            lit += textureSampleCompareLevel(shadow_map, shadow_sampler, uv + o / size, layer, depth);
        }
    }
    return lit / 16.0;
}

// The receiver moved off its surface against acne (see the offsets above)
// for cascade `i`, in that cascade's clip space.
fn shadow_clip(i: u32, rel: vec3<f32>, n: vec3<f32>, lift_m: f32) -> vec4<f32> {
    let sun = view.sun_dir.xyz;
    let towards_sun = select(-n, n, dot(n, sun) >= 0.0);
    let texel = view.shadow_texel[i];
    let p = rel + towards_sun * (SHADOW_NORMAL_OFFSET * texel) + sun * (SHADOW_SUN_OFFSET * texel + lift_m);
    return view.shadow_from_eye[i] * vec4<f32>(p, 1.0);
}

// The first cascade whose map holds the receiver with room for the filter
// (its index; the cascade count where none does).
fn shadow_cascade(rel: vec3<f32>, n: vec3<f32>, lift_m: f32) -> u32 {
    let count = u32(view.shadow.x);
    for (var i = 0u; i < count; i++) {
        if cascade_holds(shadow_clip(i, rel, n, lift_m)) {
            return i;
        }
    }
    return count;
}

// Whether a cascade's map holds the receiver at `c` (its clip position).
fn cascade_holds(c: vec4<f32>) -> bool {
    let reach = select(view.shadow.z, SOFT_SEARCH_TEXELS, light_on(view, LIGHT_SOFT_SHADOWS));
    let margin = (reach + 1.0) / view.shadow.y;
    let uv = vec2<f32>(0.5 + 0.5 * c.x, 0.5 - 0.5 * c.y);
    return all(uv >= vec2<f32>(margin)) && all(uv <= vec2<f32>(1.0 - margin)) && c.z >= 0.0;
}

// The sun's visibility from cascade `i` alone at the receiver's clip
// position `c` there (1 above every caster).
fn cascade_visibility(i: u32, c: vec4<f32>) -> f32 {
    let uv = vec2<f32>(0.5 + 0.5 * c.x, 0.5 - 0.5 * c.y);
    if c.z > 1.0 {
        return 1.0; // above every caster
    }
    if light_on(view, LIGHT_SOFT_SHADOWS) {
        let m = view.shadow_from_eye[i];
        let depth_per_m = length(vec3<f32>(m[0].z, m[1].z, m[2].z));
        return shadow_soft(uv, i, c.z, view.shadow_texel[i], depth_per_m);
    }
    return shadow_pcf(uv, i, c.z);
}

// How much of the sun reaches the eye-relative point `rel` with normal `n`
// (1 lit, 0 shadowed). `lift_m` moves the receiver towards the sun first
// (flat billboards, which stand for a whole crown, lift by their half width
// so they are shaded by other trees, not by their own caster). Where no
// cascade holds the point (shadows off, beyond the shadow distance) the
// precomputed `open` term stands in, and the shadows fade into it.
fn sun_visibility(rel: vec3<f32>, n: vec3<f32>, lift_m: f32, open: f32) -> f32 {
    let count = u32(view.shadow.x);
    if view.params.x != 0u {
        return 1.0;
    }
    if count == 0u {
        return open;
    }
    let fade = smoothstep(SHADOW_FADE_START * view.shadow.w, view.shadow.w, length(rel));
    if fade >= 1.0 {
        return open;
    }
    // The first cascade that holds it, its clip position worked out once.
    for (var i = 0u; i < count; i++) {
        let c = shadow_clip(i, rel, n, lift_m);
        if cascade_holds(c) {
            return mix(cascade_visibility(i, c), open, fade);
        }
    }
    return open;
}
