//! Stage 4 of the bake: terrain tiles (`terrain/<level>/<x>_<y>.terr`, see
//! `sylva::format::terrain`) from a ground-height function — the `--dem`
//! GeoTIFFs, or the demo's procedural hills.
//!
//! A quadtree of regular grids of [`TERRAIN_GRID`]² cells: the finest level's
//! vertices are the DEM's resolution apart; each coarser level doubles the
//! spacing and keeps every other vertex, so a parent's vertices are its
//! children's even vertices with the same heights. A tile's geometric error is
//! the largest vertical distance from its bilinear surface to its children's
//! vertices plus their own error (the finest level's is 0: it is the data).
//! Tiles without any data are not written; a parent says which children exist.

use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

use anyhow::Result;
use rayon::prelude::*;
use sylva::format::terrain::{quantise, TerrainChild, TerrainEntry, TerrainTile, TERRAIN_HOLE};

/// Cells per terrain tile side (65 × 65 vertices, 8.5 KB a tile).
pub const TERRAIN_GRID: u16 = 64;
/// Most finest-level tiles per side of the root: coarser than the DEM beyond
/// (a 128 × 128 tile quadtree is about 190 MB).
pub const MAX_FINEST_TILES_PER_SIDE: f64 = 128.0;

/// Ground heights to bake into terrain.
pub struct TerrainSource<'a> {
    /// Ground height (metres relative to the scene origin) at a point in metres
    /// relative to the scene origin, `None` where there is no data.
    pub height: &'a (dyn Fn(f64, f64) -> Option<f32> + Sync),
    /// The square-ish region to cover, relative metres: min x, min y, max x, max y.
    pub region: [f64; 4],
    /// Finest vertex spacing wanted, metres (the DEM's pixel size).
    pub resolution_m: f64,
    /// Where the heights came from, for reports.
    pub source: String,
}

/// What the build of one tile tells its parent.
struct Built {
    info: TerrainChild,
    /// Heights of its vertices before quantisation (NaN: no data).
    raw: Vec<f32>,
}

/// Writes the terrain quadtree into `dir/terrain` and returns its manifest
/// entry, or `None` when the region has no ground data.
///
/// # Errors
/// A tile that cannot be written.
pub fn write_terrain(src: &TerrainSource<'_>, dir: &Path, log: &dyn Fn(&str)) -> Result<Option<TerrainEntry>> {
    let started = std::time::Instant::now();
    let [x0, y0, x1, y1] = src.region;
    let extent = (x1 - x0).max(y1 - y0).max(1.0);
    let grid = f64::from(TERRAIN_GRID);
    let mut resolution = src.resolution_m.max(0.01);
    let finest_needed = extent / (grid * resolution);
    if finest_needed > MAX_FINEST_TILES_PER_SIDE {
        let coarser = extent / (grid * MAX_FINEST_TILES_PER_SIDE);
        log(&format!(
            "terrain: {extent:.0} m at {resolution:.2} m would be {finest_needed:.0}² finest tiles; baked at {coarser:.2} m"
        ));
        resolution = coarser;
    }
    // On a 1/64 m step: the root's size (64 × resolution × 2^levels) and corner
    // are then short decimals that any JSON reader reads back to the bit
    // (`merge` copies shard 0's entry through a reader that is off by an ulp
    // on long ones).
    // (A pixel size a hair over a step, 1.0000001 m, stays 1 m.)
    let resolution = ((resolution * 64.0 - 1e-6).ceil() / 64.0).max(1.0 / 64.0);
    let depth = (extent / (grid * resolution)).log2().ceil().max(0.0) as u8;
    let root_size = grid * resolution * f64::from(1u32 << depth);
    // The root square is centred on the region, its corner on the resolution grid.
    let cx = ((x0 + x1) * 0.5 - root_size * 0.5) / resolution;
    let cy = ((y0 + y1) * 0.5 - root_size * 0.5) / resolution;
    let mut entry = TerrainEntry {
        path: "terrain".into(),
        origin_m: [cx.round() * resolution, cy.round() * resolution],
        root_size_m: root_size,
        grid: TERRAIN_GRID,
        levels: depth + 1,
        resolution_m: resolution,
        height_range_m: [0.0, 0.0],
        tiles: 0,
        bytes: 0,
        source: src.source.clone(),
        imagery: None,
    };
    let tiles = AtomicU64::new(0);
    let bytes = AtomicU64::new(0);
    let ctx = Ctx { src, entry: &entry, dir, tiles: &tiles, bytes: &bytes };
    let root = ctx.build(0, 0, 0)?;
    let Some(root) = root else {
        log("terrain: no ground data in the region (no terrain written)");
        return Ok(None);
    };
    entry.height_range_m = [root.info.min_m, root.info.max_m];
    entry.tiles = tiles.load(Ordering::Relaxed);
    entry.bytes = bytes.load(Ordering::Relaxed);
    log(&format!(
        "terrain: {} tiles in {} levels, {:.2} m finest spacing over {:.0} m, heights {:.1}–{:.1} m, {:.2} MB ({:.2} s)",
        entry.tiles,
        entry.levels,
        entry.resolution_m,
        entry.root_size_m,
        root.info.min_m,
        root.info.max_m,
        entry.bytes as f64 / 1e6,
        started.elapsed().as_secs_f64()
    ));
    Ok(Some(entry))
}

struct Ctx<'a> {
    src: &'a TerrainSource<'a>,
    entry: &'a TerrainEntry,
    dir: &'a Path,
    tiles: &'a AtomicU64,
    bytes: &'a AtomicU64,
}

impl Ctx<'_> {
    /// Builds tile `(level, x, y)` and everything below it.
    fn build(&self, level: u8, x: u32, y: u32) -> Result<Option<Built>> {
        let e = self.entry;
        let size = e.tile_size_m(level);
        let [ox, oy] = e.tile_origin_m(level, x, y);
        let [rx0, ry0, rx1, ry1] = self.src.region;
        if ox > rx1 || oy > ry1 || ox + size < rx0 || oy + size < ry0 {
            return Ok(None);
        }
        let finest = level + 1 == e.levels;
        let children: Vec<Option<Built>> = if finest {
            vec![None, None, None, None]
        } else {
            (0..4u32)
                .into_par_iter()
                .map(|k| self.build(level + 1, 2 * x + (k & 1), 2 * y + (k >> 1)))
                .collect::<Result<_>>()?
        };
        let n = usize::from(e.grid);
        let side = n + 1;
        let step = size / n as f64;
        // Outside the region there is no data at any level (so a coarse tile
        // shows no ground that its finer children would not).
        let raw: Vec<f32> = (0..side * side)
            .map(|v| {
                let (x, y) = (ox + (v % side) as f64 * step, oy + (v / side) as f64 * step);
                let inside = x >= rx0 - 1e-6 && x <= rx1 + 1e-6 && y >= ry0 - 1e-6 && y <= ry1 + 1e-6;
                if inside {
                    (self.src.height)(x, y).unwrap_or(f32::NAN)
                } else {
                    f32::NAN
                }
            })
            .collect();
        let any_child = children.iter().any(Option::is_some);
        let (mut lo, mut hi) = (f32::MAX, f32::MIN);
        for &h in raw.iter().filter(|h| h.is_finite()) {
            lo = lo.min(h);
            hi = hi.max(h);
        }
        for c in children.iter().flatten() {
            lo = lo.min(c.info.min_m);
            hi = hi.max(c.info.max_m);
        }
        if lo > hi {
            return Ok(None); // no data here or below
        }
        // Geometric error: the children's vertices against this surface.
        let mut error = 0.0f32;
        for (k, c) in children.iter().enumerate() {
            let Some(c) = c else { continue };
            let (qx, qy) = ((k & 1) * n, (k >> 1) * n);
            let mut worst = 0.0f32;
            for cj in 0..side {
                for ci in 0..side {
                    let h = c.raw[cj * side + ci];
                    if !h.is_finite() {
                        continue;
                    }
                    // The child vertex in this tile's cells: half-integer positions.
                    if let Some(p) = drawn_surface(&raw, side, qx + ci, qy + cj) {
                        worst = worst.max((h - p).abs());
                    }
                }
            }
            error = error.max(worst + c.info.error_m);
        }
        let (min_q, max_q) = (lo, hi);
        let heights: Vec<u16> =
            raw.iter().map(|&h| if h.is_finite() { quantise(h, min_q, max_q) } else { TERRAIN_HOLE }).collect();
        if !any_child && heights.iter().all(|&q| q == TERRAIN_HOLE) {
            return Ok(None);
        }
        let mut summary = [TerrainChild::default(); 4];
        for (s, c) in summary.iter_mut().zip(&children) {
            if let Some(c) = c {
                *s = c.info;
            }
        }
        let tile = TerrainTile {
            level,
            x,
            y,
            grid: e.grid,
            min_m: min_q,
            max_m: max_q,
            error_m: error,
            children: summary,
            heights,
        };
        let bytes = tile.encode();
        let path = self.dir.join(e.tile_url(level, x, y));
        if let Some(parent) = path.parent() {
            crate::out_dir::create_dir(parent)?;
        }
        crate::out_dir::write_file(&path, &bytes)?;
        self.tiles.fetch_add(1, Ordering::Relaxed);
        self.bytes.fetch_add(bytes.len() as u64, Ordering::Relaxed);
        let info = TerrainChild { exists: true, min_m: min_q, max_m: max_q, error_m: error };
        Ok(Some(Built { info, raw }))
    }
}

/// Height of a tile's surface as drawn (each cell two triangles split along
/// its south-west–north-east diagonal) at the point `(u2, v2) / 2` in vertex
/// units: a vertex, the middle of an edge, or a cell's centre (on the
/// diagonal: the mean of its south-west and north-east corners). Holes are
/// skipped. `terrain.wgsl` morphs towards the same surface.
fn drawn_surface(grid: &[f32], side: usize, u2: usize, v2: usize) -> Option<f32> {
    let (i, j) = (u2 / 2, v2 / 2);
    let at = |i: usize, j: usize| {
        let h = grid[j.min(side - 1) * side + i.min(side - 1)];
        h.is_finite().then_some(h)
    };
    let mean = |a: Option<f32>, b: Option<f32>| match (a, b) {
        (Some(a), Some(b)) => Some((a + b) * 0.5),
        (a, b) => a.or(b),
    };
    match (u2 % 2, v2 % 2) {
        (0, 0) => at(i, j),
        (1, 0) => mean(at(i, j), at(i + 1, j)),
        (0, 1) => mean(at(i, j), at(i, j + 1)),
        _ => mean(at(i, j), at(i + 1, j + 1)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_terrain_quadtree_covers_the_region_with_errors_that_bound_the_data() {
        let dir = std::env::temp_dir().join(format!("sylva-terrain-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        // Hills: 40 m of relief over a few hundred metres, data only west of x = 900.
        let hills = |x: f64, y: f64| {
            (x < 900.0).then(|| (100.0 + 20.0 * (x / 150.0).sin() * (y / 110.0).cos() + 0.01 * x) as f32)
        };
        let src = TerrainSource {
            height: &hills,
            region: [0.0, 0.0, 1000.0, 600.0],
            resolution_m: 4.0,
            source: "test".into(),
        };
        let e = write_terrain(&src, &dir, &|_| {}).unwrap().unwrap();
        // 1000 m at 4 m: 256 m finest tiles, 3 levels up to a 1024 m root.
        assert_eq!((e.levels, e.root_size_m, e.grid), (3, 1024.0, 64));
        let mut tiles = 0;
        let mut stack = vec![(0u8, 0u32, 0u32)];
        while let Some((l, x, y)) = stack.pop() {
            let bytes = std::fs::read(dir.join(e.tile_url(l, x, y))).unwrap();
            let t = TerrainTile::decode("t", &bytes).unwrap();
            assert_eq!(t.encode(), bytes);
            tiles += 1;
            // Every vertex with data is within the quantisation of the function.
            let [ox, oy] = e.tile_origin_m(l, x, y);
            let step = e.tile_size_m(l) / 64.0;
            for j in 0..65 {
                for i in 0..65 {
                    let (x, y) = (ox + i as f64 * step, oy + j as f64 * step);
                    // No data outside the region, at any level.
                    let inside = (0.0..=1000.0).contains(&x) && (0.0..=600.0).contains(&y);
                    let want = hills(x, y).filter(|_| inside);
                    match (t.height(i, j), want) {
                        (Some(h), Some(w)) => assert!((h - w).abs() <= (t.max_m - t.min_m) / 65534.0 + 1e-3),
                        (None, None) => {}
                        (got, want) => panic!("tile {l}/{x}/{y} vertex {i},{j}: {got:?} vs {want:?}"),
                    }
                }
            }
            if l == 0 {
                assert!(t.error_m > 1.0, "a 2 km root over 40 m hills has an error of metres: {}", t.error_m);
            }
            for (k, c) in t.children.iter().enumerate() {
                if c.exists {
                    assert!(c.error_m <= t.error_m, "a child's error exceeds its parent's");
                    stack.push((l + 1, 2 * x + (k as u32 & 1), 2 * y + (k as u32 >> 1)));
                }
            }
            if l + 1 == e.levels {
                assert_eq!(t.error_m, 0.0);
            }
        }
        assert_eq!(tiles, e.tiles);
        // Finest tiles only where the region has data (x < 900).
        let finest = (0..4u32).flat_map(|x| (0..4u32).map(move |y| (x, y)));
        let written: Vec<(u32, u32)> = finest.filter(|(x, y)| dir.join(e.tile_url(2, *x, *y)).exists()).collect();
        let [ox, oy] = e.origin_m;
        for (x, y) in &written {
            let (wx, wy) = (ox + f64::from(*x) * 256.0, oy + f64::from(*y) * 256.0);
            assert!(wx < 900.0 && wx + 256.0 > 0.0 && wy <= 600.0 && wy + 256.0 >= 0.0, "tile {x},{y} at {wx},{wy}");
        }
        assert!(written.len() >= 12, "{written:?}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
