//! The bake as one pipeline, read top to bottom in [`bake_scene`]:
//!
//! 1. trees: placements → scene trees ([`trees`]: sample, CRS, medians, density,
//!    ground heights from `--dem` ([`ground`]); run by `sylva-bake bake` before
//!    this, `demo` makes its trees itself);
//! 2. species packs ([`packs`]: every LoD of every model, rendered on the GPU);
//! 3. batches and tiles ([`tiles`]: grid cells into batches, tiles and id sidecars);
//! 4. terrain ([`terrain`]: a quadtree of height grids from the `--dem`
//!    GeoTIFFs or the demo's hills);
//! 5. write: the tile index and `scene.json` ([`crate::bake::scene_write`]).
//!
//! Each stage is a module that takes what the earlier ones made and calls no
//! other stage; the folder is written atomically ([`OutDir::write`]).

pub mod batching;
pub mod bucket;
pub mod canopy;
pub mod ground;
pub mod ground_material;
pub mod imagery;
pub mod pack_cache;
pub mod packs;
pub mod scene_write;
pub mod terrain;
pub mod tiles;
pub mod trees;

use std::path::PathBuf;

use anyhow::{bail, Result};
use glam::DVec3;
use sylva::format::manifest::{Bounds, Counts, Crs as CrsEntry, Manifest, ShardStamp, SCENE_FORMAT, SCENE_VERSION};

use crate::bake::bucket::TreeSource;
use crate::input::gltf_import::ImportedModel;
use crate::input::reproject::Crs;
use crate::out_dir::OutDir;
use crate::pack::PackOptions;

/// Everything a scene is made from.
pub struct SceneInput<'a> {
    /// Ground heights for the terrain tiles, if any (written by shard 0 only).
    pub terrain: Option<terrain::TerrainSource<'a>>,
    /// Imagery to drape on the terrain, if any (written by shard 0 only, with the terrain).
    pub imagery: Option<imagery::ImagerySource<'a>>,
    /// Species names and models, indexed by `SceneTree::species`.
    pub species: Vec<(String, ImportedModel)>,
    /// Trees relative to `origin_m` (in memory or in bucket files).
    pub trees: TreeSource,
    /// Scene CRS.
    pub crs: Crs,
    /// Scene origin in CRS coordinates.
    pub origin_m: DVec3,
    /// Batch cell size, metres.
    pub cell_size_m: u32,
    /// Cells per tile side.
    pub tile_cells: u32,
    /// Pack options.
    pub pack: PackOptions,
    /// Where to write billboard PNGs, if anywhere.
    pub debug_dump: Option<PathBuf>,
    /// The pack cache folder, if any ([`pack_cache`]).
    pub pack_cache: Option<PathBuf>,
    /// Bake only shard `.0` of `.1` of the tile grid (packs only in shard 0).
    pub shard: Option<(u32, u32)>,
    /// Most tiles per index node; scenes with more tiles get a hierarchical index.
    pub index_node_tiles: u32,
    /// Width of the finest canopy raster cells (metres).
    pub canopy_cell_m: f64,
    /// The per-tree attributes, if kept (`.attr` sidecars next to the tiles).
    pub attributes: Option<crate::input::attributes::AttributeTable>,
    /// The text ids of the trees whose id is no whole number (`.ids` version 2).
    pub text_ids: Option<trees::TextIds>,
    /// The trees' timeline (censuses, planting and removal dates), if any.
    pub timeline: Option<sylva::format::timeline::Timeline>,
}

/// What was written.
#[derive(Debug, Clone)]
pub struct SceneSummary {
    /// The manifest.
    pub manifest: Manifest,
    /// Bytes of all instance records.
    pub instance_bytes: u64,
    /// Seconds spent on packs.
    pub pack_seconds: f64,
    /// Seconds spent on tiles.
    pub tile_seconds: f64,
}

/// Bakes `input` into `out` (atomically; see [`OutDir`]): packs, tiles, index
/// and manifest.
pub fn bake_scene(input: &SceneInput<'_>, out: OutDir, log: &dyn Fn(&str)) -> Result<SceneSummary> {
    if input.trees.is_empty() && input.shard.is_none() {
        bail!("no trees to bake: every placement was skipped (see the report above)");
    }
    out.write(|dir| {
        // Packs are baked by shard 0 only; the other shards write tiles.
        let bake_packs = input.shard.is_none_or(|(index, _)| index == 0);
        let packs = packs::bake_packs(
            &input.species,
            &input.pack,
            bake_packs,
            input.pack_cache.as_deref(),
            input.debug_dump.as_deref(),
            dir,
            log,
        )?;
        let tiles = tiles::write_tiles(
            &input.trees,
            &packs.shapes,
            input.cell_size_m,
            input.tile_cells,
            input.shard,
            input.attributes.as_ref(),
            input.text_ids.as_ref(),
            dir,
            log,
        )?;
        // Terrain, by shard 0 only (like the packs; `merge` copies it).
        let mut terrain = match &input.terrain {
            Some(src) if bake_packs => terrain::write_terrain(src, dir, log)?,
            _ => None,
        };
        if let (Some(t), Some(src)) = (terrain.as_mut(), &input.imagery) {
            t.imagery = imagery::write_imagery(src, t, dir, log)?;
        }
        let mut species = packs.entries;
        for (entry, n) in species.iter_mut().zip(&tiles.species_trees) {
            entry.trees = *n;
        }
        let base = Manifest {
            format: SCENE_FORMAT.into(),
            version: SCENE_VERSION, // finish_scene writes 3 without terrain
            crs: CrsEntry { epsg: input.crs.epsg, proj4: input.crs.proj4.clone(), fit: None },
            origin_m: input.origin_m.to_array(),
            bounds: Bounds { min: [0.0; 3], max: [0.0; 3] },
            cell_size_m: input.cell_size_m as f32,
            tile_cells: input.tile_cells,
            counts: Counts { trees: 0, batches: 0, tiles: 0 },
            species,
            tiles: Vec::new(),
            index: None,
            home: None,
            shard: input.shard.map(|(index, count)| ShardStamp { index, count }),
            terrain,
            attributes: input.attributes.as_ref().map(|a| a.schema.clone()),
            canopy: None,
            timeline: input.timeline.clone(),
        };
        // A shard lists its tiles flat; `merge` builds the index of the whole.
        let flat = input.shard.is_some();
        let manifest = crate::bake::scene_write::finish_scene(
            dir,
            base,
            tiles.entries,
            crate::bake::scene_write::Layout {
                node_tiles: input.index_node_tiles,
                flat,
                canopy_cell_m: input.canopy_cell_m,
            },
            log,
        )?;
        Ok(SceneSummary {
            manifest,
            instance_bytes: tiles.instance_bytes,
            pack_seconds: packs.seconds,
            tile_seconds: tiles.seconds,
        })
    })
}
