//! Terrain tiles (`terrain/<level>/<x>_<y>.terr`): a quadtree of height grids.
//!
//! The manifest's [`TerrainEntry`] places the root square (level 0) relative to
//! the scene origin; tile `(x, y)` of level `l` is the square of side
//! `root_size_m / 2^l` whose south-west corner is `origin + (x, y) · side`
//! (rows count north). Every tile is a grid of `(grid + 1)²` quantised heights
//! over its square; a coarser tile's vertices are a subset of its children's
//! (the same points, the same heights), so a viewer can morph a child towards
//! its parent. Each tile carries its geometric error (the largest vertical
//! distance from its surface to the finest data below it), the height range
//! of its square and, for each of its four children, whether it exists with its
//! range and error — so a viewer can choose and cull children before fetching
//! them. Layout: `docs/FORMAT.md` (Terrain).

use serde::{Deserialize, Serialize};

use super::entries::check_url;
use super::error::{finite_all, DecodeError, Problem, Reader};

/// First four bytes of a terrain tile.
pub const TERRAIN_MAGIC: [u8; 4] = *b"SYTR";
/// Terrain tile version written and read by this build.
pub const TERRAIN_VERSION: u16 = 1;
/// Bytes of the terrain tile header.
pub const TERRAIN_HEADER_BYTES: usize = 96;
/// A quantised height meaning "no data" (a hole in the DEM).
pub const TERRAIN_HOLE: u16 = u16::MAX;
/// Largest quantised height with data.
pub const TERRAIN_Q_MAX: u16 = u16::MAX - 1;
/// Most cells per tile side.
pub const MAX_TERRAIN_GRID: u16 = 256;
/// Deepest level (a 2^24 subdivision of the root: millimetres over a continent).
pub const MAX_TERRAIN_LEVEL: u8 = 24;
/// Largest height magnitude a tile may declare, metres (beyond any ground on
/// Earth, far from where f32 arithmetic on ranges overflows).
pub const MAX_TERRAIN_HEIGHT_M: f32 = 1.0e6;

/// A child's summary in its parent (`exists` false: no data there, no file).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TerrainChild {
    /// Whether the child tile exists.
    pub exists: bool,
    /// Lowest height, metres relative to the scene origin.
    pub min_m: f32,
    /// Highest height.
    pub max_m: f32,
    /// Geometric error, metres.
    pub error_m: f32,
}

/// One decoded terrain tile.
#[derive(Debug, Clone, PartialEq)]
pub struct TerrainTile {
    /// Level (0: the root).
    pub level: u8,
    /// Column at its level.
    pub x: u32,
    /// Row at its level (0: south).
    pub y: u32,
    /// Cells per side (`grid + 1` vertices).
    pub grid: u16,
    /// Lowest height, metres relative to the scene origin (of its vertices and its children's).
    pub min_m: f32,
    /// Highest height.
    pub max_m: f32,
    /// Largest vertical distance from this tile's surface to the finest data below it.
    pub error_m: f32,
    /// Children in quadrant order: south-west, south-east, north-west, north-east.
    pub children: [TerrainChild; 4],
    /// `(grid + 1)²` quantised heights, row-major from the south-west corner:
    /// `min + q / 65534 · (max − min)`, [`TERRAIN_HOLE`] for no data.
    pub heights: Vec<u16>,
}

impl TerrainTile {
    /// Vertices per side.
    #[must_use]
    pub fn side(&self) -> usize {
        usize::from(self.grid) + 1
    }

    /// The height of vertex `(i, j)` (column, row from the south), `None` for a hole.
    #[must_use]
    pub fn height(&self, i: usize, j: usize) -> Option<f32> {
        let q = self.heights[j * self.side() + i];
        (q != TERRAIN_HOLE).then(|| dequantise(q, self.min_m, self.max_m))
    }

    /// Encodes the tile into its file bytes.
    #[must_use]
    pub fn encode(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(TERRAIN_HEADER_BYTES + self.heights.len() * 2);
        out.extend_from_slice(&TERRAIN_MAGIC);
        out.extend_from_slice(&TERRAIN_VERSION.to_le_bytes());
        out.extend_from_slice(&(TERRAIN_HEADER_BYTES as u16).to_le_bytes());
        let mask = self.children.iter().enumerate().fold(0u8, |m, (k, c)| m | (u8::from(c.exists) << k));
        out.push(self.level);
        out.push(mask);
        out.extend_from_slice(&self.grid.to_le_bytes());
        out.extend_from_slice(&self.x.to_le_bytes());
        out.extend_from_slice(&self.y.to_le_bytes());
        for v in [self.min_m, self.max_m, self.error_m] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for c in &self.children {
            for v in [c.min_m, c.max_m, c.error_m] {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
        out.resize(TERRAIN_HEADER_BYTES, 0);
        for q in &self.heights {
            out.extend_from_slice(&q.to_le_bytes());
        }
        out
    }

    /// Decodes and validates tile bytes; `file` names the file in errors.
    ///
    /// # Errors
    /// A [`DecodeError`] for a wrong magic, version or header size, a grid or
    /// level beyond the format's limits, a size that does not match the grid,
    /// non-finite or inverted ranges, a negative error, or a child summary
    /// without its flag.
    pub fn decode(file: &str, bytes: &[u8]) -> Result<Self, DecodeError> {
        decode_terrain(bytes).map_err(|p| DecodeError::new(file, p))
    }
}

/// Height of quantised `q` in a tile of range `min..max`.
#[must_use]
pub fn dequantise(q: u16, min: f32, max: f32) -> f32 {
    min + f32::from(q) / f32::from(TERRAIN_Q_MAX) * (max - min)
}

/// Quantised height of `h` in a tile of range `min..max` (nearest step).
#[must_use]
pub fn quantise(h: f32, min: f32, max: f32) -> u16 {
    if max <= min {
        return 0;
    }
    ((h - min) / (max - min) * f32::from(TERRAIN_Q_MAX)).round().clamp(0.0, f32::from(TERRAIN_Q_MAX)) as u16
}

fn decode_terrain(bytes: &[u8]) -> Result<TerrainTile, Problem> {
    let r = Reader::new(bytes);
    r.magic("Sylva terrain tile", &TERRAIN_MAGIC)?;
    let version = r.u16("header.version", 4)?;
    if version != TERRAIN_VERSION {
        return Err(Problem::UnsupportedVersion { found: version.into(), supported: TERRAIN_VERSION.into() });
    }
    let header = r.u16("header.header_bytes", 6)?;
    if usize::from(header) != TERRAIN_HEADER_BYTES {
        return Err(Problem::Invalid(format!("header.header_bytes is {header}, expected {TERRAIN_HEADER_BYTES}")));
    }
    let head = r.slice("header", 0, TERRAIN_HEADER_BYTES as u64)?;
    let (level, mask) = (head[8], head[9]);
    if level > MAX_TERRAIN_LEVEL {
        return Err(Problem::OutOfRange {
            what: "header.level".into(),
            value: level.into(),
            allowed: format!("at most {MAX_TERRAIN_LEVEL}"),
        });
    }
    if mask > 0xf {
        return Err(Problem::Invalid(format!("header.child_mask is {mask:#x}: only bits 0–3 (four children) exist")));
    }
    let grid = r.u16("header.grid", 10)?;
    if grid == 0 || grid > MAX_TERRAIN_GRID || !grid.is_multiple_of(2) {
        return Err(Problem::OutOfRange {
            what: "header.grid".into(),
            value: grid.into(),
            allowed: format!(
                "an even 2–{MAX_TERRAIN_GRID} cells per side (a parent's vertices are its children's even ones)"
            ),
        });
    }
    let (x, y) = (r.u32("header.x", 12)?, r.u32("header.y", 16)?);
    let span = 1u64 << level;
    if u64::from(x) >= span || u64::from(y) >= span {
        return Err(Problem::Invalid(format!("tile ({x}, {y}) lies outside level {level}'s {span}×{span} tiles")));
    }
    let f = |at: usize| f32::from_le_bytes([head[at], head[at + 1], head[at + 2], head[at + 3]]);
    let (min_m, max_m, error_m) = (f(20), f(24), f(28));
    finite_all("header height range and error", &[min_m, max_m, error_m])?;
    if [min_m, max_m, error_m].iter().any(|v| v.abs() > MAX_TERRAIN_HEIGHT_M) {
        return Err(Problem::Invalid(format!(
            "header range {min_m}..{max_m} or error {error_m} is beyond ±{MAX_TERRAIN_HEIGHT_M} m"
        )));
    }
    if min_m > max_m || error_m < 0.0 {
        return Err(Problem::Invalid(format!(
            "header range {min_m}..{max_m} or error {error_m} is inverted or negative"
        )));
    }
    let mut children = [TerrainChild::default(); 4];
    for (k, c) in children.iter_mut().enumerate() {
        let at = 32 + k * 12;
        let (cmin, cmax, cerr) = (f(at), f(at + 4), f(at + 8));
        let exists = mask & (1 << k) != 0;
        if !exists && (cmin != 0.0 || cmax != 0.0 || cerr != 0.0) {
            return Err(Problem::Invalid(format!("child {k} has a summary but no flag in the child mask")));
        }
        finite_all(&format!("child {k}"), &[cmin, cmax, cerr])?;
        if [cmin, cmax, cerr].iter().any(|v| v.abs() > MAX_TERRAIN_HEIGHT_M) {
            return Err(Problem::Invalid(format!("child {k}: range or error beyond ±{MAX_TERRAIN_HEIGHT_M} m")));
        }
        if cmin > cmax || cerr < 0.0 {
            return Err(Problem::Invalid(format!(
                "child {k}: range {cmin}..{cmax} or error {cerr} is inverted or negative"
            )));
        }
        *c = TerrainChild { exists, min_m: cmin, max_m: cmax, error_m: cerr };
    }
    if head[80..].iter().any(|&b| b != 0) {
        return Err(Problem::Invalid("header bytes 80–95 are reserved and must be 0".into()));
    }
    let side = u64::from(grid) + 1;
    let len = side * side * 2;
    let end = TERRAIN_HEADER_BYTES as u64 + len;
    if end != bytes.len() as u64 {
        return Err(if end > bytes.len() as u64 {
            Problem::Truncated { what: format!("{side}×{side} heights"), start: 0, end, len: bytes.len() as u64 }
        } else {
            Problem::Invalid(format!("{} trailing bytes after {side}×{side} heights", bytes.len() as u64 - end))
        });
    }
    let heights = r
        .slice("heights", TERRAIN_HEADER_BYTES as u64, len)?
        .chunks_exact(2)
        .map(|b| u16::from_le_bytes([b[0], b[1]]))
        .collect();
    Ok(TerrainTile { level, x, y, grid, min_m, max_m, error_m, children, heights })
}

/// The manifest's terrain entry (manifest version 4).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TerrainEntry {
    /// Folder of the tiles relative to the manifest: tile `(l, x, y)` is `<path>/<l>/<x>_<y>.terr`.
    pub path: String,
    /// South-west corner of the root square, metres relative to the scene origin.
    pub origin_m: [f64; 2],
    /// Side of the root square, metres.
    pub root_size_m: f64,
    /// Cells per tile side.
    pub grid: u16,
    /// Levels (the finest is `levels − 1`).
    pub levels: u8,
    /// Vertex spacing of the finest level, metres.
    pub resolution_m: f64,
    /// Lowest and highest ground height, metres relative to the scene origin.
    pub height_range_m: [f32; 2],
    /// Terrain tiles.
    pub tiles: u64,
    /// Bytes of all terrain tiles.
    pub bytes: u64,
    /// Where the heights came from (e.g. the DEM file names), for reports.
    pub source: String,
    /// Ground imagery draped on the terrain (manifest version 5), if baked.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub imagery: Option<ImageryEntry>,
}

/// Ground imagery baked from orthophotos (`--ortho`): one JPEG of
/// [`ImageryEntry::tile_px`]² pixels per terrain tile of the first
/// [`ImageryEntry::levels`] levels that meets [`ImageryEntry::extent_m`],
/// covering the tile's square, row 0 at the north edge. Finer terrain tiles
/// drape a part of their nearest ancestor's image. Texels outside `extent_m`
/// have no imagery (a viewer shows its own ground material there).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImageryEntry {
    /// Folder of the images relative to the manifest: tile `(l, x, y)` is `<path>/<l>/<x>_<y>.jpg`.
    pub path: String,
    /// Pixels per image side.
    pub tile_px: u32,
    /// Terrain levels with images (the finest is `levels − 1`).
    pub levels: u8,
    /// Where the imagery has data, metres relative to the scene origin: min x, min y, max x, max y.
    pub extent_m: [f64; 4],
    /// Pixel size of the source imagery, metres.
    pub resolution_m: f64,
    /// Images.
    pub tiles: u64,
    /// Bytes of all images.
    pub bytes: u64,
    /// Where the imagery came from (e.g. the orthophoto file names), for reports.
    pub source: String,
}

/// Pixels per side of a baked ground image (the only size this build reads).
pub const IMAGERY_PX: u32 = 256;

impl ImageryEntry {
    /// URL of the image of terrain tile `(level, x, y)` relative to the manifest.
    #[must_use]
    pub fn tile_url(&self, level: u8, x: u32, y: u32) -> String {
        format!("{}/{level}/{x}_{y}.jpg", self.path)
    }

    pub(crate) fn validate(&self, terrain_levels: u8) -> Result<(), Problem> {
        check_url("terrain.imagery.path", &self.path)?;
        let [x0, y0, x1, y1] = self.extent_m;
        if !(x0 <= x1 && y0 <= y1 && self.extent_m.iter().all(|v| v.is_finite())) {
            return Err(Problem::Invalid("terrain.imagery.extent_m must be finite and min ≤ max".into()));
        }
        if !(self.resolution_m.is_finite() && self.resolution_m > 0.0) {
            return Err(Problem::Invalid("terrain.imagery.resolution_m must be positive".into()));
        }
        if self.tile_px != IMAGERY_PX {
            return Err(Problem::Invalid(format!(
                "terrain.imagery.tile_px {} is not {IMAGERY_PX}, the image size this build reads",
                self.tile_px
            )));
        }
        if self.levels == 0 || self.levels > terrain_levels {
            return Err(Problem::Invalid(format!(
                "terrain.imagery.levels {} is not 1–{terrain_levels} (the terrain's levels)",
                self.levels
            )));
        }
        Ok(())
    }
}

impl TerrainEntry {
    /// URL of tile `(level, x, y)` relative to the manifest.
    #[must_use]
    pub fn tile_url(&self, level: u8, x: u32, y: u32) -> String {
        format!("{}/{level}/{x}_{y}.terr", self.path)
    }

    /// Side of a tile of `level`, metres.
    #[must_use]
    pub fn tile_size_m(&self, level: u8) -> f64 {
        self.root_size_m / f64::from(1u32 << level.min(31))
    }

    /// South-west corner of tile `(level, x, y)`, metres relative to the scene origin.
    #[must_use]
    pub fn tile_origin_m(&self, level: u8, x: u32, y: u32) -> [f64; 2] {
        let s = self.tile_size_m(level);
        [self.origin_m[0] + f64::from(x) * s, self.origin_m[1] + f64::from(y) * s]
    }

    /// Whether terrain tile `(level, x, y)` (which exists) has an image: it
    /// is one of the imagery's levels and its square meets the imagery extent.
    #[must_use]
    pub fn has_imagery(&self, level: u8, x: u32, y: u32) -> bool {
        let Some(i) = &self.imagery else { return false };
        let [ox, oy] = self.tile_origin_m(level, x, y);
        let s = self.tile_size_m(level);
        let [x0, y0, x1, y1] = i.extent_m;
        level < i.levels && ox < x1 && ox + s > x0 && oy < y1 && oy + s > y0
    }

    /// Whether a child of terrain tile `(level, x, y)` has an image of its own
    /// (finer than the tile's): a viewer refines the tile while a texel of its
    /// image projects above its threshold (`docs/FORMAT.md`, "Terrain tiles").
    #[must_use]
    pub fn has_finer_imagery_below(&self, level: u8, x: u32, y: u32) -> bool {
        self.imagery.as_ref().is_some_and(|i| level.saturating_add(1) < i.levels)
            && (0..4u32).any(|k| self.has_imagery(level + 1, 2 * x + (k & 1), 2 * y + (k >> 1)))
    }

    pub(crate) fn validate(&self) -> Result<(), Problem> {
        check_url("terrain.path", &self.path)?;
        let finite = [self.origin_m[0], self.origin_m[1], self.root_size_m, self.resolution_m];
        if finite.iter().any(|v| !v.is_finite()) || self.root_size_m <= 0.0 || self.resolution_m <= 0.0 {
            return Err(Problem::Invalid(
                "terrain: origin, root size and resolution must be finite, sizes positive".into(),
            ));
        }
        finite_all("terrain.height_range_m", &self.height_range_m)?;
        if self.grid == 0 || self.grid > MAX_TERRAIN_GRID || !self.grid.is_multiple_of(2) {
            return Err(Problem::Invalid(format!("terrain.grid {} is not an even 2–{MAX_TERRAIN_GRID}", self.grid)));
        }
        if self.height_range_m.iter().any(|v| v.abs() > MAX_TERRAIN_HEIGHT_M) {
            return Err(Problem::Invalid(format!("terrain.height_range_m is beyond ±{MAX_TERRAIN_HEIGHT_M} m")));
        }
        if self.levels == 0 || self.levels > MAX_TERRAIN_LEVEL + 1 {
            return Err(Problem::Invalid(format!("terrain.levels {} is not 1–{}", self.levels, MAX_TERRAIN_LEVEL + 1)));
        }
        if let Some(i) = &self.imagery {
            i.validate(self.levels)?;
        }
        Ok(())
    }
}
