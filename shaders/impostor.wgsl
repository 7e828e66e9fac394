// Multi-view impostors: one quad per tree facing the eye, on which each pixel
// casts its ray into the three baked views nearest the eye direction
// (hemi-octahedral grid, `impostor_views`), reprojected with each view's depth
// (one parallax step), and blends them: colour, coverage, normal, depth and the
// tree's own occlusion. The tree keeps its shape as the camera goes round it
// (a billboard turns with the camera), and writes its depth, so crowns
// interleave with their neighbours'. Lit like every other representation.
// Rust side: src/render/impostor.rs.

// (Group 0, binding 0: the view, `shaders/view.wgsl`.)

@group(1) @binding(0) var imp_color: texture_2d_array<f32>;
@group(1) @binding(1) var imp_surface: texture_2d_array<f32>;
@group(1) @binding(2) var imp_sampler: sampler;

// (Group 2: batches, instances, draw items and styles; group 3: the draw's
// params. Declared once in `shaders/trees.wgsl`.)


struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    // The pixel's ray in model space (scale 1): a point on it and its direction.
    @location(0) ray_at: vec3<f32>,
    @location(1) ray_dir: vec3<f32>,
    @location(2) @interpolate(flat) layers: vec3<u32>,
    @location(3) @interpolate(flat) weights: vec3<f32>,
    // The sphere's centre (eye-relative) and the yaw.
    @location(4) @interpolate(flat) tree_at: vec4<f32>,
    // Scale (with the thinning boost), crown aspect and variation (0–31).
    @location(5) @interpolate(flat) tree_size: vec3<f32>,
    @location(6) @interpolate(flat) item_y: u32,
    @location(7) @interpolate(flat) tint: vec3<f32>,
    // The batch's canopy cover (`batch_cover`).
    @location(8) @interpolate(flat) cover: f32,
    // The tree's pool instance (the id pass).
    @location(9) @interpolate(flat) item_x: u32,
    // The tree's style byte (`tree_style`).
    @location(10) @interpolate(flat) style: u32,
    // The first layer of the tree's mesh variant's views (0 where the pack
    // has variant 0's alone; bb_size.w variants).
    @location(11) @interpolate(flat) variant_base: u32,
};

// Model offset from the sphere's centre → eye-relative offset, and back.
fn imp_to_world(m: vec3<f32>, in: VertexOut) -> vec3<f32> {
    let s = in.tree_size.x;
    return rotate_z(vec3<f32>(m.xy * (s * in.tree_size.y), m.z * s), in.tree_at.w);
}

fn imp_to_model_dir(w: vec3<f32>, yaw: f32, s: f32, aspect: f32) -> vec3<f32> {
    let l = rotate_z(w, -yaw);
    return vec3<f32>(l.xy / (s * aspect), l.z / s);
}

@vertex
fn vs_main(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> VertexOut {
    let item = items[draw.ids.x + instance];
    let batch = batches[item.y & 0x7fffffu];
    var tree = unpack_instance(instances[item.x], batch, view);
    tree.scale *= tree_growth(styles[STYLE_FLAGS], item.x);
    let grid = max(draw.ids.w, 2u);
    let center = draw.bb_center.xyz;
    let radius = draw.bb_center.w;
    // A thinned batch's kept trees grow about their centre (as billboards do).
    let s = tree.scale * coverage_boost(thinning(batch, view), batch);
    let aspect = max(tree.aspect, 1e-3);
    let cw = tree.pos + rotate_z(vec3<f32>(center.xy * (tree.scale * aspect), center.z * tree.scale), tree.yaw);
    let to_eye = normalize(towards_eye(cw, view));
    // The views around the eye's direction in the model's frame.
    let views = impostor_views(normalize(imp_to_model_dir(to_eye, tree.yaw, s, aspect)), grid);
    // A quad facing the eye, the model's box projected onto it, at the box's
    // front: from any distance it covers the tree's outline (points farther
    // back project nearer its centre), and no more (fewer pixels to shade).
    var right = cross(vec3<f32>(0.0, 0.0, 1.0), to_eye);
    right = select(vec3<f32>(1.0, 0.0, 0.0), normalize(right), dot(right, right) > 1e-8);
    let up = cross(to_eye, right);
    let he = draw.bb_size.xyz * vec3<f32>(s * aspect, s * aspect, s);
    let ax = rotate_z(vec3<f32>(1.0, 0.0, 0.0), tree.yaw);
    let ay = rotate_z(vec3<f32>(0.0, 1.0, 0.0), tree.yaw);
    let box_extent = vec3<f32>(
        abs(dot(right, ax)) * he.x + abs(dot(right, ay)) * he.y + abs(right.z) * he.z,
        abs(dot(up, ax)) * he.x + abs(dot(up, ay)) * he.y + abs(up.z) * he.z,
        abs(dot(to_eye, ax)) * he.x + abs(dot(to_eye, ay)) * he.y + abs(to_eye.z) * he.z,
    );
    var corners = array<vec2<f32>, 6>(
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, -1.0), vec2<f32>(1.0, 1.0),
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, 1.0), vec2<f32>(-1.0, 1.0),
    );
    let c = corners[vertex % 6u];
    // In front of the eye even where it stands inside the box (a near tree
    // forced into the far tier: `--only billboards`).
    var front = box_extent.z;
    if view.viewport.w < 0.5 {
        front = min(front, 0.9 * length(cw));
    }
    let pos = cw + to_eye * front + right * (c.x * box_extent.x) + up * (c.y * box_extent.y);
    var out: VertexOut;
    out.clip = view.clip_from_eye * vec4<f32>(pos, 1.0);
    // Rays from the eye through the quad (parallel towards the sun in a cascade).
    var dir = pos;
    if view.viewport.w > 0.5 {
        dir = -to_eye;
    }
    out.ray_at = center + imp_to_model_dir(pos - cw, tree.yaw, s, aspect);
    out.ray_dir = imp_to_model_dir(dir, tree.yaw, s, aspect);
    out.layers = views.layers;
    let variants = max(u32(draw.bb_size.w), 1u);
    out.variant_base = variant_of(u32(tree.variation), variants - 1u) * grid * grid;
    out.weights = views.weights;
    out.tree_at = vec4<f32>(cw, tree.yaw);
    out.tree_size = vec3<f32>(s, aspect, tree.variation);
    out.item_y = item.y;
    out.item_x = item.x;
    out.style = tree_style(styles[STYLE_FLAGS], item.x, batch.species);
    out.tint = variation_tint(tree.variation);
    out.cover = batch_cover(batch);
    return out;
}

// What the blended views show at a pixel.
struct ImpostorHit {
    color: vec4<f32>,
    // Model space, unnormalised; the surface's data (ao and leaf packed).
    normal: vec3<f32>,
    packed: f32,
    // Model-space point the ray hits.
    at: vec3<f32>,
    // The mip level sampled.
    lod: f32,
};

// How much the normals under a texel of mip `lod` agree (`normal_length` of
// the pack's impostors, in the draw's bounds_min / bounds_extent).
fn normal_agreement(lod: f32) -> f32 {
    let r = array<f32, 8>(
        draw.bounds_min.x, draw.bounds_min.y, draw.bounds_min.z, draw.bounds_min.w,
        draw.bounds_extent.x, draw.bounds_extent.y, draw.bounds_extent.z, draw.bounds_extent.w,
    );
    let i = u32(clamp(floor(lod), 0.0, 6.0));
    return clamp(mix(r[i], r[i + 1u], clamp(lod - f32(i), 0.0, 1.0)), 0.0, 1.0);
}

fn impostor_texcoord(p: vec3<f32>, right: vec3<f32>, up: vec3<f32>, radius: f32) -> vec2<f32> {
    return vec2<f32>(0.5 + 0.5 * dot(p, right) / radius, 0.5 - 0.5 * dot(p, up) / radius);
}

// The view's normal at `uv`: the four texels around it of the nearest mip,
// each decoded, then blended. (The sampler would blend their octahedral codes,
// which bends normals across the code's fold: downward-facing leaves turned
// up and a crown lit ~7 % too brightly.)
fn impostor_normal(uv: vec2<f32>, layer: u32, lod: f32) -> vec3<f32> {
    let level = min(u32(round(lod)), textureNumLevels(imp_surface) - 1u);
    let dims = vec2<i32>(textureDimensions(imp_surface, level));
    let at = uv * vec2<f32>(dims) - 0.5;
    let base = vec2<i32>(floor(at));
    let f = at - floor(at);
    var n = vec3<f32>(0.0);
    for (var k = 0; k < 4; k++) {
        let o = vec2<i32>(k & 1, k >> 1);
        let c = clamp(base + o, vec2<i32>(0), dims - 1);
        let t = textureLoad(imp_surface, c, layer, i32(level));
        let w = select(1.0 - f.x, f.x, o.x == 1) * select(1.0 - f.y, f.y, o.y == 1);
        n += oct_decode(t.rg * 2.0 - 1.0) * w;
    }
    return n;
}

fn impostor_hit(in: VertexOut) -> ImpostorHit {
    let grid = max(draw.ids.w, 2u);
    let center = draw.bb_center.xyz;
    let radius = draw.bb_center.w;
    let d = normalize(in.ray_dir);
    let o = in.ray_at;
    // One mip level for the three views: the first view's footprint on its plane.
    let d0 = impostor_view_dir(in.layers.x, grid);
    let r0 = impostor_view_right(d0);
    let p0 = o + d * (dot(center - o, d0) / min(dot(d, d0), -1e-3)) - center;
    let uv0 = impostor_texcoord(p0, r0, cross(d0, r0), radius);
    let size = f32(textureDimensions(imp_color).x);
    let footprint = max(length(dpdx(uv0)), length(dpdy(uv0))) * size;
    // No coarser than 8×8 texels a view: a coarser mip's few texels pass or
    // fail the alpha test as blocks as wide as the bounding sphere (a far tree
    // became a square); finer ones alias a little instead.
    let lod = clamp(log2(max(footprint, 1e-6)), 0.0, max(log2(size) - 3.0, 0.0));
    var hit: ImpostorHit;
    hit.lod = lod;
    var weight = 0.0;
    for (var k = 0u; k < 3u; k++) {
        let w = in.weights[k];
        if w <= 0.0 {
            continue;
        }
        let view_index = in.layers[k];
        // The view's layer of the tree's variant.
        let layer = view_index + in.variant_base;
        let vd = impostor_view_dir(view_index, grid);
        let vr = impostor_view_right(vd);
        let vu = cross(vd, vr);
        // Rays run against the view's direction; grazing ones are clamped.
        let denom = min(dot(d, vd), -1e-3);
        let to_plane = dot(center - o, vd);
        var t = to_plane / denom;
        var surface = vec4<f32>(0.5);
        // Parallax: step to where the ray meets the depth the view saw, twice
        // (once on a far tree, where a step moves less than a texel).
        let steps = select(2, 1, lod > 2.0);
        for (var i = 0; i < steps; i++) {
            let uv = impostor_texcoord(o + d * t - center, vr, vu, radius);
            surface = textureSampleLevel(imp_surface, imp_sampler, uv, layer, lod);
            t = (to_plane + (surface.b * 2.0 - 1.0) * radius) / denom;
        }
        let at = o + d * t;
        let uv = impostor_texcoord(at - center, vr, vu, radius);
        let color = textureSampleLevel(imp_color, imp_sampler, uv, layer, lod);
        surface = textureSampleLevel(imp_surface, imp_sampler, uv, layer, lod);
        let wa = w * color.a;
        hit.color += vec4<f32>(color.rgb * wa, w * color.a);
        hit.normal += impostor_normal(uv, layer, lod) * wa;
        hit.packed += surface.a * wa;
        hit.at += at * wa;
        weight += wa;
    }
    let inv = 1.0 / max(weight, 1e-6);
    hit.color = vec4<f32>(hit.color.rgb * inv, hit.color.a);
    hit.packed *= inv;
    hit.at = select(o + d * (dot(center - o, d0) / min(dot(d, d0), -1e-3)), hit.at * inv, weight > 0.0);
    return hit;
}

// The depth of the model point `at` in this view (reversed Z).
fn impostor_depth(at: vec3<f32>, in: VertexOut) -> f32 {
    let rel = in.tree_at.xyz + imp_to_world(at - draw.bb_center.xyz, in);
    let clip = view.clip_from_eye * vec4<f32>(rel, 1.0);
    return clamp(clip.z / clip.w, 0.0, 1.0);
}

struct FragmentOut {
    @location(0) color: vec4<f32>,
    @builtin(frag_depth) depth: f32,
};

@fragment
fn fs_main(in: VertexOut) -> FragmentOut {
    let hit = impostor_hit(in);
    if !impostor_keeps(hit, in) {
        discard;
    }
    var out: FragmentOut;
    out.color = impostor_shade(hit, in);
    out.depth = impostor_depth(hit.at, in);
    return out;
}

// A moving frame's impostors (`RenderSettings::moving_impostors`, every
// level of the frame-time governor but its first): the nearest view alone, sampled once,
// and no depth of their own — the quad's, at the front of the tree's box. With
// no depth written the depth test runs before the shading, so a crown hidden
// behind nearer ones costs nothing: 6–9× cheaper on lavapipe (docs/BENCHMARKS.md).
// Crowns that interpenetrate sort by their quads while the camera moves.
@fragment
fn fs_moving(in: VertexOut) -> @location(0) vec4<f32> {
    let hit = impostor_nearest(in, true);
    if !impostor_keeps(hit, in) {
        discard;
    }
    return impostor_shade(hit, in);
}

// The blended views' coverage test, and the dither of a cross-fade.
fn impostor_keeps(hit: ImpostorHit, in: VertexOut) -> bool {
    if hit.color.a < 0.5 || !fade_keeps(in.item_y, in.clip.xy, view.eye_lo.w) {
        return false;
    }
    // Leaf-off before the bare capture has come: the wood the leaves let through.
    return !(hit.packed >= 0.5 && leaves_off(in.tree_size.z));
}

// The hit lit, hazed, highlighted.
fn impostor_shade(hit: ImpostorHit, in: VertexOut) -> vec4<f32> {
    let is_leaf = hit.packed >= 0.5;
    let baked_ao = clamp((hit.packed - select(0.0, 128.0 / 255.0, is_leaf)) * (255.0 / 127.0), 0.0, 1.0);
    // Normals follow the crown's stretch (inverse transpose of the scaling).
    let nm = hit.normal;
    let n = normalize(rotate_z(vec3<f32>(nm.xy / in.tree_size.y, nm.z), in.tree_at.w));
    // The texel's mean normal: shorter where it covers many leaves.
    let m = n * normal_agreement(hit.lod);
    let rel = in.tree_at.xyz + imp_to_world(hit.at - draw.bb_center.xyz, in);
    let own = hit.color.rgb * in.tint;
    var albedo = styled_albedo(select(own, seasonal_leaf(own, in.tree_size.z), is_leaf), styles[in.style & 63u]);
    if view.params.z == 1u {
        albedo = repr_color(REPR_BILLBOARD) * (0.6 + 0.4 * hit.color.g);
    }
    // The model's top, as the other tiers measure height in the crown.
    let top = max(draw.bb_center.z + draw.bb_size.z, 1e-3);
    let canopy = in.cover * (1.0 - clamp(hit.at.z / top, 0.0, 1.0));
    let ao = own_ao(baked_ao, view);
    let lift = draw.bb_center.w * in.tree_size.x * 0.25;
    let sun = sun_visibility(rel, n, lift, open_sun(canopy));
    let lit = highlighted(shade_filtered(albedo, m, is_leaf, view, sun, canopy, ao), in.style);
    return vec4<f32>(haze(lit, in.clip, view), 1.0);
}

// A shadow caster's coverage and depth, cheaply: the nearest of the three
// views alone, one surface sample for the depth and the coverage at the same
// texel (a shadow is a silhouette the PCF softens: the blend and the parallax
// steps of `impostor_hit` buy little there, at five times the samples).
// Returns the model-space point hit (xyz) and its coverage (w; 0 for a leaf
// texel in leaf-off).
fn impostor_cover(in: VertexOut) -> vec4<f32> {
    let hit = impostor_nearest(in, false);
    return vec4<f32>(hit.at, select(hit.color.a, 0.0, leaves_off(in.tree_size.z) && hit.packed >= 0.5));
}

// The nearest of the three views alone, on the view's plane through the box's
// centre: its colour, its surface (normal, occlusion and leaf flag) and the
// point its depth puts the hit at, from one texel (shadow casters, and a
// moving frame's impostors).
fn impostor_nearest(in: VertexOut, shading: bool) -> ImpostorHit {
    let grid = max(draw.ids.w, 2u);
    let center = draw.bb_center.xyz;
    let radius = draw.bb_center.w;
    let d = normalize(in.ray_dir);
    let o = in.ray_at;
    var k = 0u;
    if in.weights[1] > in.weights[k] {
        k = 1u;
    }
    if in.weights[2] > in.weights[k] {
        k = 2u;
    }
    let view_index = in.layers[k];
    let layer = view_index + in.variant_base;
    let vd = impostor_view_dir(view_index, grid);
    let vr = impostor_view_right(vd);
    let denom = min(dot(d, vd), -1e-3);
    let to_plane = dot(center - o, vd);
    let uv = impostor_texcoord(o + d * (to_plane / denom) - center, vr, cross(vd, vr), radius);
    // The mip from the first view's footprint, as `impostor_hit` takes it: the
    // nearest view may differ between a quad's pixels, the first does not.
    let d0 = impostor_view_dir(in.layers.x, grid);
    let r0 = impostor_view_right(d0);
    let uv0 = impostor_texcoord(o + d * (dot(center - o, d0) / min(dot(d, d0), -1e-3)) - center, r0, cross(d0, r0), radius);
    let size = f32(textureDimensions(imp_color).x);
    let footprint = max(length(dpdx(uv0)), length(dpdy(uv0))) * size;
    var hit: ImpostorHit;
    hit.lod = clamp(log2(max(footprint, 1e-6)), 0.0, max(log2(size) - 3.0, 0.0));
    hit.color = textureSampleLevel(imp_color, imp_sampler, uv, layer, hit.lod);
    let surface = textureSampleLevel(imp_surface, imp_sampler, uv, layer, hit.lod);
    hit.packed = surface.a;
    hit.at = o + d * ((to_plane + (surface.b * 2.0 - 1.0) * radius) / denom);
    if shading {
        hit.normal = impostor_normal(uv, layer, hit.lod);
    }
    return hit;
}

// Shadow cascades: depth only, the nearest view's coverage tested, its depth.
@fragment
fn fs_shadow(in: VertexOut) -> @builtin(frag_depth) f32 {
    let hit = impostor_cover(in);
    if hit.w < 0.5 || !fade_keeps(in.item_y, in.clip.xy, view.eye_lo.w) {
        discard;
    }
    return impostor_depth(hit.xyz, in);
}

// Picking: the tree's pool instance + 1, the coverage tested, the hit's depth.
@fragment
fn fs_id(in: VertexOut) -> IdOut {
    let hit = impostor_hit(in);
    if !impostor_keeps(hit, in) {
        discard;
    }
    var out: IdOut;
    out.id = in.item_x + 1u;
    out.depth = impostor_depth(hit.at, in);
    return out;
}
