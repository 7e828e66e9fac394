//! `sylva-bake merge`: joins the outputs of a sharded bake (`bake --shard I/N`)
//! into one scene, byte-identical to a single-process bake of the same input.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use sylva::format::{Manifest, TileEntry};

use crate::bake::scene_write::finish_scene;
use crate::out_dir::create_dir;
use crate::out_dir::OutDir;

/// Reads and checks the shard manifests, copies packs (from shard 0), tiles and
/// id sidecars into `out` and writes the index and manifest of the whole.
pub fn merge(
    dirs: &[PathBuf],
    out: OutDir,
    node_tiles: u32,
    canopy_cell_m: f64,
    log: &dyn Fn(&str),
) -> Result<Manifest> {
    if dirs.is_empty() {
        bail!("merge: name the shard directories (DIR_0 … DIR_N-1)");
    }
    let mut shards: Vec<(PathBuf, Manifest)> = Vec::new();
    for dir in dirs {
        let path = dir.join("scene.json");
        let bytes = sylva::paths::read_regular(&path, None, sylva::paths::MAX_SCENE_FILE_BYTES)
            .with_context(|| format!("cannot read {}", path.display()))?;
        let m = Manifest::decode(&path.display().to_string(), &bytes)?;
        if m.shard.is_none() {
            bail!("{}: not the output of `sylva-bake bake --shard` (no \"shard\" stamp)", path.display());
        }
        shards.push((dir.clone(), m));
    }
    shards.sort_by_key(|(_, m)| m.shard.map(|s| s.index));
    let count = shards[0].1.shard.map_or(0, |s| s.count);
    for (i, (dir, m)) in shards.iter().enumerate() {
        let s = m.shard.expect("checked above");
        if s.count != count {
            bail!("{}: shard {} of {}, but {} is of {count}", dir.display(), s.index, s.count, shards[0].0.display());
        }
        if s.index as usize != i {
            // Sorted by index: a smaller one here repeats the one before; a larger one skipped `i`.
            let (shard, what) = if (s.index as usize) < i { (s.index as usize, "given twice") } else { (i, "missing") };
            bail!("shard {shard} of {count} is {what} (have: {})", list_indices(&shards));
        }
    }
    if shards.len() != count as usize {
        bail!(
            "{} shard directories given, the shards say there are {count} (have: {})",
            shards.len(),
            list_indices(&shards)
        );
    }
    let first = &shards[0].1;
    for (dir, m) in &shards[1..] {
        let same = (m.crs.epsg, &m.crs.proj4) == (first.crs.epsg, &first.crs.proj4)
            && m.origin_m == first.origin_m
            && m.cell_size_m == first.cell_size_m
            && m.tile_cells == first.tile_cells
            && m.species.len() == first.species.len()
            && m.species.iter().zip(&first.species).all(|(a, b)| a.name == b.name && a.pack == b.pack)
            && m.attributes.as_ref().map(|a| &a.columns) == first.attributes.as_ref().map(|a| &a.columns);
        if !same {
            bail!(
                "{}: CRS, origin, cell size, tile size, species or attributes differ from shard 0 ({}): the shards come from different bakes",
                dir.display(),
                shards[0].0.display()
            );
        }
    }
    let mut base = first.clone();
    base.shard = None;
    for (s, entry) in base.species.iter_mut().enumerate() {
        entry.trees = shards.iter().map(|(_, m)| m.species[s].trees).sum();
    }
    out.write(|tmp| {
        create_dir(&tmp.join("species"))?;
        create_dir(&tmp.join("tiles"))?;
        // Every file is written once: two manifest entries naming one file (or
        // the manifest itself) would overwrite what was checked.
        let mut written: HashSet<String> = ["scene.json", FILE_LIST].into_iter().map(String::from).collect();
        let mut copy_checked = |from: &Path, rel: &str, check: &mut dyn FnMut(&[u8]) -> Result<()>| -> Result<()> {
            if !written.insert(plain_key(rel)) {
                bail!(
                    "{}: {rel} is named twice (or is the manifest): the shards come from different bakes",
                    from.join("scene.json").display()
                );
            }
            copy_checked(from, tmp, rel, check)
        };
        for sp in &first.species {
            // The pack and its block-compressed variants, each decoded first.
            for pack in std::iter::once(&sp.pack).chain(sp.variants.iter().map(|v| &v.pack)) {
                copy_checked(&shards[0].0, pack, &mut |b| {
                    sylva::format::decode_pack(pack, &sylva::format::stored::unstore(pack, b.to_vec())?)?;
                    Ok(())
                })?;
            }
        }
        // Terrain: written by shard 0 only, copied whole.
        if let Some(t) = &first.terrain {
            copy_terrain(&shards[0].0, tmp, t, &mut copy_checked)?;
        }
        let mut tiles: Vec<TileEntry> = Vec::new();
        let species = u32::try_from(first.species.len()).unwrap_or(u32::MAX);
        for (dir, m) in &shards {
            for t in &m.tiles {
                // Each file decoded before it is copied, the sidecars against their tile.
                let mut instances = 0usize;
                copy_checked(dir, &t.url, &mut |b| {
                    instances = sylva::format::Tile::decode(&t.url, b, species)?.instances.len();
                    Ok(())
                })?;
                copy_checked(dir, &t.ids_url, &mut |b| {
                    let ids = sylva::format::decode_ids(&t.ids_url, b)?;
                    if ids.len() != instances {
                        bail!("{}: {} ids for the tile's {instances} trees", t.ids_url, ids.len());
                    }
                    Ok(())
                })?;
                if let Some(schema) = &m.attributes {
                    let url = sylva::format::attributes::attributes_url(&t.url);
                    copy_checked(dir, &url, &mut |b| {
                        sylva::format::attributes::decode_attributes(&url, b, schema, instances)
                            .map_err(|e| anyhow::anyhow!("{e}"))?;
                        Ok(())
                    })?;
                }
            }
            tiles.extend(m.tiles.iter().cloned());
            log(&format!("merge: {} ({} tiles, {} trees)", dir.display(), m.tiles.len(), m.counts.trees));
        }
        tiles.sort_by_key(|t| (t.y, t.x));
        if let Some(w) = tiles.windows(2).find(|w| (w[0].x, w[0].y) == (w[1].x, w[1].y)) {
            bail!("tile ({}, {}) is in two shards: the shards come from different bakes", w[0].x, w[0].y);
        }
        finish_scene(tmp, base, tiles, crate::bake::scene_write::Layout { node_tiles, flat: false, canopy_cell_m }, log)
    })
}

/// Refuses an `--out` that is one of the shard folders (also through a link),
/// whatever the flags: merging would replace that shard's files with the whole.
///
/// # Errors
/// Names the shard.
pub fn refuse_output_among_inputs(out: &Path, dirs: &[PathBuf]) -> Result<()> {
    // Where --out will be: its nearest existing folder, real, and the rest of its path.
    let absolute = std::path::absolute(out).unwrap_or_else(|_| out.to_path_buf());
    let mut existing = absolute.as_path();
    let mut rest = Vec::new();
    let real_out = loop {
        if let Ok(real) = std::fs::canonicalize(existing) {
            break rest.iter().rev().fold(real, |p: PathBuf, c: &&std::ffi::OsStr| p.join(c));
        }
        match (existing.parent(), existing.file_name()) {
            (Some(parent), Some(name)) => {
                rest.push(name);
                existing = parent;
            }
            _ => return Ok(()),
        }
    };
    for dir in dirs {
        if std::fs::canonicalize(dir).is_ok_and(|d| real_out.starts_with(&d)) {
            bail!(
                "--out {} is the shard {} or inside it: merge never writes into a shard it reads (also not \
                 with --force); name a new folder",
                out.display(),
                dir.display()
            );
        }
    }
    Ok(())
}

/// A relative URL as one spelling (`./tiles//a.tile` → `tiles/a.tile`).
fn plain_key(rel: &str) -> String {
    rel.split('/').filter(|p| !p.is_empty() && *p != ".").collect::<Vec<_>>().join("/")
}

/// The bake's list of the files it wrote (docs/FORMAT.md), never copied.
const FILE_LIST: &str = ".sylva-bake-files.json";

fn list_indices(shards: &[(PathBuf, Manifest)]) -> String {
    let v: Vec<String> = shards.iter().filter_map(|(_, m)| m.shard.map(|s| s.index.to_string())).collect();
    v.join(", ")
}

/// Copies the terrain quadtree of `t` from `from` to `to`, walking it from the
/// root by the child masks (so only tiles of the tree are copied).
/// The copy of one checked file: shard folder, relative URL, check.
type CopyChecked<'c> = dyn FnMut(&Path, &str, &mut dyn FnMut(&[u8]) -> Result<()>) -> Result<()> + 'c;

fn copy_terrain(from: &Path, to: &Path, t: &sylva::format::TerrainEntry, copy: &mut CopyChecked<'_>) -> Result<()> {
    let mut stack = vec![(0u8, 0u32, 0u32)];
    while let Some((level, x, y)) = stack.pop() {
        let rel = t.tile_url(level, x, y);
        if let Some(parent) = to.join(&rel).parent() {
            create_dir(parent)?;
        }
        let mut tile = None;
        copy(from, &rel, &mut |b| {
            tile = Some(sylva::format::TerrainTile::decode(&rel, b)?);
            Ok(())
        })?;
        let tile = tile.expect("set by the check");
        if let Some(i) = t.imagery.as_ref().filter(|_| t.has_imagery(level, x, y)) {
            let img = i.tile_url(level, x, y);
            if let Some(parent) = to.join(&img).parent() {
                create_dir(parent)?;
            }
            copy(from, &img, &mut |b| {
                sylva::format::imagery::decode_image(&img, b, sylva::format::terrain::IMAGERY_PX)?;
                Ok(())
            })?;
        }
        for (k, c) in tile.children.iter().enumerate() {
            if c.exists && level + 1 < t.levels {
                stack.push((level + 1, 2 * x + (k as u32 & 1), 2 * y + (k as u32 >> 1)));
            }
        }
    }
    Ok(())
}

/// Copies `rel` (a URL the manifest decoder has checked is a plain relative
/// path) from the shard `from` to `to` after `check` accepted its bytes: the
/// shard's own regular file only — no link, also not a linked folder on the
/// way, no FIFO or device — and at most [`sylva::paths::MAX_SCENE_FILE_BYTES`]
/// (docs/SECURITY.md).
fn copy_checked(from: &Path, to: &Path, rel: &str, check: &mut dyn FnMut(&[u8]) -> Result<()>) -> Result<()> {
    let (src, dst) = (from.join(rel), to.join(rel));
    if std::fs::symlink_metadata(&src).is_ok_and(|m| m.file_type().is_symlink()) {
        bail!("{} is a symbolic link: merge copies only a shard's own files (bake the shard again)", src.display());
    }
    // No link on the way either (a linked `tiles/`, inside the shard or out of it).
    let (real, expected) = std::fs::canonicalize(&src)
        .and_then(|real| Ok((real, std::fs::canonicalize(from)?.join(plain_key(rel)))))
        .with_context(|| format!("cannot read {}", src.display()))?;
    if real != expected {
        bail!(
            "{} is reached through a linked folder ({}): merge copies only a shard's own files, not linked ones",
            src.display(),
            if real.starts_with(std::fs::canonicalize(from).unwrap_or_default()) {
                "inside its shard".to_string()
            } else {
                format!("outside its shard {}", from.display())
            }
        );
    }
    let bytes = sylva::paths::read_regular(&src, None, sylva::paths::MAX_SCENE_FILE_BYTES)
        .with_context(|| format!("cannot read {}", src.display()))?;
    check(&bytes).with_context(|| format!("{} is not what the shard's scene.json says it is", src.display()))?;
    std::fs::write(&dst, &bytes).with_context(|| format!("cannot write {}", dst.display()))?;
    Ok(())
}
