//! Terrain streaming and level selection (CPU; the GPU pass draws what this
//! picks, `src/render/terrain.rs`).
//!
//! The terrain is a quadtree ([`crate::format::terrain`]) whose tiles carry
//! their children's height ranges and errors, so a walk from the root decides
//! every level from data it has. Each frame [`TerrainTree::select`] walks the
//! resident tiles: a tile inside the view frustum whose geometric error,
//! projected at its nearest point, exceeds the threshold (pixels) is replaced
//! by its children once all of them are resident (and asks for the missing
//! ones, nearest first); otherwise it is drawn. A tile whose children have
//! baked ground images of their own is also replaced while a texel of its
//! image projects above the threshold: on flat ground (height errors of 0) the
//! images still sharpen as the camera comes down. The cut is a complete cover of
//! the terrain with data: no tile and its ancestor are both drawn. Work per
//! frame is O(tiles drawn); memory is bounded by its residency's budget (`res.max_resident`)
//! tiles (least recently used evicted, never the root or a tile in use).

use std::sync::Arc;

use glam::{DVec3, Vec3};

use super::quadtree::{QuadKey, QuadLayer, QuadResidency};
use crate::camera::ViewData;
use crate::format::terrain::{TerrainEntry, TerrainTile};

/// A tile's key: (level, x, y).
pub type TerrainKey = super::quadtree::QuadKey;

/// One tile to draw this frame.
#[derive(Debug, Clone)]
pub struct TerrainDraw {
    /// Which tile.
    pub key: TerrainKey,
    /// Its data.
    pub tile: Arc<TerrainTile>,
    /// South-west corner, metres relative to the scene origin.
    pub origin_m: [f64; 2],
    /// Side, metres.
    pub size_m: f64,
    /// The parent's geometric error (metres; infinite for the root).
    pub parent_error_m: f32,
    /// How far the tile has morphed from its parent's surface (0) to its own
    /// (1); see [`morph`].
    pub morph: f32,
    /// The ground image it drapes, if any (attached by the stream's imagery).
    pub imagery: Option<super::imagery::DrawImagery>,
}

/// The terrain of one scene: what is resident and what a view selects.
#[derive(Debug)]
pub struct TerrainTree {
    entry: TerrainEntry,
    /// The tiles resident, asked for and waited for (at most 2,048 kept).
    pub res: QuadResidency<TerrainTile>,
    /// The selection walk's stack, kept between frames (no allocation in steady state).
    stack: Vec<(TerrainKey, f32)>,
}

impl TerrainTree {
    /// A tree for the manifest's terrain entry; nothing resident yet.
    #[must_use]
    pub fn new(entry: TerrainEntry) -> Self {
        Self { entry, res: QuadResidency::new(2048), stack: Vec::new() }
    }

    /// The manifest entry.
    #[must_use]
    pub fn entry(&self) -> &TerrainEntry {
        &self.entry
    }

    /// Tiles decoded and kept.
    #[must_use]
    pub fn resident(&self) -> usize {
        self.res.resident()
    }

    /// Stores a decoded tile (checked to be the tile asked for).
    ///
    /// # Errors
    /// The tile's level or position is not `key`'s.
    pub fn insert(&mut self, key: TerrainKey, tile: TerrainTile) -> Result<(), String> {
        check(&self.entry, key, &tile)?;
        self.res.insert(key, tile);
        Ok(())
    }

    /// The ground height at a point (metres relative to the scene origin) from
    /// the finest resident tile holding it, bilinear; `None` without data.
    #[must_use]
    pub fn height_at(&self, x: f64, y: f64) -> Option<f32> {
        let mut key = (0u8, 0u32, 0u32);
        let mut best = None;
        while let Some(tile) = self.res.get(key) {
            let [ox, oy] = self.entry.tile_origin_m(key.0, key.1, key.2);
            let size = self.entry.tile_size_m(key.0);
            let (u, v) = ((x - ox) / size, (y - oy) / size);
            if !(0.0..=1.0).contains(&u) || !(0.0..=1.0).contains(&v) {
                break;
            }
            if let Some(h) = sample(tile, u, v) {
                best = Some(h);
            }
            if key.0 + 1 >= self.entry.levels {
                break;
            }
            let (cx, cy) = (u32::from(u >= 0.5), u32::from(v >= 0.5));
            key = (key.0 + 1, 2 * key.1 + cx, 2 * key.2 + cy);
        }
        best
    }

    /// Selects the tiles to draw for `view` (eye at `eye_m`, relative to the
    /// scene origin) at `threshold_px` pixels of geometric error; the tiles
    /// to fetch, nearest first, into `res.wanted`.
    pub fn select(&mut self, view: &ViewData, eye_m: DVec3, threshold_px: f32, draws: &mut Vec<TerrainDraw>) {
        self.res.next_frame();
        draws.clear();
        let mut wanted = std::mem::take(&mut self.res.wanted);
        wanted.clear();
        let root = (0u8, 0u32, 0u32);
        if self.res.is_unknown(root) {
            wanted.push((0.0, root));
        }
        let mut stack = std::mem::take(&mut self.stack);
        stack.clear();
        stack.push((root, f32::INFINITY));
        while let Some((key, parent_error)) = stack.pop() {
            let Some(tile) = self.res.use_now(key) else { continue };
            let (origin, size) = (self.entry.tile_origin_m(key.0, key.1, key.2), self.entry.tile_size_m(key.0));
            let lo = DVec3::new(origin[0], origin[1], f64::from(tile.min_m));
            let hi = DVec3::new(origin[0] + size, origin[1] + size, f64::from(tile.max_m));
            if !box_visible(view, lo - eye_m, hi - eye_m) {
                continue;
            }
            let distance = box_distance(lo - eye_m, hi - eye_m).max(1e-3) as f32;
            let error_px = tile.error_m * view.px_per_m_at_1m / distance;
            // A texel of its image, where its children have finer images.
            let texel_px = if self.entry.has_finer_imagery_below(key.0, key.1, key.2) {
                (size / f64::from(crate::format::terrain::IMAGERY_PX)) as f32 * view.px_per_m_at_1m / distance
            } else {
                0.0
            };
            // The existing children (at most four, no allocation).
            let mut kids = [((0u8, 0u32, 0u32), 0usize); 4];
            let mut n = 0;
            for k in 0..4 {
                if tile.children[k].exists && key.0 + 1 < self.entry.levels {
                    kids[n] = ((key.0 + 1, 2 * key.1 + (k as u32 & 1), 2 * key.2 + (k as u32 >> 1)), k);
                    n += 1;
                }
            }
            let children = &kids[..n];
            let refine = error_px.max(texel_px) > threshold_px && !children.is_empty();
            let ready = children.iter().all(|&(c, _)| self.res.is_done(c));
            let any_broken = children.iter().any(|&(c, _)| self.res.is_broken(c));
            if refine && ready && !any_broken {
                for &(c, _) in children {
                    stack.push((c, tile.error_m));
                }
                continue;
            }
            if refine {
                for &(c, k) in children {
                    if self.res.is_unknown(c) {
                        let s = self.entry.tile_size_m(c.0);
                        let o = self.entry.tile_origin_m(c.0, c.1, c.2);
                        let info = tile.children[k];
                        let clo = DVec3::new(o[0], o[1], f64::from(info.min_m)) - eye_m;
                        let chi = DVec3::new(o[0] + s, o[1] + s, f64::from(info.max_m)) - eye_m;
                        wanted.push((box_distance(clo, chi) as f32, c));
                    }
                }
            }
            let morph = morph(parent_error, tile.error_m, view.px_per_m_at_1m / distance, threshold_px);
            draws.push(TerrainDraw {
                key,
                tile,
                origin_m: origin,
                size_m: size,
                parent_error_m: parent_error,
                morph,
                imagery: None,
            });
        }
        wanted.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        self.res.wanted = wanted;
        self.stack = stack;
    }
}

/// Whether `tile` is the tile `key` names, of the entry's grid.
fn check(entry: &TerrainEntry, key: TerrainKey, tile: &TerrainTile) -> Result<(), String> {
    if (tile.level, tile.x, tile.y) != key || tile.grid != entry.grid {
        return Err(format!(
            "terrain tile {}/{}/{} (grid {}) where {}/{}/{} (grid {}) was asked for",
            tile.level, tile.x, tile.y, tile.grid, key.0, key.1, key.2, entry.grid
        ));
    }
    Ok(())
}

impl QuadLayer for TerrainTree {
    type Tile = TerrainTile;

    fn residency(&self) -> &QuadResidency<TerrainTile> {
        &self.res
    }

    fn residency_mut(&mut self) -> &mut QuadResidency<TerrainTile> {
        &mut self.res
    }

    fn url(&self, key: QuadKey) -> String {
        self.entry.tile_url(key.0, key.1, key.2)
    }

    fn decode(&self, url: &str, key: QuadKey, bytes: &[u8]) -> Result<TerrainTile, String> {
        let tile = TerrainTile::decode(url, bytes).map_err(|e| e.to_string())?;
        check(&self.entry, key, &tile).map_err(|e| format!("{url}: {e}"))?;
        Ok(tile)
    }
}

/// The morph of a drawn tile (CDLOD-style geomorphing, one value per tile):
/// 0 shows its parent's surface, 1 its own. It is measured at the tile's box
/// nearest the eye — the distance the selection uses — and runs from where
/// the parent was replaced by this tile (the parent's error projects to the
/// threshold: 0) to where this tile will be replaced by its children (its own
/// error at the threshold), or half that distance if sooner. So at every level
/// change the children start on their parent's surface and the parent has
/// become wholly itself: nothing pops. (A per-vertex morph by distance cannot
/// promise this when errors do not halve per level: a large tile's far
/// vertices would still be morphing when it splits.) Neighbours of one level
/// may morph by different amounts; the skirts cover the step between them.
/// `px_per_m` is pixels per metre at the box's distance.
#[must_use]
pub fn morph(parent_error_m: f32, error_m: f32, px_per_m: f32, threshold_px: f32) -> f32 {
    if !parent_error_m.is_finite() || parent_error_m <= 0.0 {
        return 1.0;
    }
    let parent_px = parent_error_m * px_per_m;
    let own_share = (error_m / parent_error_m).clamp(0.5, 1.0);
    if own_share >= 1.0 {
        return if parent_px > threshold_px { 1.0 } else { 0.0 };
    }
    ((1.0 - threshold_px.max(1e-3) / parent_px.max(1e-9)) / (1.0 - own_share)).clamp(0.0, 1.0)
}

/// Bilinear height of a tile at fractional position `(u, v)` in `[0, 1]²`.
fn sample(tile: &TerrainTile, u: f64, v: f64) -> Option<f32> {
    let n = f64::from(tile.grid);
    let (fu, fv) = (u * n, v * n);
    let (i0, j0) =
        ((fu.floor() as usize).min(tile.grid as usize - 1), (fv.floor() as usize).min(tile.grid as usize - 1));
    let (a, b) = ((fu - i0 as f64) as f32, (fv - j0 as f64) as f32);
    let mut sum = 0.0;
    let mut weight = 0.0;
    for (di, dj, w) in [(0, 0, (1.0 - a) * (1.0 - b)), (1, 0, a * (1.0 - b)), (0, 1, (1.0 - a) * b), (1, 1, a * b)] {
        if let Some(h) = tile.height(i0 + di, j0 + dj) {
            if w > 0.0 {
                sum += h * w;
                weight += w;
            }
        }
    }
    (weight > 0.0).then(|| sum / weight)
}

/// Whether the eye-relative box `lo..hi` meets the view frustum.
fn box_visible(view: &ViewData, lo: DVec3, hi: DVec3) -> bool {
    let c = ((lo + hi) * 0.5).as_vec3();
    let h = ((hi - lo) * 0.5).as_vec3();
    view.frustum.iter().all(|p| {
        let n = Vec3::new(p.x, p.y, p.z);
        n.dot(c) + p.w + n.abs().dot(h) >= 0.0
    })
}

/// Distance from the eye (the origin) to the eye-relative box `lo..hi`.
fn box_distance(lo: DVec3, hi: DVec3) -> f64 {
    let c = (lo + hi) * 0.5;
    let h = (hi - lo) * 0.5;
    (c.abs() - h).max(DVec3::ZERO).length()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;
    use crate::format::terrain::{quantise, TerrainChild};

    /// A full quadtree of `levels` over a 1024 m root at the origin, heights
    /// 0–10 m, errors halving per level (the finest 0).
    fn tree(levels: u8) -> TerrainTree {
        tree_with(levels, &|l| if l + 1 == levels { 0.0 } else { 8.0 / f32::from(1u8 << l) }, None)
    }

    /// The same with errors `error(level)` and baked imagery of `imagery` levels over the whole square.
    fn tree_with(levels: u8, error: &dyn Fn(u8) -> f32, imagery: Option<u8>) -> TerrainTree {
        let imagery = imagery.map(|levels| crate::format::terrain::ImageryEntry {
            path: "terrain/img".into(),
            tile_px: crate::format::terrain::IMAGERY_PX,
            levels,
            extent_m: [0.0, 0.0, 1024.0, 1024.0],
            resolution_m: 0.5,
            tiles: 0,
            bytes: 0,
            source: "test".into(),
        });
        let entry = TerrainEntry {
            path: "terrain".into(),
            origin_m: [0.0, 0.0],
            root_size_m: 1024.0,
            grid: 4,
            levels,
            resolution_m: 1024.0 / 4.0 / f64::from(1u32 << (levels - 1)),
            height_range_m: [0.0, 10.0],
            tiles: 0,
            bytes: 0,
            source: "test".into(),
            imagery,
        };
        let mut t = TerrainTree::new(entry);
        for l in 0..levels {
            for x in 0..(1u32 << l) {
                for y in 0..(1u32 << l) {
                    let child = TerrainChild { exists: l + 1 < levels, min_m: 0.0, max_m: 10.0, error_m: error(l + 1) };
                    let tile = TerrainTile {
                        level: l,
                        x,
                        y,
                        grid: 4,
                        min_m: 0.0,
                        max_m: 10.0,
                        error_m: error(l),
                        children: [if l + 1 < levels { child } else { TerrainChild::default() }; 4],
                        heights: (0..25).map(|i| quantise(i as f32 * 0.4, 0.0, 10.0)).collect(),
                    };
                    t.insert((l, x, y), tile).unwrap();
                }
            }
        }
        t
    }

    fn view_from(eye: DVec3, target: DVec3) -> (ViewData, DVec3) {
        let cam = Camera::look_at(eye, target);
        (cam.view_data(640, 360), eye)
    }

    #[test]
    fn a_tile_starts_on_its_parents_surface_and_is_itself_before_it_splits() {
        // Parent error 8 m, own 6 m, threshold 2 px: the parent split where
        // 8 m projected to 2 px; this tile splits where 6 m does.
        let at = |px_per_m: f32| morph(8.0, 6.0, px_per_m, 2.0);
        assert_eq!(at(2.0 / 8.0), 0.0);
        assert!((at(2.0 / 6.0) - 1.0).abs() < 1e-6);
        let mid = at(2.0 / 7.0);
        assert!(mid > 0.2 && mid < 0.8, "{mid}");
        // Errors that halve: CDLOD's range, done at twice the parent's projection.
        assert!((morph(8.0, 1.0, 4.0 / 8.0, 2.0) - 1.0).abs() < 1e-6);
        assert!(morph(8.0, 1.0, 3.0 / 8.0, 2.0) < 1.0);
        // The root has no parent; a leaf with its parent's error switches at once.
        assert_eq!(morph(f32::INFINITY, 3.0, 0.01, 2.0), 1.0);
        assert_eq!(morph(4.0, 4.0, 1.0, 2.0), 1.0);
    }

    #[test]
    fn the_selection_is_a_complete_cover_refined_near_the_eye() {
        let mut t = tree(5);
        // From the south, high enough to see the whole square, at a threshold
        // between level 2's error seen at the near (south) and far (north) edges.
        let (view, eye) = view_from(DVec3::new(512.0, -1500.0, 1200.0), DVec3::new(512.0, 512.0, 0.0));
        let (near_d, far_d) = (1500f32.hypot(1190.0), 2524f32.hypot(1190.0));
        let threshold = 2.0 * view.px_per_m_at_1m / (near_d * far_d).sqrt();
        let mut draws = Vec::new();
        t.select(&view, eye, threshold, &mut draws);
        assert!(t.res.wanted.is_empty(), "everything is resident");
        // No tile drawn with one of its ancestors, and the drawn squares cover
        // the root exactly (areas add up; the whole square is in view).
        let area: f64 = draws.iter().map(|d| d.size_m * d.size_m).sum();
        assert!((area - 1024.0 * 1024.0).abs() < 1e-6, "covered {area} m²");
        for a in &draws {
            for b in &draws {
                if a.key.0 < b.key.0 {
                    let shift = b.key.0 - a.key.0;
                    assert!(
                        (b.key.1 >> shift, b.key.2 >> shift) != (a.key.1, a.key.2),
                        "{:?} under {:?}",
                        b.key,
                        a.key
                    );
                }
            }
        }
        // Finer near the eye (the south edge), coarser far (the north edge).
        let level_at = |x: f64, y: f64| {
            let d = draws.iter().find(|d| {
                (d.origin_m[0]..d.origin_m[0] + d.size_m).contains(&x)
                    && (d.origin_m[1]..d.origin_m[1] + d.size_m).contains(&y)
            });
            d.unwrap().key.0
        };
        assert!(
            level_at(512.0, 10.0) > level_at(512.0, 1000.0),
            "near {} far {}",
            level_at(512.0, 10.0),
            level_at(512.0, 1000.0)
        );
        // The error of every drawn tile projects within the threshold, or it is the finest.
        for d in &draws {
            let lo = DVec3::new(d.origin_m[0], d.origin_m[1], 0.0) - eye;
            let hi = DVec3::new(d.origin_m[0] + d.size_m, d.origin_m[1] + d.size_m, 10.0) - eye;
            let px = d.tile.error_m * view.px_per_m_at_1m / box_distance(lo, hi).max(1e-3) as f32;
            assert!(px <= threshold || d.key.0 == 4, "{:?}: {px} px", d.key);
        }
        // Close to the ground the tile under the eye is the finest level.
        let (low, eye_low) = view_from(DVec3::new(100.0, 100.0, 15.0), DVec3::new(300.0, 300.0, 0.0));
        t.select(&low, eye_low, 2.0, &mut draws);
        assert!(draws.iter().any(|d| d.key.0 == 4), "{:?}", draws.iter().map(|d| d.key).collect::<Vec<_>>());
        // Looking away from the square, nothing is drawn.
        let (away, eye) = view_from(DVec3::new(-50.0, -50.0, 200.0), DVec3::new(-500.0, -500.0, 150.0));
        t.select(&away, eye, 2.0, &mut draws);
        assert!(draws.is_empty(), "{} tiles behind the camera", draws.len());
    }

    /// Flat ground (every error 0) with images of 3 levels: the images still
    /// sharpen near the eye (their texels project above the threshold), and
    /// the selection stops at the finest image level (nothing finer to show).
    #[test]
    fn flat_ground_refines_while_finer_images_sharpen_it() {
        let mut t = tree_with(5, &|_| 0.0, Some(3));
        let mut draws = Vec::new();
        // High above: a texel of the root's image (4 m) is under 2 px.
        let (high, eye) = view_from(DVec3::new(512.0, 512.0, 20_000.0), DVec3::new(512.0, 513.0, 0.0));
        t.select(&high, eye, 2.0, &mut draws);
        assert_eq!(draws.iter().map(|d| d.key).collect::<Vec<_>>(), vec![(0, 0, 0)]);
        // Low over the ground: level 2 (the finest images) under the eye, nothing finer.
        let (low, eye) = view_from(DVec3::new(100.0, 100.0, 15.0), DVec3::new(300.0, 300.0, 0.0));
        t.select(&low, eye, 2.0, &mut draws);
        let levels: Vec<u8> = draws.iter().map(|d| d.key.0).collect();
        assert!(levels.contains(&2) && levels.iter().all(|&l| l <= 2), "{levels:?}");
        // Without imagery the same flat ground is one tile wherever the eye is.
        let mut bare = tree_with(5, &|_| 0.0, None);
        bare.select(&low, eye, 2.0, &mut draws);
        assert_eq!(draws.iter().map(|d| d.key).collect::<Vec<_>>(), vec![(0, 0, 0)]);
    }

    #[test]
    fn missing_children_are_wanted_nearest_first_and_their_parent_drawn() {
        let full = tree(3);
        let mut t = TerrainTree::new(full.entry.clone());
        for l in 0..2u8 {
            for x in 0..1u32 << l {
                for y in 0..1u32 << l {
                    t.insert((l, x, y), (**full.res.get((l, x, y)).unwrap()).clone()).unwrap();
                }
            }
        }
        let (view, eye) = view_from(DVec3::new(10.0, 10.0, 30.0), DVec3::new(300.0, 300.0, 0.0));
        let mut draws = Vec::new();
        t.select(&view, eye, 2.0, &mut draws);
        assert!(draws.iter().all(|d| d.key.0 <= 1), "only resident levels are drawn");
        let wanted = &t.res.wanted;
        assert!(!wanted.is_empty() && wanted.iter().all(|w| w.1 .0 == 2));
        assert!(wanted.windows(2).all(|w| w[0].0 <= w[1].0), "nearest first");
        assert_eq!(wanted[0].1, (2, 0, 0), "the tile under the eye first");
        // A broken child keeps its parent drawn.
        t.res.mark_broken((2, 0, 0));
        t.select(&view, eye, 2.0, &mut draws);
        assert!(draws.iter().any(|d| d.key == (1, 0, 0)));
    }

    #[test]
    fn heights_come_from_the_finest_resident_tile_and_eviction_keeps_the_root() {
        let mut t = tree(3);
        // Heights rise 0.4 m per vertex index (row-major): vertex (i, j) = (5j + i)·0.4.
        let h = t.height_at(0.0, 0.0).unwrap();
        assert!(h.abs() < 1e-3);
        let size = 1024.0 / 4.0 / 4.0; // level 2 cell
        let h = t.height_at(size, 0.0).unwrap();
        assert!((h - 0.4).abs() < 1e-3, "{h}");
        assert_eq!(t.height_at(-1.0, 5.0), None);
        // Over a budget of 3 (a tile stored triggers the eviction), the root stays.
        t.res.max_resident = 3;
        t.res.next_frame();
        t.insert((0, 0, 0), (*full_root(&t)).clone()).unwrap();
        assert_eq!(t.resident(), 3);
        assert!(t.res.get((0, 0, 0)).is_some());
        let _ = t.insert((0, 0, 0), TerrainTile { level: 1, ..(*full_root(&t)).clone() }).unwrap_err();
    }

    fn full_root(t: &TerrainTree) -> Arc<TerrainTile> {
        Arc::clone(t.res.get((0, 0, 0)).expect("no root"))
    }
}
