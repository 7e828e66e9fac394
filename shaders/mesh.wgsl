// Mesh pass: alpha-tested, quantised tree meshes (LoD pack mesh levels), one
// indirect draw per (species × mesh level) over the draw items the cull pass
// wrote. Mode 1 (capture) writes albedo, normal and baked occlusion for the
// bake's billboards.
// Rust side: src/render/mesh.rs.

// (Group 0, binding 0: the view, `shaders/view.wgsl`.)

// Must match `MeshUniform` in src/render/gpu_data.rs.
struct MeshParams {
    pos_min: vec4<f32>,
    pos_extent: vec4<f32>,
    uv_min: vec2<f32>,
    uv_extent: vec2<f32>,
    // Billboard cloud: x the first cell word (16 × planes), y the first
    // fragment word of `cloud`; 0 for mesh levels.
    cloud: vec4<u32>,
};

// Must match `GpuMaterial` in src/render/gpu_data.rs.
struct Material {
    base_color: vec4<f32>,
    alpha_cutoff: f32,
    // Texture array layer, or -1 when untextured.
    layer: i32,
    // 0 leaf, 1 branch, 2 the planes of a billboard cloud.
    kind: u32,
    // Share of the texture's full-resolution texels passing alpha_cutoff (0 untextured).
    coverage: f32,
};

@group(1) @binding(0) var<uniform> mesh: MeshParams;
@group(1) @binding(1) var<storage, read> materials: array<Material>;
@group(1) @binding(2) var material_tex: texture_2d_array<f32>;
@group(1) @binding(3) var material_sampler: sampler;
// The billboard cloud's planes, cells and list entries (src/format/cloud.rs;
// a placeholder word for mesh levels).
@group(1) @binding(4) var<storage, read> cloud: array<u32>;
// The level's other variants (`MVAR`, src/format/mesh.rs `VariantVertex`):
// position xy (u16 × 2), z (u16) and the octahedral normal (snorm8 × 2), per
// vertex, variant 1 first; `mesh.cloud.z` of them, `mesh.cloud.w` vertices each.
@group(1) @binding(5) var<storage, read> variants: array<vec2<u32>>;

// (`variant_of`: shaders/trees.wgsl.)

// (Group 2: batches, instances, draw items and styles; group 3: the draw's
// params. Declared once in `shaders/trees.wgsl`.)


// Must match `MeshVertex` in src/format/pack.rs and the layout in src/render/mesh.rs.
struct VertexIn {
    @location(0) position_material: vec4<u32>,
    @location(1) normal_oct: vec4<f32>,
    @location(2) uv: vec2<f32>,
    @location(3) color: vec4<f32>,
};

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) uv: vec2<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) color: vec4<f32>,
    @location(3) @interpolate(flat) material: u32,
    @location(4) @interpolate(flat) item_y: u32,
    // Forest-scale occlusion (`canopy_occlusion`).
    @location(5) canopy: f32,
    // The tree's own baked sky visibility (`vertex_ao`; 1 where not baked).
    @location(6) ao: f32,
    // Billboard cloud quads: the plane (vertex colour red + 256 green), the
    // tree's yaw and crown aspect, and its colour variation.
    @location(7) @interpolate(flat) plane: u32,
    @location(8) @interpolate(flat) frame: vec2<f32>,
    @location(9) @interpolate(flat) tint: vec3<f32>,
    // The tree's pool instance (the id pass).
    @location(10) @interpolate(flat) item_x: u32,
    // The tree's style byte (`tree_style`).
    @location(11) @interpolate(flat) style: u32,
    // The tree's variation (0–31: its autumn progress).
    @location(12) @interpolate(flat) variation: f32,
};

// The occlusion byte of a vertex (`normal_oct` byte 2, snorm8): 0 not baked
// (open), 1–127 sky visibility 0–1. Must match `ao_from_snorm8` in src/format/pack.rs.
fn vertex_ao(z: f32) -> f32 {
    let q = round(z * 127.0);
    return select(1.0, (q - 1.0) / 126.0, q >= 1.0);
}

@vertex
fn vs_main(in: VertexIn, @builtin(instance_index) instance: u32, @builtin(vertex_index) vertex: u32) -> VertexOut {
    let item = items[draw.ids.x + instance];
    let batch = batches[item.y & 0x7fffffu];
    var tree = unpack_instance(instances[item.x], batch, view);
    tree.scale *= tree_growth(styles[STYLE_FLAGS], item.x);
    var out: VertexOut;
    // Leaf-off: leaf cards and cloud planes (all but wood) collapse outside the frustum.
    if leaves_off(tree.variation) && materials[in.position_material.w].kind != 1u {
        out.clip = vec4<f32>(2.0, 2.0, 0.5, 1.0);
        return out;
    }
    // The tree's variant: its own position and normal, else the level's.
    var position = vec3<f32>(in.position_material.xyz);
    var normal_oct = in.normal_oct.xy;
    let variant = variant_of(u32(tree.variation), mesh.cloud.z);
    if variant > 0u {
        let w = variants[(variant - 1u) * mesh.cloud.w + vertex];
        position = vec3<f32>(f32(w.x & 0xffffu), f32(w.x >> 16u), f32(w.y & 0xffffu));
        normal_oct = unpack4x8snorm(w.y).zw;
    }
    let local = mesh.pos_min.xyz + position / 65535.0 * mesh.pos_extent.xyz;
    let eye_rel = rotate_z(tree_scaled(local, tree), tree.yaw) + tree.pos;
    out.clip = view.clip_from_eye * vec4<f32>(eye_rel, 1.0);
    out.uv = mesh.uv_min + in.uv * mesh.uv_extent;
    // Normals of a horizontally stretched crown: the inverse transpose, xy / aspect.
    let n = oct_decode(normal_oct);
    out.normal = rotate_z(normalize(vec3<f32>(n.xy / tree.aspect, n.z)), tree.yaw);
    let tint = variation_tint(tree.variation);
    out.color = vec4<f32>(in.color.rgb * tint, in.color.a);
    out.plane = u32(round(in.color.r * 255.0)) + u32(round(in.color.g * 255.0)) * 256u;
    out.frame = vec2<f32>(tree.yaw, tree.aspect);
    out.tint = tint;
    out.variation = tree.variation;
    out.material = in.position_material.w;
    out.item_y = item.y;
    out.item_x = item.x;
    out.style = tree_style(styles[STYLE_FLAGS], item.x, batch.species);
    out.canopy = canopy_occlusion(batch, local.z / max(mesh.pos_min.z + mesh.pos_extent.z, 1e-3));
    out.ao = vertex_ao(in.normal_oct.z);
    return out;
}

struct Surface {
    albedo: vec4<f32>,
    normal: vec3<f32>,
    is_leaf: bool,
    // The tree's own sky visibility there.
    ao: f32,
};

// Shader-level LoD of the billboard cloud (García et al. 2007, §5.1): list entries
// evaluated per pixel a cell spans on screen; the rest come from the cell's
// average (the low-resolution texture).
const CLOUD_ENTRIES_PER_PX: f32 = 2.0;

struct CloudHit {
    keep: bool,
    albedo: vec4<f32>,
    // Model space, towards the plane's front.
    normal: vec3<f32>,
    ao: f32,
};

// A billboard cloud plane at plane coordinates `in.uv` (García et al. 2007, §5): the
// cell's list of leaves, front to back (back to front from behind), each
// mapped to its own texture coordinates and alpha-tested like the mesh's
// leaves; the first that passes is the pixel. Entries beyond the shader LoD
// are replaced by the cell's average coverage (a hashed test) and colour.
fn cloud_surface(in: VertexOut, front: bool, duv_dx: vec2<f32>, duv_dy: vec2<f32>) -> CloudHit {
    var out: CloudHit;
    out.keep = false;
    let cells_at = mesh.cloud.x;
    let fragments_at = mesh.cloud.y;
    // A plane the cloud does not have (the pack's validation refuses them).
    if in.plane >= cells_at / 16u {
        return out;
    }
    let p = in.plane * 16u;
    let grid = vec2<u32>(max(cloud[p + 7u], 1u), max(cloud[p + 11u], 1u));
    let st = clamp(in.uv, vec2<f32>(0.0), vec2<f32>(1.0));
    let c = min(vec2<u32>(st * vec2<f32>(grid)), grid - 1u);
    let cell = cells_at + (cloud[p + 3u] + c.y * grid.x + c.x) * 3u;
    let head = cloud[cell];
    let first = head & 0xffffffu;
    let count = head >> 24u;
    // Pixels a cell spans on screen.
    let cell_px = 1.0 / max(max(length(duv_dx * vec2<f32>(grid)), length(duv_dy * vec2<f32>(grid))), 1e-6);
    var n = min(count, u32(ceil(CLOUD_ENTRIES_PER_PX * cell_px)));
    if view.eye_hi.w > 0.5 && view.eye_hi.w < 1.5 {
        n = count; // full-resolution reference: every entry
    }
    for (var i = 0u; i < n; i++) {
        let k = select(first + count - 1u - i, first + i, front);
        let f = fragments_at + k * 10u;
        let a = vec4<f32>(
            bitcast<f32>(cloud[f]),
            bitcast<f32>(cloud[f + 1u]),
            bitcast<f32>(cloud[f + 2u]),
            bitcast<f32>(cloud[f + 3u]),
        );
        let b = vec2<f32>(bitcast<f32>(cloud[f + 4u]), bitcast<f32>(cloud[f + 5u]));
        let uv = vec2<f32>(dot(a.xy, st), dot(a.zw, st)) + b;
        let lo = unpack_halves(cloud[f + 6u]);
        let hi = unpack_halves(cloud[f + 7u]);
        if any(uv < lo) || any(uv > hi) {
            continue;
        }
        let w8 = cloud[f + 8u];
        let mat = materials[w8 & 0xffffu];
        let gx = vec2<f32>(dot(a.xy, duv_dx), dot(a.zw, duv_dx));
        let gy = vec2<f32>(dot(a.xy, duv_dy), dot(a.zw, duv_dy));
        var texel = vec4<f32>(1.0);
        if mat.layer >= 0 {
            texel = textureSampleGrad(material_tex, material_sampler, uv, mat.layer, gx, gy);
        }
        if mat.base_color.a * texel.a < mat.alpha_cutoff {
            continue;
        }
        let colour = unpack4x8unorm(cloud[f + 9u]);
        out.keep = true;
        out.albedo = mat.base_color * texel * vec4<f32>(colour.rgb * in.tint, 1.0);
        out.normal = oct_decode(unpack4x8snorm(w8).zw);
        out.ao = colour.a;
        return out;
    }
    if n < count {
        // The cell's average: its coverage by a hashed test, so a far plane
        // keeps its leaves' density; colour, normal and occlusion averaged.
        let avg = unpack4x8unorm(cloud[cell + 1u]);
        let h = fragment_hash(in.clip, view.eye_lo.w);
        if h.x < avg.a {
            let nw = cloud[cell + 2u];
            out.keep = true;
            out.albedo = vec4<f32>(srgb_to_linear3(avg.rgb) * in.tint, 1.0);
            out.normal = oct_decode(unpack4x8snorm(nw).xy);
            out.ao = unpack4x8unorm(nw).z;
        }
    }
    return out;
}

fn srgb_to_linear3(c: vec3<f32>) -> vec3<f32> {
    return select(pow((c + 0.055) / 1.055, vec3<f32>(2.4)), c / 12.92, c <= vec3<f32>(0.04045));
}

// Adaptive transparency: how far (0–1) a pixel's alpha test moves from the
// texture's alpha to a hashed test against its full-resolution coverage. A
// leaf card seen at its texture's coarsest mips (4×4 texels and below, the
// whole leaf within a pixel or two) has a mip alpha that is the same for the
// whole card: coverage-preserving mips keep the share of passing texels, but
// with four texels or one that share rounds to all or nothing, so far leaves
// vanish or turn into opaque squares. A hashed test keeps each such pixel
// with the leaf's true coverage instead: the crown keeps its density, and
// accumulated refinement steps (their seed shifts the hash) see through it.
// (From the texture's size, not its mip count: a pack may hold a shorter chain.)
// The hash takes the fragment's depth, so it changes as the camera moves: far
// crowns shimmer a little in motion, as their all-or-nothing cards did.
fn hashed_alpha_weight(texels_per_px: f32, size: f32) -> f32 {
    let lod = log2(max(texels_per_px, 1e-6));
    return clamp(lod - (log2(max(size, 1.0)) - 3.0), 0.0, 1.0);
}

// Two uniform numbers in [0, 1) for a fragment: from its pixel, its depth (so
// leaves stacked in one pixel test apart) and the refinement step.
fn fragment_hash(frag: vec4<f32>, seed: f32) -> vec2<f32> {
    var v = vec3<u32>(u32(frag.x), u32(frag.y), bitcast<u32>(frag.z) ^ (u32(seed) * 0x9e3779b9u));
    v = v * 1664525u + 1013904223u;
    v.x += v.y * v.z;
    v.y += v.z * v.x;
    v.z += v.x * v.y;
    v ^= v >> vec3<u32>(16u);
    v.x += v.y * v.z;
    v.y += v.z * v.x;
    v.z += v.x * v.y;
    return vec2<f32>(f32(v.x >> 8u), f32(v.y >> 8u)) / 16777216.0;
}

fn surface(in: VertexOut, front: bool) -> Surface {
    let mat = materials[in.material];
    // Sample unconditionally (uniform control flow), then select.
    let texel = textureSample(material_tex, material_sampler, in.uv, max(mat.layer, 0));
    let size = vec2<f32>(textureDimensions(material_tex));
    let duv_dx = dpdx(in.uv);
    let duv_dy = dpdy(in.uv);
    let texels_per_px = max(length(duv_dx * size), length(duv_dy * size));
    if mat.kind == 2u {
        let hit = cloud_surface(in, front, duv_dx, duv_dy);
        if !hit.keep || !fade_keeps(in.item_y, in.clip.xy, view.eye_lo.w) {
            discard;
        }
        // Seen from behind the plane, the leaves show their other side.
        let m = select(-hit.normal, hit.normal, front);
        var s: Surface;
        s.albedo = hit.albedo;
        s.normal = rotate_z(normalize(vec3<f32>(m.xy / in.frame.y, m.z)), in.frame.x);
        s.is_leaf = true;
        s.ao = hit.ao;
        return s;
    }
    var albedo = mat.base_color * in.color;
    var coverage = albedo.a;
    var keep = true;
    if mat.layer >= 0 {
        albedo *= texel;
        coverage = albedo.a;
        keep = coverage >= mat.alpha_cutoff;
        if view.eye_hi.w > 0.5 && view.eye_hi.w < 1.5 {
            // The accuracy reference tests coverage at the texture's full
            // resolution: a mip's alpha is an average that a far leaf card, all
            // of it sampled from the 1×1 mip, fails everywhere (the leaves vanish).
            let fine = textureSampleLevel(material_tex, material_sampler, in.uv, mat.layer, 0.0);
            keep = mat.base_color.a * in.color.a * fine.a >= mat.alpha_cutoff;
        } else if view.eye_hi.w > 1.5 && view.params.x == 0u && mat.coverage > 0.0 {
            // Drawing (not the bake's capture): adaptive transparency.
            let h = fragment_hash(in.clip, view.eye_lo.w);
            if h.y < hashed_alpha_weight(texels_per_px, size.x) {
                keep = h.x < mat.coverage * mat.base_color.a * in.color.a;
            }
        }
    } else {
        keep = coverage >= mat.alpha_cutoff;
    }
    if !keep || !fade_keeps(in.item_y, in.clip.xy, view.eye_lo.w) {
        discard;
    }
    var s: Surface;
    s.albedo = albedo;
    s.normal = normalize(select(-in.normal, in.normal, front));
    s.is_leaf = mat.kind == 0u;
    s.ao = in.ao;
    return s;
}

@fragment
fn fs_lit(in: VertexOut, @builtin(front_facing) front: bool) -> @location(0) vec4<f32> {
    let s = surface(in, front);
    var albedo = select(s.albedo.rgb, seasonal_leaf(s.albedo.rgb, in.variation), s.is_leaf);
    albedo = styled_albedo(albedo, styles[in.style & 63u]);
    if view.params.z == 1u {
        albedo = repr_color(draw.ids.y) * (0.6 + 0.4 * s.albedo.g);
    }
    let ao = own_ao(s.ao, view);
    let sun = sun_visibility(frag_rel(in.clip, view), s.normal, 0.0, open_sun(in.canopy));
    let lit = highlighted(shade(albedo, s.normal, s.is_leaf, view, sun, in.canopy, ao), in.style);
    return vec4<f32>(haze(lit, in.clip, view), 1.0);
}

// Shadow cascades: depth only, alpha-tested leaves (dappled shade).
@fragment
fn fs_shadow(in: VertexOut, @builtin(front_facing) front: bool) {
    _ = surface(in, front);
}

// Picking: the tree's pool instance + 1, alpha-tested like the colour pass.
@fragment
fn fs_id(in: VertexOut, @builtin(front_facing) front: bool) -> @location(0) u32 {
    _ = surface(in, front);
    return in.item_x + 1u;
}

struct CaptureOut {
    // Albedo (sRGB target) with coverage alpha.
    @location(0) albedo: vec4<f32>,
    // Model-frame normal * 0.5 + 0.5; alpha 1 for leaves, 0.5 for wood.
    @location(1) normal: vec4<f32>,
    // The baked sky visibility (rgb), for the billboards' BBAO array.
    @location(2) ao: vec4<f32>,
};

@fragment
fn fs_capture(in: VertexOut, @builtin(front_facing) front: bool) -> CaptureOut {
    let s = surface(in, front);
    var out: CaptureOut;
    out.albedo = vec4<f32>(s.albedo.rgb, 1.0);
    out.normal = vec4<f32>(s.normal * 0.5 + 0.5, select(0.5, 1.0, s.is_leaf));
    out.ao = vec4<f32>(vec3<f32>(s.ao), 1.0);
    return out;
}
