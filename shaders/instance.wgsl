// A tree as the passes decode it: the packed instance, its eye-relative
// position, rotation, scale and crown stretch; octahedral normals and half floats.
// Twin: `decode_eye_relative` in src/lod/select.rs. Needs layout.wgsl.

// A decoded tree, eye-relative.
struct Tree {
    pos: vec3<f32>,
    yaw: f32,
    // Height scale of the species model.
    scale: f32,
    variation: f32,
    // Horizontal over vertical scale (crown width relative to the model's; 1 without crown data).
    aspect: f32,
};

// A model-space offset of `tree` scaled to the tree: xy by scale × aspect, z by scale.
fn tree_scaled(v: vec3<f32>, tree: Tree) -> vec3<f32> {
    return vec3<f32>(v.xy * (tree.scale * tree.aspect), v.z * tree.scale);
}

// An eye-space offset stretched horizontally by the tree's crown aspect.
fn crown_stretch(v: vec3<f32>, tree: Tree) -> vec3<f32> {
    return vec3<f32>(v.xy * tree.aspect, v.z);
}

// Variation of an instance of a BATCH_CROWN_ASPECT batch: a hash of its
// position word. Must match `variation_of` in src/format/tile.rs.
fn variation_of(xy: u32) -> u32 {
    return (xy * 0x9E3779B1u) >> 27u;
}

// Eye-relative position of a batch-local point: (origin − eye_hi) − eye_lo + offset.
// Both origin and eye_hi are exact f32s, so the first difference is exact for
// nearby batches; see docs/ARCHITECTURE.md (precision).
fn eye_relative(origin_m: vec3<f32>, offset: vec3<f32>, view: View) -> vec3<f32> {
    return ((origin_m - view.eye_hi.xyz) - view.eye_lo.xyz) + offset;
}

// Decodes a PackedInstance (src/format/tile.rs) of `batch`.
fn unpack_instance(packed: vec2<u32>, batch: Batch, view: View) -> Tree {
    let x = f32(packed.x & 0xffffu);
    let y = f32(packed.x >> 16u);
    let z = f32(packed.y & 0x7ffu);
    let yaw_q = (packed.y >> 11u) & 0xffu;
    let scale_q = (packed.y >> 19u) & 0xffu;
    var t: Tree;
    t.pos = eye_relative(batch.origin_m, vec3<f32>(x * batch.xy_step_m, y * batch.xy_step_m, z * batch.z_step_m), view);
    t.yaw = f32(yaw_q) * (6.283185307 / 256.0);
    t.scale = batch.scale_min * exp2(f32(scale_q) * batch.scale_log2_step);
    let top = packed.y >> 27u;
    if (batch.flags & BATCH_CROWN_ASPECT) != 0u {
        let min = f32(batch.crown & 0xffffu) / 8192.0;
        let step = f32(batch.crown >> 16u) / 65536.0;
        t.aspect = min * exp2(f32(top) * step);
        t.variation = f32(variation_of(packed.x));
    } else {
        t.aspect = 1.0;
        t.variation = f32(top);
    }
    return t;
}

// Decodes an octahedral-encoded unit vector (snorm xy in [-1, 1]).
fn oct_decode(e: vec2<f32>) -> vec3<f32> {
    var n = vec3<f32>(e.x, e.y, 1.0 - abs(e.x) - abs(e.y));
    let t = max(-n.z, 0.0);
    n.x += select(t, -t, n.x >= 0.0);
    n.y += select(t, -t, n.y >= 0.0);
    return normalize(n);
}

// Rotation about +Z (up) by `yaw` radians.
fn rotate_z(v: vec3<f32>, yaw: f32) -> vec3<f32> {
    let c = cos(yaw);
    let s = sin(yaw);
    return vec3<f32>(c * v.x - s * v.y, s * v.x + c * v.y, v.z);
}

// IEEE half floats (low 16 bits first) → f32, decoded by hand:
// `unpack2x16float` needs a capability (SHADER_FLOAT16_IN_FLOAT32) that naga's
// WebGPU validation and some native backends do not grant.
fn half_to_f32(h: u32) -> f32 {
    let e = (h >> 10u) & 0x1fu;
    let m = f32(h & 0x3ffu);
    var v = (1.0 + m / 1024.0) * exp2(f32(e) - 15.0);
    if e == 0u {
        v = m * exp2(-24.0);
    } else if e == 31u {
        v = 65504.0;
    }
    return select(v, -v, (h & 0x8000u) != 0u);
}

fn unpack_halves(w: u32) -> vec2<f32> {
    return vec2<f32>(half_to_f32(w & 0xffffu), half_to_f32(w >> 16u));
}
