// GPU culling and LoD selection over grouped batches (Eichner 2024, §3.5, ch. 4).
// Per frame: reset → cull_batches → prepare_dispatch → cull_instances → finalize.
// The CPU oracle of the same logic is `cpu_select` in src/lod/select.rs.
// Rust side: src/render/cull.rs.

// (Group 0, binding 0: the view, `shaders/view.wgsl`.)

@group(1) @binding(0) var<storage, read> batches: array<Batch>;
@group(1) @binding(1) var<storage, read> instances: array<vec2<u32>>;
@group(1) @binding(2) var<storage, read> species: array<Species>;
@group(1) @binding(3) var<storage, read_write> visible: array<u32>;
// Words of `CullControl` (src/render/gpu_data.rs; tests/it/gpu_layout.rs checks them).
@group(1) @binding(4) var<storage, read_write> control: array<atomic<u32>>;
@group(1) @binding(5) var<storage, read_write> items: array<vec2<u32>>;
// Indirect draw args, ARGS_WORDS per slot (`DrawArgs`: count, instances, first,
// base/first, first).
@group(1) @binding(6) var<storage, read_write> args: array<atomic<u32>>;

// Indirect dispatch arguments of cull_instances; bound only to prepare_dispatch
// (a buffer may not be INDIRECT and writable storage in one dispatch).
// Words 4–7: indirect draw arguments of the batch-bounds debug view.
@group(2) @binding(0) var<storage, read_write> dispatch_args: array<u32, 8>;
// `control` again, for prepare_dispatch alone: its pipeline layout leaves group 1
// out, so the compute stage stays within WebGPU's 8 storage buffers.
@group(2) @binding(1) var<storage, read_write> dispatch_control: array<atomic<u32>>;

// Word indices shared with the Rust twins `CullControl`, `DrawArgs` and
// `CullDispatch` (tests/it/gpu_layout.rs compares them with offset_of!).
const CONTROL_WORDS: u32 = 8u;
const CONTROL_BATCHES_VISIBLE: u32 = 0u;
const CONTROL_INSTANCES_TESTED: u32 = 4u;
const CONTROL_ITEMS_DROPPED: u32 = 5u;
const ARGS_WORDS: u32 = 5u;
const ARGS_INSTANCE_COUNT: u32 = 1u;
const DISPATCH_BOUNDS_DRAW: u32 = 4u;

const WORKGROUP: u32 = 64u;
// WebGPU's limit on workgroups per dimension.
const MAX_GROUPS_X: u32 = 65535u;

@compute @workgroup_size(64)
fn reset(@builtin(global_invocation_id) gid: vec3<u32>) {
    let slot = gid.x;
    if slot == 0u {
        for (var i = 0u; i < CONTROL_WORDS; i++) {
            atomicStore(&control[i], 0u);
        }
    }
    let species_count = view.params.w;
    if slot >= species_count * REPR_COUNT {
        return;
    }
    let s = species[slot / REPR_COUNT];
    let repr = slot % REPR_COUNT;
    atomicStore(&args[slot * ARGS_WORDS], species_indices(s, repr));
    for (var i = 1u; i < ARGS_WORDS; i++) {
        atomicStore(&args[slot * ARGS_WORDS + i], 0u);
    }
}

// Box against the frustum: the box's most positive vertex per plane.
fn box_visible(center: vec3<f32>, half: vec3<f32>) -> bool {
    for (var i = 0u; i < 6u; i++) {
        let p = view.frustum[i];
        if dot(p.xyz, center) + p.w + dot(abs(p.xyz), half) < 0.0 {
            return false;
        }
    }
    return true;
}

// Distance from the eye (the origin) to an axis-aligned box.
fn box_distance(center: vec3<f32>, half: vec3<f32>) -> f32 {
    return length(max(abs(center) - half, vec3<f32>(0.0)));
}

@compute @workgroup_size(64)
fn cull_batches(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if i >= view.params.y {
        return;
    }
    let b = batches[i];
    if b.instance_count == 0u || b.species >= view.params.w {
        return;
    }
    let center = eye_relative(b.center_m, vec3<f32>(0.0), view);
    // Sphere first (cheap), then the tighter box; skipped by the baseline modes.
    let batch_culling = view.lod.w < 0.5;
    // A thinned batch draws its kept trees bigger (`coverage_boost`): its bounds grow as much.
    let grow = (coverage_boost(thinning(b, view), b) - 1.0) * b.max_height_m;
    if batch_culling && (!sphere_visible(center, b.radius_m + grow, view) || !box_visible(center, b.half_extent_m + vec3<f32>(grow))) {
        return;
    }
    if batch_culling && box_distance(center, b.half_extent_m) > view.lod.y {
        return;
    }
    // Trees not standing at the latest date: only at a date.
    let style_flags = atomicLoad(&control[STYLE_CONTROL_WORD + STYLE_FLAGS]);
    if (b.flags & BATCH_DATED) != 0u && (style_flags & STYLE_DATED) == 0u {
        return;
    }
    let s = species[b.species];
    if dot(s.slot_cap[0], vec4<u32>(1u)) + dot(s.slot_cap[1], vec4<u32>(1u)) == 0u {
        return; // nothing of this species can be drawn yet (pack not loaded)
    }
    let at = atomicAdd(&control[CONTROL_BATCHES_VISIBLE], 1u);
    visible[at] = i;
}

@compute @workgroup_size(1)
fn prepare_dispatch() {
    let n = atomicLoad(&dispatch_control[CONTROL_BATCHES_VISIBLE]);
    dispatch_args[0] = min(n, MAX_GROUPS_X);
    dispatch_args[1] = (n + MAX_GROUPS_X - 1u) / MAX_GROUPS_X;
    dispatch_args[2] = 1u;
    // Debug view: 24 line vertices per visible batch.
    dispatch_args[DISPATCH_BOUNDS_DRAW] = 24u;
    dispatch_args[DISPATCH_BOUNDS_DRAW + 1u] = n;
    dispatch_args[DISPATCH_BOUNDS_DRAW + 2u] = 0u;
    dispatch_args[DISPATCH_BOUNDS_DRAW + 3u] = 0u;
}

fn emit(species_index: u32, repr: u32, instance: u32, batch: u32, side: u32, fade: f32) {
    let s = species[species_index];
    let slot = species_index * REPR_COUNT + repr;
    let at = atomicAdd(&args[slot * ARGS_WORDS + ARGS_INSTANCE_COUNT], 1u);
    if at < species_cap(s, repr) {
        items[species_base(s, repr) + at] = vec2<u32>(instance, pack_item_y(batch, side, fade));
    } else {
        atomicAdd(&control[CONTROL_ITEMS_DROPPED], 1u);
    }
}

// The representations of a tree of projected height `h_px`: the finest ready one
// whose threshold it reaches, or two with complementary fades inside a band.
fn select_and_emit(s_index: u32, h_px: f32, instance: u32, batch: u32) {
    let s = species[s_index];
    // Ready representations, finest first, with their lower thresholds in px.
    var reprs: array<u32, 8>;
    var lower: array<f32, 8>;
    var n = 0u;
    for (var r = 0u; r < REPR_COUNT; r++) {
        if species_cap(s, r) > 0u {
            reprs[n] = r;
            lower[n] = species_lower(s, r);
            n++;
        }
    }
    if n == 0u {
        return;
    }
    // The coarsest ready representation reaches down to 0 px.
    lower[n - 1u] = 0.0;
    let band = view.lod.z;
    for (var k = 0u; k < n; k++) {
        let t = lower[k];
        if k + 1u < n && h_px < t * (1.0 + band) && h_px >= t * (1.0 - band) {
            // Inside the band around reprs[k]'s threshold: fade from k to k+1.
            let fade = (t * (1.0 + band) - h_px) / (2.0 * band * t);
            emit(s_index, reprs[k], instance, batch, 0u, fade);
            emit(s_index, reprs[k + 1u], instance, batch, 1u, fade);
            return;
        }
        if h_px >= t * (1.0 + select(0.0, band, k + 1u < n)) {
            emit(s_index, reprs[k], instance, batch, 0u, 0.0);
            return;
        }
    }
}

@compute @workgroup_size(64)
fn cull_instances(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let v = wid.x + wid.y * MAX_GROUPS_X;
    if v >= atomicLoad(&control[CONTROL_BATCHES_VISIBLE]) {
        return;
    }
    let batch_index = visible[v];
    let b = batches[batch_index];
    let s = species[b.species];
    // Prefix thinning: far density-ordered batches draw their first trees only,
    // as billboards (bigger, see `thinning`); the last one fades by its fraction.
    let thin = thinning(b, view);
    let thinned = thin.y > 1.0 && species_cap(s, REPR_BILLBOARD) > 0u;
    // The trees the view keeps (the canopy cross-fade takes its share of
    // these), and of them those held.
    let intended = select(whole_count(b), u32(ceil(thin.z)), thinned);
    let count = min(intended, b.instance_count);
    if lid == 0u {
        atomicAdd(&control[CONTROL_INSTANCES_TESTED], count);
    }
    // A style's filter: the trees it hides are culled here.
    let style_flags = atomicLoad(&control[STYLE_CONTROL_WORD + STYLE_FLAGS]);
    let styled = (style_flags & STYLE_TREES) != 0u;
    let dated = (style_flags & STYLE_DATED) != 0u;
    let growth_at = atomicLoad(&control[STYLE_CONTROL_WORD + STYLE_GROWTH_AT]);
    for (var i = lid; i < count; i += WORKGROUP) {
        let instance = b.instance_offset + i;
        if styled {
            let word = atomicLoad(&control[STYLE_CONTROL_WORD + STYLE_HEADER_WORDS + instance / 4u]);
            if (style_byte_of(word, instance) & STYLE_HIDDEN) != 0u {
                continue;
            }
        }
        var tree = unpack_instance(instances[instance], b, view);
        // At a date: drawn at its size then (`tree_growth` in the draw passes).
        if dated {
            let word = atomicLoad(&control[STYLE_CONTROL_WORD + growth_at + instance / 4u]);
            tree.scale *= f32(style_byte_of(word, instance)) / 128.0;
        }
        let center = tree.pos + rotate_z(tree_scaled(s.sphere.xyz, tree), tree.yaw);
        // A thinned batch's kept trees are drawn bigger (`coverage_boost`): so are their bounds.
        let radius = s.sphere.w * tree.scale * max(tree.aspect, 1.0) * select(1.0, coverage_boost(thin, b), thinned);
        let dist = max(length(center), 1e-3);
        // Mode 2 (no culling) draws every tree.
        if view.lod.w < 1.5 && (!sphere_visible(center, radius, view) || dist - radius > view.lod.y) {
            continue;
        }
        // An orthographic view (a shadow cascade) sizes trees in texels, at any distance.
        let px_per_m = view.lod.x / select(dist, 1.0, view.viewport.w > 0.5);
        let h_px = s.select.x * tree.scale * px_per_m;
        // Where trees are a pixel or two, the canopy raster stands in for a share of them:
        // the share of the batch's tallest tree at this tree's distance (the stream
        // fetches each batch up to that share of its tallest at the batch's nearest
        // point, and the canopy raster sizes its cells' trees by their batches'
        // tallest), so the stream holds what the cull draws and little more.
        if canopy_drops(b.max_height_m * px_per_m, i, intended, view) {
            continue;
        }
        if thinned {
            // Side 0 keeps the pixels whose dither is at least the fade.
            let fade = 1.0 - clamp(thin.x - f32(i), 0.0, 1.0);
            emit(b.species, REPR_BILLBOARD, instance, batch_index, 0u, fade);
            continue;
        }
        select_and_emit(b.species, h_px, instance, batch_index);
    }
}

// Clamps instance counts to segment capacities, so a full segment draws what it
// holds instead of reading past it.
@compute @workgroup_size(64)
fn finalize(@builtin(global_invocation_id) gid: vec3<u32>) {
    let slot = gid.x;
    if slot >= view.params.w * REPR_COUNT {
        return;
    }
    let cap = species_cap(species[slot / REPR_COUNT], slot % REPR_COUNT);
    let n = atomicLoad(&args[slot * ARGS_WORDS + ARGS_INSTANCE_COUNT]);
    atomicStore(&args[slot * ARGS_WORDS + ARGS_INSTANCE_COUNT], min(n, cap));
}
