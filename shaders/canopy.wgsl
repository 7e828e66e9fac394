// Canopy pass: where trees are a pixel or two, the forest drawn from
// its canopy rasters (scene::canopy selects them, render/canopy.rs uploads),
// cross-faded with the trees the cull pass keeps (`canopy_weight`). One
// instanced draw: a quad per raster cell at the crowns' height, its alpha the
// cell's crown cover times the canopy's share of trees of that size, so trees
// and canopy together cover what the crowns cover (no hole, no double-dark
// band). After the trees, blended, depth-tested, no depth written.
// Rust side: src/render/canopy.rs.

// (Group 0, binding 0: the view, `shaders/view.wgsl`.)

// Raster cells, `cells²` per slot, 2 words each: r | g << 8 | b << 16 | cover << 24,
// height | side << 8 | ground << 16 (format::canopy).
@group(1) @binding(0) var<storage, read> cells: array<vec2<u32>>;
@group(1) @binding(1) var<storage, read> rasters: array<CanopyRaster>;

// Must match `GpuCanopyRaster` in src/render/canopy.rs.
struct CanopyRaster {
    // Lowest corner, metres relative to the scene origin.
    origin_m: vec2<f32>,
    // Side, metres.
    size_m: f32,
    // Cells per side.
    cells: u32,
    // Ground heights' lowest and range.
    z_min: f32,
    z_span: f32,
    // Height of quantised height 255.
    height_max: f32,
    // Pool slot of the cells.
    slot: u32,
    // 1: trees the view wants here are not resident; the raster stands in
    // for them at full cover.
    stand_in: u32,
    // The crowns' batches' tallest trees over their own heights (format::canopy).
    tallest_ratio: f32,
};

// Where in the crown the canopy surface lies (share of the tree height above the ground).
const CANOPY_SURFACE: f32 = 0.75;
// The crowns seen from above, shaded as filtered leaves (`shade_filtered`):
// their mean normal (length: how much the leaves agree) and the sky they see.
const CANOPY_NORMAL: vec3<f32> = vec3<f32>(0.0, 0.0, 0.55);
const CANOPY_AO: f32 = 0.8;
// Under the sky's own light (LIGHT_SKY_LIGHT: less sky, more of it from the
// horizon), the crowns' sky as the trees' impostors see theirs.
const CANOPY_AO_SKY: f32 = 0.9;

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) @interpolate(flat) albedo: vec3<f32>,
    @location(1) @interpolate(flat) alpha: f32,
};

fn srgb_channel(c: f32) -> f32 {
    return select(pow((c + 0.055) / 1.055, 2.4), c / 12.92, c <= 0.04045);
}

// Quad corners of a cell: two triangles.
const CORNERS = array<vec2<f32>, 6>(
    vec2<f32>(0.0, 0.0), vec2<f32>(1.0, 0.0), vec2<f32>(1.0, 1.0),
    vec2<f32>(0.0, 0.0), vec2<f32>(1.0, 1.0), vec2<f32>(0.0, 1.0),
);

// Whether cell `n` of raster `r` holds no crowns. Outside the raster: not
// known (a neighbouring raster's, maybe of another level), so no wall there —
// walls along raster edges would draw seams through stands.
fn neighbour_empty(r: CanopyRaster, n: vec2<i32>) -> bool {
    let size = i32(r.cells);
    if n.x < 0 || n.y < 0 || n.x >= size || n.y >= size {
        return false;
    }
    let word = cells[r.slot * r.cells * r.cells + u32(n.y) * r.cells + u32(n.x)];
    return (word.x >> 24u) == 0u;
}

// The canopy surface of cell `n` of raster `r` (metres) and 1, or 0 and 0
// where it holds no crowns or lies outside the raster.
fn neighbour_surface(r: CanopyRaster, n: vec2<i32>) -> vec2<f32> {
    let size = i32(r.cells);
    if n.x < 0 || n.y < 0 || n.x >= size || n.y >= size {
        return vec2<f32>(0.0);
    }
    let word = cells[r.slot * r.cells * r.cells + u32(n.y) * r.cells + u32(n.x)];
    if (word.x >> 24u) == 0u {
        return vec2<f32>(0.0);
    }
    let height = f32(word.y & 0xffu) / 255.0 * r.height_max;
    let ground = r.z_min + f32(word.y >> 16u) / 65535.0 * r.z_span;
    return vec2<f32>(ground + CANOPY_SURFACE * height, 1.0);
}

@vertex
fn vs_main(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> VertexOut {
    var out: VertexOut;
    let first = rasters[0];
    let n2 = first.cells * first.cells;
    let r = rasters[instance / n2];
    let c = instance % n2;
    let word = cells[r.slot * n2 + c];
    let top_cover = f32(word.x >> 24u) / 255.0;
    let side = f32((word.y >> 8u) & 0xffu) / 32.0;
    let height = f32(word.y & 0xffu) / 255.0 * r.height_max;
    let ground = r.z_min + f32(word.y >> 16u) / 65535.0 * r.z_span;
    let cell_m = r.size_m / f32(r.cells);
    let ij = vec2<f32>(f32(c % r.cells), f32(c / r.cells));
    let z = ground + CANOPY_SURFACE * height;
    // The canopy's share of the cell's trees at the cell's centre: the cull
    // drops a share of each batch by its tallest tree's size (`canopy_drops`),
    // so the cell's trees are sized by their batches' tallest.
    let centre = eye_relative(vec3<f32>(r.origin_m, 0.0), vec3<f32>((ij + 0.5) * cell_m, z), view);
    let h_px = height * r.tallest_ratio * view.lod.x / max(length(centre), 1e-3);
    // Seen at elevation θ the crowns' sides cover ground too: the exponent of
    // the cover grows by side · cot θ (format::canopy): cover = 1 − e^(−lambda).
    let cot = min(length(centre.xy) / max(-centre.z, 1e-3), 8.0);
    let lambda = min(-log(max(1.0 - top_cover, 1e-3)), 8.0) * (1.0 + side * cot);
    // Standing in for trees still on their way: all of their cover.
    let w = select(canopy_weight(h_px, view), 1.0, r.stand_in != 0u);
    // The trees kept, a share 1 − w of them, cover t = 1 − (1 − c)^(1 − w) (as
    // a random share of trees with cover c would: more than (1 − w)c, as
    // crowns overlap); the canopy adds what makes it c: t + (1 − t)·a = c,
    // a = 1 − (1 − c)^w = 1 − e^(−w·lambda). (Not computed as (c − t)/(1 − t)
    // with 1 − c held at 1e-3: where c passed 0.999 — under closed crowns, or
    // at grazing views — that reached 1 even at w = 0, a flat opaque polygon
    // over trees drawn whole.)
    let alpha = 1.0 - exp(-w * lambda);
    out.alpha = alpha;
    out.albedo = vec3<f32>(
        srgb_channel(f32(word.x & 0xffu) / 255.0),
        srgb_channel(f32((word.x >> 8u) & 0xffu) / 255.0),
        srgb_channel(f32((word.x >> 16u) & 0xffu) / 255.0),
    );
    if alpha <= 0.0 {
        // Nothing to draw: a degenerate triangle.
        out.clip = vec4<f32>(0.0, 0.0, 0.0, 1.0);
        return out;
    }
    // At the forest's edges the trees stand as a wall: the side facing the eye
    // reaches down to the ground (the front trees' trunks and lower crowns),
    // the far side up to the tree tops. Inside a stand the cells lie flat at
    // the crowns' height, so neighbours do not overlap.
    let corner = CORNERS[vertex % 6u];
    let v = centre.xy / max(length(centre.xy), 1e-3);
    let share = abs(v) / max(abs(v.x) + abs(v.y), 1e-3);
    let step = vec2<i32>(select(-1, 1, v.x >= 0.0), select(-1, 1, v.y >= 0.0));
    let cell_i = vec2<i32>(ij);
    // Per axis: the corner's side faces away from the eye (far) or towards it (near).
    let far = (corner - 0.5) * vec2<f32>(step) > vec2<f32>(0.0);
    var rise = 0.0;
    // Between two stands' cells of different heights the lower one's surface
    // would show the ground through the step: a near edge above its (lower)
    // neighbour towards the eye comes down to it.
    var bridge = 0.0;
    for (var a = 0; a < 2; a++) {
        var n = cell_i;
        let toward = select(-step[a], step[a], far[a]);
        n[a] += toward;
        if neighbour_empty(r, n) {
            rise += select(-CANOPY_SURFACE, 1.0 - CANOPY_SURFACE, far[a]) * share[a];
        } else if !far[a] {
            let s = neighbour_surface(r, n);
            if s.y > 0.5 && s.x < z {
                bridge += (s.x - z) * share[a];
            }
        }
    }
    let local = vec3<f32>((ij + corner) * cell_m, z + rise * height + bridge);
    let pos = eye_relative(vec3<f32>(r.origin_m, 0.0), local, view);
    out.clip = view.clip_from_eye * vec4<f32>(pos, 1.0);
    return out;
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    let ao = select(CANOPY_AO, CANOPY_AO_SKY, light_on(view, LIGHT_SKY_LIGHT));
    let lit = shade_filtered(in.albedo, CANOPY_NORMAL, true, view, 1.0, 0.0, ao);
    let color = haze(lit, in.clip, view);
    return vec4<f32>(color * in.alpha, in.alpha);
}
