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
const SHADOW_NORMAL_OFFSET: f32 = 1.5;
const SHADOW_SUN_OFFSET: f32 = 1.0;
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
    let sun = view.sun_dir.xyz;
    let towards_sun = select(-n, n, dot(n, sun) >= 0.0);
    let margin = (view.shadow.z + 1.0) / view.shadow.y;
    for (var i = 0u; i < count; i++) {
        let texel = view.shadow_texel[i];
        let p = rel + towards_sun * (SHADOW_NORMAL_OFFSET * texel) + sun * (SHADOW_SUN_OFFSET * texel + lift_m);
        let c = view.shadow_from_eye[i] * vec4<f32>(p, 1.0);
        let uv = vec2<f32>(0.5 + 0.5 * c.x, 0.5 - 0.5 * c.y);
        if all(uv >= vec2<f32>(margin)) && all(uv <= vec2<f32>(1.0 - margin)) && c.z >= 0.0 {
            if c.z > 1.0 {
                return mix(1.0, open, fade); // above every caster
            }
            return mix(shadow_pcf(uv, i, c.z), open, fade);
        }
    }
    return open;
}
