// The path tracer's accumulation on a colour target (the browser's canvas):
// each pixel the mean of its samples, clamped as `to_srgb8` clamps (the
// target is sRGB: the image is linear). Rust side: `PathDisplay` in
// src/render/path_trace.rs.

// x, y: the accumulation's width and height (zw unused).
@group(0) @binding(0) var<uniform> display_size: vec4<u32>;
// Per pixel, row-major from the top: the sum of its samples (rgb) and their count (a).
@group(0) @binding(1) var<storage, read> display_accum: array<vec4<f32>>;

@vertex
fn display_vs(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    // One triangle over the whole target.
    let uv = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4<f32>(uv * 2.0 - 1.0, 0.0, 1.0);
}

@fragment
fn display_fs(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let x = min(u32(frag.x), display_size.x - 1u);
    let y = min(u32(frag.y), display_size.y - 1u);
    let s = display_accum[y * display_size.x + x];
    return vec4<f32>(clamp(s.rgb / max(s.a, 1.0), vec3<f32>(0.0), vec3<f32>(1.0)), 1.0);
}
