// The tracer's two levels (Dietrich et al. 2005, §4.1): the top level over the
// trees walked front to back, each tree entered carried into its species'
// model space and walked there (trace_bvh). Twin: src/trace/scene.rs. Needs
// trace_types.wgsl and trace.wgsl; the composing module declares (beside trace.wgsl's `bvh_nodes`,
// which hold the species' nodes and then the top level's, and `bvh_tris`)
// `trace_params: TraceParams` (uniform), `trace_instances: array<TraceInstance>`,
// `trace_species: array<TraceSpecies>`, `trace_materials: array<TraceMaterial>`
// and `trace_texels: array<u32>`.

// Must match `GpuTraceParams` in src/render/trace.rs.
struct TraceParams {
    // Where the top level starts in bvh_nodes.
    top_base: u32,
    instance_count: u32,
    pad0: u32,
    pad1: u32,
};

// Must match `GpuTraceMaterial` in src/trace/scene.rs.
struct TraceMaterial {
    base_color: vec4<f32>,
    alpha_cutoff: f32,
    // First texel of its full-resolution layer in trace_texels, or 0xffffffff.
    texel_base: u32,
    size: u32,
    // 0 leaf, 1 branch.
    kind: u32,
};

const NO_TEXTURE: u32 = 0xffffffffu;

// Alpha of a texture layer at uv: bilinear between the four nearest texel
// centres, repeating. Twin: `texel_alpha` in src/trace/scene.rs.
fn texel_alpha(base: u32, size: u32, uv: vec2<f32>) -> f32 {
    let n = i32(size);
    // Wrapped first (repeating), so the texel indices stay small whatever the uv.
    let x = fract(uv.x) * f32(size) - 0.5;
    let y = fract(uv.y) * f32(size) - 0.5;
    let x0 = floor(x);
    let y0 = floor(y);
    let fx = x - x0;
    let fy = y - y0;
    let ix = i32(x0);
    let iy = i32(y0);
    var a: array<f32, 4>;
    for (var k = 0; k < 4; k++) {
        let tx = (((ix + (k & 1)) % n) + n) % n;
        let ty = (((iy + (k >> 1u)) % n) + n) % n;
        a[k] = f32(trace_texels[base + u32(ty * n + tx)] >> 24u) / 255.0;
    }
    let top = a[0] + (a[1] - a[0]) * fx;
    let bottom = a[2] + (a[3] - a[2]) * fx;
    return top + (bottom - top) * fy;
}

// A hit's texture coordinate on `tri` at barycentric (u, v).
// Twin: `TraceSpecies::uv` in src/trace/scene.rs.
fn trace_uv(sp: TraceSpecies, tri: TraceTriangle, u: f32, v: f32) -> vec2<f32> {
    let a = sp.uv_min + vec2<f32>(f32(tri.uv.x & 0xffffu), f32(tri.uv.x >> 16u)) / 65535.0 * sp.uv_extent;
    let b = sp.uv_min + vec2<f32>(f32(tri.uv.y & 0xffffu), f32(tri.uv.y >> 16u)) / 65535.0 * sp.uv_extent;
    let c = sp.uv_min + vec2<f32>(f32(tri.uv.z & 0xffffu), f32(tri.uv.z >> 16u)) / 65535.0 * sp.uv_extent;
    let w = 1.0 - u - v;
    return w * a + u * b + v * c;
}

// The alpha test of leaf cards: the material's alpha (x its texture's) at
// least its cutoff. Twin: `TraceSpecies::keeps` in src/trace/scene.rs.
fn trace_keeps(species: u32, tri: TraceTriangle, u: f32, v: f32) -> bool {
    let sp = trace_species[species];
    let m = trace_materials[sp.material_base + tri.material];
    var alpha = m.base_color.a * f32(tri.color >> 24u) / 255.0;
    if m.texel_base != NO_TEXTURE && m.size > 0u {
        alpha *= texel_alpha(m.texel_base, m.size, trace_uv(sp, tri, u, v));
    }
    return alpha >= m.alpha_cutoff;
}

// The nearest hit in the scene: the instance's id, its place in
// trace_instances and the hit on its mesh (t < 0: none).
struct SceneHit {
    instance: u32,
    slot: u32,
    hit: TraceHit,
};

// A scene-space point or direction carried into a tree's model space (the
// inverse turn, then the inverse scale; `translate` 0 for a direction).
// Twin: `GpuInstance::to_model` in src/trace/scene.rs.
fn to_model(inst: TraceInstance, v: vec3<f32>, translate: f32) -> vec3<f32> {
    let r = v - inst.position * translate;
    let c = cos(inst.yaw);
    let s = sin(inst.yaw);
    return vec3<f32>(c * r.x + s * r.y, -s * r.x + c * r.y, r.z) * vec3<f32>(1.0 / inst.scale_xy, 1.0 / inst.scale_xy, 1.0 / inst.scale_z);
}

// The nearest hit of the ray o + t d (t < t_max) among the scene's trees.
// Twin: `TraceScene::intersect` in src/trace/scene.rs.
fn trace_scene(o: vec3<f32>, d: vec3<f32>, t_max: f32) -> SceneHit {
    var best = SceneHit(0u, 0u, TraceHit(-1.0, 0u, 0.0, 0.0, 0u));
    if trace_params.instance_count == 0u {
        return best;
    }
    let top = trace_params.top_base;
    let inv = ray_inv_dir(d);
    let root = bvh_nodes[top];
    let enter = ray_box(o, inv, root.min, root.max, t_max);
    if enter < 0.0 {
        return best;
    }
    var stack: TraceStack;
    stack.node[0] = 0u;
    stack.t[0] = enter;
    stack.sp = 1u;
    var closest = t_max;
    loop {
        if stack.sp == 0u {
            break;
        }
        stack.sp -= 1u;
        if stack.t[stack.sp] >= closest {
            continue;
        }
        let node = bvh_nodes[top + stack.node[stack.sp]];
        if node.count > 0u {
            for (var i = node.first; i < node.first + node.count; i++) {
                let inst = trace_instances[i];
                let sp_ = trace_species[inst.species & 0xffffffu];
                if sp_.node_count == 0u {
                    continue;
                }
                let h = trace_bvh(to_model(inst, o, 1.0), to_model(inst, d, 0.0), closest, inst.species & 0xffffffu, sp_.node_base, sp_.tri_base);
                if h.t > 0.0 {
                    closest = h.t;
                    best = SceneHit(inst.id, i, h);
                }
            }
            continue;
        }
        trace_push_children(&stack, o, inv, top, node.first, closest);
    }
    return best;
}
