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
    // Eye-space ray through the pixel: the inverse projection of a far point.
    let far = view.eye_from_clip * vec4<f32>(in.ndc, 1e-6, 1.0);
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
