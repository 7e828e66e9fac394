// The cull's selection rules that the draw passes share: prefix thinning and
// its coverage boost, the frustum test, draw items and their cross-fade, the
// canopy cross-fade. Twin: src/lod/select.rs (each function names its WGSL
// twin). Needs layout.wgsl and instance.wgsl.

// The batch's whole tree count (`instance_count` holds what is resident).
fn whole_count(b: Batch) -> u32 {
    return select(b.instance_count, b.flags >> PARTIAL_COUNT_SHIFT, (b.flags & BATCH_PARTIAL) != 0u);
}

// Prefix thinning (Eichner 2024, ch. 7). A density-ordered batch whose tallest tree
// is below view.viewport.z px tall at the batch's nearest point draws only its
// first n·f trees, f = (h / T)² (at least 1/64, and at least one tree): about as
// many trees per screen area as at T px. The billboard pass scales the kept
// trees up to keep the canopy's coverage (`coverage_boost`). A batch holding
// a prefix of its trees (BATCH_PARTIAL: the rest not fetched yet) keeps at
// most those, drawn as bigger as the trees they stand in for. Returns (trees
// kept, fractional; n / kept, 1 when not thinned; trees kept were the whole
// batch held, fractional: n when not thinned).
// Must match `thinning` in src/lod/select.rs.
fn thinning(b: Batch, view: View) -> vec3<f32> {
    let n = f32(whole_count(b));
    let held = max(f32(b.instance_count), 1.0);
    let t = view.viewport.z;
    if (b.flags & BATCH_DENSITY_ORDERED) == 0u || t <= 0.0 || view.lod.w > 0.5 {
        return vec3<f32>(held, n / held, n);
    }
    let center = eye_relative(b.center_m, vec3<f32>(0.0), view);
    let d = max(length(max(abs(center) - b.half_extent_m, vec3<f32>(0.0))), 1e-3);
    let h = b.max_height_m * view.lod.x / d;
    if h >= t {
        return vec3<f32>(held, n / held, n);
    }
    let f = clamp((h * h) / (t * t), THIN_MIN_FRACTION, 1.0);
    let wanted = max(n * f, 1.0);
    let kept = min(wanted, held);
    return vec3<f32>(kept, n / kept, wanted);
}

// Scale of a thinned batch's kept trees so the canopy covers about what all its
// trees did: s = (n / kept)^THIN_BOOST_EXPONENT. An exponent of ½ keeps the
// summed tree area; calibrated by the image metric it over-covers by 10–18 %
// (evenly spread kept trees overlap less than the whole batch, whose tiny
// billboards also alpha-test away part of their area) and no boost under-covers
// by up to 50 %; 0.35 keeps coverage within ±6 % (docs/BENCHMARKS.md).
const THIN_BOOST_EXPONENT: f32 = 0.35;

fn coverage_boost(thin: vec3<f32>, b: Batch) -> f32 {
    let n = f32(whole_count(b));
    if thin.x >= n {
        return 1.0;
    }
    return pow(n / thin.x, THIN_BOOST_EXPONENT);
}

// Sphere against the frustum (eye-relative).
fn sphere_visible(center: vec3<f32>, radius: f32, view: View) -> bool {
    for (var i = 0u; i < 6u; i++) {
        let p = view.frustum[i];
        if dot(p.xyz, center) + p.w < -radius {
            return false;
        }
    }
    return true;
}

// Draw item: x = instance index in the pool, y = batch index (bits 0–22),
// side (bit 23), fade (bits 24–31). The fade keeps the pixels whose dither is
// ≥ fade (side 0) or < fade (side 1): the two sides of a transition together
// cover every pixel exactly once.
fn pack_item_y(batch: u32, side: u32, fade: f32) -> u32 {
    let f = u32(clamp(fade, 0.0, 1.0) * 255.0 + 0.5);
    return (batch & 0x7fffffu) | (side << 23u) | (f << 24u);
}

// 8×8 ordered dither threshold in (0, 1), stable in screen space.
fn dither8(p: vec2<f32>) -> f32 {
    let x = u32(p.x) & 7u;
    let y = u32(p.y) & 7u;
    let v = x ^ y;
    let m = ((v & 1u) << 5u) | ((y & 1u) << 4u) | ((v & 2u) << 2u) | ((y & 2u) << 1u) | ((v & 4u) >> 1u) | ((y & 4u) >> 2u);
    return (f32(m) + 0.5) / 64.0;
}

// Whether an item's pixel survives its cross-fade mask. `seed` (the view's
// eye_lo.w: the progressive-refinement step, 0 otherwise) shifts the dither
// pattern, so accumulated steps blend the two sides instead of keeping one.
fn fade_keeps(item_y: u32, frag: vec2<f32>, seed: f32) -> bool {
    let fade = f32(item_y >> 24u) / 255.0;
    let side = (item_y >> 23u) & 1u;
    let s = u32(seed);
    let d = dither8(frag + vec2<f32>(f32(s & 7u), f32((s * 5u + (s >> 3u) * 3u) & 7u)));
    return select(d >= fade, d < fade, side == 1u);
}

// How much of a tree of `h_px` projected pixels the canopy raster stands in
// for: 1 below view.canopy.x, 0 above view.canopy.y, linear between; 0 without
// a canopy and in orthographic views (shadow cascades draw trees). Must match
// `canopy_weight` in src/lod/select.rs.
fn canopy_weight(h_px: f32, view: View) -> f32 {
    if view.canopy.x <= 0.0 || view.viewport.w > 0.5 {
        return 0.0;
    }
    return clamp((view.canopy.y - h_px) / max(view.canopy.y - view.canopy.x, 1e-3), 0.0, 1.0);
}

// Whether the canopy stands in for tree `i` of the `count` the cull considers
// of its batch (it is not drawn): a share `canopy_weight(h)` of the batch's
// trees, with `h` its tallest tree projected at tree i's distance, taken from
// the tail of the batch's density order — tree i is kept while
// i + ½ < count · (1 − w(h)), count · (1 − w) trees rounded — so a batch needs
// only its first count · (1 − w(h)) trees at its nearest point, and the
// stream fetches no more. Written as
// (count − i − ½) · (hi − lo) ≤ count · (hi − h) with only multiplications
// and subtractions, which are exactly rounded on every GPU, so the CPU oracle
// agrees bit for bit. Must match `canopy_drops` in src/lod/select.rs.
fn canopy_drops(h_px: f32, i: u32, count: u32, view: View) -> bool {
    if view.canopy.x <= 0.0 || view.viewport.w > 0.5 {
        return false;
    }
    return (f32(count - i) - 0.5) * max(view.canopy.y - view.canopy.x, 1e-3) <= f32(count) * (view.canopy.y - h_px);
}
