//! Canopy rasters at bake time (format in `sylva::format::canopy`):
//! a quadtree over the scene's square of tiles, each raster what its trees look
//! like from far away — crown cover from above and from the side, albedo,
//! height and ground per cell.
//!
//! Each species' look comes from its pack's top-view billboard (the capture at
//! 90° elevation): its opaque share of the capture's square gives the crown
//! area seen from above at scale 1, its alpha-weighted mean the albedo. A tree
//! adds `area × scale² × aspect²` to the cells its crown disc covers; cover is
//! `1 − exp(−Σ area / cell area)` (crowns overlapping at random).
//!
//! Memory is bounded whatever the tree count: squares are visited depth first,
//! each tile is read once and adds to the rasters on the path to it only, and
//! a raster is written when its square is done. Where tiles are wider than 64
//! finest cells (sparse inventories: 4 km tiles), the levels go on below a
//! tile: its trees, read once, are split among the sub-squares.

use std::path::Path;

use anyhow::{Context, Result};
use sylva::format::canopy::{Canopy, CanopyCell, CanopyEntry, CANOPY_CELLS, CANOPY_CELL_BYTES, MAX_TALLEST_RATIO};
use sylva::format::manifest::{SpeciesEntry, TileEntry};
use sylva::format::pack::{decode_pack, kind};
use sylva::format::Tile;
use sylva::render::mips::{linear_to_srgb, srgb_to_linear};
use sylva::render::settings::AUTUMN_MEAN_PROGRESS;

use crate::out_dir::{create_dir, write_file};

/// A species seen from above at scale 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeciesLook {
    /// Mean albedo of the crown from above, linear RGB.
    pub albedo: [f32; 3],
    /// Crown area seen from above, m² at scale 1.
    pub area_m2: f32,
    /// The tree's silhouette seen from the side, m² at scale 1.
    pub side_m2: f32,
    /// Model height at scale 1, metres.
    pub height_m: f32,
    /// A deciduous species' autumn and leaf-off looks (its pack's `season`);
    /// `None`: the same all year.
    pub seasons: Option<SeasonLooks>,
}

/// A deciduous species seen from above in autumn and leaf-off, at scale 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SeasonLooks {
    /// Mean albedo from above in autumn (its leaf texels recoloured as the
    /// viewer recolours them), linear RGB.
    pub autumn: [f32; 3],
    /// The bare wood's albedo from above, linear RGB.
    pub bare: [f32; 3],
    /// The bare wood's area seen from above, m².
    pub bare_area_m2: f32,
    /// Its side silhouette, m².
    pub bare_side_m2: f32,
}

/// Twigs and bark seen from far away, for a bare tree without its own captures (linear).
const BARE_ALBEDO: [f32; 3] = [0.09, 0.075, 0.06];

/// Albedo for a species whose pack has no billboards (a mid green, linear).
const FALLBACK_ALBEDO: [f32; 3] = [0.06, 0.11, 0.04];

/// Each species' look from its pack in `dir` (billboards' top view); a pack
/// without billboards gets a disc of 0.7 × its bounds' half width and a mid green.
///
/// # Errors
/// A pack that cannot be read or decoded.
pub fn species_looks(dir: &Path, species: &[SpeciesEntry], log: &dyn Fn(&str)) -> Result<Vec<SpeciesLook>> {
    species
        .iter()
        .map(|s| {
            let path = dir.join(&s.pack);
            let bytes = std::fs::read(&path).with_context(|| format!("canopy: reading {}", path.display()))?;
            let bytes = sylva::format::stored::unstore(&s.pack, bytes)?;
            let pack = decode_pack(&s.pack, &bytes)?;
            if let Some(e) = pack.meta.encodings().first() {
                anyhow::bail!("canopy: {} holds {} blocks, not the plain texels it reads", s.pack, e.name());
            }
            let autumn_linear = pack.meta.season.as_ref().map(sylva::render::settings::autumn_linear);
            // The top (and side) view of far-tier state `state`: Σ alpha, Σ
            // alpha·albedo, Σ alpha·autumn albedo, the side's Σ alpha, per texel.
            let view = |state: u32| {
                let b = pack.meta.billboards.as_ref()?;
                let size = b.texture.size as usize;
                let texels = size * size;
                let data = pack.section(kind::BILLBOARD_COLOR, state)?;
                let normals = pack.section(kind::BILLBOARD_NORMAL, state)?;
                // Layers: azimuth 0 at elevations 0 (the side) … 90° (the top).
                let layer = |l: usize| l * texels * 4..(l + 1) * texels * 4;
                let top_layer = (b.angles.max(1) - 1) as usize;
                let (side, top, top_n) =
                    (data.get(layer(0))?, data.get(layer(top_layer))?, normals.get(layer(top_layer))?);
                let (mut alpha, mut rgb, mut autumn) = (0.0f64, [0.0f64; 3], [0.0f64; 3]);
                for (t, n) in top.chunks_exact(4).zip(top_n.chunks_exact(4)) {
                    let a = f64::from(t[3]) / 255.0;
                    alpha += a;
                    let lin = [0, 1, 2].map(|k| srgb_to_linear(t[k]));
                    let fall = match autumn_linear {
                        Some(c) if n[3] > sylva::format::pack::LEAF_FLAG_MIN => {
                            sylva::render::settings::autumn_albedo(lin, c, AUTUMN_MEAN_PROGRESS)
                        }
                        _ => lin,
                    };
                    for k in 0..3 {
                        rgb[k] += a * f64::from(lin[k]);
                        autumn[k] += a * f64::from(fall[k]);
                    }
                }
                let side_alpha: f64 = side.chunks_exact(4).map(|t| f64::from(t[3]) / 255.0).sum();
                let square = f64::from(2.0 * b.half_width) * f64::from(2.0 * b.half_height);
                let to_m2 = |a: f64| (a / texels as f64 * square) as f32;
                let mean = |v: [f64; 3]| v.map(|c| if alpha > 0.0 { (c / alpha) as f32 } else { 0.0 });
                Some((mean(rgb), mean(autumn), to_m2(alpha), to_m2(side_alpha)))
            };
            let top = view(0).filter(|v| v.2 > 0.0).map(|(albedo, autumn, area_m2, side_m2)| {
                let seasons = pack.meta.season.as_ref().map(|m| {
                    // The bare wood's own top view where the pack has it; else
                    // the leafy crown thinned to the bare cover.
                    let (bare, bare_area_m2, bare_side_m2) = match view(1).filter(|v| v.2 > 0.0) {
                        Some((bare, _, area, side)) => (bare, area, side),
                        None => (BARE_ALBEDO, area_m2 * m.bare_cover, side_m2 * m.bare_cover),
                    };
                    SeasonLooks { autumn, bare, bare_area_m2, bare_side_m2 }
                });
                SpeciesLook { albedo, area_m2, side_m2, height_m: s.height_m, seasons }
            });
            Ok(top.unwrap_or_else(|| {
                log(&format!("canopy: {} has no billboards; its crowns are drawn as plain green discs", s.name));
                let half = 0.5 * ((s.bounds.max[0] - s.bounds.min[0]) + (s.bounds.max[1] - s.bounds.min[1])) * 0.5;
                let (area_m2, side_m2) = (
                    std::f32::consts::PI * (0.7 * half).powi(2),
                    // A crown of that width down half the tree.
                    1.4 * half * 0.5 * s.height_m,
                );
                SpeciesLook {
                    albedo: FALLBACK_ALBEDO,
                    area_m2,
                    side_m2,
                    height_m: s.height_m,
                    seasons: pack.meta.season.as_ref().map(|m| SeasonLooks {
                        autumn: sylva::render::settings::autumn_albedo(
                            FALLBACK_ALBEDO,
                            autumn_linear.unwrap_or(FALLBACK_ALBEDO),
                            AUTUMN_MEAN_PROGRESS,
                        ),
                        bare: BARE_ALBEDO,
                        bare_area_m2: area_m2 * m.bare_cover,
                        bare_side_m2: side_m2 * m.bare_cover,
                    }),
                }
            }))
        })
        .collect()
}

/// One tree as the canopy sees it.
#[derive(Debug, Clone, Copy)]
struct CanopyTree {
    x: f32,
    y: f32,
    ground: f32,
    height: f32,
    /// Its batch's tallest tree (the cull's cross-fade sizes the batch by it).
    tallest: f32,
    area: f32,
    side: f32,
    albedo: [f32; 3],
    /// Autumn albedo; bare area, side and albedo (leaf-off; as leaf-on for an evergreen).
    autumn: [f32; 3],
    bare_area: f32,
    bare_side: f32,
    bare: [f32; 3],
}

/// A raster being summed.
struct Acc {
    origin: [f32; 2],
    size: f32,
    /// Per cell: Σ area, Σ area·rgb, Σ area·height, Σ area·ground, Σ side area.
    sums: Vec<[f64; 7]>,
    /// Per cell, with seasons: Σ area·autumn rgb, Σ bare area, Σ bare area·rgb, Σ bare side.
    season_sums: Option<Vec<[f64; 8]>>,
    z: [f32; 2],
    height_max: f32,
    height_min: f32,
    /// Σ area · batch tallest and Σ area · height over the raster.
    tallest: [f64; 2],
}

impl Acc {
    /// The same, with the cells' seasons.
    fn with_seasons(mut self, seasons: bool) -> Self {
        if seasons {
            self.season_sums = Some(vec![[0.0; 8]; self.sums.len()]);
        }
        self
    }

    /// A raster over the square at `origin` (metres relative to the scene origin) of side `size`.
    fn new(origin: [f64; 2], size: f64) -> Self {
        Self {
            origin: [origin[0] as f32, origin[1] as f32],
            size: size as f32,
            sums: vec![[0.0; 7]; (CANOPY_CELLS * CANOPY_CELLS) as usize],
            season_sums: None,
            z: [f32::INFINITY, f32::NEG_INFINITY],
            height_max: 0.0,
            height_min: f32::INFINITY,
            tallest: [0.0; 2],
        }
    }

    fn add(&mut self, t: &CanopyTree) {
        let n = CANOPY_CELLS as i64;
        let cell = self.size / CANOPY_CELLS as f32;
        let r = (t.area / std::f32::consts::PI).sqrt();
        let at = |v: f32, o: f32| ((v - o) / cell).floor() as i64;
        let (cx, cy) = (at(t.x, self.origin[0]), at(t.y, self.origin[1]));
        // The cells whose centres lie inside the crown disc share its area
        // (the trunk's cell alone when the crown is smaller than a cell).
        let mut cells: Vec<(i64, i64)> = Vec::new();
        if r > 0.5 * cell {
            let (x0, x1) = (at(t.x - r, self.origin[0]), at(t.x + r, self.origin[0]));
            let (y0, y1) = (at(t.y - r, self.origin[1]), at(t.y + r, self.origin[1]));
            for y in y0..=y1 {
                for x in x0..=x1 {
                    let (px, py) = (self.origin[0] + (x as f32 + 0.5) * cell, self.origin[1] + (y as f32 + 0.5) * cell);
                    if (px - t.x).hypot(py - t.y) <= r {
                        cells.push((x, y));
                    }
                }
            }
        }
        if cells.is_empty() {
            cells.push((cx, cy));
        }
        let share = f64::from(t.area) / cells.len() as f64;
        let side = f64::from(t.side) / cells.len() as f64;
        for (x, y) in cells {
            let (x, y) = (x.clamp(0, n - 1), y.clamp(0, n - 1));
            let s = &mut self.sums[(y * n + x) as usize];
            s[0] += share;
            for k in 0..3 {
                s[1 + k] += share * f64::from(t.albedo[k]);
            }
            s[4] += share * f64::from(t.height);
            s[5] += share * f64::from(t.ground);
            s[6] += side;
            if let Some(seasons) = self.season_sums.as_mut() {
                let q = &mut seasons[(y * n + x) as usize];
                let bare = share * f64::from(t.bare_area / t.area.max(1e-9));
                for k in 0..3 {
                    q[k] += share * f64::from(t.autumn[k]);
                    q[4 + k] += bare * f64::from(t.bare[k]);
                }
                q[3] += bare;
                q[7] += side * f64::from(t.bare_side / t.side.max(1e-9));
            }
        }
        self.z = [self.z[0].min(t.ground), self.z[1].max(t.ground)];
        self.height_max = self.height_max.max(t.height);
        self.height_min = self.height_min.min(t.height);
        self.tallest[0] += f64::from(t.area) * f64::from(t.tallest.max(t.height));
        self.tallest[1] += f64::from(t.area) * f64::from(t.height);
    }

    fn finish(self, children: u8) -> Canopy {
        let cell_area = f64::from(self.size / CANOPY_CELLS as f32).powi(2);
        let z = if self.z[0] <= self.z[1] { self.z } else { [0.0, 0.0] };
        let mut c = Canopy {
            cells: CANOPY_CELLS,
            origin_m: self.origin,
            size_m: self.size,
            z_range_m: z,
            height_max_m: self.height_max,
            height_min_m: self.height_min.min(self.height_max),
            children,
            tallest_ratio: if self.tallest[1] > 0.0 {
                ((self.tallest[0] / self.tallest[1]) as f32).clamp(1.0, MAX_TALLEST_RATIO)
            } else {
                1.0
            },
            data: vec![0; self.sums.len() * CANOPY_CELL_BYTES],
            seasons: self.season_sums.as_ref().map(|q| vec![0; q.len() * CANOPY_CELL_BYTES]),
        };
        for (i, s) in self.sums.iter().enumerate() {
            if s[0] <= 0.0 {
                continue;
            }
            let cell = CanopyCell {
                color: [1, 2, 3].map(|k| linear_to_srgb((s[k] / s[0]) as f32)),
                cover: (1.0 - (-s[0] / cell_area).exp()) as f32,
                height_m: (s[4] / s[0]) as f32,
                side: (s[6] / s[0]) as f32,
                ground_m: (s[5] / s[0]) as f32,
            };
            let packed = c.pack_cell(&cell);
            c.data[i * CANOPY_CELL_BYTES..(i + 1) * CANOPY_CELL_BYTES].copy_from_slice(&packed);
            if let (Some(q), Some(out)) = (self.season_sums.as_ref().map(|q| q[i]), c.seasons.as_mut()) {
                // Autumn: the albedo; leaf-off: the bare wood's cover, albedo and side.
                let bare = if q[3] > 0.0 { [4, 5, 6].map(|k| linear_to_srgb((q[k] / q[3]) as f32)) } else { [0; 3] };
                let side = if q[3] > 0.0 { q[7] / q[3] } else { 0.0 };
                out[i * CANOPY_CELL_BYTES..(i + 1) * CANOPY_CELL_BYTES].copy_from_slice(&[
                    linear_to_srgb((q[0] / s[0]) as f32),
                    linear_to_srgb((q[1] / s[0]) as f32),
                    linear_to_srgb((q[2] / s[0]) as f32),
                    ((1.0 - (-q[3] / cell_area).exp()).clamp(0.0, 1.0) * 255.0).round() as u8,
                    bare[0],
                    bare[1],
                    bare[2],
                    (side * 32.0).round().clamp(0.0, 255.0) as u8,
                ]);
            }
        }
        c
    }
}

/// Reads tile `t` from `dir` and gives its trees.
fn tile_trees(dir: &Path, t: &TileEntry, looks: &[SpeciesLook], out: &mut Vec<CanopyTree>) -> Result<()> {
    let bytes = std::fs::read(dir.join(&t.url)).with_context(|| format!("canopy: reading {}", t.url))?;
    let tile = Tile::decode(&t.url, &bytes, looks.len() as u32)?;
    out.clear();
    // The canopy rasters show the trees standing at the latest date (far views
    // at another date show those too; only nearer trees follow the date).
    for b in tile.batches.iter().filter(|b| b.flags & sylva::format::tile::BATCH_DATED == 0) {
        let look = &looks[b.species as usize];
        let start = b.instance_offset as usize;
        for p in &tile.instances[start..start + b.instance_count as usize] {
            let i = p.decode(b);
            out.push(CanopyTree {
                x: i.position_m[0],
                y: i.position_m[1],
                ground: i.position_m[2],
                height: look.height_m * i.scale,
                tallest: b.max_height_m,
                area: look.area_m2 * (i.scale * i.aspect).powi(2),
                // Width scales by scale · aspect, height by scale.
                side: look.side_m2 * i.scale * i.scale * i.aspect,
                albedo: look.albedo,
                autumn: look.seasons.map_or(look.albedo, |l| l.autumn),
                bare_area: look.seasons.map_or(look.area_m2, |l| l.bare_area_m2) * (i.scale * i.aspect).powi(2),
                bare_side: look.seasons.map_or(look.side_m2, |l| l.bare_side_m2) * i.scale * i.scale * i.aspect,
                bare: look.seasons.map_or(look.albedo, |l| l.bare),
            });
        }
    }
    Ok(())
}

/// Writes the canopy quadtree of `tiles` (tiles of `tile_m` metres) into
/// `dir/canopy` and gives the manifest's entry. Its root covers the index's
/// root square of tiles; each level halves the square, down to the smallest
/// squares at least 64 cells of `finest_cell_m` wide
/// ([`sylva::format::canopy::FINEST_CELL_M`] by default) — below a tile's
/// square where tiles are wider than that.
///
/// # Errors
/// A tile that cannot be read, or a file that cannot be written.
pub fn write_quadtree(
    dir: &Path,
    tiles: &[TileEntry],
    tile_m: f64,
    finest_cell_m: f64,
    looks: &[SpeciesLook],
) -> Result<CanopyEntry> {
    let [x0, y0, size] = sylva::format::index::tile_square(tiles);
    let mut levels = 1u8;
    let root_m = size as f64 * tile_m;
    while levels < MAX_LEVELS && root_m / f64::from(1u32 << levels) >= f64::from(CANOPY_CELLS) * finest_cell_m {
        levels += 1;
    }
    let mut entry = CanopyEntry {
        path: "canopy".into(),
        origin_m: [x0 as f64 * tile_m, y0 as f64 * tile_m],
        root_size_m: size as f64 * tile_m,
        levels,
        cells: CANOPY_CELLS,
        rasters: 0,
        bytes: 0,
    };
    let mut walk = Walk {
        dir,
        entry: &mut entry,
        tile_square: [x0, y0, size],
        looks,
        seasons: looks.iter().any(|l| l.seasons.is_some()),
        stack: Vec::new(),
        trees: Vec::new(),
    };
    let all: Vec<&TileEntry> = tiles.iter().collect();
    walk.visit(0, 0, 0, &all)?;
    Ok(entry)
}

/// The depth-first walk of [`write_quadtree`]: the rasters on the path.
struct Walk<'a> {
    dir: &'a Path,
    entry: &'a mut CanopyEntry,
    tile_square: [i64; 3],
    looks: &'a [SpeciesLook],
    /// A species has seasons: every raster holds the cells' seasons.
    seasons: bool,
    stack: Vec<Acc>,
    trees: Vec<CanopyTree>,
}

impl Walk<'_> {
    /// Writes raster `(level, x, y)` (over `tiles`, all inside its square) and those below it.
    fn visit(&mut self, level: u8, x: u32, y: u32, tiles: &[&TileEntry]) -> Result<()> {
        self.stack
            .push(Acc::new(self.entry.origin_of(level, x, y), self.entry.size_m(level)).with_seasons(self.seasons));
        let mut children = 0u8;
        if level + 1 >= self.entry.levels {
            for t in tiles {
                tile_trees(self.dir, t, self.looks, &mut self.trees)?;
                for acc in &mut self.stack {
                    self.trees.iter().for_each(|tree| acc.add(tree));
                }
            }
        } else if self.tile_square[2] >> (level + 1) == 0 {
            // One tile's square, split further: its trees among the sub-squares.
            let mut trees = Vec::new();
            for t in tiles {
                tile_trees(self.dir, t, self.looks, &mut self.trees)?;
                trees.extend_from_slice(&self.trees);
            }
            children = self.split(level, x, y, &trees)?;
        } else {
            // The children's squares in tile coordinates: half this one's side.
            let half = self.tile_square[2] >> (level + 1);
            let (cx0, cy0) =
                (self.tile_square[0] + i64::from(2 * x) * half, self.tile_square[1] + i64::from(2 * y) * half);
            for i in 0..4u32 {
                let (qx, qy) = (cx0 + i64::from(i & 1) * half, cy0 + i64::from(i >> 1) * half);
                let part: Vec<&TileEntry> = tiles
                    .iter()
                    .copied()
                    .filter(|t| (qx..qx + half).contains(&i64::from(t.x)) && (qy..qy + half).contains(&i64::from(t.y)))
                    .collect();
                if !part.is_empty() {
                    children |= 1 << i;
                    self.visit(level + 1, 2 * x + (i & 1), 2 * y + (i >> 1), &part)?;
                }
            }
        }
        self.finish_raster(level, x, y, children)
    }

    /// Writes the raster on top of the stack.
    fn finish_raster(&mut self, level: u8, x: u32, y: u32, children: u8) -> Result<()> {
        let acc = self.stack.pop().expect("pushed by the caller");
        let url = self.entry.raster_url(level, x, y);
        let bytes = write(self.dir, &url, &acc.finish(children))?;
        self.entry.rasters += 1;
        self.entry.bytes += bytes;
        Ok(())
    }

    /// Below a tile: the children of raster `(level, x, y)` from `trees` (all
    /// inside its square, by trunk), written depth first; gives the child bits.
    fn split(&mut self, level: u8, x: u32, y: u32, trees: &[CanopyTree]) -> Result<u8> {
        let size = self.entry.size_m(level + 1);
        let [ox, oy] = self.entry.origin_of(level, x, y);
        let mut children = 0u8;
        for i in 0..4u32 {
            let (qx, qy) = (ox + f64::from(i & 1) * size, oy + f64::from(i >> 1) * size);
            // Trunks on the middle lines go east and north; on the outer edges stay in.
            let inside = |v: f32, lo: f64, first: bool| {
                let v = f64::from(v);
                (first || v >= lo) && (!first || v < lo + size)
            };
            let part: Vec<CanopyTree> =
                trees.iter().copied().filter(|t| inside(t.x, qx, i & 1 == 0) && inside(t.y, qy, i >> 1 == 0)).collect();
            if part.is_empty() {
                continue;
            }
            children |= 1 << i;
            let (cl, cx, cy) = (level + 1, 2 * x + (i & 1), 2 * y + (i >> 1));
            self.stack.push(Acc::new(self.entry.origin_of(cl, cx, cy), size).with_seasons(self.seasons));
            let grand = if cl + 1 >= self.entry.levels {
                for acc in &mut self.stack {
                    part.iter().for_each(|tree| acc.add(tree));
                }
                0
            } else {
                self.split(cl, cx, cy, &part)?
            };
            self.finish_raster(cl, cx, cy, grand)?;
        }
        Ok(children)
    }
}

/// Most levels a canopy quadtree has (finest squares of 960 m, cells of 15 m,
/// under a root of up to 31,000 km).
const MAX_LEVELS: u8 = 16;

fn write(dir: &Path, url: &str, canopy: &Canopy) -> Result<u64> {
    let bytes = canopy.encode();
    Canopy::decode(url, &bytes)?; // what the viewer will read
    let path = dir.join(url);
    if let Some(parent) = path.parent() {
        create_dir(parent)?;
    }
    write_file(&path, &bytes)?;
    Ok(bytes.len() as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tree(x: f32, height: f32, tallest: f32, area: f32) -> CanopyTree {
        let albedo = [0.1, 0.2, 0.05];
        CanopyTree {
            x,
            y: 10.0,
            ground: 0.0,
            height,
            tallest,
            area,
            side: 1.0,
            albedo,
            autumn: albedo,
            bare_area: area,
            bare_side: 1.0,
            bare: albedo,
        }
    }

    #[test]
    fn deciduous_crowns_turn_in_autumn_and_thin_in_leaf_off() {
        // Two crowns in one cell: an evergreen and a deciduous one, whose bare
        // wood covers a fifth of its crown and is brown.
        let mut acc = Acc::new([0.0, 0.0], 64.0).with_seasons(true);
        acc.add(&tree(10.0, 20.0, 20.0, 1.0));
        let autumn = [0.5, 0.1, 0.02];
        let bare = [0.1, 0.08, 0.06];
        acc.add(&CanopyTree { autumn, bare_area: 0.2, bare_side: 0.3, bare, ..tree(10.2, 20.0, 20.0, 1.0) });
        let c = Canopy::decode("c", &acc.finish(0).encode()).unwrap();
        let at = |season| {
            let cells = c.cells_in(season);
            let cell = Canopy { data: cells.to_vec(), seasons: None, ..c.clone() };
            cell.cell(10, 10)
        };
        use sylva::format::pack::Season;
        let (on, fall, off) = (at(Season::LeafOn), at(Season::Autumn), at(Season::LeafOff));
        assert!(on.cover > 0.0);
        assert_eq!((fall.cover, fall.height_m), (on.cover, on.height_m), "autumn only recolours");
        assert!(fall.color[0] > on.color[0] + 40, "autumn reddens: {:?} → {:?}", on.color, fall.color);
        // (1 − e^−2 → 1 − e^−1.2: the evergreen keeps its crown.)
        assert!(off.cover < on.cover - 0.1 && off.cover > 0.0, "leaf-off thins: {} → {}", on.cover, off.cover);
        // Seen from the side (Λ (1 + side), Λ = −ln(1 − cover)) it thins too.
        let from_side = |c: CanopyCell| -(1.0 - c.cover).ln() * (1.0 + c.side);
        assert!(from_side(off) < from_side(on) * 0.8, "from the side: {} → {}", from_side(on), from_side(off));
        // Without seasons the raster holds none.
        assert!(Acc::new([0.0, 0.0], 64.0).finish(0).seasons.is_none());
    }

    #[test]
    fn the_tallest_ratio_weighs_each_trees_batch_by_its_crown() {
        let mut acc = Acc::new([0.0, 0.0], 64.0);
        // A 10 m tree of a batch whose tallest is 20 m, and that tallest tree;
        // a third crown twice as large, of a batch of 30 m trees.
        acc.add(&tree(5.0, 10.0, 20.0, 4.0));
        acc.add(&tree(20.0, 20.0, 20.0, 4.0));
        acc.add(&tree(40.0, 30.0, 30.0, 8.0));
        let c = acc.finish(0);
        let want = (4.0 * 20.0 + 4.0 * 20.0 + 8.0 * 30.0) / (4.0 * 10.0 + 4.0 * 20.0 + 8.0 * 30.0);
        assert!((c.tallest_ratio - want).abs() < 1e-6, "{} against {want}", c.tallest_ratio);
        let back = Canopy::decode("c.cnpy", &c.encode()).unwrap();
        assert_eq!(back.tallest_ratio, c.tallest_ratio);
        // No trees: 1. A batch record below its own tree (not written by the
        // bake) counts the tree's height: never below 1.
        assert_eq!(Acc::new([0.0, 0.0], 64.0).finish(0).tallest_ratio, 1.0);
        let mut low = Acc::new([0.0, 0.0], 64.0);
        low.add(&tree(5.0, 10.0, 5.0, 4.0));
        low.add(&tree(20.0, 10.0, 20.0, 4.0));
        let want = (4.0 * 10.0 + 4.0 * 20.0) / (4.0 * 10.0 + 4.0 * 10.0);
        assert!((low.finish(0).tallest_ratio - want).abs() < 1e-6);
    }
}
