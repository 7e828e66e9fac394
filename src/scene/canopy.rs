//! Canopy rasters: streaming and selection (CPU; the GPU pass draws what this
//! picks, `src/render/canopy.rs`; the format is `crate::format::canopy`).
//!
//! The rasters form a quadtree like the terrain's. Each frame
//! [`CanopyTree::select`] walks the resident rasters from the root: a raster in
//! view whose cells project above `cell_px` pixels at its nearest point is
//! replaced by its children once those in view are resident (and asks for the
//! missing ones, nearest first); otherwise it is drawn. Children cover exactly
//! the trees of their parent's square, so the cut never draws a tree's canopy
//! twice. A raster whose every tree projects above `px_hi` (trees drawn whole)
//! is neither drawn nor refined — unless trees the view wants there are not
//! resident yet (a tile still loading, an index node not read, a tile given up
//! on or beyond the pools' reach): then the raster *stands in* for them at full
//! cover, refined like any other, so a view streaming in shows the forest, not
//! bare ground. Memory is bounded by its residency's budget (1,024 rasters;
//! [`super::quadtree::QuadResidency`]: least recently used evicted, never the
//! root nor one used this frame).

use std::sync::Arc;

use glam::{DVec3, Vec3};

use super::quadtree::{QuadKey, QuadLayer, QuadResidency};
use crate::camera::ViewData;
use crate::format::canopy::{Canopy, CanopyEntry, CanopyKey};

/// Most rasters a view draws (the GPU pool's size): a view that would draw
/// more is cut coarser.
pub const MAX_CANOPY_DRAWS: usize = 512;

/// One raster to draw this frame.
#[derive(Debug, Clone)]
pub struct CanopyDraw {
    /// Which raster.
    pub key: CanopyKey,
    /// Its data.
    pub canopy: Arc<Canopy>,
    /// Trees the view wants in its square are not resident: drawn at full
    /// cover whatever the trees' size.
    pub stand_in: bool,
}

/// Whether the square `[x0, y0] + size` meets any of `gaps` (`[x0, y0, x1, y1]`).
fn meets_gap(o: [f64; 2], size: f64, gaps: &[[f32; 4]]) -> bool {
    gaps.iter().any(|g| {
        f64::from(g[0]) < o[0] + size
            && o[0] < f64::from(g[2])
            && f64::from(g[1]) < o[1] + size
            && o[1] < f64::from(g[3])
    })
}

/// The canopy rasters of one scene: what is resident and what a view selects.
#[derive(Debug)]
pub struct CanopyTree {
    entry: CanopyEntry,
    /// The rasters resident, asked for and waited for (at most 1,024 kept, 32 KB
    /// each, 64 KB with their seasons).
    pub res: QuadResidency<Canopy>,
    /// The walk's stack: a raster, and whether it may meet a gap (its parent did).
    stack: Vec<(CanopyKey, bool)>,
}

/// Distance from the eye (origin) to the eye-relative box `lo..hi` at its
/// nearest and farthest points, if it meets the frustum.
fn box_distance(view: &ViewData, lo: Vec3, hi: Vec3) -> Option<(f32, f32)> {
    let (c, h) = ((lo + hi) * 0.5, (hi - lo) * 0.5);
    let visible = view.frustum.iter().all(|p| p.truncate().dot(c) + p.w + p.truncate().abs().dot(h) >= 0.0);
    visible.then(|| ((c.abs() - h).max(Vec3::ZERO).length(), (c.abs() + h).length()))
}

impl CanopyTree {
    /// A tree for the manifest's canopy entry; nothing resident yet.
    #[must_use]
    pub fn new(entry: CanopyEntry) -> Self {
        Self { entry, res: QuadResidency::new(1024), stack: Vec::new() }
    }

    /// The manifest entry.
    #[must_use]
    pub fn entry(&self) -> &CanopyEntry {
        &self.entry
    }

    /// Rasters decoded and kept.
    #[must_use]
    pub fn resident(&self) -> usize {
        self.res.resident()
    }

    /// Whether the root's raster is resident: until then trees are drawn at every size.
    #[must_use]
    pub fn ready(&self) -> bool {
        self.res.get((0, 0, 0)).is_some()
    }

    /// Whether the root's raster is not yet resident nor given up on.
    #[must_use]
    pub fn root_loading(&self) -> bool {
        !self.res.is_done((0, 0, 0))
    }

    /// Stores raster `key`, checked to be the square the key names.
    ///
    /// # Errors
    /// The raster's square or cell count is not the key's.
    pub fn insert(&mut self, key: CanopyKey, canopy: Canopy) -> Result<(), String> {
        check(&self.entry, key, &canopy)?;
        self.res.insert(key, canopy);
        Ok(())
    }

    /// Selects the rasters to draw for `view` (eye at `eye_m` relative to the
    /// scene origin), refining while cells project above `cell_px` pixels
    /// (`px_per_m`: pixels per metre at 1 m, × quality); the rasters to fetch,
    /// nearest first, into `res.wanted`. `gaps` (`[x0, y0, x1, y1]`, metres) are where
    /// trees the view wants are not resident: rasters meeting one stand in.
    #[allow(clippy::too_many_arguments)]
    pub fn select(
        &mut self,
        view: &ViewData,
        eye_m: DVec3,
        px_per_m: f32,
        cell_px: f32,
        px_hi: f32,
        gaps: &[[f32; 4]],
        draws: &mut Vec<CanopyDraw>,
    ) {
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
        stack.push((root, !gaps.is_empty()));
        while let Some((key, may_meet)) = stack.pop() {
            let Some(canopy) = self.res.get(key).cloned() else { continue };
            let low = canopy.height_min_m;
            let Some((d, far)) = self.raster_distance(view, eye_m, key, &canopy) else { continue };
            self.res.use_now(key);
            let (l, x, y) = key;
            // (A raster meets only gaps its parent meets: checked down from the root.)
            let stand_in = may_meet && meets_gap(self.entry.origin_of(l, x, y), self.entry.size_m(l), gaps);
            if low * px_per_m / far.max(1e-3) >= px_hi && !stand_in {
                continue; // every tree here is drawn whole
            }
            // The canopy shows only where its shortest trees are below px_hi:
            // nearer than that its cells' size does not matter (unless it stands in).
            let shown_from = if stand_in { 0.0 } else { low * px_per_m / px_hi };
            let cell_on_screen = canopy.cell_m() * px_per_m / d.max(shown_from).max(1e-3);
            if cell_on_screen > cell_px && canopy.children != 0 && l + 1 < self.entry.levels {
                let mut ready = true;
                for i in 0..4u32 {
                    if canopy.children & (1 << i) == 0 {
                        continue;
                    }
                    let child = (l + 1, 2 * x + (i & 1), 2 * y + (i >> 1));
                    if self.res.use_now(child).is_some() {
                        // Kept while its siblings load (not evicted under them).
                    } else if !self.res.is_unknown(child) {
                        ready = false; // asked for, or given up on
                    } else if let Some((dc, _)) = self.square_distance(view, eye_m, child, &canopy) {
                        // Only children in view are waited for.
                        ready = false;
                        wanted.push((dc, child));
                    }
                }
                if ready {
                    for i in 0..4u32 {
                        if canopy.children & (1 << i) != 0 {
                            stack.push(((l + 1, 2 * x + (i & 1), 2 * y + (i >> 1)), stand_in));
                        }
                    }
                    continue;
                }
            }
            draws.push(CanopyDraw { key, canopy, stand_in });
        }
        wanted.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        self.res.wanted = wanted;
        self.stack = stack;
    }

    /// Nearest and farthest distance of raster `key`'s box (its square from the
    /// lowest ground to the highest tree top), if in view.
    fn raster_distance(&self, view: &ViewData, eye_m: DVec3, key: CanopyKey, c: &Canopy) -> Option<(f32, f32)> {
        let [ox, oy] = self.entry.origin_of(key.0, key.1, key.2);
        let s = self.entry.size_m(key.0);
        let lo = DVec3::new(ox, oy, f64::from(c.z_range_m[0]));
        let hi = DVec3::new(ox + s, oy + s, f64::from(c.z_range_m[1] + c.height_max_m));
        box_distance(view, (lo - eye_m).as_vec3(), (hi - eye_m).as_vec3())
    }

    /// The same for a child not yet read, with its parent's heights.
    fn square_distance(&self, view: &ViewData, eye_m: DVec3, key: CanopyKey, parent: &Canopy) -> Option<(f32, f32)> {
        self.raster_distance(view, eye_m, key, parent)
    }
}

/// Whether `canopy` is the raster of the square `key` names, of the entry's cells.
fn check(entry: &CanopyEntry, key: CanopyKey, canopy: &Canopy) -> Result<(), String> {
    let (l, x, y) = key;
    let [ox, oy] = entry.origin_of(l, x, y);
    let size = entry.size_m(l);
    let near = |a: f64, b: f32| (a - f64::from(b)).abs() <= 1e-3 * size.max(1.0);
    if canopy.cells != entry.cells
        || !near(ox, canopy.origin_m[0])
        || !near(oy, canopy.origin_m[1])
        || !near(size, canopy.size_m)
        || (l + 1 >= entry.levels && canopy.children != 0)
    {
        return Err(format!(
            "raster {l}/{x}/{y} covers {:?} + {} m in {} cells, not the {} m square at {:?} in {}",
            canopy.origin_m,
            canopy.size_m,
            canopy.cells,
            size,
            [ox, oy],
            entry.cells
        ));
    }
    Ok(())
}

impl QuadLayer for CanopyTree {
    type Tile = Canopy;

    fn residency(&self) -> &QuadResidency<Canopy> {
        &self.res
    }

    fn residency_mut(&mut self) -> &mut QuadResidency<Canopy> {
        &mut self.res
    }

    fn url(&self, key: QuadKey) -> String {
        self.entry.raster_url(key.0, key.1, key.2)
    }

    fn decode(&self, url: &str, key: QuadKey, bytes: &[u8]) -> Result<Canopy, String> {
        let canopy = Canopy::decode(url, bytes).map_err(|e| e.to_string())?;
        check(&self.entry, key, &canopy).map_err(|e| format!("{url}: {e}"))?;
        Ok(canopy)
    }
}
