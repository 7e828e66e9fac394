// The tracer's top level built on the GPU (issue 48): a linear BVH over the
// trees (Lauterbach et al. 2009, §3: instances ordered along a Morton curve;
// Karras 2012, §3-4: every inner node's range and split found at once from
// the sorted codes). Passes, each a dispatch (src/render/top_level.rs):
// `top_bounds` (the box of the trees' centres), `top_codes` (each tree's
// placed box and Morton code), `top_sort` (one step of Batcher's bitonic
// merge sort a dispatch), `top_gather` (the trees in curve order),
// `top_split` (Karras' inner nodes and their children) and `top_refit` (each
// inner node's box from its children's, as many times as the tree is deep).
//
// The layout is the walks' (trace.wgsl): an inner node's children side by
// side. Inner node k's children lie at 1 + 2k and 2 + 2k (from the trees'
// root), the root at 0; a leaf holds one tree (first = its place in
// trace_instances, count = 1). 2n - 1 nodes for n trees. With the ground (one
// instance after the trees, as large as the view: in a linear BVH its box
// would swell every node above its place on the curve) the root has two
// children: the ground's leaf at 1 and the trees' root at 2 (`top_join`).
// Needs trace_types.wgsl.

// Must match `TopBuild` in src/render/top_level.rs.
struct TopBuild {
    // Trees, and the sort's length (a power of two, at least count).
    count: u32,
    padded: u32,
    // Where the top level starts in bvh_nodes.
    top_base: u32,
    // 1: instance `count` is the ground, beside the trees at the root.
    ground: u32,
};

// One bitonic step: the sequence length being merged and the compare distance.
struct SortStep {
    k: u32,
    j: u32,
};

@group(0) @binding(0) var<uniform> build: TopBuild;
@group(0) @binding(1) var<uniform> step: SortStep;
@group(0) @binding(2) var<storage, read_write> bvh_nodes: array<BvhNode>;
@group(0) @binding(3) var<storage, read> trace_species: array<TraceSpecies>;
// The trees as loaded, and in curve order (what the walks read).
@group(0) @binding(4) var<storage, read> source: array<TraceInstance>;
@group(0) @binding(5) var<storage, read_write> trace_instances: array<TraceInstance>;
// Per slot of the sort: (Morton code, tree index).
@group(0) @binding(6) var<storage, read_write> codes: array<vec2<u32>>;
// Per inner node the slot that holds it.
@group(0) @binding(7) var<storage, read_write> parents: array<u32>;
// The centres' box as order-preserving integers (min xyz, max xyz).
@group(0) @binding(8) var<storage, read_write> centre_box: array<atomic<u32>, 6>;

const EMPTY: f32 = 3.0e38;

// Thread index across a 2D grid of 64-wide groups (more than 65,535 groups).
fn thread(id: vec3<u32>, groups: vec3<u32>) -> u32 {
    return id.x + id.y * groups.x * 64u;
}

// A tree's species box placed as the raster places it: the box around its
// eight corners. Twin: the corner loop of `TraceScene::build` in src/trace/scene.rs.
fn placed_box(inst: TraceInstance) -> array<vec3<f32>, 2> {
    let root = bvh_nodes[trace_species[inst.species & 0xffffffu].node_base];
    let c = cos(inst.yaw);
    let s = sin(inst.yaw);
    var lo = vec3<f32>(EMPTY);
    var hi = vec3<f32>(-EMPTY);
    for (var k = 0u; k < 8u; k++) {
        let m = select(root.min, root.max, vec3<bool>((k & 1u) != 0u, (k & 2u) != 0u, (k & 4u) != 0u));
        let v = m * vec3<f32>(inst.scale_xy, inst.scale_xy, inst.scale_z);
        let p = vec3<f32>(c * v.x - s * v.y, s * v.x + c * v.y, v.z) + inst.position;
        lo = min(lo, p);
        hi = max(hi, p);
    }
    return array<vec3<f32>, 2>(lo, hi);
}

// A float as an integer of the same order (negative floats flipped).
fn ordered(x: f32) -> u32 {
    let b = bitcast<u32>(x);
    return select(b | 0x80000000u, ~b, (b & 0x80000000u) != 0u);
}

fn unordered(u: u32) -> f32 {
    return bitcast<f32>(select(~u, u & 0x7fffffffu, (u & 0x80000000u) != 0u));
}

fn centre(i: u32) -> vec3<f32> {
    let b = placed_box(source[i]);
    return 0.5 * (b[0] + b[1]);
}

@compute @workgroup_size(64)
fn top_bounds(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread(id, groups);
    if i >= build.count {
        return;
    }
    let c = centre(i);
    for (var a = 0u; a < 3u; a++) {
        atomicMin(&centre_box[a], ordered(c[a]));
        atomicMax(&centre_box[3u + a], ordered(c[a]));
    }
}

// 10 bits spread to every third bit (Karras 2012's expandBits).
fn spread(v: u32) -> u32 {
    var x = v & 0x3ffu;
    x = (x * 0x00010001u) & 0xFF0000FFu;
    x = (x * 0x00000101u) & 0x0F00F00Fu;
    x = (x * 0x00000011u) & 0xC30C30C3u;
    x = (x * 0x00000005u) & 0x49249249u;
    return x;
}

@compute @workgroup_size(64)
fn top_codes(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread(id, groups);
    if i >= build.padded {
        return;
    }
    // Past the trees: codes above every real one (sorted last, never read).
    var code = 0xffffffffu;
    if i < build.count {
        let lo = vec3<f32>(unordered(atomicLoad(&centre_box[0])), unordered(atomicLoad(&centre_box[1])), unordered(atomicLoad(&centre_box[2])));
        let hi = vec3<f32>(unordered(atomicLoad(&centre_box[3])), unordered(atomicLoad(&centre_box[4])), unordered(atomicLoad(&centre_box[5])));
        // One scale for the three axes (the box's longest side): a forest is
        // flat, and its few metres of height spread over 1,024 steps would
        // split it by height before place.
        let e = hi - lo;
        let side = max(max(max(e.x, e.y), e.z), 1e-6);
        let q = vec3<u32>(clamp((centre(i) - lo) / side, vec3<f32>(0.0), vec3<f32>(1.0)) * 1023.0);
        code = (spread(q.x) << 2u) | (spread(q.y) << 1u) | spread(q.z);
    }
    codes[i] = vec2<u32>(code, i);
}

@compute @workgroup_size(64)
fn top_sort(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread(id, groups);
    let l = i ^ step.j;
    if i >= build.padded || l <= i {
        return;
    }
    let a = codes[i];
    let b = codes[l];
    // (code, index) pairs: every key distinct.
    let greater = a.x > b.x || (a.x == b.x && a.y > b.y);
    if greater == ((i & step.k) == 0u) {
        codes[i] = b;
        codes[l] = a;
    }
}

@compute @workgroup_size(64)
fn top_gather(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread(id, groups);
    if i < build.count {
        trace_instances[i] = source[codes[i].y];
    }
}

// Karras 2012's δ: the length of the common prefix of sorted keys i and j
// (the tree's index breaking ties: 32 + the prefix of the indices), -1 past the ends.
fn prefix(i: i32, j: i32) -> i32 {
    if j < 0 || j >= i32(build.count) {
        return -1;
    }
    let a = codes[i].x;
    let b = codes[j].x;
    if a == b {
        return 32 + i32(countLeadingZeros(u32(i ^ j)));
    }
    return i32(countLeadingZeros(a ^ b));
}

// Where the trees' hierarchy starts in the top level (after the root and
// the ground's leaf where there is a ground).
fn trees_at() -> u32 {
    return 2u * build.ground;
}

// A node in slot `at` of the trees' hierarchy: a leaf over tree j, or an
// empty inner node k whose children follow at 1 + 2k (its box made by top_refit).
fn leaf(at: u32, j: u32) {
    let b = padded(placed_box(trace_instances[j]));
    bvh_nodes[build.top_base + trees_at() + at] = BvhNode(b[0], j, b[1], 1u);
}

// A box grown by a millionth of its coordinates' size: this GPU's sine and
// cosine may place a corner a rounding away from where the walk's own
// transform puts the tree's surface, and a box must never cut a tree.
fn padded(b: array<vec3<f32>, 2>) -> array<vec3<f32>, 2> {
    let pad = 1e-6 * max(abs(b[0]), abs(b[1])) + vec3<f32>(1e-6);
    return array<vec3<f32>, 2>(b[0] - pad, b[1] + pad);
}

fn inner(at: u32, k: u32) {
    bvh_nodes[build.top_base + trees_at() + at] = BvhNode(vec3<f32>(EMPTY), trees_at() + 1u + 2u * k, vec3<f32>(-EMPTY), 0u);
    parents[k] = at;
}

@compute @workgroup_size(64)
fn top_split(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let t = thread(id, groups);
    if build.count == 1u {
        if t == 0u {
            leaf(0u, 0u);
        }
        return;
    }
    if t + 1u >= build.count {
        return;
    }
    let i = i32(t);
    if i == 0 {
        inner(0u, 0u);
    }
    // Karras 2012, Figure 4: the range's direction, its other end (j) by an
    // exponential then a binary search, then the split.
    let d = select(-1, 1, prefix(i, i + 1) - prefix(i, i - 1) > 0);
    let floor_ = prefix(i, i - d);
    var reach = 2;
    while prefix(i, i + reach * d) > floor_ {
        reach *= 2;
    }
    var l = 0;
    for (var s = reach / 2; s >= 1; s /= 2) {
        if prefix(i, i + (l + s) * d) > floor_ {
            l += s;
        }
    }
    let j = i + l * d;
    let shared_ = prefix(i, j);
    var split = 0;
    var div = 2;
    loop {
        let s = (l + div - 1) / div;
        if prefix(i, i + (split + s) * d) > shared_ {
            split += s;
        }
        if s <= 1 {
            break;
        }
        div *= 2;
    }
    let g = i + split * d + min(d, 0);
    let first = 1u + 2u * t;
    if min(i, j) == g {
        leaf(first, u32(g));
    } else {
        inner(first, u32(g));
    }
    if max(i, j) == g + 1 {
        leaf(first + 1u, u32(g + 1));
    } else {
        inner(first + 1u, u32(g + 1));
    }
}

// Inner node k's box from its children's. Run once per level of the tree
// (inner boxes start empty and only grow towards their union, so a read of a
// box another thread is writing is never too large: each 32-bit word read is
// the old or the new value, both within the final box, and first and count
// never change; WGSL itself leaves such a race's result undefined, and
// ordered-integer atomics would make it formal at a cost).
@compute @workgroup_size(64)
fn top_refit(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let k = thread(id, groups);
    if k + 1u >= build.count {
        return;
    }
    let base = build.top_base + trees_at();
    let a = bvh_nodes[base + 1u + 2u * k];
    let b = bvh_nodes[base + 2u + 2u * k];
    bvh_nodes[base + parents[k]] = BvhNode(min(a.min, b.min), trees_at() + 1u + 2u * k, max(a.max, b.max), 0u);
}

// With a ground: the root over the ground's leaf (1) and the trees' root (2).
@compute @workgroup_size(1)
fn top_join() {
    let g = padded(placed_box(trace_instances[build.count]));
    let base = build.top_base;
    bvh_nodes[base + 1u] = BvhNode(g[0], build.count, g[1], 1u);
    let t = bvh_nodes[base + 2u];
    bvh_nodes[base] = BvhNode(min(g[0], t.min), 1u, max(g[1], t.max), 0u);
}
