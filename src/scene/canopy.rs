//! Canopy rasters: streaming and selection (CPU; the GPU pass draws what this
//! picks, `src/render/canopy.rs`; the format is `crate::format::canopy`).
//!
//! Every index node (and a flat scene) has a raster of its trees seen from
//! far away. Each frame [`CanopyTree::select`] walks the known nodes from the
//! root like the terrain's quadtree: a resident raster in view whose cells
//! project above `cell_px` pixels at its nearest point is replaced by its
//! children's once those in view are resident (and asks for the missing ones,
//! nearest first); otherwise it is drawn. A node's children cover exactly its
//! trees, so the cut never draws a tree's canopy twice. Memory is bounded by
//! [`CanopyTree::max_resident`] rasters (least recently used evicted, never
//! the root nor one drawn this frame).

use std::collections::HashMap;
use std::sync::Arc;

use glam::Vec3;

use super::index_walk::{IndexWalk, NodeContent};
use crate::camera::ViewData;
use crate::format::canopy::Canopy;
use crate::format::Bounds;

/// One raster to draw this frame.
#[derive(Debug, Clone)]
pub struct CanopyDraw {
    /// The index node it belongs to (0: the root).
    pub node: usize,
    /// Its data.
    pub canopy: Arc<Canopy>,
}

#[derive(Debug, Clone)]
enum Slot {
    Loading,
    Broken,
    /// `low`: its cells' lowest mean tree height (m).
    Resident {
        canopy: Arc<Canopy>,
        low: f32,
        used: u64,
    },
}

/// The canopy rasters of one scene: what is resident and what a view selects.
#[derive(Debug)]
pub struct CanopyTree {
    slots: HashMap<usize, Slot>,
    frame: u64,
    stack: Vec<usize>,
    /// Most rasters kept decoded (32 KB each).
    pub max_resident: usize,
}

impl Default for CanopyTree {
    fn default() -> Self {
        Self { slots: HashMap::new(), frame: 0, stack: Vec::new(), max_resident: 1024 }
    }
}

/// Distance from the eye to a box's nearest and farthest points, if it meets the frustum.
fn box_distance(view: &ViewData, b: &Bounds) -> Option<(f32, f32)> {
    let eye = view.eye_hi + view.eye_lo;
    let (lo, hi) = (Vec3::from(b.min) - eye, Vec3::from(b.max) - eye);
    let (c, h) = ((lo + hi) * 0.5, (hi - lo) * 0.5);
    let visible = view.frustum.iter().all(|p| p.truncate().dot(c) + p.w + p.truncate().abs().dot(h) >= 0.0);
    visible.then(|| ((c.abs() - h).max(Vec3::ZERO).length(), (c.abs() + h).length()))
}

impl CanopyTree {
    /// Rasters decoded and kept.
    #[must_use]
    pub fn resident(&self) -> usize {
        self.slots.values().filter(|s| matches!(s, Slot::Resident { .. })).count()
    }

    /// Whether the root's raster is resident: until then trees are drawn at every size.
    #[must_use]
    pub fn ready(&self) -> bool {
        matches!(self.slots.get(&0), Some(Slot::Resident { .. }))
    }

    /// Whether the root's raster is not yet resident nor given up on.
    #[must_use]
    pub fn root_loading(&self) -> bool {
        !matches!(self.slots.get(&0), Some(Slot::Resident { .. } | Slot::Broken))
    }

    /// Whether node `n`'s raster is neither resident, requested nor broken.
    #[must_use]
    pub fn is_unknown(&self, n: usize) -> bool {
        !self.slots.contains_key(&n)
    }

    /// Marks node `n`'s raster as requested.
    pub fn mark_loading(&mut self, n: usize) {
        self.slots.insert(n, Slot::Loading);
    }

    /// Gives up on node `n`'s raster (its parent's is drawn instead).
    pub fn mark_broken(&mut self, n: usize) {
        self.slots.insert(n, Slot::Broken);
    }

    /// Forgets a failed request so it is asked for again.
    pub fn forget(&mut self, n: usize) {
        self.slots.remove(&n);
    }

    /// Stores node `n`'s decoded raster.
    pub fn insert(&mut self, n: usize, canopy: Canopy) {
        let low = canopy.min_height_m();
        self.slots.insert(n, Slot::Resident { canopy: Arc::new(canopy), low, used: self.frame });
        self.evict();
    }

    /// Selects the rasters to draw for `view` over the nodes `walk` knows,
    /// refining while cells project above `cell_px` pixels (`px_per_m`: pixels
    /// per metre at 1 m), and appends the rasters to fetch (nearest first).
    /// A node whose every tree projects above `px_hi` pixels (trees drawn
    /// whole) is neither drawn nor refined.
    #[allow(clippy::too_many_arguments)]
    pub fn select(
        &mut self,
        view: &ViewData,
        px_per_m: f32,
        walk: &IndexWalk,
        cell_px: f32,
        px_hi: f32,
        draws: &mut Vec<CanopyDraw>,
        wanted: &mut Vec<(f32, usize)>,
    ) {
        self.frame += 1;
        draws.clear();
        if walk.nodes_known() == 0 || walk.node(0).canopy.is_none() {
            return;
        }
        if self.is_unknown(0) {
            wanted.push((0.0, 0));
        }
        let mut stack = std::mem::take(&mut self.stack);
        stack.clear();
        stack.push(0);
        while let Some(n) = stack.pop() {
            let frame = self.frame;
            let Some(Slot::Resident { canopy, low, used }) = self.slots.get_mut(&n) else { continue };
            let info = walk.node(n);
            let Some((d, far)) = box_distance(view, &info.bounds) else { continue };
            *used = frame;
            if *low * px_per_m / far.max(1e-3) >= px_hi {
                continue; // every tree below is drawn whole: no canopy there
            }
            let canopy = Arc::clone(canopy);
            let cell_on_screen = canopy.cell_m() * px_per_m / d.max(1e-3);
            let children: &[usize] = match &info.content {
                NodeContent::Loaded { children, .. } => children,
                NodeContent::Unloaded => &[],
            };
            if cell_on_screen > cell_px && !children.is_empty() {
                let mut ready = true;
                for &c in children {
                    let child = walk.node(c);
                    let Some((dc, _)) = box_distance(view, &child.bounds) else { continue };
                    match self.slots.get(&c) {
                        Some(Slot::Resident { .. }) => {}
                        Some(Slot::Broken) => ready = false,
                        Some(Slot::Loading) => ready = false,
                        None if child.canopy.is_some() => {
                            ready = false;
                            wanted.push((dc, c));
                        }
                        None => ready = false,
                    }
                }
                if ready {
                    stack.extend(children.iter().copied());
                    continue;
                }
            }
            draws.push(CanopyDraw { node: n, canopy });
        }
        wanted.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        self.stack = stack;
    }

    /// Drops the least recently used rasters beyond [`Self::max_resident`]
    /// (never the root, never one used this frame).
    fn evict(&mut self) {
        let resident = self.resident();
        if resident <= self.max_resident {
            return;
        }
        let mut old: Vec<(u64, usize)> = self
            .slots
            .iter()
            .filter_map(|(&n, s)| match s {
                Slot::Resident { used, .. } if n > 0 && *used < self.frame => Some((*used, n)),
                _ => None,
            })
            .collect();
        // Oldest first; of one frame the deepest (highest id: children follow parents) first.
        old.sort_unstable_by_key(|&(used, n)| (used, std::cmp::Reverse(n)));
        for (_, n) in old.into_iter().take(resident - self.max_resident) {
            self.slots.remove(&n);
        }
    }
}
