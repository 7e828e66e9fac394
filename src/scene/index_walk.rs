//! Walking the tile index for a view: which index nodes to fetch and which
//! tiles the view wants. Independent of the renderer and of fetching, so it is
//! tested against a brute-force oracle.

use glam::Vec3;

use crate::camera::ViewData;
use crate::format::index::IndexNode;
use crate::format::{Bounds, Manifest, TileEntry};

/// Where a node stands.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum NodeContent {
    /// Not read yet.
    Unloaded,
    /// Read: its children (node ids) and tiles (tile ids).
    Loaded { children: Vec<usize>, tiles: Vec<usize> },
}

/// One node of the index as the walker knows it.
#[derive(Debug, Clone)]
pub(crate) struct NodeInfo {
    /// URL relative to the manifest.
    pub url: String,
    /// Bounds its parent declared.
    pub bounds: Bounds,
    /// Trees its parent declared.
    pub trees: u64,
    /// Loaded or not.
    pub content: NodeContent,
    /// The tallest tree below it, metres, when known (its parent's entry, or
    /// once it is loaded).
    pub height_m: Option<f32>,
}

/// Where far trees give way to the canopy rasters (set only while the
/// scene's canopy is drawn): a node or tile whose tallest tree projects below
/// `px_lo` pixels at its nearest point is drawn by the canopy alone, so the
/// walk neither reads nor fetches it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CanopyGate {
    /// Pixels per metre at 1 m, × quality.
    pub px_per_m: f32,
    /// Projected tree height (px) below which the canopy stands in for every tree.
    pub px_lo: f32,
}

impl CanopyGate {
    /// Whether the canopy alone draws a node at distance `d`.
    fn covers_node(&self, info: &NodeInfo, d: f32) -> bool {
        info.height_m.is_some_and(|h| h * self.px_per_m / d.max(1e-3) < self.px_lo)
    }

    /// Whether the canopy alone draws a tile at distance `d`.
    fn covers_tile(&self, t: &TileEntry, d: f32) -> bool {
        t.levels.as_ref().is_some_and(|l| l.height_m * self.px_per_m / d.max(1e-3) < self.px_lo)
    }
}

/// Ids with their distance from the eye, nearest first.
pub type ByDistance = Vec<(f32, usize)>;

/// The part of the index read so far.
#[derive(Debug, Clone, Default)]
pub struct IndexWalk {
    pub(crate) nodes: Vec<NodeInfo>,
    /// Every tile known so far (from the flat list or loaded leaves).
    pub tiles: Vec<TileEntry>,
    declared_nodes: u64,
}

/// Distance from the eye to a box, and whether it meets the frustum; `None`
/// when it does not or lies beyond `reach` (plus `margin`).
fn box_distance(view: &ViewData, b: &Bounds, reach: f32, margin: f32) -> Option<f32> {
    let eye = view.eye_hi + view.eye_lo;
    let lo = Vec3::from(b.min) - eye - Vec3::splat(margin);
    let hi = Vec3::from(b.max) - eye + Vec3::splat(margin);
    let (c, h) = ((lo + hi) * 0.5, (hi - lo) * 0.5);
    let visible = view.frustum.iter().all(|p| p.truncate().dot(c) + p.w + p.truncate().abs().dot(h) >= 0.0);
    let d = (c.abs() - h).max(Vec3::ZERO).length();
    (visible && d <= reach + margin).then_some(d)
}

/// The tallest tree of `tiles` (`None` if any tile does not say).
fn tallest(tiles: &[TileEntry]) -> Option<f32> {
    tiles.iter().try_fold(0f32, |h, t| t.levels.as_ref().map(|l| h.max(l.height_m)))
}

/// Whether the view wants a tile with bounds `b` (the oracle's rule too).
#[must_use]
pub fn tile_wanted(view: &ViewData, b: &Bounds, draw_distance_m: f32) -> Option<f32> {
    box_distance(view, b, draw_distance_m, 0.0)
}

impl IndexWalk {
    /// The index of a manifest: its flat list as one loaded root, or its root node unread.
    #[must_use]
    pub fn new(m: &Manifest) -> Self {
        match &m.index {
            Some(index) => Self {
                nodes: vec![NodeInfo {
                    url: index.root.clone(),
                    bounds: m.bounds,
                    trees: m.counts.trees,
                    content: NodeContent::Unloaded,
                    height_m: None,
                }],
                tiles: Vec::new(),
                declared_nodes: index.nodes,
            },
            None => Self {
                nodes: vec![NodeInfo {
                    url: String::new(),
                    bounds: m.bounds,
                    trees: m.counts.trees,
                    content: NodeContent::Loaded { children: Vec::new(), tiles: (0..m.tiles.len()).collect() },
                    height_m: tallest(&m.tiles),
                }],
                tiles: m.tiles.clone(),
                declared_nodes: 0,
            },
        }
    }

    /// Nodes read so far (0 for a flat manifest).
    #[must_use]
    pub fn nodes_loaded(&self) -> u64 {
        if self.declared_nodes == 0 {
            return 0;
        }
        self.nodes.iter().filter(|n| matches!(n.content, NodeContent::Loaded { .. })).count() as u64
    }

    /// Nodes the manifest declares (0 for a flat manifest).
    #[must_use]
    pub fn nodes_declared(&self) -> u64 {
        self.declared_nodes
    }

    /// URL of node `n`.
    #[must_use]
    pub fn node_url(&self, n: usize) -> &str {
        &self.nodes[n].url
    }

    /// Walks the nodes that meet the view: returns the wanted tiles and the
    /// unread nodes to fetch, each as (distance, id), nearest first.
    #[must_use]
    pub fn walk(&self, view: &ViewData, draw_distance_m: f32) -> (ByDistance, ByDistance) {
        let (mut tiles, mut fetch, mut stack) = (Vec::new(), Vec::new(), Vec::new());
        self.walk_into(view, draw_distance_m, None, &mut tiles, &mut fetch, &mut stack);
        (tiles, fetch)
    }

    /// [`Self::walk`] into the caller's buffers (cleared first): no allocation
    /// once they have grown to the view's size.
    pub fn walk_into(
        &self,
        view: &ViewData,
        draw_distance_m: f32,
        canopy: Option<&CanopyGate>,
        tiles: &mut ByDistance,
        fetch: &mut ByDistance,
        stack: &mut Vec<usize>,
    ) {
        tiles.clear();
        fetch.clear();
        stack.clear();
        if self.nodes.is_empty() {
            return;
        }
        stack.push(0);
        // A small margin keeps float rounding from dropping a tile on a node's edge.
        let margin = 0.01 + 1e-6 * draw_distance_m.min(1e6);
        while let Some(n) = stack.pop() {
            let node = &self.nodes[n];
            let Some(d) = box_distance(view, &node.bounds, draw_distance_m, margin) else { continue };
            // Where the canopy alone draws the node, neither it nor its tiles are read.
            if canopy.is_some_and(|g| g.covers_node(node, d)) {
                continue;
            }
            match &node.content {
                NodeContent::Unloaded => fetch.push((d, n)),
                NodeContent::Loaded { children, tiles: ts } => {
                    stack.extend(children);
                    for &t in ts {
                        if let Some(d) = tile_wanted(view, &self.tiles[t].bounds, draw_distance_m) {
                            if !canopy.is_some_and(|g| g.covers_tile(&self.tiles[t], d)) {
                                tiles.push((d, t));
                            }
                        }
                    }
                }
            }
        }
        // Unstable sorts do not allocate; ids break ties, so the order is fixed.
        let order = |a: &(f32, usize), b: &(f32, usize)| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1));
        tiles.sort_unstable_by(order);
        fetch.sort_unstable_by(order);
    }

    /// Reads node `n` from `bytes`; returns the ids of the tiles it adds.
    ///
    /// # Errors
    /// A message when the bytes do not decode, the node does not match what its
    /// parent declared, or the index grows past the node count it declared.
    pub fn load_node(&mut self, n: usize, file: &str, bytes: &[u8]) -> Result<std::ops::Range<usize>, String> {
        let node = IndexNode::decode(file, bytes).map_err(|e| e.to_string())?;
        let expected = &self.nodes[n];
        if node.trees != expected.trees {
            return Err(format!("{file}: holds {} trees, its parent says {}", node.trees, expected.trees));
        }
        let inside = (0..3).all(|k| {
            expected.bounds.min[k] <= node.bounds.min[k] + 1e-3 && node.bounds.max[k] <= expected.bounds.max[k] + 1e-3
        });
        if !inside {
            return Err(format!("{file}: bounds {:?} leave its parent's {:?}", node.bounds, expected.bounds));
        }
        if self.nodes.len() as u64 + node.children.len() as u64 > self.declared_nodes {
            return Err(format!(
                "{file}: the index has more nodes than the {} the manifest declares",
                self.declared_nodes
            ));
        }
        for c in &node.children {
            let inside = (0..3)
                .all(|k| node.bounds.min[k] <= c.bounds.min[k] + 1e-3 && c.bounds.max[k] <= node.bounds.max[k] + 1e-3);
            if !inside {
                return Err(format!("{file}: child {} leaves the node's bounds", c.url));
            }
        }
        let first_tile = self.tiles.len();
        let mut children = Vec::with_capacity(node.children.len());
        let height =
            tallest(&node.tiles).and_then(|h0| node.children.iter().try_fold(h0, |h, c| c.height_m.map(|x| h.max(x))));
        if self.nodes[n].height_m.is_none() {
            self.nodes[n].height_m = height;
        }
        for c in node.children {
            children.push(self.nodes.len());
            self.nodes.push(NodeInfo {
                url: c.url,
                bounds: c.bounds,
                trees: c.trees,
                content: NodeContent::Unloaded,
                height_m: c.height_m,
            });
        }
        // Tiles must lie inside the node's bounds too, or the walk could miss them.
        for t in &node.tiles {
            let inside = (0..3)
                .all(|k| node.bounds.min[k] <= t.bounds.min[k] + 1e-3 && t.bounds.max[k] <= node.bounds.max[k] + 1e-3);
            if !inside {
                return Err(format!("{file}: tile ({}, {}) leaves the node's bounds", t.x, t.y));
            }
        }
        self.tiles.extend(node.tiles);
        let tiles = (first_tile..self.tiles.len()).collect();
        self.nodes[n].content = NodeContent::Loaded { children, tiles };
        Ok(first_tile..self.tiles.len())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;
    use crate::format::index::build_index;
    use crate::format::{Counts, Crs};
    use glam::DVec3;

    fn scene(n: i32) -> (Manifest, Vec<TileEntry>) {
        let mut tiles = Vec::new();
        let mut rng = 12345u64;
        for y in -n..n {
            for x in -n..n {
                rng = rng.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                if rng >> 60 == 0 {
                    continue; // holes, like lakes
                }
                let (fx, fy) = (x as f32 * 512.0, y as f32 * 512.0);
                let z = ((rng >> 40) % 300) as f32;
                // Trees overhang their tile by a few metres, as real crowns do.
                tiles.push(TileEntry {
                    x,
                    y,
                    url: format!("tiles/{x}_{y}.tile"),
                    ids_url: format!("tiles/{x}_{y}.ids"),
                    bytes: 1,
                    trees: 10,
                    batches: 1,
                    bounds: Bounds { min: [fx - 4.0, fy - 4.0, z], max: [fx + 516.0, fy + 516.0, z + 40.0] },
                    attribute_codes: None,
                    levels: None,
                });
            }
        }
        let built = build_index(&tiles, 9);
        let m = Manifest {
            format: "sylva-scene".into(),
            version: 2,
            crs: Crs { epsg: 32633, proj4: String::new(), fit: None },
            origin_m: [0.0; 3],
            bounds: crate::format::index::union_bounds(tiles.iter().map(|t| &t.bounds)).unwrap(),
            cell_size_m: 64.0,
            tile_cells: 8,
            counts: Counts { trees: 10 * tiles.len() as u64, batches: tiles.len() as u64, tiles: tiles.len() as u64 },
            species: Vec::new(),
            tiles: Vec::new(),
            index: Some(built.reference.clone()),
            home: None,
            shard: None,
            terrain: None,
            attributes: None,
            canopy: None,
            timeline: None,
        };
        (m, tiles)
    }

    /// Reads every node the walk asks for until it asks for none.
    fn settle(
        walk: &mut IndexWalk,
        nodes: &std::collections::HashMap<String, Vec<u8>>,
        view: &ViewData,
        dd: f32,
    ) -> Vec<usize> {
        loop {
            let (tiles, fetch) = walk.walk(view, dd);
            if fetch.is_empty() {
                let mut ids: Vec<usize> = tiles.into_iter().map(|(_, t)| t).collect();
                ids.sort_unstable();
                return ids;
            }
            for (_, n) in fetch {
                let url = walk.node_url(n).to_string();
                walk.load_node(n, &url, &nodes[&url]).unwrap();
            }
        }
    }

    #[test]
    fn walk_matches_brute_force() {
        let (m, all) = scene(24);
        let built = build_index(&all, 9);
        let nodes: std::collections::HashMap<String, Vec<u8>> =
            built.nodes.iter().map(|(u, n)| (u.clone(), n.encode())).collect();
        let mut rng = 99u64;
        let mut next = || {
            rng = rng.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (rng >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut fewer = 0;
        let mut nonempty = 0;
        for case in 0..200 {
            let eye = DVec3::new((next() - 0.5) * 30_000.0, (next() - 0.5) * 30_000.0, 2.0 + next().powi(3) * 20_000.0);
            let cam = Camera {
                eye_m: eye,
                heading_rad: next() * std::f64::consts::TAU,
                pitch_rad: -next() * 1.5,
                ..Camera::default()
            };
            let view = cam.view_data(800, 450);
            let dd = [500.0, 3000.0, 12_000.0, 1e7][case % 4];
            let mut walk = IndexWalk::new(&m);
            let got = settle(&mut walk, &nodes, &view, dd);
            // Oracle: every tile of the scene, tested one by one.
            let mut expected: Vec<(i32, i32)> =
                all.iter().filter(|t| tile_wanted(&view, &t.bounds, dd).is_some()).map(|t| (t.x, t.y)).collect();
            let mut found: Vec<(i32, i32)> = got.iter().map(|&t| (walk.tiles[t].x, walk.tiles[t].y)).collect();
            expected.sort_unstable();
            found.sort_unstable();
            assert_eq!(found, expected, "case {case}: eye {eye:?}, draw distance {dd}");
            nonempty += usize::from(!expected.is_empty());
            if walk.nodes_loaded() < built.reference.nodes {
                fewer += 1;
            }
        }
        assert!(nonempty > 60, "only {nonempty} of 200 views see any tile: the test would prove little");
        // Most views read only part of the index.
        assert!(fewer > 100, "only {fewer} of 200 views read less than the whole index");
    }

    #[test]
    fn rejects_a_node_that_lies_about_its_subtree() {
        let (m, all) = scene(6);
        let built = build_index(&all, 9);
        let mut walk = IndexWalk::new(&m);
        let mut root = built.nodes[0].1.clone();
        root.trees += 1;
        let err = walk.load_node(0, "index/r.json", &root.encode()).unwrap_err();
        assert!(err.contains("index/r.json") && err.contains("trees"), "{err}");
        let mut root = built.nodes[0].1.clone();
        root.bounds.max[2] += 1000.0;
        let err = walk.load_node(0, "index/r.json", &root.encode()).unwrap_err();
        assert!(err.contains("leave its parent"), "{err}");
    }
}
