// Background: sky above the horizon, ground below, from the view ray of each
// pixel, so clearings and gaps between trees do not show a flat clear colour.
// Drawn first in the forest pass, without depth. Rust side: src/render/forest.rs.

// (Group 0, binding 0: the view, `shaders/view.wgsl`.)

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) ndc: vec2<f32>,
};

@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> VertexOut {
    // One triangle covering the screen.
    let p = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u)) * 2.0 - 1.0;
    var out: VertexOut;
    out.clip = vec4<f32>(p, 0.0, 1.0);
    out.ndc = p;
    return out;
}

// Must match `SKY_*` colours in src/render/forest.rs (linear RGB).
const SKY_ZENITH: vec3<f32> = vec3<f32>(0.23, 0.42, 0.72);
const SKY_HORIZON: vec3<f32> = HAZE_COLOR;
const GROUND: vec3<f32> = vec3<f32>(0.16, 0.15, 0.08);

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    // Eye-space ray through the pixel: invert the projection on a far point.
    let inv = inverse4(view.clip_from_eye);
    let far = inv * vec4<f32>(in.ndc, 1e-6, 1.0);
    let dir = normalize(far.xyz / far.w);
    let up = dir.z;
    if light_on(view, LIGHT_SKY) {
        return vec4<f32>(sky_background(dir), 1.0);
    }
    var color: vec3<f32>;
    if up >= 0.0 {
        color = mix(SKY_HORIZON, SKY_ZENITH, sqrt(up));
    } else {
        color = mix(SKY_HORIZON * 0.5 + GROUND * 0.5, GROUND, sqrt(min(-up * 4.0, 1.0)));
    }
    return vec4<f32>(color * sky_scale(view), 1.0);
}

// The clear sky (Preetham et al. 1999) above the horizon, below it level
// ground of the background's albedo lit by the sun and the sky — what the path
// tracer's rays that leave the scene see (`sky` in path_trace.wgsl; CPU twin
// `SkyLight::radiance`).
fn sky_background(d: vec3<f32>) -> vec3<f32> {
    if d.z >= 0.0 {
        return sky_radiance(d, view);
    }
    let up45 = normalize(vec3<f32>(d.xy, length(d.xy) + 1e-3));
    return GROUND * (view.sun_color.rgb * max(view.sun_dir.z, 0.0) + sky_radiance(up45, view));
}

// General 4×4 inverse (WGSL has none); used once per pixel of a cheap pass.
fn inverse4(m: mat4x4<f32>) -> mat4x4<f32> {
    let a00 = m[0][0]; let a01 = m[0][1]; let a02 = m[0][2]; let a03 = m[0][3];
    let a10 = m[1][0]; let a11 = m[1][1]; let a12 = m[1][2]; let a13 = m[1][3];
    let a20 = m[2][0]; let a21 = m[2][1]; let a22 = m[2][2]; let a23 = m[2][3];
    let a30 = m[3][0]; let a31 = m[3][1]; let a32 = m[3][2]; let a33 = m[3][3];
    let b00 = a00 * a11 - a01 * a10;
    let b01 = a00 * a12 - a02 * a10;
    let b02 = a00 * a13 - a03 * a10;
    let b03 = a01 * a12 - a02 * a11;
    let b04 = a01 * a13 - a03 * a11;
    let b05 = a02 * a13 - a03 * a12;
    let b06 = a20 * a31 - a21 * a30;
    let b07 = a20 * a32 - a22 * a30;
    let b08 = a20 * a33 - a23 * a30;
    let b09 = a21 * a32 - a22 * a31;
    let b10 = a21 * a33 - a23 * a31;
    let b11 = a22 * a33 - a23 * a32;
    let det = b00 * b11 - b01 * b10 + b02 * b09 + b03 * b08 - b04 * b07 + b05 * b06;
    let inv_det = 1.0 / det;
    return mat4x4<f32>(
        vec4<f32>(a11 * b11 - a12 * b10 + a13 * b09, a02 * b10 - a01 * b11 - a03 * b09, a31 * b05 - a32 * b04 + a33 * b03, a22 * b04 - a21 * b05 - a23 * b03) * inv_det,
        vec4<f32>(a12 * b08 - a10 * b11 - a13 * b07, a00 * b11 - a02 * b08 + a03 * b07, a32 * b02 - a30 * b05 - a33 * b01, a20 * b05 - a22 * b02 + a23 * b01) * inv_det,
        vec4<f32>(a10 * b10 - a11 * b08 + a13 * b06, a01 * b08 - a00 * b10 - a03 * b06, a30 * b04 - a31 * b02 + a33 * b00, a21 * b02 - a20 * b04 - a23 * b00) * inv_det,
        vec4<f32>(a11 * b07 - a10 * b09 - a12 * b06, a00 * b09 - a01 * b07 + a02 * b06, a31 * b01 - a30 * b03 - a32 * b00, a20 * b03 - a21 * b01 + a22 * b00) * inv_det,
    );
}
