//! Stage 3 of the bake: the trees into grid-cell batches and tiles
//! ([`crate::bake::batching`]), written to `tiles/` with their id and attribute sidecars, one group
//! of whole tiles in memory at a time (all trees, or one bucket of a bake larger
//! than memory). A shard keeps the trees of its own tiles.

use std::path::Path;
use std::time::Instant;

use anyhow::Result;
use rayon::prelude::*;
use sylva::format::attributes::encode_attributes;
use sylva::format::ids::{encode_tree_ids, TreeIds};
use sylva::format::manifest::{Bounds, TileEntry, TileLevels};

use crate::input::attributes::AttributeTable;

use crate::bake::batching::{build_tiles, shard_of_tile, tile_of, SceneTree, SpeciesShape};
use crate::bake::bucket::TreeSource;
use crate::out_dir::{create_dir, write_file};

/// What the tiles stage wrote.
pub struct Tiles {
    /// One entry per tile written.
    pub entries: Vec<TileEntry>,
    /// Trees written per species.
    pub species_trees: Vec<u64>,
    /// Bytes of all instance records.
    pub instance_bytes: u64,
    /// Seconds spent.
    pub seconds: f64,
}

/// Batches `trees` of the species `shapes` into tiles of `tile_cells` cells of
/// `cell_size_m` and writes them into `dir/tiles/` (only shard `.0` of `.1`'s
/// tiles with `shard`), with their attribute sidecars from `attributes`.
#[allow(clippy::too_many_arguments)] // the stage's inputs, each used once
pub fn write_tiles(
    trees: &TreeSource,
    shapes: &[SpeciesShape],
    cell_size_m: u32,
    tile_cells: u32,
    shard: Option<(u32, u32)>,
    attributes: Option<&AttributeTable>,
    text_ids: Option<&super::trees::TextIds>,
    dir: &Path,
    log: &dyn Fn(&str),
) -> Result<Tiles> {
    let t0 = Instant::now();
    create_dir(&dir.join("tiles"))?;
    let mut species_trees = vec![0u64; shapes.len()];
    let mut entries: Vec<(TileEntry, u64)> = Vec::new();
    let mut kept = 0u64;
    trees.for_each_group(&mut |group| {
        let shard_trees: Vec<SceneTree>;
        // (A streamed bake's buckets hold the shard's trees only already.)
        let group: &[SceneTree] = match shard {
            Some((index, count)) if matches!(trees, TreeSource::Memory(_)) => {
                shard_trees = group
                    .iter()
                    .filter(|t| {
                        let (x, y) = tile_of(t.pos, cell_size_m, tile_cells);
                        shard_of_tile(x, y, count) == index
                    })
                    .copied()
                    .collect();
                &shard_trees
            }
            _ => group,
        };
        kept += group.len() as u64;
        for t in group {
            species_trees[t.species as usize] += 1;
        }
        let built = build_tiles(group, shapes, cell_size_m, tile_cells);
        let written: Vec<(TileEntry, u64)> = built
            .par_iter()
            .map(|bt| -> Result<(TileEntry, u64)> {
                let stem = format!("tiles/{}_{}", bt.tile.tile_x, bt.tile.tile_y);
                let bytes = bt.tile.encode();
                write_file(&dir.join(format!("{stem}.tile")), &bytes)?;
                let texts: Vec<(u32, String)> = match text_ids {
                    Some(table) => bt
                        .rows
                        .iter()
                        .enumerate()
                        .filter(|(i, _)| bt.ids[*i] >= 1 << 63)
                        .filter_map(|(i, &row)| table.get(row).map(|t| (i as u32, t.to_string())))
                        .collect(),
                    None => Vec::new(),
                };
                write_file(
                    &dir.join(format!("{stem}.ids")),
                    &encode_tree_ids(&TreeIds { numbers: bt.ids.clone(), texts })
                        .map_err(|e| anyhow::anyhow!("{stem}.ids: {e}"))?,
                )?;
                let attribute_codes = match attributes {
                    Some(a) => {
                        let codes = a.codes_for(&bt.rows);
                        write_file(&dir.join(format!("{stem}.attr")), &encode_attributes(&a.schema, &codes))?;
                        Some(codes.ranges(&a.schema))
                    }
                    None => None,
                };
                Ok((
                    TileEntry {
                        x: bt.tile.tile_x,
                        y: bt.tile.tile_y,
                        url: format!("{stem}.tile"),
                        ids_url: format!("{stem}.ids"),
                        bytes: bytes.len() as u64,
                        trees: bt.tile.instances.len() as u64,
                        batches: bt.tile.batches.len() as u32,
                        bounds: Bounds { min: bt.bounds.0, max: bt.bounds.1 },
                        attribute_codes,
                        levels: Some(TileLevels {
                            bytes: bt.tile.level_bytes(),
                            height_m: bt.tile.levels().tallest_m,
                            version: bt.tile.version(),
                        }),
                    },
                    bt.tile.instance_bytes() as u64,
                ))
            })
            .collect::<Result<_>>()?;
        entries.extend(written);
        Ok(())
    })?;
    if let Some((index, count)) = shard {
        log(&format!("shard {index}/{count}: {kept} of {} trees", trees.len()));
    }
    let instance_bytes = entries.iter().map(|(_, b)| b).sum();
    Ok(Tiles {
        entries: entries.into_iter().map(|(e, _)| e).collect(),
        species_trees,
        instance_bytes,
        seconds: t0.elapsed().as_secs_f64(),
    })
}
