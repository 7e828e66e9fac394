// The bindings every tree pass (meshes, billboards, impostors, clusters)
// shares, declared once: the pools' batches, instances and the draw items the
// cull pass wrote (group 2; the styles at binding 3, `shaders/styles.wgsl`),
// and the draw's params (group 3, a dynamic offset per draw). Bound by
// `SharedLayouts::instance_group` and `draw_group` (src/render/layouts.rs).

@group(2) @binding(0) var<storage, read> batches: array<Batch>;
@group(2) @binding(1) var<storage, read> instances: array<vec2<u32>>;
@group(2) @binding(2) var<storage, read> items: array<vec2<u32>>;

@group(3) @binding(0) var<uniform> draw: DrawParams;
