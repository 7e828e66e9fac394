// The path tracer's geometry (issue 48): the slab test, Möller & Trumbore's
// ray–triangle test and the nearest-hit walk of a species' BVH. Twins:
// src/trace/mod.rs and src/trace/bvh.rs, the same operations in the same order
// (a GPU may fuse multiply-adds: hits agree to rounding, tests/it/gpu_trace.rs).
// Needs trace_types.wgsl; the composing module declares `bvh_nodes: array<BvhNode>` and
// `bvh_tris: array<TraceTriangle>` (storage, read) and the alpha test
// `fn trace_keeps(species: u32, tri: TraceTriangle, u: f32, v: f32) -> bool`.

// A triangle: first corner, the edges from it, the mesh's index of it, its
// material and its corners' quantised texture coordinates (u | v << 16).
// Must match `GpuTriangle` in src/trace/bvh.rs.
struct TraceTriangle {
    v0: vec3<f32>,
    id: u32,
    e1: vec3<f32>,
    material: u32,
    e2: vec3<f32>,
    // The corners' vertex colours averaged, linear RGBA8 (r low).
    color: u32,
    uv: vec4<u32>,
};

// A ray's nearest hit: t < 0 for none. Twin: `Hit` in src/trace/mod.rs.
struct TraceHit {
    t: f32,
    // The mesh's index of the triangle.
    triangle: u32,
    u: f32,
    v: f32,
    // Its place in bvh_tris.
    index: u32,
};

// Entries of a walk's stack (src/trace/bvh.rs `STACK`; the build's depth bound keeps it enough).
const TRACE_STACK: u32 = 64u;

// 1 / d per axis, components nearer zero than 1e-20 replaced by ±1e-20 first.
// Twin: `inv_dir` in src/trace/mod.rs.
fn ray_inv_dir(d: vec3<f32>) -> vec3<f32> {
    let tiny = select(vec3<f32>(1e-20), vec3<f32>(-1e-20), d < vec3<f32>(0.0));
    return 1.0 / select(d, tiny, abs(d) < vec3<f32>(1e-20));
}

// The slab test (Kay & Kajiya 1986; Williams et al. 2005, §3): the distance at
// which the ray enters the box (0 inside), or -1 if it misses it or enters at
// or beyond t_max. Twin: `ray_box` in src/trace/mod.rs.
fn ray_box(o: vec3<f32>, inv: vec3<f32>, bmin: vec3<f32>, bmax: vec3<f32>, t_max: f32) -> f32 {
    let t0 = (bmin - o) * inv;
    let t1 = (bmax - o) * inv;
    let near = min(t0, t1);
    let far = max(t0, t1);
    let enter = max(max(max(near.x, near.y), near.z), 0.0);
    let exit = min(min(far.x, far.y), far.z);
    if enter <= exit && enter < t_max {
        return enter;
    }
    return -1.0;
}

// Möller & Trumbore 1997 (§2-3), both sides: (t, u, v) where the ray meets the
// triangle at t in (0, t_max), else t = -1. Twin: `ray_triangle` in src/trace/mod.rs.
fn ray_triangle(o: vec3<f32>, d: vec3<f32>, tri: TraceTriangle, t_max: f32) -> vec3<f32> {
    let miss = vec3<f32>(-1.0, 0.0, 0.0);
    let p = cross(d, tri.e2);
    let det = dot(tri.e1, p);
    if abs(det) < 1e-12 {
        return miss;
    }
    let inv = 1.0 / det;
    let s = o - tri.v0;
    let u = dot(s, p) * inv;
    if u < 0.0 || u > 1.0 {
        return miss;
    }
    let q = cross(s, tri.e1);
    let v = dot(d, q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return miss;
    }
    let t = dot(tri.e2, q) * inv;
    if t > 0.0 && t < t_max {
        return vec3<f32>(t, u, v);
    }
    return miss;
}

// A walk's stack: node indices (relative to the hierarchy's first node) and
// the distances at which the ray entered them.
struct TraceStack {
    node: array<u32, TRACE_STACK>,
    t: array<f32, TRACE_STACK>,
    sp: u32,
};

// An inner node's children (at `first` and `first + 1` from `base` in
// bvh_nodes) that the ray enters before `closest`, pushed the farther first so
// the nearer is walked next. Both walks' step (trace_bvh, trace_scene); twin:
// the child step of `walk` in src/trace/bvh.rs.
fn trace_push_children(stack: ptr<function, TraceStack>, o: vec3<f32>, inv: vec3<f32>, base: u32, first: u32, closest: f32) {
    let a = first;
    let b = first + 1u;
    let na = bvh_nodes[base + a];
    let nb = bvh_nodes[base + b];
    let ta = ray_box(o, inv, na.min, na.max, closest);
    let tb = ray_box(o, inv, nb.min, nb.max, closest);
    let sp = (*stack).sp;
    if ta >= 0.0 && tb >= 0.0 && sp + 2u <= TRACE_STACK {
        let near_a = !(tb < ta);
        (*stack).node[sp] = select(a, b, near_a);
        (*stack).t[sp] = select(ta, tb, near_a);
        (*stack).node[sp + 1u] = select(b, a, near_a);
        (*stack).t[sp + 1u] = select(tb, ta, near_a);
        (*stack).sp = sp + 2u;
    } else if ta >= 0.0 && sp < TRACE_STACK {
        (*stack).node[sp] = a;
        (*stack).t[sp] = ta;
        (*stack).sp = sp + 1u;
    } else if tb >= 0.0 && sp < TRACE_STACK {
        (*stack).node[sp] = b;
        (*stack).t[sp] = tb;
        (*stack).sp = sp + 1u;
    }
}

// The nearest hit of the ray o + t d (t < t_max) that `trace_keeps` keeps, in
// the hierarchy of `species` whose nodes start at node_base and triangles at
// tri_base, walked front to back. Twin: `Bvh::intersect_where` in src/trace/bvh.rs.
fn trace_bvh(o: vec3<f32>, d: vec3<f32>, t_max: f32, species: u32, node_base: u32, tri_base: u32) -> TraceHit {
    var hit = TraceHit(-1.0, 0u, 0.0, 0.0, 0u);
    let inv = ray_inv_dir(d);
    let root = bvh_nodes[node_base];
    let enter = ray_box(o, inv, root.min, root.max, t_max);
    if enter < 0.0 {
        return hit;
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
        let node = bvh_nodes[node_base + stack.node[stack.sp]];
        if node.count > 0u {
            for (var i = node.first; i < node.first + node.count; i++) {
                let tri = bvh_tris[tri_base + i];
                let h = ray_triangle(o, d, tri, closest);
                if h.x > 0.0 && trace_keeps(species, tri, h.y, h.z) {
                    closest = h.x;
                    hit = TraceHit(h.x, tri.id, h.y, h.z, tri_base + i);
                }
            }
            continue;
        }
        trace_push_children(&stack, o, inv, node_base, node.first, closest);
    }
    return hit;
}
