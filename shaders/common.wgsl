// Shared helpers for every Sylva pass. Prepended to each pass's WGSL by
// `src/render/shaders.rs`, so the structs here exist once.

// Must match `ViewUniform` in src/render/gpu_data.rs.
struct View {
    // Camera-relative clip transform: world positions are given relative to `eye_m`.
    clip_from_eye: mat4x4<f32>,
    // Camera position, metres relative to the scene origin (for billboards and LoD).
    eye_m: vec4<f32>,
    // Unit vector towards the sun (xyz), w unused.
    sun_dir: vec4<f32>,
    // Sun colour (rgb) times intensity.
    sun_color: vec4<f32>,
    // Ambient colour (rgb).
    ambient: vec4<f32>,
    // x: render mode (0 lit, 1 capture albedo+normal, 2 debug colour), yzw unused.
    params: vec4<u32>,
};

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
fn shade(albedo: vec3<f32>, n: vec3<f32>, is_leaf: bool, view: View) -> vec3<f32> {
    let ndl = dot(n, view.sun_dir.xyz);
    var diffuse = max(ndl, 0.0);
    if is_leaf {
        diffuse = max(ndl, 0.0) * 0.75 + abs(ndl) * 0.25;
    }
    return albedo * (view.ambient.rgb + view.sun_color.rgb * diffuse);
}

// Per-tree tint/variation (0–31) → a small brightness/hue change.
fn variation_tint(variation: f32) -> vec3<f32> {
    let v = variation / 31.0 - 0.5;
    return vec3<f32>(1.0 + 0.12 * v, 1.0 + 0.08 * v, 1.0 - 0.05 * v);
}
