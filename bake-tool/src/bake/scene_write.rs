//! The last stage of a bake (and of `merge`): the tile index (or a flat list)
//! and `scene.json`, checked with the viewer's own decoder; plus the file
//! helpers every stage writes with. Writes are atomic and remove nothing the
//! bake did not write ([`crate::out_dir`]). Output is deterministic.

use std::path::Path;

use anyhow::Result;
use sylva::format::build_index;
use sylva::format::manifest::{Bounds, Counts, Manifest, TileEntry};

use crate::out_dir::{create_dir, write_file};

/// File-name-safe version of a species name.
pub fn safe_name(name: &str) -> String {
    let s: String = name
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '_' { c.to_ascii_lowercase() } else { '_' })
        .collect();
    if s.is_empty() {
        "species".into()
    } else {
        s
    }
}

/// How [`finish_scene`] lays a scene out.
#[derive(Debug, Clone, Copy)]
pub struct Layout {
    /// Most tiles per index node.
    pub node_tiles: u32,
    /// A flat tile list whatever the count (a shard's part).
    pub flat: bool,
    /// Width of the finest canopy raster cells (metres).
    pub canopy_cell_m: f64,
}

/// Finishes a scene in `dir` from its species and tiles: writes the index (or a
/// flat list) and `scene.json`. Shared by the bake and by `merge`, so both give
/// the same bytes.
pub fn finish_scene(
    dir: &Path,
    mut base: Manifest,
    mut tiles: Vec<TileEntry>,
    layout: Layout,
    log: &dyn Fn(&str),
) -> Result<Manifest> {
    let Layout { node_tiles, flat, canopy_cell_m } = layout;
    tiles.sort_by_key(|t| (t.y, t.x));
    let bounds = sylva::format::index::union_bounds(tiles.iter().map(|t| &t.bounds))
        .unwrap_or(Bounds { min: [0.0; 3], max: [0.0; 3] });
    base.bounds = bounds;
    base.counts = Counts {
        trees: tiles.iter().map(|t| t.trees).sum(),
        batches: tiles.iter().map(|t| u64::from(t.batches)).sum(),
        tiles: tiles.len() as u64,
    };
    // The oldest version that holds what the scene has, so older viewers read it.
    // Tiles in prefix levels need version 7 (tile version 3), 9 (version 4:
    // the levels' steps differ, so older viewers must refuse the scene).
    let levels = tiles.iter().filter_map(|t| t.levels.as_ref()).map(|l| l.version).max();
    base.version = match &base.terrain {
        _ if levels.is_some_and(|v| v >= 4) => 9,
        _ if levels.is_some() => 7,
        _ if base.attributes.is_some() => 6,
        Some(t) if t.imagery.is_some() => 5,
        Some(_) => 4,
        None => 3,
    };
    base.home = sylva::format::manifest::densest_group(&tiles);
    // Canopy rasters for far views (version 8; 10 for canopy version 2, 11 for 3): not in a shard's part (merge
    // makes them from all the tiles), nor for a scene without trees.
    let looks = if base.shard.is_none() && !tiles.is_empty() {
        Some(crate::bake::canopy::species_looks(dir, &base.species, log)?)
    } else {
        None
    };
    if let Some(looks) = &looks {
        let tile_m = f64::from(base.cell_size_m) * f64::from(base.tile_cells);
        let started = std::time::Instant::now();
        let entry = crate::bake::canopy::write_quadtree(dir, &tiles, tile_m, canopy_cell_m, looks)?;
        log(&format!(
            "canopy: {} rasters in {} levels, finest cells {:.1} m, {:.2} MB ({:.1} s)",
            entry.rasters,
            entry.levels,
            entry.size_m(entry.levels - 1) / f64::from(entry.cells),
            entry.bytes as f64 / 1e6,
            started.elapsed().as_secs_f64()
        ));
        base.canopy = Some(entry);
        // Canopy rasters of version 3 (the cells' seasons): version 11.
        base.version = base.version.max(11);
    }
    if !flat && tiles.len() > node_tiles as usize {
        let built = build_index(&tiles, node_tiles);
        create_dir(&dir.join("index"))?;
        for (url, node) in &built.nodes {
            write_file(&dir.join(url), &node.encode())?;
        }
        base.index = Some(built.reference);
        base.tiles = Vec::new();
    } else {
        base.index = None;
        base.tiles = tiles;
    }
    let bytes = base.encode();
    // Validate what we wrote with the same decoder the viewer uses.
    Manifest::decode("scene.json", &bytes)?;
    write_file(&dir.join("scene.json"), &bytes)?;
    Ok(base)
}
