//! Assembles and writes a scene directory: packs, tiles, id sidecars, manifest.
//!
//! Writes are atomic and remove nothing the bake did not write
//! ([`crate::out_dir`]). Output is deterministic.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use glam::DVec3;
use rayon::prelude::*;
use sylva::format::build_index;
use sylva::format::manifest::{
    Bounds, Counts, Crs as CrsEntry, Manifest, ShardStamp, SpeciesEntry, TileEntry, SCENE_FORMAT, SCENE_VERSION,
};
use sylva::format::tile::encode_ids;
use sylva::render::capture::CapturePipelines;
use sylva::render::GpuContext;

use crate::batching::{build_tiles, shard_of_tile, tile_of, SceneTree, SpeciesShape};
use crate::bucket::TreeSource;
use crate::gltf_import::ImportedModel;
use crate::out_dir::OutDir;
use crate::pack_build::{build_pack, PackOptions};
use crate::reproject::Crs;

/// Everything a scene is made from.
pub struct SceneInput {
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
    /// Bake only shard `.0` of `.1` of the tile grid (packs only in shard 0).
    pub shard: Option<(u32, u32)>,
    /// Most tiles per index node; scenes with more tiles get a hierarchical index.
    pub index_node_tiles: u32,
}

/// What was written.
#[derive(Debug, Clone)]
pub struct SceneSummary {
    /// The manifest.
    pub manifest: Manifest,
    /// Bytes of all instance records.
    pub instance_bytes: u64,
    /// Seconds spent on packs and on tiles.
    pub pack_seconds: f64,
    /// Seconds spent on tiles.
    pub tile_seconds: f64,
}

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

/// Horizontal radius and z range of a model, for batch bounds.
pub fn shape_of(model: &ImportedModel) -> SpeciesShape {
    let (lo, hi) = model.bounds();
    let radius_xy = model.vertices.iter().map(|v| v.position.truncate().length()).fold(0.0f32, f32::max);
    SpeciesShape { radius_xy, z_min: lo.z, z_max: hi.z }
}

/// Bakes and writes the scene into `out` (atomically; see [`OutDir`]).
pub fn write_scene(input: &SceneInput, out: OutDir, log: &dyn Fn(&str)) -> Result<SceneSummary> {
    if input.trees.is_empty() && input.shard.is_none() {
        bail!("no trees to bake: every placement was skipped (see the report above)");
    }
    out.write(|tmp| write_into(input, tmp, log))
}

/// Writes a file; the error names it (a full disk, a read-only folder).
pub fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    std::fs::write(path, bytes).with_context(|| format!("cannot write {}", path.display()))
}

/// Creates a folder and its parents; the error names it.
pub fn create_dir(path: &Path) -> Result<()> {
    std::fs::create_dir_all(path).with_context(|| format!("cannot create {}", path.display()))
}

/// Bytes of a pack's header, section table and `META` section (the first section).
fn pack_head_bytes(pack: &[u8]) -> u64 {
    let at = sylva::format::pack::PACK_HEADER_BYTES;
    let word = |o: usize| u64::from_le_bytes(pack[o..o + 8].try_into().expect("8 bytes"));
    word(at + 8) + word(at + 16)
}

/// Finishes a scene in `dir` from its species and tiles: writes the index (or a
/// flat list) and `scene.json`. Shared by the bake and by `merge`, so both give
/// the same bytes.
pub fn finish_scene(
    dir: &Path,
    mut base: Manifest,
    mut tiles: Vec<TileEntry>,
    node_tiles: u32,
    flat: bool,
) -> Result<Manifest> {
    tiles.sort_by_key(|t| (t.y, t.x));
    let bounds = sylva::format::index::union_bounds(tiles.iter().map(|t| &t.bounds))
        .unwrap_or(Bounds { min: [0.0; 3], max: [0.0; 3] });
    base.bounds = bounds;
    base.counts = Counts {
        trees: tiles.iter().map(|t| t.trees).sum(),
        batches: tiles.iter().map(|t| u64::from(t.batches)).sum(),
        tiles: tiles.len() as u64,
    };
    base.version = SCENE_VERSION;
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

fn write_into(input: &SceneInput, dir: &Path, log: &dyn Fn(&str)) -> Result<SceneSummary> {
    create_dir(&dir.join("species"))?;
    create_dir(&dir.join("tiles"))?;
    let t0 = Instant::now();
    let bake_packs = input.shard.is_none_or(|(index, _)| index == 0);
    let gpu_and_pipelines = if bake_packs {
        let gpu =
            GpuContext::new_headless_blocking().context("the billboard bake renders with the GPU (or lavapipe)")?;
        log(&format!("rendering billboards on {}", gpu.adapter_summary()));
        let pipelines = CapturePipelines::new(&gpu.device, wgpu::TextureFormat::Rgba8UnormSrgb);
        Some((gpu, pipelines))
    } else {
        log("packs are baked by shard 0; this shard writes tiles only");
        None
    };
    let mut species_entries = Vec::new();
    let mut shapes = Vec::new();
    for (name, model) in &input.species {
        shapes.push(shape_of(model));
        let file = format!("species/{}.pack", safe_name(name));
        let Some((gpu, pipelines)) = &gpu_and_pipelines else {
            let (lo, hi) = model.bounds();
            species_entries.push(SpeciesEntry {
                name: name.clone(),
                pack: file,
                bytes: 0,
                height_m: model.height(),
                bounds: Bounds { min: lo.to_array(), max: hi.to_array() },
                trees: 0,
                head_bytes: None,
            });
            continue;
        };
        let built =
            build_pack(name, model, &input.pack, gpu, pipelines).with_context(|| format!("species {name:?}"))?;
        write_file(&dir.join(&file), &built.bytes)?;
        if let Some(dump) = &input.debug_dump {
            dump_billboards(dump, name, &built)?;
        }
        log(&format!(
            "  pack {name}: {} triangles in level 0, {} mesh levels, {} billboard angles, {:.2} MB",
            built.meta.mesh_levels[0].index_count / 3,
            built.meta.mesh_levels.len(),
            built.meta.billboards.as_ref().map_or(0, |b| b.angles),
            built.bytes.len() as f64 / 1e6
        ));
        species_entries.push(SpeciesEntry {
            name: name.clone(),
            pack: file,
            bytes: built.bytes.len() as u64,
            height_m: built.meta.height_m,
            bounds: Bounds { min: built.meta.bounds_min, max: built.meta.bounds_max },
            trees: 0,
            head_bytes: Some(pack_head_bytes(&built.bytes)),
        });
    }
    let pack_seconds = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    // Tiles, one group of whole tiles in memory at a time (all trees, or one
    // bucket of a bake larger than memory). A shard keeps the trees of its tiles.
    let mut tree_counts = vec![0u64; input.species.len()];
    let mut entries: Vec<(TileEntry, u64)> = Vec::new();
    let mut kept = 0u64;
    input.trees.for_each_group(&mut |group| {
        let shard_trees: Vec<SceneTree>;
        // (A streamed bake's buckets hold the shard's trees only already.)
        let trees: &[SceneTree] = match input.shard {
            Some((index, count)) if matches!(input.trees, TreeSource::Memory(_)) => {
                shard_trees = group
                    .iter()
                    .filter(|t| {
                        let (x, y) = tile_of(t.pos, input.cell_size_m, input.tile_cells);
                        shard_of_tile(x, y, count) == index
                    })
                    .copied()
                    .collect();
                &shard_trees
            }
            _ => group,
        };
        kept += trees.len() as u64;
        for t in trees {
            tree_counts[t.species as usize] += 1;
        }
        let tiles = build_tiles(trees, &shapes, input.cell_size_m, input.tile_cells);
        let written: Vec<(TileEntry, u64)> = tiles
            .par_iter()
            .map(|bt| -> Result<(TileEntry, u64)> {
                let stem = format!("tiles/{}_{}", bt.tile.tile_x, bt.tile.tile_y);
                let bytes = bt.tile.encode();
                write_file(&dir.join(format!("{stem}.tile")), &bytes)?;
                write_file(&dir.join(format!("{stem}.ids")), &encode_ids(&bt.ids))?;
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
                    },
                    bt.tile.instance_bytes() as u64,
                ))
            })
            .collect::<Result<_>>()?;
        entries.extend(written);
        Ok(())
    })?;
    if let Some((index, count)) = input.shard {
        log(&format!("shard {index}/{count}: {kept} of {} trees", input.trees.len()));
    }
    for (entry, n) in species_entries.iter_mut().zip(&tree_counts) {
        entry.trees = *n;
    }
    let tile_seconds = t1.elapsed().as_secs_f64();
    let instance_bytes = entries.iter().map(|(_, b)| b).sum();
    let tile_entries: Vec<TileEntry> = entries.into_iter().map(|(e, _)| e).collect();
    let base = Manifest {
        format: SCENE_FORMAT.into(),
        version: SCENE_VERSION,
        crs: CrsEntry { epsg: input.crs.epsg, proj4: input.crs.proj4.clone() },
        origin_m: input.origin_m.to_array(),
        bounds: Bounds { min: [0.0; 3], max: [0.0; 3] },
        cell_size_m: input.cell_size_m as f32,
        tile_cells: input.tile_cells,
        counts: Counts { trees: 0, batches: 0, tiles: 0 },
        species: species_entries,
        tiles: Vec::new(),
        index: None,
        shard: input.shard.map(|(index, count)| ShardStamp { index, count }),
    };
    // A shard lists its tiles flat; `merge` builds the index of the whole.
    let manifest = finish_scene(dir, base, tile_entries, input.index_node_tiles, input.shard.is_some())?;
    Ok(SceneSummary { manifest, instance_bytes, pack_seconds, tile_seconds })
}

/// Writes each billboard layer (colour and normals) as PNG for a look.
fn dump_billboards(dir: &Path, name: &str, built: &crate::pack_build::BuiltPack) -> Result<()> {
    create_dir(dir)?;
    let Some(bb) = &built.meta.billboards else { return Ok(()) };
    let s = bb.texture.size;
    let n = built.billboard_color.len() as u32;
    // One strip per kind: layers side by side, over a grey checker so alpha shows.
    for (kind, layers, checker) in [("color", &built.billboard_color, true), ("normal", &built.billboard_normal, false)]
    {
        let mut img = image::RgbaImage::new(s * n, s);
        for (l, layer) in layers.iter().enumerate() {
            for y in 0..s {
                for x in 0..s {
                    let i = ((y * s + x) * 4) as usize;
                    let a = f32::from(layer[i + 3]) / 255.0;
                    let bg = if checker && ((x / 8 + y / 8) % 2 == 0) { 200.0 } else { 150.0 };
                    let px = if checker {
                        [0, 1, 2].map(|c| (f32::from(layer[i + c]) * a + bg * (1.0 - a)) as u8)
                    } else {
                        [layer[i], layer[i + 1], layer[i + 2]]
                    };
                    img.put_pixel(l as u32 * s + x, y, image::Rgba([px[0], px[1], px[2], 255]));
                }
            }
        }
        let path = dir.join(format!("{}-billboards-{kind}.png", safe_name(name)));
        img.save(&path).with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}
