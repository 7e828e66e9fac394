//! The hierarchical tile index (`index/*.json`): a quadtree of small nodes over
//! the tile grid, so a viewer loads only the nodes whose bounds meet its view
//! and draw distance and the manifest stays small whatever the tree count.
//!
//! The manifest names the root node ([`IndexRef`]). A node lists either tiles
//! (a leaf, at most [`IndexRef::node_tiles`] of them) or up to four children,
//! one per quadrant of its square of tile coordinates, each with the bounds of
//! every tree below it. Bounds nest: a child's bounds lie inside its parent's,
//! so a walk that skips a node whose bounds miss the view misses no tile.

use serde::{Deserialize, Serialize};

use super::entries::{check_url, validate_bounds, Bounds, TileEntry};
pub use super::entries::{IndexRef, MAX_INDEX_DEPTH};
use super::error::{at_most, DecodeError, Problem};

/// Value of a node's `format` field.
pub const INDEX_FORMAT: &str = "sylva-index";
/// Index node version written and read by this build.
pub const INDEX_VERSION: u32 = 1;
/// Most tiles one node may list.
pub const MAX_NODE_TILES: usize = 4096;
/// Default tiles per leaf node: a node of 64 tiles is about 16 KB of JSON.
pub const DEFAULT_NODE_TILES: u32 = 64;

/// A child of a node: where it is and what lies below it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChildEntry {
    /// Node URL relative to the manifest.
    pub url: String,
    /// Bounds of every tree below the child.
    pub bounds: Bounds,
    /// Trees below the child.
    pub trees: u64,
    /// Tiles below the child.
    pub tiles: u64,
    /// The tallest tree below the child, metres (scene version 8): where it
    /// is below a pixel, the canopy rasters draw the child's trees and a view
    /// reads neither the child nor its tiles.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height_m: Option<f32>,
}

/// One node (`index/r….json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IndexNode {
    /// Always [`INDEX_FORMAT`].
    pub format: String,
    /// Always [`INDEX_VERSION`].
    pub version: u32,
    /// Tile coordinates covered: the square `[x0, x0 + size) × [y0, y0 + size)`.
    pub square: [i64; 3],
    /// Bounds of every tree below the node.
    pub bounds: Bounds,
    /// Trees below the node.
    pub trees: u64,
    /// Tiles listed here (a leaf), sorted by row then column.
    pub tiles: Vec<TileEntry>,
    /// Children (an inner node), in quadrant order.
    pub children: Vec<ChildEntry>,
}

impl IndexNode {
    /// Parses and validates a node. `file` names it in errors.
    ///
    /// # Errors
    /// A [`DecodeError`] for JSON that does not parse or match the schema, a wrong
    /// format or version, bad bounds or URLs, too many entries, a node that is both
    /// a leaf and inner, tiles outside its square, or counts that do not add up.
    pub fn decode(file: &str, bytes: &[u8]) -> Result<Self, DecodeError> {
        let inner = || -> Result<Self, Problem> {
            let n: Self = serde_json::from_slice(bytes).map_err(|e| Problem::Json(e.to_string()))?;
            if n.format != INDEX_FORMAT {
                return Err(Problem::Invalid(format!(
                    "\"format\" is {:?}, expected \"{INDEX_FORMAT}\": not a Sylva index node",
                    n.format
                )));
            }
            if n.version != INDEX_VERSION {
                return Err(Problem::UnsupportedVersion { found: n.version, supported: INDEX_VERSION });
            }
            n.validate()?;
            Ok(n)
        };
        inner().map_err(|p| DecodeError::new(file, p))
    }

    /// Serialises to compact JSON.
    #[must_use]
    pub fn encode(&self) -> Vec<u8> {
        let mut v = serde_json::to_vec(self).expect("IndexNode serialises");
        v.push(b'\n');
        v
    }

    fn validate(&self) -> Result<(), Problem> {
        validate_bounds("bounds", &self.bounds)?;
        at_most("tiles count", self.tiles.len() as u64, MAX_NODE_TILES as u64)?;
        at_most("children count", self.children.len() as u64, 4)?;
        let [x0, y0, size] = self.square;
        if size <= 0 || size > 1 << 33 {
            return Err(Problem::Invalid(format!("square size {size} must be in 1..=2^33")));
        }
        if !self.tiles.is_empty() && !self.children.is_empty() {
            return Err(Problem::Invalid("a node lists tiles and children: it must be one or the other".into()));
        }
        let mut trees = 0u64;
        for (i, t) in self.tiles.iter().enumerate() {
            let what = format!("tiles[{i}]");
            t.validate(&what)?;
            let (x, y) = (i64::from(t.x), i64::from(t.y));
            if x < x0 || x >= x0 + size || y < y0 || y >= y0 + size {
                return Err(Problem::Invalid(format!(
                    "{what} ({}, {}) lies outside the node's square {:?}",
                    t.x, t.y, self.square
                )));
            }
            trees = trees.saturating_add(t.trees);
        }
        for (i, c) in self.children.iter().enumerate() {
            let what = format!("children[{i}]");
            check_url(&format!("{what}.url"), &c.url)?;
            validate_bounds(&format!("{what}.bounds"), &c.bounds)?;
            if let Some(h) = c.height_m {
                let h = super::error::finite(format!("{what}.height_m"), f64::from(h))?;
                if h < 0.0 {
                    return Err(Problem::Invalid(format!("{what}.height_m is {h}: heights are not negative")));
                }
            }
            trees = trees.saturating_add(c.trees);
        }
        if trees != self.trees {
            return Err(Problem::Invalid(format!("\"trees\" is {} but the entries hold {trees}", self.trees)));
        }
        Ok(())
    }
}

/// Union of bounds (`None` for none).
#[must_use]
pub fn union_bounds<'a>(all: impl IntoIterator<Item = &'a Bounds>) -> Option<Bounds> {
    all.into_iter().fold(None, |acc: Option<Bounds>, b| {
        Some(match acc {
            None => *b,
            Some(a) => Bounds {
                min: [0, 1, 2].map(|k| a.min[k].min(b.min[k])),
                max: [0, 1, 2].map(|k| a.max[k].max(b.max[k])),
            },
        })
    })
}

/// A built index: the nodes to write (URL and node, root first) and the
/// manifest's reference to them.
#[derive(Debug, Clone, PartialEq)]
pub struct BuiltIndex {
    /// What the manifest says.
    pub reference: IndexRef,
    /// Every node with its URL, parents before children.
    pub nodes: Vec<(String, IndexNode)>,
}

/// Builds the quadtree over `tiles` (any order; at least one) with at most
/// `node_tiles` tiles per leaf. Deterministic: the same tiles give the same nodes.
///
/// # Panics
/// If `tiles` is empty or `node_tiles` is 0.
#[must_use]
pub fn build_index(tiles: &[TileEntry], node_tiles: u32) -> BuiltIndex {
    assert!(!tiles.is_empty() && node_tiles > 0);
    let mut sorted: Vec<TileEntry> = tiles.to_vec();
    sorted.sort_by_key(|t| (t.y, t.x));
    let mut nodes = Vec::new();
    let depth = build_node("index/r", tile_square(&sorted), sorted, node_tiles as usize, &mut nodes);
    BuiltIndex {
        reference: IndexRef { root: "index/r.json".into(), nodes: nodes.len() as u64, depth, node_tiles },
        nodes,
    }
}

/// The index root's square `[x0, y0, size]` over `tiles` (at least one): the
/// smallest power-of-two square of tile coordinates from their lowest corner.
#[must_use]
pub fn tile_square(tiles: &[TileEntry]) -> [i64; 3] {
    let (mut x0, mut y0) = (i64::MAX, i64::MAX);
    let (mut x1, mut y1) = (i64::MIN, i64::MIN);
    for t in tiles {
        x0 = x0.min(t.x.into());
        y0 = y0.min(t.y.into());
        x1 = x1.max(t.x.into());
        y1 = y1.max(t.y.into());
    }
    let span = (x1 - x0 + 1).max(y1 - y0 + 1).max(1);
    [x0, y0, (span as u64).next_power_of_two() as i64]
}

/// Builds the node `stem` over `tiles` (all inside `square`); returns its depth.
fn build_node(
    stem: &str,
    square: [i64; 3],
    tiles: Vec<TileEntry>,
    node_tiles: usize,
    out: &mut Vec<(String, IndexNode)>,
) -> u32 {
    let bounds = union_bounds(tiles.iter().map(|t| &t.bounds)).expect("a node has tiles");
    let trees = tiles.iter().map(|t| t.trees).sum();
    let url = format!("{stem}.json");
    let at = out.len();
    out.push((
        url,
        IndexNode {
            format: INDEX_FORMAT.into(),
            version: INDEX_VERSION,
            square,
            bounds,
            trees,
            tiles: Vec::new(),
            children: Vec::new(),
        },
    ));
    if tiles.len() <= node_tiles || square[2] == 1 {
        out[at].1.tiles = tiles;
        return 1;
    }
    let [x0, y0, size] = square;
    let half = size / 2;
    let mut quadrants: [Vec<TileEntry>; 4] = Default::default();
    for t in tiles {
        let q = usize::from(i64::from(t.x) >= x0 + half) + 2 * usize::from(i64::from(t.y) >= y0 + half);
        quadrants[q].push(t);
    }
    let mut depth = 0;
    let mut children = Vec::new();
    for (q, part) in quadrants.into_iter().enumerate() {
        if part.is_empty() {
            continue;
        }
        let child_square = [x0 + half * (q as i64 % 2), y0 + half * (q as i64 / 2), half];
        let child_stem = format!("{stem}{q}");
        let child_at = out.len();
        depth = depth.max(build_node(&child_stem, child_square, part, node_tiles, out));
        let (url, node) = &out[child_at];
        children.push(ChildEntry {
            url: url.clone(),
            bounds: node.bounds,
            trees: node.trees,
            tiles: count_tiles(out, child_at),
            height_m: tallest_below(out, child_at),
        });
    }
    out[at].1.children = children;
    depth + 1
}

/// The tallest tree below the node at `at` in `out` (its tiles' `levels`; None
/// when a tile has none).
fn tallest_below(out: &[(String, IndexNode)], at: usize) -> Option<f32> {
    let n = &out[at].1;
    if n.children.is_empty() {
        return n.tiles.iter().try_fold(0f32, |h, t| t.levels.as_ref().map(|l| h.max(l.height_m)));
    }
    n.children.iter().try_fold(0f32, |h, c| c.height_m.map(|x| h.max(x)))
}

/// Tiles below the node at `at` in `out` (its subtree follows it contiguously).
fn count_tiles(out: &[(String, IndexNode)], at: usize) -> u64 {
    let n = &out[at].1;
    if n.children.is_empty() {
        return n.tiles.len() as u64;
    }
    n.children.iter().map(|c| c.tiles).sum()
}

/// A walk of every tile of a scene — the manifest's flat list, or the leaves of
/// its index — fed node by node by whoever fetches them (a local folder:
/// [`read_all_tiles`]; the browser's `query`: the wasm `TileWalk`), so both
/// take the same checks: URLs as the decoders check them, no node twice (a
/// node that is its own child, or a cycle, stops the walk at once), and no
/// more nodes than the manifest declares.
#[derive(Debug, Clone)]
pub struct TileWalk {
    declared: u64,
    depth: u32,
    visited: u64,
    /// Nodes to fetch: (URL, level; the root is level 1).
    stack: Vec<(String, u32)>,
    seen: std::collections::HashSet<String>,
    tiles: Vec<TileEntry>,
}

/// The most index nodes a walk fetches, whatever a manifest declares.
pub const MAX_WALK_NODES: u64 = 1 << 22;

/// A node URL as one spelling: `./a/./b.json` and `a/b.json` are one node.
fn node_key(url: &str) -> String {
    url.split('/').filter(|p| !p.is_empty() && *p != ".").collect::<Vec<_>>().join("/")
}

impl TileWalk {
    /// Starts at the manifest's root node, or with its flat list of tiles.
    #[must_use]
    pub fn new(m: &super::Manifest) -> Self {
        let (stack, tiles) = match &m.index {
            Some(index) => (vec![(index.root.clone(), 1)], Vec::new()),
            None => (Vec::new(), m.tiles.clone()),
        };
        Self {
            declared: m.index.as_ref().map_or(0, |i| i.nodes.clamp(1, MAX_WALK_NODES)),
            depth: m.index.as_ref().map_or(0, |i| i.depth.max(1)),
            visited: 0,
            stack,
            seen: std::collections::HashSet::new(),
            tiles,
        }
    }

    /// The node to fetch next (relative to the scene), or None when done;
    /// checked before it is fetched: a node met before, one more than the
    /// manifest declares, or one deeper than its declared depth is an error.
    ///
    /// # Errors
    /// That node, named, and why it is not fetched.
    pub fn next_url(&self) -> Result<Option<&str>, String> {
        let Some((url, level)) = self.stack.last() else { return Ok(None) };
        if self.visited >= self.declared {
            return Err(format!("{url}: the index has more nodes than the {} it declares", self.declared));
        }
        if *level > self.depth {
            return Err(format!("{url}: deeper than the {} levels the index declares", self.depth));
        }
        if self.seen.contains(&node_key(url)) {
            return Err(format!("{url}: the index reaches this node twice (a node is its own descendant)"));
        }
        Ok(Some(url))
    }

    /// Every node the walk knows it will fetch (the next one last): a
    /// fetcher that waits for the network asks for them together, so a walk
    /// takes as many rounds as the index has levels, not nodes.
    pub fn pending_urls(&self) -> impl Iterator<Item = &str> {
        self.stack.iter().map(|(url, _)| url.as_str())
    }

    /// Takes the bytes of the node [`Self::next_url`] named.
    ///
    /// # Errors
    /// A node that does not decode, or a walk [`Self::next_url`] refuses; the
    /// message names the node.
    pub fn feed(&mut self, bytes: &[u8]) -> Result<(), String> {
        if self.next_url()?.is_none() {
            return Err("the index walk is complete".into());
        }
        let Some((url, level)) = self.stack.pop() else { return Err("the index walk is complete".into()) };
        self.visited += 1;
        self.seen.insert(node_key(&url));
        let node = IndexNode::decode(&url, bytes).map_err(|e| e.to_string())?;
        self.tiles.extend(node.tiles);
        self.stack.extend(node.children.into_iter().rev().map(|c| (c.url, level + 1)));
        Ok(())
    }

    /// The tiles, in row order (y, then x).
    #[must_use]
    pub fn finish(mut self) -> Vec<TileEntry> {
        self.tiles.sort_by_key(|t| (t.y, t.x));
        self.tiles
    }
}

/// Every tile of a local scene directory: the manifest's flat list, or the
/// leaves of its index read from `dir` ([`TileWalk`]).
///
/// # Errors
/// A message naming the node that cannot be read or decoded.
#[cfg(not(target_arch = "wasm32"))]
pub fn read_all_tiles(dir: &std::path::Path, m: &super::Manifest) -> Result<Vec<TileEntry>, String> {
    let mut walk = TileWalk::new(m);
    while let Some(url) = walk.next_url().map_err(|e| format!("{}: {e}", dir.display()))? {
        let path = dir.join(url);
        let bytes = crate::paths::read_regular(&path, None, crate::paths::MAX_SCENE_FILE_BYTES)
            .map_err(|e| format!("cannot read index node {}: {e}", path.display()))?;
        walk.feed(&bytes).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    Ok(walk.finish())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tile(x: i32, y: i32) -> TileEntry {
        let (fx, fy) = (x as f32 * 100.0, y as f32 * 100.0);
        TileEntry {
            x,
            y,
            url: format!("tiles/{x}_{y}.tile"),
            ids_url: format!("tiles/{x}_{y}.ids"),
            bytes: 100,
            trees: (x.unsigned_abs() + y.unsigned_abs() + 1).into(),
            batches: 1,
            bounds: Bounds { min: [fx, fy, 0.0], max: [fx + 100.0, fy + 100.0, 10.0 + x as f32] },
            attribute_codes: None,
            levels: None,
        }
    }

    #[test]
    fn builds_a_valid_nested_quadtree() {
        let tiles: Vec<TileEntry> = (-7..9)
            .flat_map(|y| (-3..12).map(move |x| (x, y)))
            .filter(|(x, y)| (x * y) % 5 != 1)
            .map(|(x, y)| tile(x, y))
            .collect();
        let built = build_index(&tiles, 7);
        assert!(built.reference.depth >= 3, "depth {}", built.reference.depth);
        assert_eq!(built.nodes[0].0, "index/r.json");
        let by_url: std::collections::HashMap<&str, &IndexNode> =
            built.nodes.iter().map(|(u, n)| (u.as_str(), n)).collect();
        let mut leaf_tiles = 0;
        for (url, node) in &built.nodes {
            let decoded = IndexNode::decode(url, &node.encode()).unwrap();
            assert_eq!(&decoded, node);
            assert!(node.tiles.len() <= 7 || node.square[2] == 1);
            leaf_tiles += node.tiles.len();
            for c in &node.children {
                let child = by_url[c.url.as_str()];
                assert_eq!(child.bounds, c.bounds);
                assert_eq!(child.trees, c.trees);
                for k in 0..3 {
                    assert!(node.bounds.min[k] <= c.bounds.min[k] && c.bounds.max[k] <= node.bounds.max[k]);
                }
            }
        }
        assert_eq!(leaf_tiles, tiles.len());
        assert_eq!(built.nodes[0].1.trees, tiles.iter().map(|t| t.trees).sum::<u64>());
        // Same input in another order: same nodes.
        let mut shuffled = tiles.clone();
        shuffled.reverse();
        assert_eq!(build_index(&shuffled, 7), built);
    }

    /// Walks `nodes` (url → bytes) from the manifest's root as the browser's `query` does.
    fn walk(
        m: &super::super::Manifest,
        nodes: &std::collections::HashMap<String, Vec<u8>>,
    ) -> Result<Vec<TileEntry>, String> {
        let mut w = TileWalk::new(m);
        let declared = m.index.as_ref().map_or(0, |i| i.nodes);
        let mut fetched = 0;
        while let Some(url) = w.next_url()? {
            // Every check comes before the fetch: never more fetches than declared nodes.
            fetched += 1;
            assert!(fetched <= declared, "fetch {fetched} of {declared} declared nodes");
            let bytes = nodes.get(url).cloned().unwrap_or_default();
            w.feed(&bytes)?;
        }
        Ok(w.finish())
    }

    #[test]
    fn the_tile_walk_visits_each_node_once_and_stops_at_a_cycle() {
        let fixture = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/forest-small/scene.json");
        let mut m = super::super::Manifest::decode("scene.json", &std::fs::read(fixture).unwrap()).unwrap();
        let tiles: Vec<TileEntry> = (0..6).flat_map(|y| (0..6).map(move |x| tile(x, y))).collect();
        let built = build_index(&tiles, 4);
        assert!(built.nodes.len() > 3);
        m.tiles.clear();
        m.index = Some(built.reference.clone());
        let mut nodes: std::collections::HashMap<String, Vec<u8>> =
            built.nodes.iter().map(|(u, n)| (u.clone(), n.encode())).collect();
        let mut all = walk(&m, &nodes).unwrap();
        all.sort_by_key(|t| (t.y, t.x));
        assert_eq!(all, tiles, "every tile once, in row order");
        // A node that is its own child, and a child that points back at the root: stopped at once.
        let (root_url, root) = built.nodes[0].clone();
        let mut own = root.clone();
        own.children[0].url.clone_from(&root_url);
        nodes.insert(root_url.clone(), own.encode());
        let e = walk(&m, &nodes).unwrap_err();
        assert!(e.contains("reaches this node twice"), "{e}");
        nodes.insert(root_url.clone(), root.encode());
        let (child_url, child) =
            built.nodes.iter().find(|(_, n)| !n.children.is_empty() && n.square != root.square).cloned().unwrap();
        let mut back = child.clone();
        back.children[0].url.clone_from(&root_url);
        nodes.insert(child_url.clone(), back.encode());
        assert!(walk(&m, &nodes).unwrap_err().contains("twice"));
        // The same node spelt another way ("./" before it) is the same node.
        back.children[0].url = format!("./{root_url}");
        nodes.insert(child_url.clone(), back.encode());
        let e = walk(&m, &nodes).unwrap_err();
        assert!(e.contains("twice"), "{e}");
        nodes.insert(child_url, child.encode());
        // Deeper than the manifest declares: refused before the fetch.
        m.index.as_mut().unwrap().depth = 1;
        assert!(walk(&m, &nodes).unwrap_err().contains("deeper than the 1 levels"));
        m.index.as_mut().unwrap().depth = built.reference.depth;
        // More nodes than the manifest declares; a node that is missing or does not decode.
        m.index.as_mut().unwrap().nodes = 2;
        assert!(walk(&m, &nodes).unwrap_err().contains("more nodes than the 2 it declares"));
        m.index.as_mut().unwrap().nodes = built.reference.nodes;
        nodes.insert(root_url.clone(), b"{\"format\": \"sylva-index\"".to_vec());
        assert!(walk(&m, &nodes).unwrap_err().contains(&root_url));
        // A child URL that leaves the scene never reaches a fetch: the node's decoder refuses it.
        let mut out = root.clone();
        out.children[0].url = "../../etc/passwd".into();
        nodes.insert(root_url.clone(), out.encode());
        let e = walk(&m, &nodes).unwrap_err();
        assert!(e.contains("etc/passwd"), "{e}");
        // …also spelt as a browser would resolve it (%2e%2e is ".."), or with a query.
        for url in ["%2e%2e/%2e%2e/etc/passwd", "index/r.json?again"] {
            let mut out = root.clone();
            out.children[0].url = url.into();
            nodes.insert(root_url.clone(), out.encode());
            let e = walk(&m, &nodes).unwrap_err();
            assert!(e.contains("no %, ? or #"), "{url}: {e}");
        }
    }

    #[test]
    fn rejects_bad_nodes() {
        let built = build_index(&[tile(0, 0), tile(1, 0)], 64);
        let good = built.nodes[0].1.clone();
        let err = |f: &dyn Fn(&mut IndexNode), needle: &str| {
            let mut n = good.clone();
            f(&mut n);
            let msg = IndexNode::decode("index/r.json", &n.encode()).unwrap_err().to_string();
            assert!(msg.contains(needle) && msg.contains("index/r.json"), "{msg}");
        };
        err(&|n| n.trees += 1, "entries hold");
        err(&|n| n.tiles[0].url = "../x".into(), "relative path");
        err(&|n| n.tiles[0].x = 99, "outside the node's square");
        err(&|n| n.format = "x".into(), "not a Sylva index node");
        err(&|n| n.version = 9, "version 9");
        err(
            &|n| {
                n.children.push(ChildEntry {
                    url: "index/r0.json".into(),
                    bounds: n.bounds,
                    trees: 0,
                    tiles: 0,
                    height_m: None,
                });
            },
            "one or the other",
        );
        assert!(IndexNode::decode("n", b"[1,2]").unwrap_err().to_string().contains("invalid JSON"));
    }
}
