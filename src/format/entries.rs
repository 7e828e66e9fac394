//! Entries shared by the manifest and the index nodes: bounds, tile entries,
//! the index pointer, and their checks (each written once). Both
//! [`super::manifest`] and [`super::index`] import from here and never from
//! each other's types.

use serde::{Deserialize, Serialize};

use super::error::{finite_all, Problem};

/// Most levels below the root (tile coordinates are i32: 32 halvings cover them).
pub const MAX_INDEX_DEPTH: u32 = 33;

/// An axis-aligned box in metres relative to the scene origin.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Bounds {
    /// Lower corner.
    pub min: [f32; 3],
    /// Upper corner.
    pub max: [f32; 3],
}

/// One tile of the flat tile index.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TileEntry {
    /// Tile column.
    pub x: i32,
    /// Tile row.
    pub y: i32,
    /// Tile URL relative to the manifest.
    pub url: String,
    /// Tree-id sidecar URL relative to the manifest.
    pub ids_url: String,
    /// File size in bytes.
    pub bytes: u64,
    /// Trees in the tile.
    pub trees: u64,
    /// Batches in the tile.
    pub batches: u32,
    /// Bounds of every tree in the tile.
    pub bounds: Bounds,
    /// Per attribute column (`scene.json` `attributes`), the smallest and
    /// largest code of the tile's values (`null`: none has a value): a search
    /// skips tiles that cannot match (manifest version 6; categories are
    /// sorted, so a prefix's codes are a run).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub attribute_codes: Option<Vec<Option<[u32; 2]>>>,
    /// The prefix levels of a version 3 tile (manifest version 7): what a view
    /// fetches of it by byte range. Without it the tile is fetched whole.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub levels: Option<TileLevels>,
}

/// A tile's prefix levels (tile versions 3 and 4), as its index entry lists them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TileLevels {
    /// File bytes up to the end of each level (the last: the whole file).
    pub bytes: Vec<u64>,
    /// The tallest tree of the tile in metres (its batches' `max_height_m`):
    /// with the tile's distance, how much of it a view draws.
    pub height_m: f32,
    /// The tile file's version, which says how its levels step (scene
    /// version 9: 4, √2 steps; absent in scenes before: 3, 2× steps).
    #[serde(default = "tile_version_3")]
    pub version: u16,
}

fn tile_version_3() -> u16 {
    3
}

impl TileLevels {
    /// How the tile's levels split its tallest batch (what a view decides
    /// before the tile's batches are in).
    #[must_use]
    pub fn scheme(&self) -> super::tile::Levels {
        super::tile::Levels { version: self.version, count: self.bytes.len() as u32, tallest_m: self.height_m }
    }
}

/// The manifest's pointer to the index.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IndexRef {
    /// URL of the root node, relative to the manifest.
    pub root: String,
    /// Nodes in the whole index.
    pub nodes: u64,
    /// Levels of nodes (1: the root is a leaf).
    pub depth: u32,
    /// Most tiles a leaf lists.
    pub node_tiles: u32,
}

/// Where the trees are: the largest group of touching tiles (8-neighbours)
/// by tree count. Views aim here first, not at the middle of the whole extent,
/// which for two districts far apart is empty.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Home {
    /// Bounds of every tree of the group.
    pub bounds: Bounds,
    /// Trees in the group.
    pub trees: u64,
}

/// The [`Home`] of a scene's tiles: the group of touching tiles holding the
/// most trees (ties: the one with the lowest tile row, then column). `None` for
/// no tiles. Deterministic whatever the order of `tiles`.
#[must_use]
pub fn densest_group(tiles: &[TileEntry]) -> Option<Home> {
    let mut order: Vec<usize> = (0..tiles.len()).collect();
    order.sort_by_key(|&i| (tiles[i].y, tiles[i].x));
    let at: std::collections::HashMap<(i32, i32), usize> =
        order.iter().map(|&i| ((tiles[i].x, tiles[i].y), i)).collect();
    let mut group = vec![usize::MAX; tiles.len()];
    let mut best: Option<Home> = None;
    for &start in &order {
        if group[start] != usize::MAX {
            continue;
        }
        group[start] = start;
        let mut stack = vec![start];
        let mut home = Home { bounds: tiles[start].bounds, trees: 0 };
        while let Some(i) = stack.pop() {
            let t = &tiles[i];
            home.trees += t.trees;
            for k in 0..3 {
                home.bounds.min[k] = home.bounds.min[k].min(t.bounds.min[k]);
                home.bounds.max[k] = home.bounds.max[k].max(t.bounds.max[k]);
            }
            for (dx, dy) in [(-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)] {
                let n = (t.x.saturating_add(dx), t.y.saturating_add(dy));
                if let Some(&j) = at.get(&n) {
                    if group[j] == usize::MAX {
                        group[j] = start;
                        stack.push(j);
                    }
                }
            }
        }
        if best.is_none_or(|b| home.trees > b.trees) {
            best = Some(home);
        }
    }
    best
}

impl IndexRef {
    /// Checks the pointer: a relative root URL, positive sizes, depth ≤ [`MAX_INDEX_DEPTH`].
    pub(crate) fn validate(&self) -> Result<(), Problem> {
        check_url("index.root", &self.root)?;
        if self.nodes == 0 || self.node_tiles == 0 || self.depth == 0 || self.depth > MAX_INDEX_DEPTH {
            return Err(Problem::Invalid(format!(
                "index {self:?}: nodes, node_tiles and depth must be positive (depth ≤ {MAX_INDEX_DEPTH})"
            )));
        }
        Ok(())
    }
}

impl TileEntry {
    /// Checks the entry's URLs and bounds; `what` names it in errors.
    pub(crate) fn validate(&self, what: &str) -> Result<(), Problem> {
        check_url(&format!("{what}.url"), &self.url)?;
        check_url(&format!("{what}.ids_url"), &self.ids_url)?;
        if let Some(codes) = &self.attribute_codes {
            if codes.len() > super::attributes::MAX_ATTRIBUTE_COLUMNS || codes.iter().flatten().any(|[lo, hi]| lo > hi)
            {
                return Err(Problem::Invalid(format!("{what}.attribute_codes: more columns than allowed or lo > hi")));
            }
        }
        if let Some(l) = &self.levels {
            let rising = l.bytes.windows(2).all(|w| w[0] <= w[1]);
            if l.bytes.is_empty()
                || l.bytes.len() > super::tile::MAX_TILE_LEVELS as usize
                || !rising
                || l.bytes.last() != Some(&self.bytes)
                || !(l.height_m.is_finite() && l.height_m >= 0.0)
                || !(3..=super::tile::TILE_VERSION).contains(&l.version)
            {
                return Err(Problem::Invalid(format!(
                    "{what}.levels: 1 to {} rising byte ends ending at the tile's {} bytes, a height ≥ 0 and a tile version 3 to {} expected",
                    super::tile::MAX_TILE_LEVELS,
                    self.bytes,
                    super::tile::TILE_VERSION
                )));
            }
        }
        validate_bounds(&format!("{what}.bounds"), &self.bounds)
    }
}

pub(crate) fn validate_bounds(what: &str, b: &Bounds) -> Result<(), Problem> {
    finite_all(&format!("{what}.min"), &b.min)?;
    finite_all(&format!("{what}.max"), &b.max)?;
    if b.min.iter().zip(&b.max).any(|(lo, hi)| lo > hi) {
        return Err(Problem::Invalid(format!("{what}: min {:?} exceeds max {:?}", b.min, b.max)));
    }
    Ok(())
}

/// A URL in a manifest must stay inside the scene: relative, no `..`, no scheme.
pub(crate) fn check_url(what: &str, url: &str) -> Result<(), Problem> {
    let bad = url.is_empty()
        || url.starts_with('/')
        || url.contains('\\')
        || url.contains(':')
        // A browser reads %2e%2e as "..", and ? or # as no part of the path.
        || url.contains(['%', '?', '#'])
        || url.split('/').any(|seg| seg == ".." || seg.is_empty());
    if bad {
        return Err(Problem::Invalid(format!(
            "{what} {url:?} must be a relative path inside the scene directory (no %, ? or #)"
        )));
    }
    Ok(())
}
