// The tracer's two levels (Dietrich et al. 2005, §4.1): the top level over the
// trees walked front to back, each tree entered carried into its species'
// model space and walked there (trace_bvh). Twin: src/trace/scene.rs. Needs
// trace.wgsl; the composing module declares `trace_top: array<BvhNode>`,
// `trace_instances: array<TraceInstance>` and `trace_species: array<TraceSpecies>`.

// A tree. Must match `GpuInstance` in src/trace/scene.rs.
struct TraceInstance {
    position: vec3<f32>,
    yaw: f32,
    // Model xy -> scene: scale x crown aspect; z: scale.
    scale_xy: f32,
    scale_z: f32,
    species: u32,
    id: u32,
};

// Where a species' hierarchy starts. Must match `GpuSpeciesBvh` in src/trace/scene.rs.
struct TraceSpecies {
    node_base: u32,
    tri_base: u32,
    node_count: u32,
    pad: u32,
};

// The nearest hit in the scene: the instance's id and the hit on its mesh (t < 0: none).
struct SceneHit {
    instance: u32,
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
    var best = SceneHit(0u, TraceHit(-1.0, 0u, 0.0, 0.0));
    if arrayLength(&trace_instances) == 0u {
        return best;
    }
    let inv = ray_inv_dir(d);
    let root = trace_top[0];
    let enter = ray_box(o, inv, root.min, root.max, t_max);
    if enter < 0.0 {
        return best;
    }
    var stack_node: array<u32, TRACE_STACK>;
    var stack_t: array<f32, TRACE_STACK>;
    stack_node[0] = 0u;
    stack_t[0] = enter;
    var sp = 1u;
    var closest = t_max;
    loop {
        if sp == 0u {
            break;
        }
        sp -= 1u;
        if stack_t[sp] >= closest {
            continue;
        }
        let node = trace_top[stack_node[sp]];
        if node.count > 0u {
            for (var i = node.first; i < node.first + node.count; i++) {
                let inst = trace_instances[i];
                let sp_ = trace_species[inst.species];
                if sp_.node_count == 0u {
                    continue;
                }
                let h = trace_bvh(to_model(inst, o, 1.0), to_model(inst, d, 0.0), closest, sp_.node_base, sp_.tri_base);
                if h.t > 0.0 {
                    closest = h.t;
                    best = SceneHit(inst.id, h);
                }
            }
            continue;
        }
        let a = node.first;
        let b = node.first + 1u;
        let na = trace_top[a];
        let nb = trace_top[b];
        let ta = ray_box(o, inv, na.min, na.max, closest);
        let tb = ray_box(o, inv, nb.min, nb.max, closest);
        if ta >= 0.0 && tb >= 0.0 && sp + 2u <= TRACE_STACK {
            if tb < ta {
                stack_node[sp] = a;
                stack_t[sp] = ta;
                stack_node[sp + 1u] = b;
                stack_t[sp + 1u] = tb;
            } else {
                stack_node[sp] = b;
                stack_t[sp] = tb;
                stack_node[sp + 1u] = a;
                stack_t[sp + 1u] = ta;
            }
            sp += 2u;
        } else if ta >= 0.0 && sp < TRACE_STACK {
            stack_node[sp] = a;
            stack_t[sp] = ta;
            sp += 1u;
        } else if tb >= 0.0 && sp < TRACE_STACK {
            stack_node[sp] = b;
            stack_t[sp] = tb;
            sp += 1u;
        }
    }
    return best;
}
