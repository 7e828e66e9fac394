// Progressive refinement (src/render/refine.rs): one triangle over the target
// copying `src` texel for texel. Drawn twice per refined frame: the scene
// blended into the linear accumulation (blend constant = the frame's weight),
// then the shown accumulation resolved into the host's target.

@group(0) @binding(0) var src: texture_2d<f32>;

@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let p = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u)) * 2.0 - 1.0;
    return vec4<f32>(p, 0.0, 1.0);
}

@fragment
fn fs_main(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    return textureLoad(src, vec2<i32>(frag.xy), 0);
}
