// Light: one model for every representation (sun, sky hemisphere, haze, the
// trees' own and the canopy's occlusion), the per-tree tint and the LoD debug
// colours. Needs layout.wgsl.

// One lighting model for every representation, so a tree keeps its colour when
// its LoD changes. Leaves also pass some light through (wrap term).
// Sky light: a hemisphere instead of a flat ambient term. Surfaces facing up
// see the sky (a little brighter and bluer than `view.ambient`), surfaces
// facing down the light the ground bounces back (darker, warmer), so the
// undersides of crowns and the shaded sides of trunks read. Leaves (thin,
// scattering, normals only roughly meaningful) lean half as far either way.
const SKY_TINT: vec3<f32> = vec3<f32>(1.1, 1.12, 1.18);
const GROUND_BOUNCE: vec3<f32> = vec3<f32>(0.62, 0.58, 0.5);

fn sky_light(n: vec3<f32>, is_leaf: bool, view: View) -> vec3<f32> {
    if light_on(view, LIGHT_SKY_LIGHT) {
        // The sky's own light (src/render/sky_light.rs); a leaf sees the sky
        // on both its sides, the far side's through it.
        if is_leaf {
            let t = leaf_share(view);
            return (1.0 - t) * sky_sh(n, view) + t * sky_sh(-n, view);
        }
        return sky_sh(n, view);
    }
    var up = 0.5 + 0.5 * clamp(n.z, -1.0, 1.0);
    if is_leaf {
        up = 0.5 + 0.25 * clamp(n.z, -1.0, 1.0);
    }
    return view.ambient.rgb * mix(GROUND_BOUNCE, SKY_TINT, up);
}

fn light_on(view: View, part: u32) -> bool {
    return (view.sky.parts.x & part) != 0u;
}

// The share of a leaf's light that comes from its far side: the tracer's
// leaf (reflecting 1 - t of its albedo, transmitting t) with transmission
// on, else the old wrap term's quarter.
fn leaf_share(view: View) -> f32 {
    return select(0.25, view.sky.sun.w, light_on(view, LIGHT_TRANSMISSION));
}

// The sky's irradiance over pi on a surface facing n (`sh_irradiance`).
fn sky_sh(n: vec3<f32>, view: View) -> vec3<f32> {
    return sh_irradiance(n, view.sky.sh);
}

// The clear sky's radiance towards the unit direction d (render units,
// linear sRGB; at and below the horizon, the horizon's). Twin: `SkyLight::sky`.
fn sky_radiance(d: vec3<f32>, view: View) -> vec3<f32> {
    return preetham_radiance(d, view.sky.sun.xyz, view.sky.zenith, view.sky.perez);
}

// Aerial perspective: what lies `rel` from the eye, seen through the air —
// dimmed by its transmittance and veiled by the light it scatters towards
// the eye (`air_light_dir`), so far ground fades into the horizon's colour
// at every sun position (sky_model.wgsl).
fn aerial(color: vec3<f32>, rel: vec3<f32>, view: View) -> vec3<f32> {
    let t = air_transmittance(rel, view.eye_hi.z + view.eye_lo.z, view.sky.rayleigh, view.sky.mie);
    return color * t + air_light(rel, view.sky.air) * (1.0 - t);
}

// Aerial perspective: light scattered by the air between the eye and a
// surface veils it towards the horizon's colour, more with distance and less
// high up (density falling by e every HAZE_HEIGHT_M above the scene origin).
// Visibility (3/β) about 50 km at the ground (a clear day). Not in the LoD
// debug colours.
const HAZE_PER_M: f32 = 1.0 / 16000.0;
const HAZE_HEIGHT_M: f32 = 1500.0;
// The sky's horizon colour (shaders/sky.wgsl): far things fade into it.
const HAZE_COLOR: vec3<f32> = vec3<f32>(0.62, 0.74, 0.86);

// How bright the sky is relative to day (the ambient light's luminance
// against the default's): the sky and the haze darken at dusk.
fn sky_scale(view: View) -> f32 {
    return clamp(dot(view.ambient.rgb, vec3<f32>(0.2126, 0.7152, 0.0722)) / 0.4573, 0.15, 1.5);
}

// `color` seen through the air at `rel` (metres from the eye, world axes).
fn haze_at(color: vec3<f32>, rel: vec3<f32>, view: View) -> vec3<f32> {
    if view.params.z == 1u {
        return color;
    }
    if light_on(view, LIGHT_AERIAL) {
        return aerial(color, rel, view);
    }
    let eye_z = view.eye_hi.z + view.eye_lo.z;
    let h = max(eye_z + 0.5 * rel.z, 0.0);
    let f = 1.0 - exp(-length(rel) * HAZE_PER_M * exp(-h / HAZE_HEIGHT_M));
    return mix(color, HAZE_COLOR * sky_scale(view), f);
}

// `color` of the fragment at `frag` (@builtin(position): pixel and depth),
// its distance recovered through the inverse projection.
fn haze(color: vec3<f32>, frag: vec4<f32>, view: View) -> vec3<f32> {
    return haze_at(color, frag_rel(frag, view), view);
}

// Eye-relative position of the fragment at `frag` (@builtin(position): pixel
// and depth), through the inverse projection.
fn frag_rel(frag: vec4<f32>, view: View) -> vec3<f32> {
    let ndc = vec2<f32>(frag.x / view.viewport.x * 2.0 - 1.0, 1.0 - frag.y / view.viewport.y * 2.0);
    let p = view.eye_from_clip * vec4<f32>(ndc, frag.z, 1.0);
    return p.xyz / p.w;
}

// `sun` is the fraction of the sun that reaches the surface (shadows, 1 lit);
// `occlusion` the fraction of the sky its surroundings hide (`canopy_occlusion`).
fn shade(albedo: vec3<f32>, n: vec3<f32>, is_leaf: bool, view: View, sun: f32, occlusion: f32, ao: f32) -> vec3<f32> {
    let ndl = dot(n, view.sun_dir.xyz);
    var diffuse = max(ndl, 0.0);
    if is_leaf {
        // Reflected on the lit side, transmitted from the far one; the wrap
        // term (transmission off) reflects all and adds a quarter of |n.l|.
        let t = leaf_share(view);
        diffuse = select(max(ndl, 0.0) + t * max(-ndl, 0.0), (1.0 - t) * max(ndl, 0.0) + t * max(-ndl, 0.0), light_on(view, LIGHT_TRANSMISSION));
    }
    let sky = sky_light(n, is_leaf, view) * sky_visibility(albedo, occlusion, ao, view);
    return albedo * (sky + view.sun_color.rgb * (diffuse * sun));
}

// The share of the sky a surface sees: the forest's (`occlusion`) and its
// own tree's (`ao`) occlusion. With the sky's light on, the light that the
// occluders (leaves, wood, of about the surface's albedo) scatter on is added
// back: Jimenez et al. 2016 ("Practical Real-Time Strategies for Accurate
// Indirect Occlusion", §5, eq. 10), the fit of multi-bounce occlusion
// to a visibility and an albedo.
fn sky_visibility(albedo: vec3<f32>, occlusion: f32, ao: f32, view: View) -> vec3<f32> {
    let v = (1.0 - CANOPY_SKY_OCCLUSION * occlusion) * ao;
    if !light_on(view, LIGHT_SKY_LIGHT) {
        return vec3<f32>(v);
    }
    let a = 2.0404 * albedo - 0.3324;
    let b = -4.7951 * albedo + 0.6417;
    let c = 2.7552 * albedo + 0.6903;
    return max(vec3<f32>(v), ((a * v + b) * v + c) * v);
}

// `shade` for a pre-filtered surface (a billboard's or an impostor's texel
// averages many leaves): `m` is the mean of the unit normals it covers, whose
// length r (≤ 1) says how much they agree. Shading the normalised mean lights
// a spread of leaves as one leaf turned towards it (a far crown read 5–15 %
// off its leaves); the mean of the shading is wanted. The sky term and the
// signed part of the sun's are linear in the normal, so the mean normal gives
// them exactly. For the mean |n·l|, the normals are taken as spread evenly in
// a cone about the mean (r = (1 + cos α) / 2): from |n̂·l| for one direction
// (r = 1) to ½ for a hemisphere (r = ½, as the leaves facing a viewer are),
// linearly in r.
fn shade_filtered(albedo: vec3<f32>, m: vec3<f32>, is_leaf: bool, view: View, sun: f32, occlusion: f32, ao: f32) -> vec3<f32> {
    let r = clamp(length(m), 1e-4, 1.0);
    let ndl = dot(m, view.sun_dir.xyz);
    let spread = clamp(2.0 * r - 1.0, 0.0, 1.0);
    let mean_abs = mix(0.5, abs(ndl) / r, spread);
    // max(x, 0) = (x + |x|) / 2; leaves: (1 - t) max(x, 0) + t max(-x, 0)
    // = (1 - 2t) x / 2 + |x| / 2 (transmission on), else max(x, 0) + t max(-x, 0).
    var diffuse = 0.5 * ndl + 0.5 * mean_abs;
    if is_leaf {
        let t = leaf_share(view);
        if light_on(view, LIGHT_TRANSMISSION) {
            diffuse = 0.5 * (1.0 - 2.0 * t) * ndl + 0.5 * mean_abs;
        } else {
            diffuse = 0.5 * (1.0 - t) * ndl + 0.5 * (1.0 + t) * mean_abs;
        }
    }
    let sky = sky_light(m, is_leaf, view) * sky_visibility(albedo, occlusion, ao, view);
    return albedo * (sky + view.sun_color.rgb * (max(diffuse, 0.0) * sun));
}

// A tree's own ambient occlusion, baked per species (bake-tool/src/pack/ao.rs): the
// sky a point inside its crown sees through the tree's leaves and wood, the
// same field sampled by every level of detail (mesh vertices, the billboard
// capture, ellipsoids, lines). `baked` is 1 where a pack has none; the view's
// ambient.w switches it on (1) or off (0).
fn own_ao(baked: f32, view: View) -> f32 {
    return mix(1.0, clamp(baked, 0.0, 1.0), view.ambient.w);
}

// Forest-scale occlusion, the same for every representation of a tree: in a
// dense stand the neighbours' crowns hide part of the sky and of the sun from
// a tree, the more the lower in its crown (its top stays open), so clearings,
// edges and thinned stands read lighter than closed canopy. The stand's
// density is its batch's (a tree's neighbours × crown area over the batch's
// footprint, crown radius a fifth of the tallest tree's height: a lone tree
// is open); within the shadow
// distance the shadow map replaces the sun term (`sun_visibility`).
const CANOPY_CROWN_RADIUS: f32 = 0.2;
// At full cover, the bottom of a crown loses this much of the sky and of the sun.
const CANOPY_SKY_OCCLUSION: f32 = 0.45;
const CANOPY_SUN_OCCLUSION: f32 = 0.6;

// Fraction of the ground around one of a batch's trees that its neighbours'
// crowns cover (0–1).
fn batch_cover(b: Batch) -> f32 {
    let footprint = 4.0 * max(b.half_extent_m.x * b.half_extent_m.y, 1.0);
    let r = CANOPY_CROWN_RADIUS * b.max_height_m;
    let neighbours = f32(max(b.instance_count, 1u) - 1u);
    return clamp(neighbours * 3.14159265 * r * r / footprint, 0.0, 1.0);
}

// Occlusion (0 open – 1 closed) of a point at `rel_height` (0 base – 1 top) of a tree of batch `b`.
fn canopy_occlusion(b: Batch, rel_height: f32) -> f32 {
    return batch_cover(b) * (1.0 - clamp(rel_height, 0.0, 1.0));
}

// The sun reaching a point with that occlusion where no shadow map covers it.
// (A tree's own ambient occlusion dims only its sky light: it is an average
// over the sky, and the shadow map, where it covers, knows which leaves the
// sun reaches — dimming the sun by it too would make shadows brighten trees.)
fn open_sun(occlusion: f32) -> f32 {
    return 1.0 - CANOPY_SUN_OCCLUSION * occlusion;
}

// Direction from `p` (eye-relative) towards the eye; in an orthographic view
// (a shadow cascade: the eye is the sun) the same for every point.
fn towards_eye(p: vec3<f32>, view: View) -> vec3<f32> {
    if view.viewport.w > 0.5 {
        let near = view.eye_from_clip * vec4<f32>(0.0, 0.0, 1.0, 1.0);
        let far = view.eye_from_clip * vec4<f32>(0.0, 0.0, 0.0, 1.0);
        return normalize(near.xyz / near.w - far.xyz / far.w);
    }
    return -p;
}

// Per-tree tint/variation (0–31) → a small brightness/hue change.
fn variation_tint(variation: f32) -> vec3<f32> {
    let v = variation / 31.0 - 0.5;
    return vec3<f32>(1.0 + 0.12 * v, 1.0 + 0.08 * v, 1.0 - 0.05 * v);
}

// Debug colour of a representation (Eichner 2024, Fig. 3.1 style).
fn repr_color(repr: u32) -> vec3<f32> {
    switch repr {
        case 0u: { return vec3<f32>(0.9, 0.2, 0.2); }
        case 1u: { return vec3<f32>(0.95, 0.8, 0.2); }
        case 2u: { return vec3<f32>(0.85, 0.3, 0.85); }
        case 3u: { return vec3<f32>(0.2, 0.85, 0.3); }
        case 4u: { return vec3<f32>(0.1, 0.65, 0.45); }
        case 5u: { return vec3<f32>(0.1, 0.5, 0.55); }
        case 6u: { return vec3<f32>(0.3, 0.4, 0.6); }
        default: { return vec3<f32>(0.2, 0.5, 0.95); }
    }
}
