// Terrain pass: every selected terrain tile in one instanced draw, before the
// trees, lit like them. A tile is a (grid + 1)² height grid pulled from the
// resident height pool, with a skirt (an extra ring of vertices dropped below
// the edge) against cracks between levels, and its vertices (and normals)
// morphed towards the parent level's surface by the tile's morph factor, so
// level changes do not pop (CDLOD-style geomorphing, one factor per tile:
// scene::terrain::morph).
// Rust side: src/render/terrain.rs; selection: src/scene/terrain.rs.

// (Group 0, binding 0: the view, `shaders/view.wgsl`.)

// Quantised heights, two u16 per word, `words` words per pool slot.
@group(1) @binding(0) var<storage, read> heights: array<u32>;
@group(1) @binding(1) var<storage, read> tiles: array<TerrainDraw>;
@group(1) @binding(2) var<uniform> params: TerrainParams;
// Ground images (scene::imagery): 256² sRGB layers with mipmaps, alpha = coverage.
@group(2) @binding(0) var images: texture_2d_array<f32>;
@group(2) @binding(1) var image_sampler: sampler;

// Must match `GpuTerrainDraw` in src/render/terrain.rs.
struct TerrainDraw {
    // South-west corner (xy, metres relative to the scene origin), lowest height (z).
    origin_m: vec3<f32>,
    // Pool slot of the heights.
    slot: u32,
    // Side of the square, metres.
    size_m: f32,
    // Highest minus lowest height (quantisation range).
    range_m: f32,
    // Morph from the parent's surface (0) to the tile's own (1), per tile
    // (scene::terrain::morph: measured where the selection measures).
    morph: f32,
    // How far the skirt hangs below the edge, metres.
    skirt_m: f32,
    // Where the tile lies in its image: uv offset (xy) and scale (zw).
    image_uv: vec4<f32>,
    // Layer of the image, NO_IMAGE for none.
    layer: u32,
    // The draws (index + 1; 0: none) of the neighbours of this level drawn
    // beside it: west | east << 16, south | north << 16 (`height_across`).
    across_x: u32,
    across_y: u32,
    pad2: u32,
    // The neighbours' images (west, east, south, north) where another than
    // this tile's: offset (xy) and scale (z) of this tile's place carried
    // across the edge, layer (w; -1: none). For `photo_across`.
    image_across: array<vec4<f32>, 4>,
};

const NO_IMAGE: u32 = 0xffffffffu;

// Light on level ground under the default daylight (render::Lighting::default:
// the sky light facing up plus the sun at its default height).
const DAY_FLAT_LIGHT: vec3<f32> = vec3<f32>(1.159, 1.184, 1.227);

// Must match `TerrainParams` in src/render/terrain.rs.
struct TerrainParams {
    // Cells per tile side.
    grid: u32,
    // Words per pool slot.
    words: u32,
    // Selection threshold, pixels.
    threshold_px: f32,
    // Bits: 1 colour by level (debug view), 2 no geomorphing (comparisons),
    // 4 colour by shadow cascade, 8 with 4: the first cascade's ground shaded by the second.
    debug: u32,
};

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    // 1 where every vertex of the triangle has data (holes: < 1, discarded).
    @location(1) valid: f32,
    @location(2) @interpolate(flat) level_tint: f32,
    // Position in the tile (east, north; 0–1) mapped into its image's uv.
    @location(3) image_uv: vec2<f32>,
    @location(4) @interpolate(flat) layer: u32,
    // Position in the tile (east, north; 0–1).
    @location(5) tile_uv: vec2<f32>,
    // The neighbours' images (`TerrainDraw::image_across`), passed on: a
    // fragment shader's storage reads cost llvmpipe 5x the whole frame.
    @location(6) @interpolate(flat) across_w: vec4<f32>,
    @location(7) @interpolate(flat) across_e: vec4<f32>,
    @location(8) @interpolate(flat) across_s: vec4<f32>,
    @location(9) @interpolate(flat) across_n: vec4<f32>,
    // The tile's share of its image's side (`image_uv.z`).
    @location(10) @interpolate(flat) image_scale: f32,
};

const HOLE: u32 = 0xffffu;

fn quantised(slot: u32, i: u32, j: u32) -> u32 {
    let v = j * (params.grid + 1u) + i;
    let word = heights[slot * params.words + (v >> 1u)];
    return (word >> ((v & 1u) * 16u)) & 0xffffu;
}

// (height, 1) at vertex (i, j) of tile `t`, or (0, 0) for a hole.
fn height_at(t: TerrainDraw, i: u32, j: u32) -> vec2<f32> {
    let q = quantised(t.slot, i, j);
    if q == HOLE {
        // At the tile's lowest height, so the sliver left by the discard is short.
        return vec2<f32>(t.origin_m.z, 0.0);
    }
    return vec2<f32>(t.origin_m.z + f32(q) / 65534.0 * t.range_m, 1.0);
}

// Mean height of the valid vertices among a few, or the fallback.
fn mean_valid(a: vec2<f32>, b: vec2<f32>, c: vec2<f32>, d: vec2<f32>, fallback: f32) -> f32 {
    let n = a.y + b.y + c.y + d.y;
    if n < 0.5 {
        return fallback;
    }
    return (a.x * a.y + b.x * b.y + c.x * c.y + d.x * d.y) / n;
}

// (height, 1) at vertex (i, j) of tile `t`, where i or j may lie up to a
// tile beyond its edge: then the neighbour of its level drawn there
// (`across_x`, `across_y`), else (0, 0) as for a hole. Normals along an edge
// then take the same differences on both sides — before, each side took its
// own one-sided difference and the ground's shading broke along the edge
// (the seam of docs/images/shadows-close.png).
fn height_across(t: TerrainDraw, i: i32, j: i32) -> vec2<f32> {
    let n = i32(params.grid);
    if i >= 0 && i <= n && j >= 0 && j <= n {
        return height_at(t, u32(i), u32(j));
    }
    var ii = i;
    var jj = j;
    var k = 0u;
    if i < 0 {
        k = t.across_x & 0xffffu;
        ii = i + n;
    } else if i > n {
        k = t.across_x >> 16u;
        ii = i - n;
    } else if j < 0 {
        k = t.across_y & 0xffffu;
        jj = j + n;
    } else {
        k = t.across_y >> 16u;
        jj = j - n;
    }
    if k == 0u || ii < 0 || ii > n || jj < 0 || jj > n {
        return vec2<f32>(0.0, 0.0);
    }
    return height_at(tiles[k - 1u], u32(ii), u32(jj));
}

// Normal at vertex (i, j) from central differences over `d` steps either
// side (one-sided where a side is missing: a hole, or an edge with no
// neighbour drawn beyond it); `h` the vertex's own height.
fn grid_normal(t: TerrainDraw, i: i32, j: i32, d: i32, h: f32, step: f32) -> vec3<f32> {
    let x0 = height_across(t, i - d, j);
    let x1 = height_across(t, i + d, j);
    let y0 = height_across(t, i, j - d);
    let y1 = height_across(t, i, j + d);
    let dx = select(h, x1.x, x1.y > 0.5) - select(h, x0.x, x0.y > 0.5);
    let dy = select(h, y1.x, y1.y > 0.5) - select(h, y0.x, y0.y > 0.5);
    let span = f32(d) * step;
    return normalize(vec3<f32>(-dx / max((x0.y + x1.y) * span, 1e-6), -dy / max((y0.y + y1.y) * span, 1e-6), 1.0));
}

// The parent level's normal at this tile's even vertex (i, j): differences
// over the parent's neighbours, two of this tile's steps away.
fn parent_normal(t: TerrainDraw, i: u32, j: u32, step: f32) -> vec3<f32> {
    return grid_normal(t, i32(i), i32(j), 2, height_at(t, i, j).x, step);
}

@vertex
fn vs_main(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> VertexOut {
    let t = tiles[instance];
    let n = params.grid;
    let ring = n + 3u; // vertices per row with the skirt ring
    let gi = vertex % ring;
    let gj = vertex / ring;
    let i = u32(clamp(i32(gi) - 1, 0, i32(n)));
    let j = u32(clamp(i32(gj) - 1, 0, i32(n)));
    let skirt = gi == 0u || gj == 0u || gi == ring - 1u || gj == ring - 1u;
    let step = t.size_m / f32(n);
    let own = height_at(t, i, j);
    var h = own.x;
    // The parent's surface here: its vertices are this tile's even ones.
    let im = u32(max(i32(i) - 1, 0));
    let ip = min(i + 1u, n);
    let jm = u32(max(i32(j) - 1, 0));
    let jp = min(j + 1u, n);
    var coarse = h;
    let odd_i = (i & 1u) == 1u;
    let odd_j = (j & 1u) == 1u;
    if odd_i && odd_j {
        // A parent cell's centre: its triangles split it along the south-west –
        // north-east diagonal (as the index buffer does), so the parent surface
        // there is the mean of those two corners.
        let a = height_at(t, im, jm);
        let b = height_at(t, ip, jp);
        coarse = mean_valid(a, b, a, b, h);
    } else if odd_i {
        let a = height_at(t, im, j);
        let b = height_at(t, ip, j);
        coarse = mean_valid(a, b, a, b, h);
    } else if odd_j {
        let a = height_at(t, i, jm);
        let b = height_at(t, i, jp);
        coarse = mean_valid(a, b, a, b, h);
    }
    let local = vec3<f32>(f32(i) * step, f32(j) * step, 0.0);
    var morph = t.morph;
    if (params.debug & 2u) != 0u {
        morph = 1.0;
    }
    h = mix(coarse, h, morph);
    if skirt {
        h -= t.skirt_m;
    }
    // Normal from central differences of the neighbours, morphed like the
    // height: towards the parent's normal (the same differences over its
    // vertices, this tile's even ones), so the light does not pop either.
    let fine_n = grid_normal(t, i32(i), i32(j), 1, own.x, step);
    // The parent interpolates its vertex normals across its triangles: at an
    // edge's middle the mean of the edge's ends, at a cell's centre (on the
    // diagonal) the mean of its south-west and north-east corners.
    var coarse_n = parent_normal(t, i, j, step);
    if odd_i && odd_j {
        coarse_n = parent_normal(t, im, jm, step) + parent_normal(t, ip, jp, step);
    } else if odd_i {
        coarse_n = parent_normal(t, im, j, step) + parent_normal(t, ip, j, step);
    } else if odd_j {
        coarse_n = parent_normal(t, i, jm, step) + parent_normal(t, i, jp, step);
    }
    let normal = normalize(mix(normalize(coarse_n), fine_n, morph));
    var out: VertexOut;
    let pos = eye_relative(vec3<f32>(t.origin_m.xy, 0.0), local + vec3<f32>(0.0, 0.0, h), view);
    out.clip = view.clip_from_eye * vec4<f32>(pos, 1.0);
    out.normal = normal;
    out.valid = own.y;
    out.level_tint = log2(max(t.size_m, 1.0));
    let tile_uv = vec2<f32>(f32(i), f32(j)) / f32(n);
    out.image_uv = t.image_uv.xy + tile_uv * t.image_uv.zw;
    out.layer = t.layer;
    out.tile_uv = tile_uv;
    out.across_w = t.image_across[0];
    out.across_e = t.image_across[1];
    out.across_s = t.image_across[2];
    out.across_n = t.image_across[3];
    out.image_scale = t.image_uv.z;
    return out;
}

// Ground colours (linear RGB): forest-floor litter on gentle ground, bare soil
// on steep (no imagery yet). Never green-dominant, so image tests that count
// foliage pixels count trees only.
const LITTER: vec3<f32> = vec3<f32>(0.17, 0.155, 0.09);
const SOIL: vec3<f32> = vec3<f32>(0.23, 0.19, 0.13);

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    if in.valid < 0.999 {
        discard;
    }
    let n = normalize(in.normal);
    var albedo = mix(LITTER, SOIL, smoothstep(0.82, 0.55, n.z));
    if (params.debug & 1u) != 0u {
        // Alternating tints per level (tile size), to see the selection.
        let k = u32(in.level_tint) % 3u;
        albedo = select(select(vec3<f32>(0.5, 0.3, 0.3), vec3<f32>(0.3, 0.5, 0.3), k == 1u), vec3<f32>(0.3, 0.3, 0.5), k == 2u);
    }
    let sun = sun_visibility(frag_rel(in.clip, view), n, 0.0, 1.0);
    if (params.debug & 4u) != 0u {
        // Coloured by the shadow cascade (black: none holds it), as bright as
        // the sun there; with bit 8 the first cascade's ground is shaded by
        // the second (the same ground's light from either).
        let rel = frag_rel(in.clip, view);
        let count = u32(view.shadow.x);
        let held = shadow_cascade(rel, n, 0.0);
        let k = select(9u, held, count > 0u && held < count);
        var vis = sun;
        if (params.debug & 8u) != 0u && k == 0u && count > 1u {
            vis = cascade_visibility(1u, shadow_clip(1u, rel, n, 0.0));
        }
        let c = vec3<f32>(vec3<u32>(k) == vec3<u32>(0u, 1u, 2u)) + f32(k == 3u);
        return vec4<f32>(c * (0.5 + 0.5 * vis), 1.0);
    }
    var lit = shade(albedo, n, false, view, sun, 0.0, 1.0);
    // Sampled everywhere (uniform control flow), used where there is an image.
    let has = in.layer != NO_IMAGE && (params.debug & 1u) == 0u;
    // The image's uv made finite and bounded: a 2×2 quad at the ground's far
    // edge can hold a helper pixel on the horizon, where perspective-correct
    // interpolation divides by 1/w = 0 (a level camera puts the horizon on a
    // row of pixel centres). Sampled at that infinite uv, Mesa 22.3 llvmpipe's
    // anisotropic filter looped for seconds (70 s for one 80×45 frame 4 m
    // above the ground, 0.3 s with this). On the ground uv is in 0–1 and
    // nothing changes.
    let uv = vec2<f32>(in.image_uv.x, 1.0 - in.image_uv.y);
    let uv_safe = finite_uv(uv);
    // (Per pixel: the blend across image edges follows the footprint smoothly.)
    let ddx = dpdxFine(uv_safe);
    let ddy = dpdyFine(uv_safe);
    let own = textureSampleGrad(images, image_sampler, uv_safe, select(0u, in.layer, has), ddx, ddy);
    let photo = photo_across(in, has, in.image_scale, uv_safe, ddx, ddy, own);
    // A photograph already holds the light of its day: relit relative to flat
    // ground under the default daylight, so level ground at midday shows its
    // own colours, slopes their relief, and dusk darkens it like the rest.
    let relit = shade(photo.rgb, n, false, view, sun, 0.0, 1.0) / DAY_FLAT_LIGHT;
    lit = mix(lit, relit, select(0.0, photo.a, has));
    return vec4<f32>(haze(lit, in.clip, view), 1.0);
}

fn finite_uv(uv: vec2<f32>) -> vec2<f32> {
    let finite = (bitcast<vec2<u32>>(uv) & vec2<u32>(0x7f800000u)) != vec2<u32>(0x7f800000u);
    return clamp(select(vec2<f32>(0.0), uv, finite), vec2<f32>(-1.0), vec2<f32>(2.0));
}

// The neighbour's image `across` (`TerrainDraw::image_across`) at this
// fragment's place carried across the edge (its edge texels, as the sampler
// clamps), at mip `lod` of this tile's image (shifted by the two images'
// scales); layer 0, unused, where there is none.
fn neighbour_photo(across: vec4<f32>, scale: f32, tile_uv: vec2<f32>, lod: f32) -> vec4<f32> {
    let s = abs(across.z);
    let at = across.xy + tile_uv * s;
    let uv = finite_uv(vec2<f32>(at.x, 1.0 - at.y));
    let level = max(lod + log2(max(s, 1e-9) / max(scale, 1e-9)), 0.0);
    return textureSampleLevel(images, image_sampler, uv, u32(max(across.w, 0.0)), level);
}

// Ground images meet without a seam: each image is filtered within itself
// (the sampler clamps at its edge), so where two tiles drape different
// images the last half texel on either side of their edge showed its own
// edge texel alone, a hard step along the edge — most of all close by, where
// one texel spans many pixels (the vertical seam through docs/images/
// shadows-close.png, whose eye stood on such an edge). Within half a texel
// of the mip the sampler reads (its level estimated as the anisotropic
// filter picks it, at most 4:1), the nearer neighbour's edge texels across
// each axis are blended in, half and half at the edge: bilinear filtering
// across the two images. The neighbours' edge texels are read at the level
// of the footprint's longer axis (llvmpipe's anisotropic filter, clamped at
// an image's edge, took its taps by the quad: 2 x 2 blocks), their images
// named by the draw record, passed on by the vertex shader (storage reads in
// the fragments cost llvmpipe 5 times the frame).
fn photo_across(in: VertexOut, has: bool, scale: f32, uv: vec2<f32>, ddx: vec2<f32>, ddy: vec2<f32>, own: vec4<f32>) -> vec4<f32> {
    let px = f32(IMAGE_TEXELS);
    let fx = length(ddx * px);
    let fy = length(ddy * px);
    let lod = max(log2(max(min(fx, fy), max(fx, fy) / 4.0)), 0.0);
    let half = 0.5 * exp2(lod) / px;
    // The nearer edge on each axis: west or east, south or north (v runs north to south).
    let across_x = select(in.across_w, in.across_e, uv.x > 0.5);
    let across_y = select(in.across_n, in.across_s, uv.y > 0.5);
    let to_x = min(uv.x, 1.0 - uv.x);
    let to_y = min(uv.y, 1.0 - uv.y);
    let level = log2(max(max(fx, fy), 1e-6));
    let photo_x = neighbour_photo(across_x, scale, in.tile_uv, level);
    let photo_y = neighbour_photo(across_y, scale, in.tile_uv, level);
    // Half at the edge; whole where the neighbour's image goes on across it
    // unblended (scale negated: it drapes an ancestor's image there).
    let edge_x = select(0.5, 1.0, across_x.z < 0.0);
    let edge_y = select(0.5, 1.0, across_y.z < 0.0);
    let wx = select(0.0, edge_x * (1.0 - to_x / half), has && across_x.w >= 0.0 && to_x < half);
    let wy = select(0.0, edge_y * (1.0 - to_y / half), has && across_y.w >= 0.0 && to_y < half);
    return mix(mix(own, photo_x, wx), photo_y, wy);
}

// Texels a side of a ground image (scene::imagery::IMAGE_PX).
const IMAGE_TEXELS: u32 = 256u;

// Picking: the ground hides the trees behind it and is no tree (0).
@fragment
fn fs_id(in: VertexOut) -> @location(0) u32 {
    if in.valid < 0.999 {
        discard;
    }
    return 0u;
}
