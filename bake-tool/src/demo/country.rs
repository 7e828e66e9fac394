//! `sylva-bake demo --layout country`: a synthetic country for benchmarks of
//! far views — 10^8 trees and more, generated block by block and streamed into
//! the bucketed bake, so memory stays bounded whatever the count.
//!
//! The land is an irregular island (a warped radial falloff: bays, peninsulas,
//! offshore islets) with lakes, a coastal plain rising to hills and uplands,
//! and a patchwork of land cover: large forested regions, woods and parcels of
//! farmland in the lowlands (rectangular wood lots along a rotated field grid),
//! and within the woods stands of different ages, clumps and gaps. Spruce holds
//! the uplands, birch grows in patches, beech elsewhere. Its size follows the
//! tree count at about [`STAND_DENSITY_HA`] trees per hectare in closed stands
//! (10^8 trees: land about 100 km across).
//!
//! Trees are generated per square block of [`BLOCK_M`]: each block's count is
//! fixed first (its share of the whole, from the forest field sampled on a
//! coarse grid, distributed so the total is exact), then its trees are drawn by
//! rejection from the field with a generator seeded by the block, so the result
//! does not depend on the order or the thread that makes a block. One row of
//! blocks is in memory at a time (about 67 MB of trees at 10^8, growing with
//! the square root of the count).

use glam::DVec3;
use rayon::prelude::*;

use crate::bake::batching::SceneTree;
use crate::rng::{fbm, hash64, Rng};

/// Trees per hectare where the forest field is 1 (a closed, mature stand).
pub const STAND_DENSITY_HA: f64 = 500.0;
/// Side of a generation block (metres).
pub const BLOCK_M: f64 = 1024.0;
/// Probes per block side for the block's share of trees.
const PROBES: usize = 8;

/// The country: its size and every block's tree count.
pub struct Country {
    seed: u64,
    /// Half the side of the square holding the land (metres from the origin).
    pub half_m: f64,
    /// Blocks per side.
    blocks: usize,
    /// Mean forest field per block, row by row (south to north).
    means: Vec<f64>,
    /// The largest forest-field value among each block's probes.
    peaks: Vec<f32>,
    /// Trees per block.
    counts: Vec<u32>,
}

fn smoothstep(e0: f64, e1: f64, x: f64) -> f64 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Uniform in [0, 1) from a hash.
fn unit(h: u64) -> f64 {
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// What the land is at a point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Site {
    /// Ground height (metres above the origin; the sea at 0).
    pub z: f64,
    /// Sea or lake.
    pub water: bool,
    /// The forest field: trees per candidate in a closed stand (0–1).
    pub forest: f64,
    /// A farmland parcel's hash (0–1), where the land is not wooded.
    pub parcel: f64,
    /// How far inland (0 at the coast, 1 well inland).
    pub inland: f64,
}

impl Country {
    /// A country holding `trees` trees (≥ 1).
    ///
    /// # Errors
    /// The land drawn for this seed and size has no forest at all.
    pub fn new(trees: u64, seed: u64) -> anyhow::Result<Self> {
        // The square's share covered by the forest field, measured at a first
        // guess and the size corrected (it barely changes with size).
        let mut share = 0.17;
        let mut country = Self::sized(trees, seed, share);
        for _ in 0..2 {
            let measured = country.means.iter().sum::<f64>() / country.means.len() as f64;
            if measured <= 0.0 || (measured / share - 1.0).abs() < 0.05 {
                break;
            }
            share = measured;
            country = Self::sized(trees, seed, share);
        }
        if country.means.iter().sum::<f64>() <= 0.0 {
            anyhow::bail!(
                "the country drawn for seed {seed} and {trees} trees has no forest to put them in: try another --seed or more --trees"
            );
        }
        country.distribute(trees);
        Ok(country)
    }

    fn sized(trees: u64, seed: u64, share: f64) -> Self {
        let area_m2 = trees as f64 / STAND_DENSITY_HA * 10_000.0 / share;
        let blocks = ((area_m2.sqrt() / BLOCK_M).ceil() as usize).max(2);
        let half_m = blocks as f64 * BLOCK_M * 0.5;
        let mut c = Self { seed, half_m, blocks, means: Vec::new(), peaks: Vec::new(), counts: Vec::new() };
        let probes: Vec<(f64, f32)> = (0..blocks * blocks).into_par_iter().map(|b| c.probe(b)).collect();
        c.means = probes.iter().map(|p| p.0).collect();
        c.peaks = probes.iter().map(|p| p.1).collect();
        c
    }

    /// A block's south-west corner.
    fn corner(&self, b: usize) -> (f64, f64) {
        let (bx, by) = (b % self.blocks, b / self.blocks);
        (bx as f64 * BLOCK_M - self.half_m, by as f64 * BLOCK_M - self.half_m)
    }

    /// The block's mean and largest forest field over a grid of probes.
    fn probe(&self, b: usize) -> (f64, f32) {
        let (x0, y0) = self.corner(b);
        let step = BLOCK_M / PROBES as f64;
        let (mut sum, mut peak) = (0.0, 0.0f64);
        for j in 0..PROBES {
            for i in 0..PROBES {
                let f = self.site(x0 + (i as f64 + 0.5) * step, y0 + (j as f64 + 0.5) * step).forest;
                sum += f;
                peak = peak.max(f);
            }
        }
        (sum / (PROBES * PROBES) as f64, peak as f32)
    }

    /// Every block's count from its share of the field, largest remainders
    /// first, so the counts add up to `trees` exactly.
    fn distribute(&mut self, trees: u64) {
        let total: f64 = self.means.iter().sum();
        let mut counts = Vec::with_capacity(self.means.len());
        let mut rest: Vec<(f64, usize)> = Vec::new();
        let mut given = 0u64;
        for (b, m) in self.means.iter().enumerate() {
            let want = trees as f64 * m / total;
            let n = want.floor() as u64;
            given += n;
            counts.push(n as u32);
            rest.push((want - n as f64, b));
        }
        rest.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        for &(_, b) in rest.iter().cycle().take(trees.saturating_sub(given) as usize) {
            counts[b] += 1;
        }
        self.counts = counts;
    }

    /// Trees in all.
    #[cfg(test)]
    pub fn trees(&self) -> u64 {
        self.counts.iter().map(|&n| u64::from(n)).sum()
    }

    /// The square holding the land: `[min x, min y, max x, max y]` (metres).
    #[must_use]
    pub fn extent(&self) -> [f64; 4] {
        [-self.half_m, -self.half_m, self.half_m, self.half_m]
    }

    /// 64 m cells the forest fills, as if it were closed stands (for the
    /// batch cell size, like [`crate::bake::batching::default_cell_size`]).
    #[must_use]
    pub fn forest_cells64(&self) -> u64 {
        let area: f64 = self.means.iter().sum::<f64>() * BLOCK_M * BLOCK_M;
        (area / (64.0 * 64.0)).ceil().max(1.0) as u64
    }

    /// The land at `(x, y)` (metres from the origin).
    #[must_use]
    pub fn site(&self, x: f64, y: f64) -> Site {
        let s = self.seed.wrapping_mul(0x9E37_79B9);
        let h = self.half_m;
        // The coast: a radial falloff warped at two scales.
        let r = (x * x + y * y).sqrt() / (h * 0.82);
        let land = 1.0 - r * r
            + 1.3 * (fbm(s + 11, x, y, h * 0.5) - 0.5)
            + 0.6 * (fbm(s + 12, x, y, h * 0.12) - 0.5)
            + 0.12 * (fbm(s + 13, x, y, 3000.0) - 0.5);
        let inland = smoothstep(0.0, 0.5, land);
        // Hills and uplands inland, a plain along the coast.
        let hills = fbm(s + 14, x, y, h * 0.35);
        let ridges = 1.0 - (2.0 * fbm(s + 15, x, y, 7000.0) - 1.0).abs();
        let mut z = 1.0 + inland * (620.0 * hills.powi(3) + 140.0 * ridges * hills) + 12.0 * fbm(s + 16, x, y, 700.0);
        let lake = land > 0.08 && fbm(s + 17, x, y, 2200.0) > 0.72 && hills < 0.55;
        let water = land <= 0.0 || lake;
        if land <= 0.0 {
            z = -2.0;
        }
        // A regional field grid, rotated by region, of ~180 × 300 m parcels.
        let angle = 1.2 * fbm(s + 18, x, y, h * 0.5);
        let (c, sn) = (angle.cos(), angle.sin());
        let (u, v) = ((x * c + y * sn) / 180.0, (-x * sn + y * c) / 300.0);
        let parcel = unit(hash64(
            s ^ ((u.floor() as i64 as u64).wrapping_mul(0x1F1F_1F1F)
                ^ (v.floor() as i64 as u64).wrapping_mul(0x7A3D_5B11)),
        ));
        // Forested regions (more in the uplands), woods, and wood lots among the fields.
        let region = fbm(s + 19, x, y, h * 0.3) + z / 1500.0;
        let woods = fbm(s + 20, x, y, 1400.0);
        let wooded = smoothstep(0.5, 0.6, 0.6 * region + 0.4 * woods);
        let lot = if parcel < 0.06 + 0.3 * smoothstep(0.35, 0.6, region) { 1.0 } else { 0.0 };
        let cover = wooded.max(lot);
        // Within the woods: clumps and gaps, fewer trees on the high tops.
        let clump = fbm(s + 21, x, y, 60.0);
        let gaps = smoothstep(0.25, 0.4, fbm(s + 22, x, y, 250.0));
        let treeline = 1.0 - smoothstep(700.0, 820.0, z);
        let forest =
            if water { 0.0 } else { cover * (0.5 + 0.5 * clump) * gaps * treeline * smoothstep(0.0, 0.06, land) };
        Site { z, water, forest, parcel, inland }
    }

    /// The ground height at `(x, y)` (metres above the origin).
    #[must_use]
    pub fn ground(&self, x: f64, y: f64) -> f64 {
        self.site(x, y).z
    }

    /// The ground imagery at `(x, y)`: sea and lakes, beaches, farmland
    /// parcels of crops, pasture and bare soil, the floor of the woods, upland
    /// heath (sRGB 0–255, full coverage).
    #[must_use]
    pub fn colour(&self, x: f64, y: f64) -> [f32; 4] {
        let site = self.site(x, y);
        let mix = |a: [f64; 3], b: [f64; 3], t: f64| {
            [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t, a[2] + (b[2] - a[2]) * t]
        };
        let c = if site.water {
            let deep = smoothstep(0.0, 0.3, -site.inland + 0.05 * fbm(self.seed + 40, x, y, 500.0));
            mix([52.0, 74.0, 88.0], [30.0, 48.0, 66.0], deep)
        } else {
            const CROPS: [[f64; 3]; 5] = [
                [150.0, 160.0, 80.0],
                [188.0, 170.0, 110.0],
                [112.0, 138.0, 64.0],
                [136.0, 110.0, 82.0],
                [170.0, 176.0, 96.0],
            ];
            let field = CROPS[(site.parcel * 997.0) as usize % CROPS.len()];
            let floor = [70.0, 72.0, 44.0];
            let mut c = mix(field, floor, smoothstep(0.02, 0.2, site.forest));
            // Heath above the fields, sand at the coast.
            c = mix(c, [128.0, 116.0, 96.0], smoothstep(550.0, 800.0, site.z));
            c = mix([196.0, 184.0, 150.0], c, smoothstep(0.0, 0.04, site.inland));
            let v = 0.9 + 0.2 * fbm(self.seed + 41, x, y, 40.0);
            [c[0] * v, c[1] * v, c[2] * v]
        };
        [c[0] as f32, c[1] as f32, c[2] as f32, 1.0]
    }

    /// Blocks per side.
    #[must_use]
    pub fn blocks(&self) -> usize {
        self.blocks
    }

    /// The trees of block row `row` (south to north), in block order, ids
    /// continuing from `first_id`.
    #[must_use]
    pub fn row(&self, row: usize, first_id: u64) -> Vec<SceneTree> {
        let start = row * self.blocks;
        let blocks: Vec<Vec<SceneTree>> = (start..start + self.blocks).into_par_iter().map(|b| self.block(b)).collect();
        let mut trees = blocks.concat();
        for (k, t) in trees.iter_mut().enumerate() {
            t.id = first_id + k as u64;
        }
        trees
    }

    /// Trees in block row `row`.
    #[cfg(test)]
    pub fn row_trees(&self, row: usize) -> u64 {
        self.counts[row * self.blocks..(row + 1) * self.blocks].iter().map(|&n| u64::from(n)).sum()
    }

    /// Block `b`'s trees (ids set by [`Self::row`]); fewer than its count only
    /// where its forest is too scarce for the draws to find (reported by the caller).
    fn block(&self, b: usize) -> Vec<SceneTree> {
        let n = self.counts[b] as usize;
        let (x0, y0) = self.corner(b);
        let peak = f64::from(self.peaks[b]).max(1e-6);
        let mut rng = Rng::new(hash64(self.seed ^ (b as u64).wrapping_mul(0xA076_1D64_78BD_642F)));
        let mut trees = Vec::with_capacity(n);
        let mut tries = 0usize;
        while trees.len() < n {
            tries += 1;
            let x = x0 + f64::from(rng.f32()) * BLOCK_M;
            let y = y0 + f64::from(rng.f32()) * BLOCK_M;
            let site = self.site(x, y);
            // Accept by the field over the block's peak; a block whose probes
            // saw more forest than its trees can find is filled where the
            // field is not zero after many tries (never on water).
            let limit = n * 64 + 4096;
            if site.forest <= 0.0 || (tries < limit && f64::from(rng.f32()) * peak > site.forest) {
                if tries > limit * 4 {
                    // A block whose forest the probes saw but no draw finds:
                    // (never in practice) stop with what it has.
                    break;
                }
                continue;
            }
            let s = self.seed.wrapping_mul(0x9E37_79B9);
            // Stands of different ages: young ones shorter and denser-looking.
            let age = fbm(s + 30, x, y, 350.0);
            let zone = fbm(s + 31, x, y, 5000.0);
            let birch = fbm(s + 32, x, y, 300.0);
            let species = if zone + site.z / 500.0 > 0.85 {
                0
            } else if birch > 0.62 {
                2
            } else {
                1
            };
            trees.push(SceneTree {
                pos: DVec3::new(x, y, site.z),
                species,
                scale: (0.5 + 0.75 * age as f32) * rng.range(0.8, 1.1),
                aspect: 1.0,
                yaw_rad: rng.range(0.0, std::f32::consts::TAU),
                variation: (rng.next_u64() % 32) as u8,
                id: 0,
                row: 0,
                dated: false,
            });
        }
        trees
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_country_holds_the_count_exactly_on_land_in_every_species() {
        let c = Country::new(300_000, 3).unwrap();
        assert_eq!(c.trees(), 300_000);
        let mut all = Vec::new();
        for row in 0..c.blocks() {
            let t = c.row(row, all.len() as u64);
            assert_eq!(t.len() as u64, c.row_trees(row));
            all.extend(t);
        }
        assert_eq!(all.len(), 300_000);
        let mut species = [0usize; 3];
        for (i, t) in all.iter().enumerate() {
            assert_eq!(t.id, i as u64);
            let site = c.site(t.pos.x, t.pos.y);
            assert!(!site.water && site.forest > 0.0, "tree {i} at {:?} stands on {site:?}", t.pos);
            assert!((t.pos.z - site.z).abs() < 1e-9);
            assert!(t.pos.x.abs() <= c.half_m && t.pos.y.abs() <= c.half_m);
            species[t.species as usize] += 1;
        }
        assert!(species.iter().all(|&n| n > 3000), "{species:?}");
        // Same seed, same trees (rows are made by several threads).
        assert_eq!(Country::new(300_000, 3).unwrap().row(c.blocks() / 2, 0), c.row(c.blocks() / 2, 0));
    }

    #[test]
    fn the_country_is_land_and_sea_forest_and_fields() {
        let c = Country::new(2_000_000, 1).unwrap();
        // 10^6 trees at ~500 a hectare in closed stands: a few km across.
        assert!(c.half_m > 4_000.0 && c.half_m < 20_000.0, "{}", c.half_m);
        let n = 200;
        let (mut sea, mut forest, mut open) = (0, 0, 0);
        for j in 0..n {
            for i in 0..n {
                let x = (i as f64 + 0.5) / n as f64 * 2.0 * c.half_m - c.half_m;
                let y = (j as f64 + 0.5) / n as f64 * 2.0 * c.half_m - c.half_m;
                let s = c.site(x, y);
                if s.water {
                    sea += 1;
                } else if s.forest > 0.0 {
                    forest += 1;
                } else {
                    open += 1;
                }
            }
        }
        let all = f64::from(n * n);
        // The corners are sea; the rest a mix of woods and open land.
        assert!(c.site(-c.half_m, -c.half_m).water && c.site(c.half_m, c.half_m).water);
        for (what, k, lo, hi) in [("water", sea, 0.2, 0.7), ("forest", forest, 0.1, 0.5), ("open", open, 0.1, 0.6)] {
            let f = f64::from(k) / all;
            assert!(f > lo && f < hi, "{what}: {f:.2} of the square");
        }
        // Hills inland.
        let top = (0..n * n)
            .map(|k| c.ground((k % n) as f64 * 50.0 - 5000.0, (k / n) as f64 * 50.0 - 5000.0))
            .fold(0.0, f64::max);
        assert!(top > 50.0, "highest ground {top:.0} m");
    }
}
