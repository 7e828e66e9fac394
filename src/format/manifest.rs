//! The scene manifest (`scene.json`): what a viewer reads first.
//!
//! Coordinates: the scene CRS is projected (metres); `origin_m` is an f64 point
//! in it and every other position in a scene (bounds, batch origins) is in
//! metres relative to it, x east, y north, z up.

use serde::{Deserialize, Serialize};

use super::entries::{check_url, validate_bounds};
pub use super::entries::{densest_group, Bounds, Home, IndexRef, TileEntry, TileLevels};
use super::error::{finite, DecodeError, Problem};

/// Value of the manifest's `format` field.
pub const SCENE_FORMAT: &str = "sylva-scene";
/// Newest manifest version this build writes and reads (it reads 1 to 12).
/// Version 2 added the hierarchical index, pack head sizes and shard stamps;
/// version 3 where the trees are (`home`); version 4 the terrain; version 5
/// ground imagery (`terrain.imagery`); version 6 per-tree attributes
/// (`attributes`); version 7 tiles in prefix levels (tile version 3, the
/// entries' `levels`); version 8 canopy rasters (`canopy`, and the index's
/// child entries' `height_m`); version 9 tiles in levels of √2 steps (tile
/// version 4, the entries' `levels.version`); version 10 canopy rasters of
/// version 2 (`tallest_ratio` in their header); version 11 canopy rasters of
/// version 3 (the cells' seasons) and packs that may hold a deciduous
/// species' seasons (`META.season`, the bare far tiers); version 12 the
/// geographic fit (`crs.fit`) and packs' block-compressed variants
/// (`species[].variants`).
/// The bake writes the oldest version that holds what a scene has (11 for
/// every scene with trees, 12 with a geographic fit or packs' block-compressed variants, 9 for a
/// shard's part, which has no canopy (12 for shard 0's, with the variants); 3 to 8
/// for older bakes), so older viewers refuse newer scenes with a clear message.
pub const SCENE_VERSION: u32 = 12;
/// Most species a scene may list.
pub const MAX_SPECIES: usize = 65_536;
/// Most tiles a flat tile index may list.
pub const MAX_TILES: usize = 1 << 22;

/// The scene's coordinate reference system.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Crs {
    /// EPSG code, e.g. 32633 for UTM zone 33N.
    pub epsg: u32,
    /// The proj4 definition used by the bake.
    pub proj4: String,
    /// lon/lat ↔ scene metres fitted by the bake (version 12): what the
    /// browser uses for geographic coordinates, without a projection library.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fit: Option<super::geofit::GeoFit>,
}

/// One species and its LoD pack.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpeciesEntry {
    /// Species (model) name.
    pub name: String,
    /// Pack URL relative to the manifest.
    pub pack: String,
    /// Pack size in bytes.
    pub bytes: u64,
    /// Model height at scale 1, metres.
    pub height_m: f32,
    /// Model bounds at scale 1.
    pub bounds: Bounds,
    /// Trees of this species in the scene.
    pub trees: u64,
    /// Bytes of the pack's header, section table and `META` section: a viewer
    /// fetches this range first and then only the sections its views need.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub head_bytes: Option<u64>,
    /// The same pack with its textures block-encoded for GPUs that sample
    /// them (version 12): a viewer whose device can takes one instead.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub variants: Vec<PackVariant>,
}

/// A species pack's block-compressed variant (`species[].variants[]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PackVariant {
    /// The block encoding of its texture arrays (`"bc7"`, `"etc2"`); viewers skip
    /// names they do not know.
    pub textures: String,
    /// Pack URL relative to the manifest.
    pub pack: String,
    /// Pack size in bytes.
    pub bytes: u64,
    /// Bytes of its head (as [`SpeciesEntry::head_bytes`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub head_bytes: Option<u64>,
}

/// The pack a viewer fetches for a species: its URL, sizes and the
/// textures' block encoding (`None`: plain texels).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PackChoice<'a> {
    /// URL relative to the manifest.
    pub pack: &'a str,
    /// File bytes.
    pub bytes: u64,
    /// Head bytes, if known.
    pub head_bytes: Option<u64>,
    /// The block encoding of its textures.
    pub encoding: Option<super::pack::TexelEncoding>,
}

impl SpeciesEntry {
    /// The first variant whose encoding is in `encodings` (what the device
    /// samples, best first), else the plain pack.
    #[must_use]
    pub fn pack_for(&self, encodings: &[super::pack::TexelEncoding]) -> PackChoice<'_> {
        for e in encodings {
            if let Some(v) = self.variants.iter().find(|v| v.textures == e.name()) {
                return PackChoice { pack: &v.pack, bytes: v.bytes, head_bytes: v.head_bytes, encoding: Some(*e) };
            }
        }
        PackChoice { pack: &self.pack, bytes: self.bytes, head_bytes: self.head_bytes, encoding: None }
    }
}

/// Most variants a species may list.
pub const MAX_PACK_VARIANTS: usize = 8;

/// Scene-wide counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Counts {
    /// Trees.
    pub trees: u64,
    /// Batches.
    pub batches: u64,
    /// Tiles.
    pub tiles: u64,
}

/// `scene.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// Always [`SCENE_FORMAT`].
    pub format: String,
    /// Always [`SCENE_VERSION`] for this build.
    pub version: u32,
    /// Projected CRS of the scene.
    pub crs: Crs,
    /// Scene origin in CRS coordinates (metres), f64.
    pub origin_m: [f64; 3],
    /// Bounds of every tree, relative to the origin.
    pub bounds: Bounds,
    /// Grid cell size of the batches, metres.
    pub cell_size_m: f32,
    /// Cells per tile side.
    pub tile_cells: u32,
    /// Scene-wide counts.
    pub counts: Counts,
    /// Species, indexed by `GpuBatch::species`.
    pub species: Vec<SpeciesEntry>,
    /// The tile index (flat); empty when `index` is given.
    pub tiles: Vec<TileEntry>,
    /// The hierarchical tile index (version 2), instead of the flat list.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub index: Option<IndexRef>,
    /// Where the trees are (version 3): the largest group of touching tiles.
    /// Views aim here first.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub home: Option<Home>,
    /// Set on one shard's output of a sharded bake (`sylva-bake bake --shard`):
    /// not a scene to view until `sylva-bake merge` has joined the shards.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shard: Option<ShardStamp>,
    /// The terrain quadtree (version 4), if the scene has ground heights.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub terrain: Option<super::terrain::TerrainEntry>,
    /// The per-tree attribute columns (version 6), if the bake kept any: each
    /// tile's values are in the sidecar next to it
    /// ([`super::attributes::attributes_url`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub attributes: Option<super::attributes::AttributeSchema>,
    /// The canopy rasters (version 8): a quadtree of what the forest looks like
    /// where trees are a pixel or two.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub canopy: Option<super::canopy::CanopyEntry>,
    /// The trees at a date (censuses, planting and removal dates): which
    /// attribute columns hold each tree's timeline ([`super::timeline`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timeline: Option<super::timeline::Timeline>,
}

/// Which shard of a sharded bake wrote a directory.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShardStamp {
    /// This shard, 0-based.
    pub index: u32,
    /// Shards in all.
    pub count: u32,
}

impl Manifest {
    /// Parses and validates `scene.json`. `file` names it in errors.
    ///
    /// # Errors
    /// A [`DecodeError`] for JSON that does not parse or match the schema, a wrong
    /// format name or version, non-finite numbers, inverted bounds, counts that do
    /// not add up, or URLs that leave the scene directory.
    pub fn decode(file: &str, bytes: &[u8]) -> Result<Self, DecodeError> {
        let inner = || -> Result<Self, Problem> {
            // Check the format and version first so an older/newer file gets the
            // right message instead of a schema mismatch.
            let value: serde_json::Value = serde_json::from_slice(bytes).map_err(|e| Problem::Json(e.to_string()))?;
            let format = value.get("format").and_then(|f| f.as_str());
            if format != Some(SCENE_FORMAT) {
                return Err(Problem::Invalid(format!(
                    "\"format\" is {:?}, expected \"{SCENE_FORMAT}\": not a Sylva scene manifest",
                    format.unwrap_or("missing")
                )));
            }
            let version = value.get("version").and_then(serde_json::Value::as_u64);
            if !version.is_some_and(|v| (1..=u64::from(SCENE_VERSION)).contains(&v)) {
                return Err(Problem::UnsupportedVersion {
                    found: version.unwrap_or(0).min(u32::MAX.into()) as u32,
                    supported: SCENE_VERSION,
                });
            }
            let m: Self = serde_json::from_value(value).map_err(|e| Problem::Json(e.to_string()))?;
            m.validate()?;
            Ok(m)
        };
        inner().map_err(|p| DecodeError::new(file, p))
    }

    /// Where the views of this scene aim first: [`Self::home`], else the densest
    /// group of a flat tile list, else the bounds of every tree.
    #[must_use]
    pub fn focus(&self) -> Bounds {
        self.home.or_else(|| densest_group(&self.tiles)).map_or(self.bounds, |h| h.bounds)
    }

    /// Serialises to pretty JSON.
    #[must_use]
    pub fn encode(&self) -> Vec<u8> {
        let mut v = serde_json::to_vec_pretty(self).expect("Manifest serialises");
        v.push(b'\n');
        v
    }

    fn validate(&self) -> Result<(), Problem> {
        if let Some(fit) = &self.crs.fit {
            if self.version < 12 {
                return Err(Problem::Invalid("\"crs.fit\" needs manifest version 12".into()));
            }
            fit.validate()?;
        }
        if let Some(t) = &self.timeline {
            t.resolve(self.attributes.as_ref())?;
        }
        if let Some(c) = &self.canopy {
            if self.version < 8 {
                return Err(Problem::Invalid("\"canopy\" needs manifest version 8".into()));
            }
            c.validate()?;
        }
        if self.version < 7 && self.tiles.iter().any(|t| t.levels.is_some()) {
            return Err(Problem::Invalid("tiles with \"levels\" need manifest version 7".into()));
        }
        if self.version < 9 && self.tiles.iter().any(|t| t.levels.as_ref().is_some_and(|l| l.version >= 4)) {
            return Err(Problem::Invalid("tiles with \"levels\" of tile version 4 need manifest version 9".into()));
        }
        if let Some(a) = &self.attributes {
            if self.version < 6 {
                return Err(Problem::Invalid("\"attributes\" needs manifest version 6".into()));
            }
            a.validate()?;
        }
        if let Some(t) = &self.terrain {
            if self.version < 4 {
                return Err(Problem::Invalid("\"terrain\" needs manifest version 4".into()));
            }
            if t.imagery.is_some() && self.version < 5 {
                return Err(Problem::Invalid("\"terrain.imagery\" needs manifest version 5".into()));
            }
            t.validate()?;
        }
        for (i, o) in self.origin_m.iter().enumerate() {
            finite(format!("origin_m[{i}]"), *o)?;
        }
        validate_bounds("bounds", &self.bounds)?;
        finite("cell_size_m", self.cell_size_m.into())?;
        if self.cell_size_m <= 0.0 || self.tile_cells == 0 {
            return Err(Problem::Invalid("cell_size_m and tile_cells must be positive".into()));
        }
        if self.species.len() > MAX_SPECIES || self.tiles.len() > MAX_TILES {
            return Err(Problem::Invalid(format!(
                "{} species / {} tiles exceed the limits {MAX_SPECIES} / {MAX_TILES}",
                self.species.len(),
                self.tiles.len()
            )));
        }
        for (i, s) in self.species.iter().enumerate() {
            let what = format!("species[{i}]");
            check_url(&format!("{what}.pack"), &s.pack)?;
            if !s.variants.is_empty() && self.version < 12 {
                return Err(Problem::Invalid(format!("{what}.variants needs manifest version 12")));
            }
            if s.variants.len() > MAX_PACK_VARIANTS {
                return Err(Problem::Invalid(format!(
                    "{what}.variants: {} variants exceed {MAX_PACK_VARIANTS}",
                    s.variants.len()
                )));
            }
            for (k, v) in s.variants.iter().enumerate() {
                check_url(&format!("{what}.variants[{k}].pack"), &v.pack)?;
                if v.textures.is_empty() || v.textures.len() > 16 {
                    return Err(Problem::Invalid(format!(
                        "{what}.variants[{k}].textures {:?} is no encoding name",
                        v.textures
                    )));
                }
            }
            finite(format!("{what}.height_m"), s.height_m.into())?;
            validate_bounds(&format!("{what}.bounds"), &s.bounds)?;
        }
        if let Some(index) = &self.index {
            if self.version < 2 {
                return Err(Problem::Invalid("\"index\" needs manifest version 2".into()));
            }
            if !self.tiles.is_empty() {
                return Err(Problem::Invalid("a manifest with an \"index\" must have an empty \"tiles\" list".into()));
            }
            index.validate()?;
        }
        if let Some(h) = &self.home {
            if self.version < 3 {
                return Err(Problem::Invalid("\"home\" needs manifest version 3".into()));
            }
            validate_bounds("home.bounds", &h.bounds)?;
        }
        if let Some(s) = &self.shard {
            if s.count == 0 || s.index >= s.count {
                return Err(Problem::Invalid(format!("shard {} of {}: must be 0 ≤ index < count", s.index, s.count)));
            }
        }
        let species_trees = self.species.iter().fold(0u64, |a, s| a.saturating_add(s.trees));
        if self.index.is_some() {
            // Tile sums are checked node by node as the index is read.
            if species_trees != self.counts.trees {
                return Err(Problem::Invalid(format!(
                    "counts.trees {} does not match the species ({species_trees} trees)",
                    self.counts.trees
                )));
            }
            return Ok(());
        }
        let mut trees = 0u64;
        let mut batches = 0u64;
        for (i, t) in self.tiles.iter().enumerate() {
            t.validate(&format!("tiles[{i}]"))?;
            trees = trees.saturating_add(t.trees);
            batches = batches.saturating_add(t.batches.into());
        }
        if trees != self.counts.trees
            || species_trees != self.counts.trees
            || batches != self.counts.batches
            || self.tiles.len() as u64 != self.counts.tiles
        {
            return Err(Problem::Invalid(format!(
                "counts {:?} do not match the tiles ({trees} trees, {batches} batches, {} tiles) and species ({species_trees} trees)",
                self.counts,
                self.tiles.len()
            )));
        }
        Ok(())
    }
}
