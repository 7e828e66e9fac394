//! The last stage of a bake (and of `merge`): the tile index (or a flat list)
//! and `scene.json`, checked with the viewer's own decoder; plus the file
//! helpers every stage writes with. Writes are atomic and remove nothing the
//! bake did not write ([`crate::out_dir`]). Output is deterministic.

use std::path::Path;

use anyhow::{Context, Result};
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
    // The geographic fit the browser converts lon/lat with (version 12): not
    // in a shard's part (merge fits the whole scene; the parts' CRS must agree).
    base.crs.fit = if base.shard.is_none() { geo_fit(&base, log) } else { None };
    // So are packs' block-compressed variants.
    if base.crs.fit.is_some() || base.species.iter().any(|s| !s.variants.is_empty()) {
        base.version = base.version.max(12);
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

/// Least margin of the geographic fit's box around a scene, metres.
const GEO_FIT_MARGIN_M: f64 = 25_000.0;

/// The scene's geographic fit ([`sylva::format::geofit`]) over its trees and
/// terrain and a margin of twice their size, at least 25 km, on each side
/// (cameras and links well beyond the forest stay within a millimetre; further
/// out the fit goes on linearly); `None`, with a warning, where the projection
/// cannot be fitted there.
pub fn geo_fit(m: &Manifest, log: &dyn Fn(&str)) -> Option<sylva::format::geofit::GeoFit> {
    let b = &m.bounds;
    let mut bx = [f64::from(b.min[0]), f64::from(b.min[1]), f64::from(b.max[0]), f64::from(b.max[1])];
    if let Some(t) = &m.terrain {
        let [x, y] = t.origin_m;
        bx = [bx[0].min(x), bx[1].min(y), bx[2].max(x + t.root_size_m), bx[3].max(y + t.root_size_m)];
    }
    let margin = (2.0 * (bx[2] - bx[0]).max(bx[3] - bx[1])).max(GEO_FIT_MARGIN_M);
    let bx = [bx[0] - margin, bx[1] - margin, bx[2] + margin, bx[3] + margin];
    let fitted = sylva::geo::GeoFrame::new(&m.crs.proj4, m.origin_m).and_then(|g| g.fit(bx));
    match fitted {
        Ok(fit) => {
            if fit.error_m > sylva::format::geofit::FIT_TOLERANCE_M {
                log(&format!(
                    "warning: the geographic fit is {:.1} mm from the projection at worst (the goal: 1 mm): lon/lat in \
                     browsers are that far off",
                    fit.error_m * 1000.0
                ));
            }
            log(&format!(
                "geographic fit: degree {}, within {:.2} mm over {:.1} × {:.1} km",
                fit.degree,
                fit.error_m * 1000.0,
                (bx[2] - bx[0]) / 1000.0,
                (bx[3] - bx[1]) / 1000.0
            ));
            Some(fit)
        }
        Err(e) => {
            log(&format!("warning: no geographic fit ({e}): browsers will not convert lon/lat for this scene"));
            None
        }
    }
}

/// Adds the geographic fit to a scene baked before it (or refits it) and
/// rewrites its `scene.json` in place (a temporary file renamed: a reader
/// sees the old or the new manifest). Nothing else of the scene changes.
///
/// # Errors
/// A scene folder without a readable, valid `scene.json`, a projection that
/// cannot be fitted, or a manifest that cannot be written.
pub fn add_geo_fit(dir: &Path, log: &dyn Fn(&str)) -> Result<Manifest> {
    let path = dir.join("scene.json");
    let name = path.display().to_string();
    let bytes = sylva::paths::read_regular(&path, None, sylva::paths::MAX_SCENE_FILE_BYTES)
        .with_context(|| format!("cannot read {name} (is {} a baked scene folder?)", dir.display()))?;
    let mut m = Manifest::decode(&name, &bytes)?;
    let had = m.crs.fit.is_some();
    m.crs.fit = None;
    let fit =
        geo_fit(&m, log).ok_or_else(|| anyhow::anyhow!("{name}: the scene CRS {:?} cannot be fitted", m.crs.proj4))?;
    m.crs.fit = Some(fit);
    m.version = m.version.max(12);
    let out = m.encode();
    Manifest::decode(&name, &out)?;
    let tmp = dir.join(".scene.json.geo-fit");
    write_file(&tmp, &out)?;
    if let Err(e) = std::fs::rename(&tmp, &path) {
        // (Nothing left behind that a later bake would take for a foreign file.)
        let _ = std::fs::remove_file(&tmp);
        return Err(e).with_context(|| format!("cannot replace {name}"));
    }
    log(&format!(
        "{}: {} the geographic fit (manifest version {})",
        name,
        if had { "refitted" } else { "added" },
        m.version
    ));
    Ok(m)
}
