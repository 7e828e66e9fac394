//! The cull pass's selection on the CPU, exactly as `shaders/cull.wgsl` and
//! the rules it shares in `shaders/select.wgsl` (each function names its WGSL
//! twin): which batches and trees a view draws, with which representation,
//! how far thinning and the canopy cross-fade reach. The streamer uses the
//! canopy's share to fetch only the prefix a view draws; tests compare the GPU's
//! draw items with [`cpu_select`].

use glam::{Vec3, Vec4};

use super::shared::{GpuSpecies, Repr, ViewUniform, REPR_COUNT};
use crate::format::tile::{CrownRange, GpuBatch, PackedInstance, BATCH_CROWN_ASPECT};

/// One draw item as the GPU writes it: (instance index in the pool, batch | side | fade).
pub type DrawItem = (u32, u32);

/// Decodes an item's `y` word into (batch, side, fade byte).
#[must_use]
pub fn unpack_item_y(y: u32) -> (u32, u32, u32) {
    (y & 0x7f_ffff, (y >> 23) & 1, y >> 24)
}

fn pack_item_y(batch: u32, side: u32, fade: f32) -> u32 {
    let f = (fade.clamp(0.0, 1.0) * 255.0 + 0.5) as u32;
    (batch & 0x7f_ffff) | (side << 23) | (f << 24)
}

fn rotate_z(v: Vec3, yaw: f32) -> Vec3 {
    let (s, c) = yaw.sin_cos();
    Vec3::new(c * v.x - s * v.y, s * v.x + c * v.y, v.z)
}

fn eye_relative(origin: Vec3, offset: Vec3, view: &ViewUniform) -> Vec3 {
    let hi = Vec4::from(view.eye_hi).truncate();
    let lo = Vec4::from(view.eye_lo).truncate();
    ((origin - hi) - lo) + offset
}

fn sphere_visible(c: Vec3, r: f32, view: &ViewUniform) -> bool {
    view.frustum.iter().all(|p| Vec3::new(p[0], p[1], p[2]).dot(c) + p[3] >= -r)
}

fn box_visible(c: Vec3, h: Vec3, view: &ViewUniform) -> bool {
    view.frustum.iter().all(|p| {
        let n = Vec3::new(p[0], p[1], p[2]);
        n.dot(c) + p[3] + n.abs().dot(h) >= 0.0
    })
}

/// Per-slot selection result: `slots[species * REPR_COUNT + repr]` lists the draw items.
/// Also the batches that passed the batch test.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Selection {
    /// Draw items per slot (order unspecified on the GPU: compare as sets).
    pub slots: Vec<Vec<DrawItem>>,
    /// Indices of visible batches.
    pub visible_batches: Vec<u32>,
    /// Items dropped because their segment was full.
    pub dropped: u32,
}

/// The selection of `shaders/cull.wgsl`, on the CPU. `batches` are pool batches
/// (instance offsets into `instances`); `view` is the frame's uniform.
#[must_use]
pub fn cpu_select(
    view: &ViewUniform,
    batches: &[GpuBatch],
    instances: &[PackedInstance],
    species: &[GpuSpecies],
) -> Selection {
    cpu_select_styled(view, batches, instances, species, |_| false)
}

/// How much bigger a thinned batch's kept trees are drawn: (n / kept)^this.
/// Must match `THIN_BOOST_EXPONENT` in `shaders/select.wgsl`.
const THIN_BOOST_EXPONENT: f32 = 0.35;

/// As [`cpu_select`], leaving out the pool instances `hidden` names (the
/// trees a style's filter hides: `crate::scene::style::STYLE_HIDDEN` in
/// their style byte, which the cull shader reads).
#[must_use]
pub fn cpu_select_styled(
    view: &ViewUniform,
    batches: &[GpuBatch],
    instances: &[PackedInstance],
    species: &[GpuSpecies],
    hidden: impl Fn(u32) -> bool,
) -> Selection {
    cpu_select_at(view, batches, instances, species, false, |i| (!hidden(i)).then_some(1.0))
}

/// As [`cpu_select_styled`], at a date (`dated`: the batches flagged
/// [`crate::format::tile::BATCH_DATED`] are drawn too) with each pool
/// instance's look: `None` hidden (filtered out, or not standing then), else
/// the scale it is drawn at over its own (its growth byte's,
/// [`crate::format::timeline::growth_of_byte`]). As `cull_instances` in
/// `shaders/cull.wgsl` with `STYLE_DATED`.
#[must_use]
pub fn cpu_select_at(
    view: &ViewUniform,
    batches: &[GpuBatch],
    instances: &[PackedInstance],
    species: &[GpuSpecies],
    dated: bool,
    look: impl Fn(u32) -> Option<f32>,
) -> Selection {
    let species_count = view.params[3] as usize;
    let mut sel = Selection { slots: vec![Vec::new(); species_count * REPR_COUNT as usize], ..Default::default() };
    for (i, b) in batches.iter().enumerate().take(view.params[1] as usize) {
        if b.instance_count == 0 || b.species as usize >= species_count {
            continue;
        }
        if !dated && b.flags & crate::format::tile::BATCH_DATED != 0 {
            continue;
        }
        let center = eye_relative(Vec3::from(b.center_m), Vec3::ZERO, view);
        let half = Vec3::from(b.half_extent_m);
        let batch_culling = view.lod[3] < 0.5;
        // A thinned batch draws its kept trees bigger (`coverage_boost`): its bounds grow as much.
        let (kept, boost, all) = thinning(b, view);
        let boosted = if kept < b.whole_count() as f32 { boost.powf(THIN_BOOST_EXPONENT) } else { 1.0 };
        let grow = (boosted - 1.0) * b.max_height_m;
        if batch_culling
            && (!sphere_visible(center, b.radius_m + grow, view)
                || !box_visible(center, half + Vec3::splat(grow), view))
        {
            continue;
        }
        if batch_culling && (center.abs() - half).max(Vec3::ZERO).length() > view.lod[1] {
            continue;
        }
        let s = &species[b.species as usize];
        if s.slot_cap.iter().sum::<u32>() == 0 {
            continue;
        }
        sel.visible_batches.push(i as u32);
        let thinned = boost > 1.0 && s.slot_cap[Repr::Billboard as usize] > 0;
        // The trees the view keeps (the canopy cross-fade takes its share of these), and of them those held.
        let intended = if thinned { all.ceil() as u32 } else { b.whole_count() };
        let count = intended.min(b.instance_count);
        for k in 0..count {
            let index = b.instance_offset + k;
            let Some(growth) = look(index) else { continue };
            let packed = instances[index as usize];
            let mut d = decode_eye_relative(packed, b, view);
            d.2 *= growth;
            // As `tree_scaled` in WGSL: xy · (scale · aspect), z · scale.
            let sa = d.2 * d.3;
            let c = d.0 + rotate_z(Vec3::new(s.sphere[0] * sa, s.sphere[1] * sa, s.sphere[2] * d.2), d.1);
            // A thinned batch's kept trees are drawn bigger (`coverage_boost`): so are their bounds.
            let grown = if thinned && kept < b.whole_count() as f32 { boost.powf(THIN_BOOST_EXPONENT) } else { 1.0 };
            let r = s.sphere[3] * d.2 * d.3.max(1.0) * grown;
            let dist = c.length().max(1e-3);
            if view.lod[3] < 1.5 && (!sphere_visible(c, r, view) || dist - r > view.lod[1]) {
                continue;
            }
            let px_per_m = view.lod[0] / if view.viewport[3] > 0.5 { 1.0 } else { dist };
            let h_px = s.select[0] * d.2 * px_per_m;
            // The canopy's share by the batch's tallest tree at this distance (as in WGSL).
            if canopy_drops(b.max_height_m * px_per_m, k, intended, view) {
                continue;
            }
            if thinned {
                let slot = (b.species * REPR_COUNT + Repr::Billboard as u32) as usize;
                let fade = 1.0 - (kept - k as f32).clamp(0.0, 1.0);
                if (sel.slots[slot].len() as u32) < s.slot_cap[Repr::Billboard as usize] {
                    sel.slots[slot].push((index, pack_item_y(i as u32, 0, fade)));
                } else {
                    sel.dropped += 1;
                }
                continue;
            }
            select(&mut sel, view, s, b.species, h_px, index, i as u32);
        }
    }
    sel
}

/// How much of a tree of `h_px` projected pixels the canopy stands in for,
/// exactly as `canopy_weight` in `shaders/select.wgsl`.
#[must_use]
pub fn canopy_weight(h_px: f32, view: &ViewUniform) -> f32 {
    let [lo, hi, _, _] = view.canopy;
    if lo <= 0.0 || view.viewport[3] > 0.5 {
        return 0.0;
    }
    ((hi - h_px) / (hi - lo).max(1e-3)).clamp(0.0, 1.0)
}

/// Whether the canopy stands in for tree `i` of the `count` the cull
/// considers of its batch (`h_px`: the batch's tallest tree projected at tree
/// i's distance) — the tail of the density order: kept while
/// `i + ½ < count · (1 − w(h))` — exactly as `canopy_drops` in
/// `shaders/select.wgsl`.
#[must_use]
pub fn canopy_drops(h_px: f32, i: u32, count: u32, view: &ViewUniform) -> bool {
    let [lo, hi, _, _] = view.canopy;
    if lo <= 0.0 || view.viewport[3] > 0.5 {
        return false;
    }
    ((count - i) as f32 - 0.5) * (hi - lo).max(1e-3) <= count as f32 * (hi - h_px)
}

/// The trees of a batch's first `count` that the canopy cross-fade can keep
/// when its tallest tree projects to `h_px` (at most): the prefix a view
/// needs (`canopy_drops` keeps tree `i` only while `i + ½ < count · (1 − w)`).
#[must_use]
pub fn canopy_keeps(h_px: f32, count: u32, canopy: [f32; 2]) -> u32 {
    ((count as f32 * canopy_share(h_px, canopy)).ceil() as u32).min(count)
}

/// The share `1 − w(h)` of the trees of `h_px` projected pixels that the
/// canopy cross-fade keeps (band `canopy`, px).
#[must_use]
pub fn canopy_share(h_px: f32, canopy: [f32; 2]) -> f32 {
    let [lo, hi] = canopy;
    if lo <= 0.0 {
        return 1.0;
    }
    ((h_px - lo) / (hi - lo).max(1e-3)).clamp(0.0, 1.0)
}

/// Prefix thinning of a batch, exactly as `thinning` in `shaders/select.wgsl`:
/// (trees kept, fractional; n / kept, 1 when not thinned; trees kept were the
/// whole batch held, fractional: n when not thinned).
#[must_use]
pub fn thinning(b: &GpuBatch, view: &ViewUniform) -> (f32, f32, f32) {
    let n = b.whole_count() as f32;
    let held = (b.instance_count as f32).max(1.0);
    let t = view.viewport[2];
    if b.flags & crate::format::tile::BATCH_DENSITY_ORDERED == 0 || t <= 0.0 || view.lod[3] > 0.5 {
        return (held, n / held, n);
    }
    let center = eye_relative(Vec3::from(b.center_m), Vec3::ZERO, view);
    let d = (center.abs() - Vec3::from(b.half_extent_m)).max(Vec3::ZERO).length().max(1e-3);
    let h = b.max_height_m * view.lod[0] / d;
    if h >= t {
        return (held, n / held, n);
    }
    let f = ((h * h) / (t * t)).clamp(THIN_MIN_FRACTION, 1.0);
    let all = (n * f).max(1.0);
    let kept = all.min(held);
    (kept, n / kept, all)
}

/// Fewest trees a thinned batch keeps, as a fraction (`THIN_MIN_FRACTION` in WGSL).
pub const THIN_MIN_FRACTION: f32 = 1.0 / 64.0;

/// (eye-relative position, yaw, scale, crown aspect) of an instance, exactly as `unpack_instance` in WGSL.
fn decode_eye_relative(p: PackedInstance, b: &GpuBatch, view: &ViewUniform) -> (Vec3, f32, f32, f32) {
    let x = (p.xy & 0xffff) as f32;
    let y = (p.xy >> 16) as f32;
    let z = (p.zysv & 0x7ff) as f32;
    let yaw = ((p.zysv >> 11) & 0xff) as f32 * (std::f32::consts::TAU / 256.0);
    let scale = b.scale_min * (((p.zysv >> 19) & 0xff) as f32 * b.scale_log2_step).exp2();
    let pos = eye_relative(Vec3::from(b.origin_m), Vec3::new(x * b.xy_step_m, y * b.xy_step_m, z * b.z_step_m), view);
    let aspect = if b.flags & BATCH_CROWN_ASPECT != 0 { CrownRange::unpack(b.crown).aspect(p.zysv >> 27) } else { 1.0 };
    (pos, yaw, scale, aspect)
}

fn select(sel: &mut Selection, view: &ViewUniform, s: &GpuSpecies, species: u32, h_px: f32, instance: u32, batch: u32) {
    let ready: Vec<(Repr, f32)> =
        Repr::ALL.into_iter().filter(|r| s.slot_cap[*r as usize] > 0).map(|r| (r, s.lower_px[r as usize])).collect();
    let mut ready = ready;
    let n = ready.len();
    if n == 0 {
        return;
    }
    ready[n - 1].1 = 0.0;
    let band = view.lod[2];
    let emit = |repr: Repr, side: u32, fade: f32, sel: &mut Selection| {
        let slot = (species * REPR_COUNT + repr as u32) as usize;
        if (sel.slots[slot].len() as u32) < s.slot_cap[repr as usize] {
            sel.slots[slot].push((instance, pack_item_y(batch, side, fade)));
        } else {
            sel.dropped += 1;
        }
    };
    for k in 0..n {
        let t = ready[k].1;
        if k + 1 < n && h_px < t * (1.0 + band) && h_px >= t * (1.0 - band) {
            let fade = (t * (1.0 + band) - h_px) / (2.0 * band * t);
            emit(ready[k].0, 0, fade, sel);
            emit(ready[k + 1].0, 1, fade, sel);
            return;
        }
        let hi = if k + 1 < n { band } else { 0.0 };
        if h_px >= t * (1.0 + hi) {
            emit(ready[k].0, 0, 0.0, sel);
            return;
        }
    }
}
