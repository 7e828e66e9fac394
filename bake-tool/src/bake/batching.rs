//! Grouped batches and tiles (Eichner 2024, §3.4).
//!
//! Trees are grouped per species into square grid cells by spatial hashing
//! (only occupied cells exist); each group is a batch with bounds for culling
//! and instances quantised relative to the batch origin (the cell corner).
//! Batches whose trees span more height than 11 bits of 2 cm steps are split
//! into height bands, so the 1 cm position error bound always holds.
//! Cells are grouped into tiles of `tile_cells`² cells, one file each.

use glam::DVec3;
use rayon::prelude::*;
use sylva::format::tile::{
    CrownRange, GpuBatch, PackedInstance, Tile, BATCH_CROWN_ASPECT, BATCH_DATED, BATCH_DENSITY_ORDERED, MAX_XY_STEP_M,
    MAX_Z_STEP_M, SCALE_BITS, YAW_BITS, Z_BITS,
};

/// One tree in scene coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SceneTree {
    /// Trunk base, metres relative to the scene origin.
    pub pos: DVec3,
    /// Species index.
    pub species: u32,
    /// Scale of the species model (its height over the model's).
    pub scale: f32,
    /// Horizontal over vertical scale: the crown width relative to the model's
    /// at this height (1: the model's own proportions).
    pub aspect: f32,
    /// Yaw in radians.
    pub yaw_rad: f32,
    /// Tint/variation 0–31.
    pub variation: u8,
    /// Tree id (see `docs/FORMAT.md`).
    pub id: u64,
    /// 1-based input row, for the attribute sidecars (0: none, e.g. the demo).
    pub row: u32,
    /// Not standing at the scene's latest date: in batches of its own,
    /// flagged `BATCH_DATED` (drawn only at a date).
    pub dated: bool,
}

/// A species model's extent at scale 1, for batch bounds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeciesShape {
    /// Largest horizontal distance of the model from its trunk axis.
    pub radius_xy: f32,
    /// Lowest model z.
    pub z_min: f32,
    /// Highest model z.
    pub z_max: f32,
}

/// Largest cell size (metres) whose 16-bit quantisation keeps the 1 cm bound.
pub const MAX_CELL_SIZE_M: u32 = (MAX_XY_STEP_M * 65535.0) as u32;
/// Height span of one batch: 2^11 − 1 steps of `MAX_Z_STEP_M` (the split keeps 2 cm
/// of it for rounding the batch origin down to whole centimetres).
pub const Z_BAND_M: f64 = ((1 << Z_BITS) - 1) as f64 * MAX_Z_STEP_M as f64;

/// A tile and the ids of its instances (same order).
pub struct BuiltTile {
    /// The tile.
    pub tile: Tile,
    /// Tree ids, one per instance.
    pub ids: Vec<u64>,
    /// Input rows (1-based; 0: none), one per instance, for the attributes.
    pub rows: Vec<u32>,
    /// Bounds of all trees, relative to the origin (min, max).
    pub bounds: ([f32; 3], [f32; 3]),
}

/// Picks a cell size so an occupied cell holds about `target` trees of all species:
/// estimate the density from occupied 64 m cells, then round to a power of two in 16–512 m.
pub fn default_cell_size(trees: &[SceneTree], target: f64) -> u32 {
    let mut cells = std::collections::HashSet::new();
    for t in trees {
        cells.insert(cell64(t.pos));
    }
    cell_size_for(trees.len() as u64, cells.len() as u64, target)
}

/// The 64 m cell of a position (the density estimate's grid).
#[must_use]
pub fn cell64(pos: DVec3) -> (i64, i64) {
    ((pos.x / 64.0).floor() as i64, (pos.y / 64.0).floor() as i64)
}

/// [`default_cell_size`] from counts: `trees` in `cells` occupied 64 m cells.
#[must_use]
pub fn cell_size_for(trees: u64, cells: u64, target: f64) -> u32 {
    if trees == 0 || cells == 0 {
        return 64;
    }
    let per_cell = trees as f64 / cells as f64;
    let size = 64.0 * (target / per_cell).sqrt();
    let pow = size.log2().round().clamp(4.0, 9.0);
    2f64.powf(pow) as u32
}

/// The tile (column, row) holding a tree at `pos` (metres from the origin):
/// the same rule [`build_tiles`] groups by.
#[must_use]
pub fn tile_of(pos: DVec3, cell_size_m: u32, tile_cells: u32) -> (i64, i64) {
    let cell = f64::from(cell_size_m);
    let tc = i64::from(tile_cells);
    (((pos.x / cell).floor() as i64).div_euclid(tc), ((pos.y / cell).floor() as i64).div_euclid(tc))
}

/// The shard (of `count`) that bakes tile `(x, y)`: a hash of the tile, so every
/// shard gets a similar share of any region.
#[must_use]
pub fn shard_of_tile(x: i64, y: i64, count: u32) -> u32 {
    tile_hash(x, y, 0x9E37_79B9_7F4A_7C15, 0xC2B2_AE3D_27D4_EB4F, count)
}

/// A well-mixed hash of tile `(x, y)` with its own multipliers, modulo `count`.
#[must_use]
pub fn tile_hash(x: i64, y: i64, mx: u64, my: u64, count: u32) -> u32 {
    let mut h = (x as u64).wrapping_mul(mx) ^ (y as u64).wrapping_mul(my);
    h ^= h >> 31;
    h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    h ^= h >> 29;
    (h % u64::from(count.max(1))) as u32
}

/// Builds the tiles of a scene. `cell_size_m` ≤ [`MAX_CELL_SIZE_M`].
///
/// # Panics
/// If `cell_size_m` is 0 or above [`MAX_CELL_SIZE_M`], or a tree's species has no shape.
pub fn build_tiles(trees: &[SceneTree], shapes: &[SpeciesShape], cell_size_m: u32, tile_cells: u32) -> Vec<BuiltTile> {
    assert!(cell_size_m > 0 && cell_size_m <= MAX_CELL_SIZE_M, "cell size {cell_size_m} m");
    assert!(tile_cells > 0);
    let cell = f64::from(cell_size_m);
    // Key: tile, cell, species, dated. Sorting keys with the tree index makes the order deterministic.
    let mut keyed: Vec<([i64; 6], usize)> = trees
        .par_iter()
        .enumerate()
        .map(|(i, t)| {
            let cx = (t.pos.x / cell).floor() as i64;
            let cy = (t.pos.y / cell).floor() as i64;
            let tc = i64::from(tile_cells);
            ([cy.div_euclid(tc), cx.div_euclid(tc), cy, cx, i64::from(t.species), i64::from(t.dated)], i)
        })
        .collect();
    keyed.par_sort_unstable_by(|a, b| {
        a.0.cmp(&b.0).then_with(|| trees[a.1].pos.z.total_cmp(&trees[b.1].pos.z)).then(a.1.cmp(&b.1))
    });
    // Split into tiles.
    let mut tile_ranges = Vec::new();
    let mut start = 0;
    for i in 1..=keyed.len() {
        if i == keyed.len() || keyed[i].0[..2] != keyed[start].0[..2] {
            tile_ranges.push(start..i);
            start = i;
        }
    }
    tile_ranges
        .into_par_iter()
        .map(|range| {
            let group = &keyed[range];
            let (ty, tx) = (group[0].0[0], group[0].0[1]);
            let mut batches = Vec::new();
            let mut instances = Vec::with_capacity(group.len());
            let mut ids = Vec::with_capacity(group.len());
            let mut rows = Vec::with_capacity(group.len());
            let mut b0 = 0;
            for i in 1..=group.len() {
                let split = i == group.len()
                    || group[i].0 != group[b0].0
                    || trees[group[i].1].pos.z - trees[group[b0].1].pos.z > Z_BAND_M - 0.02;
                if split {
                    let key = group[b0].0;
                    let members: Vec<&SceneTree> = group[b0..i].iter().map(|(_, t)| &trees[*t]).collect();
                    let corner = [key[3] as f64 * cell, key[2] as f64 * cell];
                    let members = density_order(members, corner, cell);
                    let batch = make_batch(
                        &members,
                        &shapes[key[4] as usize],
                        corner,
                        cell,
                        instances.len() as u32,
                        &mut instances,
                    );
                    ids.extend(members.iter().map(|t| t.id));
                    rows.extend(members.iter().map(|t| t.row));
                    batches.push(batch);
                    b0 = i;
                }
            }
            let mut lo = [f32::MAX; 3];
            let mut hi = [f32::MIN; 3];
            for b in &batches {
                for k in 0..3 {
                    lo[k] = lo[k].min(b.center_m[k] - b.half_extent_m[k]);
                    hi[k] = hi[k].max(b.center_m[k] + b.half_extent_m[k]);
                }
            }
            BuiltTile {
                tile: Tile { tile_x: tx as i32, tile_y: ty as i32, batches, instances },
                ids,
                rows,
                bounds: (lo, hi),
            }
        })
        .collect()
}

/// Orders the trees of a batch so that every prefix is an even thinning of the
/// whole (Eichner 2024, ch. 7): level by level, the not yet chosen tree nearest the
/// centre of each square of a grid twice as fine as the level before; squares
/// of one level in a scrambled order, so a prefix that ends inside a level is
/// still spread over the cell. Deterministic.
pub fn density_order(members: Vec<&SceneTree>, corner: [f64; 2], cell: f64) -> Vec<&SceneTree> {
    let n = members.len();
    if n <= 2 {
        return members;
    }
    if n <= FARTHEST_POINT_MAX {
        return farthest_point_order(members, corner, cell);
    }
    let mut taken = vec![false; n];
    let mut out = Vec::with_capacity(n);
    let mut best: std::collections::HashMap<(u32, u32), (f64, usize)> = std::collections::HashMap::new();
    let mut occupied: std::collections::HashSet<(u32, u32)> = std::collections::HashSet::new();
    for level in 0..24u32 {
        let g = 1u32 << level;
        let size = cell / f64::from(g);
        best.clear();
        occupied.clear();
        for (i, t) in members.iter().enumerate() {
            let fx = ((t.pos.x - corner[0]) / size).clamp(0.0, f64::from(g) - 1e-9);
            let fy = ((t.pos.y - corner[1]) / size).clamp(0.0, f64::from(g) - 1e-9);
            let (sx, sy) = (fx.floor() as u32, fy.floor() as u32);
            if taken[i] {
                occupied.insert((sx, sy));
                continue;
            }
            let d = (fx - f64::from(sx) - 0.5).powi(2) + (fy - f64::from(sy) - 0.5).powi(2);
            let e = best.entry((sx, sy)).or_insert((f64::MAX, usize::MAX));
            if (d, i) < *e {
                *e = (d, i);
            }
        }
        // Squares still empty first, so a prefix ending in this level fills gaps.
        let mut chosen: Vec<(bool, u64, u32, u32, usize)> = best
            .iter()
            .map(|(&(sx, sy), &(_, i))| (occupied.contains(&(sx, sy)), scramble(sx, sy, level), sx, sy, i))
            .collect();
        chosen.sort_unstable();
        for (_, _, _, _, i) in chosen {
            taken[i] = true;
            out.push(members[i]);
        }
        if out.len() == n {
            return out;
        }
    }
    // Trees closer than cell / 2^23 apart: the rest in their original order.
    out.extend(members.iter().enumerate().filter(|(i, _)| !taken[*i]).map(|(_, t)| *t));
    out
}

/// Batches up to this many trees are ordered by exact farthest-point sampling
/// (O(n²)); larger ones by the grid hierarchy (O(n log n)).
pub const FARTHEST_POINT_MAX: usize = 4096;

/// Farthest-point order: first the tree nearest the cell's centre, then always
/// the tree farthest from all chosen so far (ties: the earlier tree), distances
/// taken around the cell as a torus. Every prefix is then within a factor 2 of
/// the most even subset of its size (the k-centre bound).
fn farthest_point_order(members: Vec<&SceneTree>, corner: [f64; 2], cell: f64) -> Vec<&SceneTree> {
    let n = members.len();
    // Cell-local f32 coordinates: exact enough (cells are ≤ 655 m) and fast.
    let xs: Vec<f32> = members.iter().map(|t| (t.pos.x - corner[0]) as f32).collect();
    let ys: Vec<f32> = members.iter().map(|t| (t.pos.y - corner[1]) as f32).collect();
    let c = (cell * 0.5) as f32;
    let w = cell as f32;
    let mut dist: Vec<f32> = xs.iter().zip(&ys).map(|(x, y)| (x - c) * (x - c) + (y - c) * (y - c)).collect();
    let mut next = (0..n).min_by(|&a, &b| dist[a].total_cmp(&dist[b]).then(a.cmp(&b))).unwrap_or(0);
    dist.iter_mut().for_each(|d| *d = f32::INFINITY);
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        let p = next;
        out.push(members[p]);
        dist[p] = -1.0;
        let (px, py) = (xs[p], ys[p]);
        let mut far = -1.0f32;
        for i in 0..n {
            // On the torus of the cell: batches tile the plane, so a tree near one
            // edge is near the trees beyond it (and edges are not favoured).
            let dx = (xs[i] - px).abs();
            let dy = (ys[i] - py).abs();
            let (dx, dy) = (dx.min(w - dx), dy.min(w - dy));
            let d = dx * dx + dy * dy;
            if d < dist[i] {
                dist[i] = d;
            }
            if dist[i] > far {
                far = dist[i];
                next = i;
            }
        }
    }
    out
}

/// A hash of a grid square, for a scrambled but deterministic order.
fn scramble(x: u32, y: u32, level: u32) -> u64 {
    let mut h = u64::from(x) << 32 | u64::from(y);
    h ^= u64::from(level).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    h = (h ^ (h >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    h = (h ^ (h >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    h ^ (h >> 31)
}

/// Quantises `members` (one cell, one species, one height band) into a batch.
fn make_batch(
    members: &[&SceneTree],
    shape: &SpeciesShape,
    corner: [f64; 2],
    cell: f64,
    offset: u32,
    out: &mut Vec<PackedInstance>,
) -> GpuBatch {
    let z_min = members.iter().map(|t| t.pos.z).fold(f64::MAX, f64::min);
    // Round the z origin down to whole centimetres so it is stored exactly enough.
    let z0 = (z_min * 100.0).floor() / 100.0;
    let (s_min, s_max) = members.iter().fold((f32::MAX, f32::MIN), |(lo, hi), t| (lo.min(t.scale), hi.max(t.scale)));
    let scale_levels = ((1u32 << SCALE_BITS) - 1) as f32;
    let scale_log2_step = if s_max > s_min { (s_max / s_min).log2() / scale_levels } else { 0.0 };
    // Crown aspects only where a tree differs from its model's proportions;
    // other batches keep the variation bits (and the tile stays version 1).
    let (a_min, a_max) = members.iter().fold((f32::MAX, f32::MIN), |(lo, hi), t| (lo.min(t.aspect), hi.max(t.aspect)));
    let crown = (a_min != 1.0 || a_max != 1.0).then(|| CrownRange::covering(a_min, a_max));
    let mut batch = GpuBatch {
        origin_m: [corner[0] as f32, corner[1] as f32, z0 as f32],
        instance_offset: offset,
        center_m: [0.0; 3],
        radius_m: 0.0,
        half_extent_m: [0.0; 3],
        instance_count: members.len() as u32,
        species: members[0].species,
        xy_step_m: (cell / 65535.0) as f32,
        z_step_m: MAX_Z_STEP_M,
        scale_min: s_min,
        scale_log2_step,
        max_height_m: 0.0,
        flags: BATCH_DENSITY_ORDERED
            | if crown.is_some() { BATCH_CROWN_ASPECT } else { 0 }
            | if members[0].dated { BATCH_DATED } else { 0 },
        crown: crown.map_or(0, CrownRange::pack),
    };
    let xy_step = cell / 65535.0;
    let z_max_q = (1u32 << Z_BITS) - 1;
    let mut lo = [f32::MAX; 3];
    let mut hi = [f32::MIN; 3];
    for t in members {
        let qx = ((t.pos.x - corner[0]) / xy_step).round().clamp(0.0, 65535.0) as u16;
        let qy = ((t.pos.y - corner[1]) / xy_step).round().clamp(0.0, 65535.0) as u16;
        let qz = ((t.pos.z - z0) / f64::from(MAX_Z_STEP_M)).round().clamp(0.0, f64::from(z_max_q)) as u32;
        let turns = (t.yaw_rad / std::f32::consts::TAU).rem_euclid(1.0);
        let qyaw = ((turns * (1 << YAW_BITS) as f32).round() as u32) % (1 << YAW_BITS);
        let qs = if scale_log2_step > 0.0 {
            ((t.scale / s_min).log2() / scale_log2_step).round().clamp(0.0, scale_levels) as u32
        } else {
            0
        };
        let top = crown.map_or(u32::from(t.variation), |c| c.quantise(t.aspect));
        let packed = PackedInstance::new(qx, qy, qz, qyaw, qs, top);
        // Bounds from the decoded values: exactly what the GPU will draw.
        let d = packed.decode(&batch);
        let r = shape.radius_xy * d.scale * d.aspect;
        lo[0] = lo[0].min(d.position_m[0] - r);
        lo[1] = lo[1].min(d.position_m[1] - r);
        lo[2] = lo[2].min(d.position_m[2] + shape.z_min * d.scale);
        hi[0] = hi[0].max(d.position_m[0] + r);
        hi[1] = hi[1].max(d.position_m[1] + r);
        hi[2] = hi[2].max(d.position_m[2] + shape.z_max * d.scale);
        batch.max_height_m = batch.max_height_m.max((shape.z_max - shape.z_min) * d.scale);
        out.push(packed);
    }
    for k in 0..3 {
        batch.center_m[k] = (lo[k] + hi[k]) * 0.5;
        // Slack for f32 rounding of the centre: a relative hair plus two ulps of the
        // centre itself, which matter for batches far from the scene origin.
        let ulp = batch.center_m[k].abs() * f32::EPSILON;
        batch.half_extent_m[k] = (hi[k] - lo[k]) * 0.5 * 1.0001 + 1e-3 + 2.0 * ulp;
    }
    batch.radius_m = glam::Vec3::from(batch.half_extent_m).length();
    batch
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lcg(seed: &mut u64) -> f64 {
        *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (*seed >> 11) as f64 / (1u64 << 53) as f64
    }

    fn random_trees(n: usize, seed: u64) -> Vec<SceneTree> {
        let mut s = seed;
        (0..n)
            .map(|i| SceneTree {
                pos: DVec3::new(
                    lcg(&mut s) * 3000.0 - 1500.0,
                    lcg(&mut s) * 2000.0 - 700.0,
                    lcg(&mut s) * 120.0 - 20.0,
                ),
                species: (i % 3) as u32,
                scale: 0.2 + lcg(&mut s) as f32 * 1.5,
                // Species 0 keeps its model's proportions (no crown data).
                aspect: if i % 3 == 0 { 1.0 } else { 0.3 + lcg(&mut s) as f32 * 2.7 },
                yaw_rad: lcg(&mut s) as f32 * 7.0,
                variation: (lcg(&mut s) * 32.0) as u8,
                id: i as u64,
                row: 0,
                dated: false,
            })
            .collect()
    }

    /// Covering radius of a subset: the farthest any tree of `all` is from the
    /// subset's nearest tree (the largest gap a thinning leaves), around the cell
    /// as a torus (batches tile the plane), in units of the spacing of a
    /// perfectly even subset of that size, sqrt(area / k).
    fn covering_radius(subset: &[&SceneTree], all: &[&SceneTree], cell: f64) -> f64 {
        let r = all
            .iter()
            .map(|t| {
                subset
                    .iter()
                    .map(|s| {
                        let d = (s.pos - t.pos).truncate().abs();
                        d.x.min(cell - d.x).hypot(d.y.min(cell - d.y))
                    })
                    .fold(f64::MAX, f64::min)
            })
            .fold(0.0, f64::max);
        r / (cell * cell / subset.len() as f64).sqrt()
    }

    #[test]
    fn density_order_makes_every_prefix_an_even_thinning() {
        // Farthest-point order (up to FARTHEST_POINT_MAX trees), then the grid hierarchy.
        even_prefixes(3000, 0.9, 0.75);
        even_prefixes(FARTHEST_POINT_MAX as u64 + 1000, 1.2, 0.9);
    }

    fn even_prefixes(n: u64, most: f64, of_random: f64) {
        let cell = 128.0;
        let mut seed = 7;
        let trees: Vec<SceneTree> = (0..n)
            .map(|i| SceneTree {
                pos: DVec3::new(lcg(&mut seed) * cell, lcg(&mut seed) * cell, 0.0),
                species: 0,
                scale: 1.0,
                aspect: 1.0,
                yaw_rad: 0.0,
                variation: 0,
                id: i,
                row: 0,
                dated: false,
            })
            .collect();
        let members: Vec<&SceneTree> = trees.iter().collect();
        let ordered = density_order(members.clone(), [0.0, 0.0], cell);
        // A permutation, and the same again for the same input.
        let mut ids: Vec<u64> = ordered.iter().map(|t| t.id).collect();
        assert_eq!(ordered, density_order(members.clone(), [0.0, 0.0], cell));
        ids.sort_unstable();
        assert_eq!(ids, (0..n).collect::<Vec<u64>>());
        for k in [16, 50, 100, 300, 1000] {
            // The input order is random: a random thinning is the baseline.
            let random = covering_radius(&members[..k], &members, cell);
            let even = covering_radius(&ordered[..k], &members, cell);
            assert!(
                even < most && even < of_random * random,
                "prefix {k} of {n}: the largest gap is {even:.2} spacings (a random subset's: {random:.2})"
            );
        }
    }

    const SHAPES: [SpeciesShape; 3] = [
        SpeciesShape { radius_xy: 5.0, z_min: 0.0, z_max: 20.0 },
        SpeciesShape { radius_xy: 3.0, z_min: -0.5, z_max: 30.0 },
        SpeciesShape { radius_xy: 8.0, z_min: 0.0, z_max: 12.0 },
    ];

    #[test]
    fn every_tree_in_exactly_one_batch_within_bounds_and_error() {
        let trees = random_trees(20_000, 7);
        let tiles = build_tiles(&trees, &SHAPES, 128, 4);
        let mut seen = vec![0u32; trees.len()];
        for bt in &tiles {
            // Round trip through the file format too.
            let bytes = bt.tile.encode();
            let tile = Tile::decode("t", &bytes, 3).unwrap();
            assert_eq!(tile, bt.tile);
            for b in &tile.batches {
                let run = b.instance_offset as usize..(b.instance_offset + b.instance_count) as usize;
                for (inst, id) in tile.instances[run.clone()].iter().zip(&bt.ids[run]) {
                    let t = &trees[*id as usize];
                    seen[*id as usize] += 1;
                    assert_eq!(t.species, b.species);
                    let d = inst.decode(b);
                    let err =
                        DVec3::new(f64::from(d.position_m[0]), f64::from(d.position_m[1]), f64::from(d.position_m[2]))
                            - t.pos;
                    assert!(err.length() <= 0.01, "position error {err} m");
                    assert!((d.scale / t.scale - 1.0).abs() < 0.01, "scale {} vs {}", d.scale, t.scale);
                    // Crown aspects to half a quantisation step (a 10× range in a
                    // batch: 1/62 of log2(10), 3.8 %).
                    let half_step = f32::from(CrownRange::unpack(b.crown).log2_step_q) / 65536.0 / 2.0;
                    let err = (d.aspect / t.aspect).log2().abs();
                    assert!(err <= half_step + 1e-4 && err < 0.06, "aspect {} vs {}", d.aspect, t.aspect);
                    let shape = SHAPES[t.species as usize];
                    for k in 0..3 {
                        let top = if k == 2 {
                            d.position_m[2] + shape.z_max * d.scale
                        } else {
                            d.position_m[k] + shape.radius_xy * d.scale * d.aspect
                        };
                        assert!(top <= b.center_m[k] + b.half_extent_m[k], "tree outside its batch bounds");
                        assert!(d.position_m[k] >= b.center_m[k] - b.half_extent_m[k] - 1e-3);
                    }
                    let yaw_err = (d.yaw_rad - t.yaw_rad.rem_euclid(std::f32::consts::TAU)).abs();
                    assert!(yaw_err < 0.013 || (std::f32::consts::TAU - yaw_err) < 0.013, "yaw {yaw_err}");
                    if b.flags & BATCH_CROWN_ASPECT == 0 {
                        assert_eq!(d.variation, t.variation);
                        assert_eq!(t.aspect, 1.0, "a tree with a crown aspect in a batch without");
                    } else {
                        assert_eq!(u32::from(d.variation), sylva::format::tile::variation_of(inst.xy));
                    }
                }
                // The sphere contains the box.
                assert!(b.radius_m >= glam::Vec3::from(b.half_extent_m).length() - 1e-3);
            }
        }
        assert!(seen.iter().all(|&n| n == 1), "some tree is in no batch or in two");
        // Both kinds of batch were made: species 0 without crowns (written as
        // tile version 1 where it is alone, in the old layout), the others with.
        let all: Vec<&GpuBatch> = tiles.iter().flat_map(|t| &t.tile.batches).collect();
        assert!(all.iter().any(|b| b.species == 0 && b.flags & BATCH_CROWN_ASPECT == 0));
        assert!(all.iter().filter(|b| b.species != 0).all(|b| b.flags & BATCH_CROWN_ASPECT != 0));
        assert!(
            tiles
                .iter()
                .all(|t| t.tile.whole_version() == 2
                    && u16::from(t.tile.encode()[4]) == sylva::format::tile::TILE_VERSION)
        );
        let only_plain =
            build_tiles(&trees.iter().filter(|t| t.species == 0).copied().collect::<Vec<_>>(), &SHAPES, 128, 4);
        assert!(only_plain.iter().all(|t| t.tile.whole_version() == 1 && t.tile.encode_whole()[4] == 1));
    }

    #[test]
    fn cell_and_tile_edges_and_extreme_scales_keep_the_bounds() {
        // Trees exactly on, just below and just above cell and tile edges, far from
        // the origin (10^5 to 10^6 m), 0.5 m to 120 m tall (scales 0.025 to 6 of a
        // 20 m model) in the same cells.
        let cell = 64.0;
        let mut trees = Vec::new();
        for (i, base) in [0.0, 1.0e5, 1.0e6].into_iter().enumerate() {
            for k in -3i32..=3 {
                let edge = base + f64::from(k) * cell * 4.0; // a tile edge every 4 cells
                for (j, dx) in [-1e-9, 0.0, 1e-9, -0.004, 0.004, cell * 0.5].into_iter().enumerate() {
                    let id = trees.len();
                    trees.push(SceneTree {
                        pos: DVec3::new(edge + dx, edge - dx, (id % 7) as f64),
                        species: 0,
                        scale: if (id + j) % 2 == 0 { 0.025 } else { 6.0 },
                        aspect: 1.0,
                        yaw_rad: 0.0,
                        variation: (i * 7 + j) as u8 % 32,
                        id: id as u64,
                        row: 0,
                        dated: false,
                    });
                }
            }
        }
        let tiles = build_tiles(&trees, &SHAPES, cell as u32, 4);
        let mut seen = vec![0u32; trees.len()];
        for bt in &tiles {
            let tile = Tile::decode("t", &bt.tile.encode(), 3).unwrap();
            for b in &tile.batches {
                let run = b.instance_offset as usize..(b.instance_offset + b.instance_count) as usize;
                for (inst, id) in tile.instances[run.clone()].iter().zip(&bt.ids[run]) {
                    let t = &trees[*id as usize];
                    seen[*id as usize] += 1;
                    let d = inst.decode(b);
                    let p =
                        DVec3::new(f64::from(d.position_m[0]), f64::from(d.position_m[1]), f64::from(d.position_m[2]));
                    // f32 positions 10^6 m out are good to 6 cm; the quantisation itself to 1 cm.
                    let ulp = (t.pos.x.abs().max(1.0) as f32).to_bits();
                    let f32_step = f64::from(f32::from_bits(ulp + 1) - f32::from_bits(ulp));
                    let err = (p - t.pos).length();
                    assert!(err <= 0.01 + f32_step, "tree {id} at {:?}: position error {err} m", t.pos);
                    assert!((d.scale / t.scale - 1.0).abs() < 0.01, "scale {} vs {}", d.scale, t.scale);
                    let top = d.position_m[2] + SHAPES[0].z_max * d.scale;
                    assert!(top <= b.center_m[2] + b.half_extent_m[2] + 1e-3, "a 120 m tree pokes out of its batch");
                }
            }
        }
        assert!(seen.iter().all(|&n| n == 1), "a tree on an edge is in no batch or in two");
    }

    #[test]
    fn tall_height_ranges_split_into_bands() {
        let mut trees = random_trees(500, 3);
        for (i, t) in trees.iter_mut().enumerate() {
            t.pos = DVec3::new(10.0 + i as f64 * 0.01, 10.0, i as f64 * 0.5); // 250 m of height in one cell
            t.species = 0;
        }
        let tiles = build_tiles(&trees, &SHAPES, 64, 8);
        assert_eq!(tiles.len(), 1);
        assert!(tiles[0].tile.batches.len() >= 7, "{} batches", tiles[0].tile.batches.len());
    }

    #[test]
    fn build_is_deterministic() {
        let trees = random_trees(5000, 11);
        let a: Vec<Vec<u8>> = build_tiles(&trees, &SHAPES, 64, 8).iter().map(|t| t.tile.encode()).collect();
        let b: Vec<Vec<u8>> = build_tiles(&trees, &SHAPES, 64, 8).iter().map(|t| t.tile.encode()).collect();
        assert_eq!(a, b);
    }

    #[test]
    fn default_cell_size_follows_density() {
        let dense = random_trees(50_000, 1); // ~17 trees per 64 m cell
        let c = default_cell_size(&dense, 500.0);
        assert!((256..=512).contains(&c), "{c}");
    }
}
