// Cluster pass (Clasen et al. 2010, §5): the ellipsoids and lines of one cluster level, one
// indirect draw per (species × cluster tier). Six vertices per primitive: the
// first `draw.cluster.y` primitives are ellipsoids, the next `draw.cluster.w`
// lines. Both are ray-cast per pixel on a tight screen-space proxy and write
// their true depth.
// - Ellipsoids: the proxy is the exact screen-space bounding rectangle of the
//   projected quadric (Sigg et al. 2006); the ray is intersected in the
//   ellipsoid's local frame where it is the unit sphere; the hit point is the
//   direction into two noise cube maps (alpha holes against the level's
//   threshold t, normal perturbation), at the mip of the ellipsoid's noise level
//   l_j or coarser when the screen-space derivatives ask for it (no aliasing).
// - Lines: capsules on a quad around the projected segment.
// Rust side: src/render/cluster.rs.

// (Group 0, binding 0: the view, `shaders/view.wgsl`.)

@group(1) @binding(0) var<storage, read> records: array<u32>;
@group(1) @binding(1) var noise_alpha: texture_cube<f32>;
@group(1) @binding(2) var noise_normal: texture_cube<f32>;
@group(1) @binding(3) var noise_sampler: sampler;
// The tree's own sky visibility (bake-tool/src/pack/ao.rs) over the box
// draw.ao_field_min .. + ao_field_size in model space; one white texel where
// the pack has none.
@group(1) @binding(4) var ao_field: texture_3d<f32>;

// (Group 2: batches, instances, draw items and styles; group 3: the draw's
// params. Declared once in `shaders/trees.wgsl`.)


struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    // Ellipsoid: centre (xyz), minus its largest radius in w (≤ 0).
    // Line: start point (xyz), 1 in w.
    @location(0) @interpolate(flat) p0: vec4<f32>,
    // Ellipsoid: the rows of its world → local unit sphere map.
    // Line: end point (xyz), radius (w).
    @location(1) @interpolate(flat) p1: vec4<f32>,
    @location(2) @interpolate(flat) p2: vec4<f32>,
    @location(3) @interpolate(flat) p3: vec4<f32>,
    // Albedo (rgb), noise mip (w).
    @location(4) @interpolate(flat) color: vec4<f32>,
    @location(5) @interpolate(flat) item_y: u32,
    // Forest-scale occlusion: the batch's crown cover (`batch_cover`), taken
    // per pixel at the hit's height like the meshes' per vertex.
    @location(6) @interpolate(flat) cover: f32,
    // The tree's eye-relative position (xyz) and yaw (w), and its height scale
    // and crown aspect: the hit point back into model space for `field_ao`;
    // its variation (0–31: its autumn progress).
    @location(7) @interpolate(flat) tree_at: vec4<f32>,
    @location(8) @interpolate(flat) tree_size: vec3<f32>,
    // The tree's pool instance (the id pass).
    @location(9) @interpolate(flat) item_x: u32,
    // The tree's style byte (`tree_style`).
    @location(10) @interpolate(flat) style: u32,
};

// An eye-relative point in the tree's model space (scale 1).
fn to_model(p: vec3<f32>, in: VertexOut) -> vec3<f32> {
    let local = rotate_z(p - in.tree_at.xyz, -in.tree_at.w);
    let s = max(in.tree_size.x, 1e-6);
    return vec3<f32>(local.xy / (s * max(in.tree_size.y, 1e-6)), local.z / s);
}

// The tree's own occlusion at `model`: its field, the same field the mesh
// vertices and billboards were baked from.
fn field_ao(model: vec3<f32>) -> f32 {
    let uvw = (model - draw.ao_field_min.xyz) / max(draw.ao_field_size.xyz, vec3<f32>(1e-6));
    return textureSampleLevel(ao_field, noise_sampler, uvw, 0.0).r;
}

struct Ellipsoid {
    center: vec3<f32>,
    rotation: vec4<f32>,
    radii: vec3<f32>,
    color: vec3<f32>,
    level: f32,
};

fn dequantise(q: vec3<f32>) -> vec3<f32> {
    return draw.bounds_min.xyz + q * draw.bounds_extent.xyz;
}

// Must match `PackedEllipsoid` in src/format/cluster.rs.
fn unpack_ellipsoid(i: u32) -> Ellipsoid {
    let base = draw.cluster.x + i * 6u;
    let xy = unpack2x16unorm(records[base]);
    let zl = unpack2x16unorm(records[base + 1u]);
    let rxy = unpack_halves(records[base + 2u]);
    let rz = unpack_halves(records[base + 3u]);
    var e: Ellipsoid;
    e.center = dequantise(vec3<f32>(xy, zl.x));
    e.level = zl.y * 16.0;
    e.radii = vec3<f32>(rxy, rz.x);
    e.rotation = normalize(unpack4x8snorm(records[base + 4u]));
    let c = unpack4x8unorm(records[base + 5u]).rgb;
    // sRGB → linear (the records store sRGB bytes).
    e.color = select(pow((c + 0.055) / 1.055, vec3<f32>(2.4)), c / 12.92, c <= vec3<f32>(0.04045));
    return e;
}

fn quat_rotate(q: vec4<f32>, v: vec3<f32>) -> vec3<f32> {
    let t = 2.0 * cross(q.xyz, v);
    return v + q.w * t + cross(q.xyz, t);
}

// Minkowski-style product with D = diag(1, 1, 1, −1).
fn dot_d(a: vec4<f32>, b: vec4<f32>) -> f32 {
    return a.x * b.x + a.y * b.y + a.z * b.z - a.w * b.w;
}

const CORNERS = array<vec2<f32>, 6>(
    vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, -1.0), vec2<f32>(1.0, 1.0),
    vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, 1.0), vec2<f32>(-1.0, 1.0),
);

fn ellipsoid_vertex(e: Ellipsoid, tree: Tree, corner: vec2<f32>, out: ptr<function, VertexOut>) {
    let center = tree.pos + rotate_z(tree_scaled(e.center, tree), tree.yaw);
    let r = max(e.radii * tree.scale, vec3<f32>(1e-6));
    let a0 = rotate_z(quat_rotate(e.rotation, vec3<f32>(1.0, 0.0, 0.0)), tree.yaw);
    let a1 = rotate_z(quat_rotate(e.rotation, vec3<f32>(0.0, 1.0, 0.0)), tree.yaw);
    let a2 = rotate_z(quat_rotate(e.rotation, vec3<f32>(0.0, 0.0, 1.0)), tree.yaw);
    // T: unit sphere → eye-relative space, columns D·a_i·r_i with the crown
    // stretch D = diag(k, k, 1) (an ellipsoid stays an ellipsoid); T' =
    // clip_from_eye · T. Its rows give the bounding rectangle in NDC as the
    // roots of two quadratics.
    let c0 = crown_stretch(a0 * r.x, tree);
    let c1 = crown_stretch(a1 * r.y, tree);
    let c2 = crown_stretch(a2 * r.z, tree);
    let t = view.clip_from_eye * mat4x4<f32>(
        vec4<f32>(c0, 0.0), vec4<f32>(c1, 0.0), vec4<f32>(c2, 0.0), vec4<f32>(center, 1.0));
    let row0 = vec4<f32>(t[0].x, t[1].x, t[2].x, t[3].x);
    let row1 = vec4<f32>(t[0].y, t[1].y, t[2].y, t[3].y);
    let row3 = vec4<f32>(t[0].w, t[1].w, t[2].w, t[3].w);
    let c = dot_d(row3, row3);
    let bx = dot_d(row0, row3);
    let by = dot_d(row1, row3);
    let hx = bx * bx - c * dot_d(row0, row0);
    let hy = by * by - c * dot_d(row1, row1);
    var ndc: vec2<f32>;
    let reach = max(r.x, max(r.y, r.z)) * max(tree.aspect, 1.0);
    if !sphere_visible(center, reach, view) {
        ndc = vec2<f32>(2.0); // outside the frustum (or behind the eye): nothing to draw
    } else if c >= 0.0 {
        // The ellipsoid crosses the eye plane (w = 0): its projection is unbounded.
        ndc = corner;
    } else if hx < 0.0 || hy < 0.0 {
        ndc = vec2<f32>(2.0); // degenerate: off screen
    } else {
        let x0 = (bx - sqrt(hx)) / c;
        let x1 = (bx + sqrt(hx)) / c;
        let y0 = (by - sqrt(hy)) / c;
        let y1 = (by + sqrt(hy)) / c;
        let lo = vec2<f32>(min(x0, x1), min(y0, y1));
        let hi = vec2<f32>(max(x0, x1), max(y0, y1));
        // Half a pixel of margin for rasterisation.
        let margin = 1.0 / max(view.viewport.xy, vec2<f32>(1.0));
        ndc = clamp(mix(lo - margin, hi + margin, corner * 0.5 + 0.5), vec2<f32>(-1.0), vec2<f32>(1.0));
    }
    // The proxy sits at the ellipsoid's front-most depth: with exact depth off
    // (fs_proxy_depth) early depth tests stay on and only interpenetrating
    // primitives can sort wrongly.
    var v = pixel_ray(vec2<f32>(0.0))[1];
    if is_perspective() {
        v = normalize(center);
    }
    let support = length(vec3<f32>(dot(c0, v), dot(c1, v), dot(c2, v)));
    var front = center - v * min(support, max(dot(center, v) - 1e-3, 0.0));
    if view.viewport.w > 0.5 {
        // A shadow cascade keeps the proxy at the centre's depth: early depth
        // tests stay on, and the crown's sunward half is nearer the sun than
        // its shadow-map depth (lit), its far half farther (shaded).
        front = center;
    }
    let cc = view.clip_from_eye * vec4<f32>(front, 1.0);
    let depth = clamp(cc.z / max(abs(cc.w), 1e-20), 0.0, 1.0);
    (*out).clip = vec4<f32>(ndc, depth, 1.0);
    // The rows of T⁻¹ = diag(1/r) · Aᵀ · D⁻¹: world → unit sphere (and, as
    // Tᵀ⁻¹, the normal of the unit sphere's point s is Σ s_i · p_i).
    (*out).p0 = vec4<f32>(center, -reach);
    let k = vec3<f32>(tree.aspect, tree.aspect, 1.0);
    (*out).p1 = vec4<f32>(a0 / (k * r.x), 0.0);
    (*out).p2 = vec4<f32>(a1 / (k * r.y), 0.0);
    (*out).p3 = vec4<f32>(a2 / (k * r.z), 0.0);
    (*out).color = vec4<f32>(e.color * variation_tint(tree.variation), e.level);
}

fn is_perspective() -> bool {
    return abs(view.clip_from_eye[3][3]) < 0.5;
}

// A point on the near plane and the unit direction of the ray through NDC `ndc`.
fn pixel_ray(ndc: vec2<f32>) -> array<vec3<f32>, 2> {
    // Reversed Z: depth 1 is the near plane, 0.5 a farther finite plane for both
    // the infinite perspective and orthographic projections.
    let hn = view.eye_from_clip * vec4<f32>(ndc, 1.0, 1.0);
    let hm = view.eye_from_clip * vec4<f32>(ndc, 0.5, 1.0);
    let pn = hn.xyz / hn.w;
    let pm = hm.xyz / hm.w;
    return array<vec3<f32>, 2>(pn, normalize(pm - pn));
}

fn line_vertex(i: u32, tree: Tree, corner: vec2<f32>, out: ptr<function, VertexOut>) {
    // Must match `PackedLine` in src/format/cluster.rs.
    let base = draw.cluster.z + i * 4u;
    let w0 = unpack2x16unorm(records[base]);
    let w1 = unpack2x16unorm(records[base + 1u]);
    let w2 = unpack2x16unorm(records[base + 2u]);
    let radii = unpack_halves(records[base + 3u]);
    let a = tree.pos + rotate_z(tree_scaled(dequantise(vec3<f32>(w0, w1.x)), tree), tree.yaw);
    let b = tree.pos + rotate_z(tree_scaled(dequantise(vec3<f32>(w1.y, w2)), tree), tree.yaw);
    let mid = 0.5 * (a + b);
    var v: vec3<f32>;
    if is_perspective() {
        v = normalize(mid);
    } else {
        v = pixel_ray(vec2<f32>(0.0))[1];
    }
    // At least half a pixel wide, so thin lines do not break up (Clasen et al. 2010, §2).
    let px_m = select(1.0, length(mid), is_perspective()) / max(view.lod.x, 1e-6);
    let r = max(0.5 * (radii.x + radii.y) * tree.scale, 0.5 * px_m);
    let axis = b - a;
    var side = cross(axis, v);
    if dot(side, side) < 1e-12 * max(dot(axis, axis), 1e-12) {
        side = cross(vec3<f32>(0.0, 0.0, 1.0), v);
        if dot(side, side) < 1e-12 {
            side = vec3<f32>(1.0, 0.0, 0.0);
        }
    }
    side = normalize(side);
    let u = normalize(cross(v, side));
    let ea = dot(a - mid, u);
    let eb = dot(b - mid, u);
    // 15 % margin: the quad lies in the plane through the midpoint, the ends may be nearer.
    let m = r * 1.15;
    if !sphere_visible(mid, 0.5 * length(axis) + m, view) {
        (*out).clip = vec4<f32>(2.0, 2.0, 0.5, 1.0); // outside the frustum: a degenerate quad
        (*out).p0 = vec4<f32>(a, 1.0);
        (*out).p1 = vec4<f32>(b, r);
        (*out).p2 = vec4<f32>(0.0);
        (*out).p3 = vec4<f32>(0.0);
        (*out).color = vec4<f32>(0.0);
        return;
    }
    let along = select(min(ea, eb) - m, max(ea, eb) + m, corner.y > 0.0);
    let p = mid + u * along + side * (corner.x * m);
    (*out).clip = view.clip_from_eye * vec4<f32>(p, 1.0);
    (*out).p0 = vec4<f32>(a, 1.0);
    (*out).p1 = vec4<f32>(b, r);
    (*out).p2 = vec4<f32>(0.0);
    (*out).p3 = vec4<f32>(0.0);
    (*out).color = vec4<f32>(draw.line_color.rgb * variation_tint(tree.variation), 0.0);
}

@vertex
fn vs_main(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> VertexOut {
    let item = items[draw.ids.x + instance];
    let batch = batches[item.y & 0x7fffffu];
    var tree = unpack_instance(instances[item.x], batch, view);
    tree.scale *= tree_growth(styles[STYLE_FLAGS], item.x);
    let prim = vertex / 6u;
    let corner = CORNERS[vertex % 6u];
    var out: VertexOut;
    if prim < draw.cluster.y && leaves_off(tree.variation) {
        // Leaf-off: the foliage's ellipsoids go, the branches' lines stay.
        out.clip = vec4<f32>(2.0, 2.0, 0.5, 1.0);
    } else if prim < draw.cluster.y {
        ellipsoid_vertex(unpack_ellipsoid(prim), tree, corner, &out);
    } else {
        line_vertex(prim - draw.cluster.y, tree, corner, &out);
    }
    out.item_y = item.y;
    out.item_x = item.x;
    out.style = tree_style(styles[STYLE_FLAGS], item.x, batch.species);
    out.tree_at = vec4<f32>(tree.pos, tree.yaw);
    out.tree_size = vec3<f32>(tree.scale, tree.aspect, tree.variation);
    out.cover = batch_cover(batch);
    return out;
}

struct FragmentOut {
    @location(0) color: vec4<f32>,
    @builtin(frag_depth) depth: f32,
};

// Ray–capsule intersection (distance along the unit ray, or −1), with the
// outward normal.
fn capsule_hit(ro: vec3<f32>, rd: vec3<f32>, pa: vec3<f32>, pb: vec3<f32>, r: f32) -> vec4<f32> {
    let ba = pb - pa;
    let oa = ro - pa;
    let baba = dot(ba, ba);
    let bard = dot(ba, rd);
    let baoa = dot(ba, oa);
    let rdoa = dot(rd, oa);
    let oaoa = dot(oa, oa);
    let a = baba - bard * bard;
    var b = baba * rdoa - baoa * bard;
    var c = baba * oaoa - baoa * baoa - r * r * baba;
    var h = b * b - a * c;
    if h >= 0.0 && a > 1e-12 {
        let t = (-b - sqrt(h)) / a;
        let y = baoa + t * bard;
        if y > 0.0 && y < baba {
            let n = (oa + t * rd - ba * (y / baba)) / r;
            return vec4<f32>(normalize(n), t);
        }
    }
    // The caps (spheres at the ends).
    var best = vec4<f32>(0.0, 0.0, 0.0, -1.0);
    for (var k = 0; k < 2; k++) {
        let oc = select(ro - pb, oa, k == 0);
        let bb = dot(rd, oc);
        let cc = dot(oc, oc) - r * r;
        let hh = bb * bb - cc;
        if hh >= 0.0 {
            let t = -bb - sqrt(hh);
            if t > 0.0 && (best.w < 0.0 || t < best.w) {
                best = vec4<f32>(normalize(oc + t * rd), t);
            }
        }
    }
    return best;
}

// Where a pixel's ray meets the primitive (discarded where it misses).
struct ClusterHit {
    // Eye-relative point and normal.
    p: vec3<f32>,
    n: vec3<f32>,
    // Its depth in this view.
    depth: f32,
    is_line: bool,
};

fn cluster_hit(in: VertexOut) -> ClusterHit {
    let ndc = vec2<f32>(in.clip.x / view.viewport.x * 2.0 - 1.0, 1.0 - in.clip.y / view.viewport.y * 2.0);
    let ray = pixel_ray(ndc);
    let is_line = in.p0.w > 0.5;
    // Ellipsoid: intersect in the local frame where it is the unit sphere. The
    // ray origin is first moved next to the primitive so f32 keeps its precision
    // at any distance.
    let centre = select(in.p0.xyz, 0.5 * (in.p0.xyz + in.p1.xyz), is_line);
    let reach = select(-in.p0.w, 0.5 * length(in.p1.xyz - in.p0.xyz) + in.p1.w, is_line);
    let skip = max(dot(centre - ray[0], ray[1]) - reach * 1.01, 0.0);
    let o = ray[0] + ray[1] * skip;
    let oc = o - in.p0.xyz;
    let lo = vec3<f32>(dot(oc, in.p1.xyz), dot(oc, in.p2.xyz), dot(oc, in.p3.xyz));
    let ld = vec3<f32>(dot(ray[1], in.p1.xyz), dot(ray[1], in.p2.xyz), dot(ray[1], in.p3.xyz));
    let qa = dot(ld, ld);
    let qb = dot(lo, ld);
    let qc = dot(lo, lo) - 1.0;
    let disc = qb * qb - qa * qc;
    let root = sqrt(max(disc, 0.0));
    var t_hit = (-qb - root) / max(qa, 1e-30);
    if t_hit < 0.0 {
        t_hit = (-qb + root) / max(qa, 1e-30);
    }
    let s = normalize(lo + ld * t_hit);
    // Noise mip: the ellipsoid's level l_j (mip L − l_j has 2^l_j texels a side),
    // or coarser where the hit point moves faster than that per pixel.
    let size_log2 = draw.cluster_noise.z;
    let footprint = max(length(dpdx(s)), length(dpdy(s))) * exp2(size_log2);
    let mip = max(size_log2 - in.color.w, log2(max(footprint, 1e-6)));
    var n: vec3<f32>;
    var t: f32;
    if is_line {
        let hit = capsule_hit(o, ray[1], in.p0.xyz, in.p1.xyz, in.p1.w);
        if hit.w < 0.0 {
            discard;
        }
        n = hit.xyz;
        t = skip + hit.w;
    } else {
        if disc < 0.0 || t_hit < 0.0 {
            discard;
        }
        let holes = textureSampleLevel(noise_alpha, noise_sampler, s, mip).r;
        if holes < draw.cluster_noise.x {
            discard;
        }
        n = normalize(in.p1.xyz * s.x + in.p2.xyz * s.y + in.p3.xyz * s.z);
        var nn = textureSampleLevel(noise_normal, noise_sampler, s, mip).xyz * 2.0 - 1.0;
        nn = select(nn, -nn, dot(nn, n) < 0.0);
        n = normalize(mix(n, normalize(nn + vec3<f32>(1e-6)), draw.cluster_noise.y));
        t = skip + t_hit;
    }
    if !fade_keeps(in.item_y, in.clip.xy, view.eye_lo.w) {
        discard;
    }
    var hit: ClusterHit;
    hit.p = ray[0] + ray[1] * t;
    let clip = view.clip_from_eye * vec4<f32>(hit.p, 1.0);
    hit.depth = clamp(clip.z / clip.w, 0.0, 1.0);
    hit.n = n;
    hit.is_line = is_line;
    return hit;
}

fn cluster_fragment(in: VertexOut) -> FragmentOut {
    let hit = cluster_hit(in);
    var out: FragmentOut;
    out.depth = hit.depth;
    var albedo = styled_albedo(select(seasonal_leaf(in.color.rgb, in.tree_size.z), in.color.rgb, hit.is_line), styles[in.style & 63u]);
    if view.params.z == 1u {
        albedo = repr_color(draw.ids.y);
    }
    // Forest-scale occlusion at the hit's height, as meshes have it per vertex.
    let model = to_model(hit.p, in);
    let top = max(draw.bounds_min.z + draw.bounds_extent.z, 1e-3);
    let canopy = in.cover * (1.0 - clamp(model.z / top, 0.0, 1.0));
    // Looked up a little out along the normal, in model space (the same
    // distance sideways and up, whatever the crown's aspect).
    let ao = own_ao(field_ao(model + rotate_z(hit.n, -in.tree_at.w) * draw.ao_field_min.w), view);
    let sun = sun_visibility(hit.p, hit.n, 0.0, open_sun(canopy));
    let lit = highlighted(shade(albedo, hit.n, !hit.is_line, view, sun, canopy, ao), in.style);
    out.color = vec4<f32>(haze_at(lit, hit.p, view), 1.0);
    return out;
}

@fragment
fn fs_main(in: VertexOut) -> FragmentOut {
    return cluster_fragment(in);
}

// Benchmark variant: keeps the proxy's depth (early depth tests stay on, but
// intersecting primitives sort by their centres) to measure what exact depth costs.
@fragment
fn fs_proxy_depth(in: VertexOut) -> @location(0) vec4<f32> {
    return cluster_fragment(in).color;
}

// Shadow cascades: depth only, the proxy's depth (the primitive's centre, see
// `ellipsoid_vertex`) where the ray meets the primitive.
@fragment
fn fs_shadow(in: VertexOut) {
    _ = cluster_hit(in);
}

// Picking: the tree's pool instance + 1 where the ray meets the primitive,
// with the exact depth.
@fragment
fn fs_id(in: VertexOut) -> IdOut {
    let hit = cluster_hit(in);
    var out: IdOut;
    out.id = in.item_x + 1u;
    out.depth = hit.depth;
    return out;
}

// Picking with the proxy's depth, as `fs_proxy_depth` draws: the same tree wins a pixel.
@fragment
fn fs_id_proxy_depth(in: VertexOut) -> @location(0) u32 {
    _ = cluster_hit(in);
    return in.item_x + 1u;
}
