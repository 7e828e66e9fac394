// Debug view: the boxes of the batches that passed the batch test, as lines
// (24 vertices per box, one instance per visible batch, one indirect draw).
// Rust side: src/render/forest.rs.

// (Group 0, binding 0: the view, `shaders/view.wgsl`.)
@group(1) @binding(0) var<storage, read> batches: array<Batch>;
@group(1) @binding(1) var<storage, read> visible: array<u32>;

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) color: vec3<f32>,
};

@vertex
fn vs_main(@builtin(vertex_index) v: u32, @builtin(instance_index) i: u32) -> VertexOut {
    let b = batches[visible[i]];
    // 12 edges: for each axis, the 4 edges along it.
    let edge = v / 2u;
    let end = v % 2u;
    let axis = edge / 4u;
    let k = edge % 4u;
    var corner = vec3<f32>(0.0);
    let a1 = (axis + 1u) % 3u;
    let a2 = (axis + 2u) % 3u;
    corner[axis] = f32(end) * 2.0 - 1.0;
    corner[a1] = f32(k & 1u) * 2.0 - 1.0;
    corner[a2] = f32((k >> 1u) & 1u) * 2.0 - 1.0;
    let p = eye_relative(b.center_m, corner * b.half_extent_m, view);
    var out: VertexOut;
    out.clip = view.clip_from_eye * vec4<f32>(p, 1.0);
    // Colour by species so neighbouring batches of different species are told apart.
    let hue = f32(b.species % 6u) / 6.0;
    out.color = clamp(abs(fract(vec3<f32>(hue) + vec3<f32>(0.0, 0.333, 0.667)) * 6.0 - 3.0) - 1.0, vec3<f32>(0.0), vec3<f32>(1.0));
    return out;
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    return vec4<f32>(in.color, 1.0);
}
