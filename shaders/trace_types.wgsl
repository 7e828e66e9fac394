// The tracer's records shared by its walks (trace.wgsl, trace_scene.wgsl) and
// the top level's build on the GPU (top_level.wgsl).

// A node of a species' hierarchy. Must match `BvhNode` in src/trace/bvh.rs.
struct BvhNode {
    min: vec3<f32>,
    // A leaf's first triangle; an inner node's first child (the second follows).
    first: u32,
    max: vec3<f32>,
    // A leaf's triangle count; 0 for an inner node.
    count: u32,
};

// A tree. Must match `GpuInstance` in src/trace/scene.rs.
struct TraceInstance {
    position: vec3<f32>,
    yaw: f32,
    // Model xy -> scene: scale x crown aspect; z: scale.
    scale_xy: f32,
    scale_z: f32,
    // The species (bits 0-23) and the tree's tint (24-31: variation + 1, 0 none).
    species: u32,
    id: u32,
};

// Where a species' hierarchy and materials start, and how its texture
// coordinates dequantise. Must match `GpuSpeciesBvh` in src/trace/scene.rs.
struct TraceSpecies {
    node_base: u32,
    tri_base: u32,
    node_count: u32,
    material_base: u32,
    uv_min: vec2<f32>,
    uv_extent: vec2<f32>,
};
