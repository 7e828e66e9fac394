//! Stage 2 of the bake: a LoD pack per species (mesh levels, billboards rendered
//! on the GPU, clusters; [`crate::pack`]), written to `species/`, with the
//! manifest's species entries and the shapes the tiles bound batches with.
//! Packs found in the `--pack-cache` ([`super::pack_cache`]) are taken from it.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use sylva::format::manifest::{Bounds, PackVariant, SpeciesEntry};
use sylva::render::capture::CapturePipelines;
use sylva::render::GpuContext;

use super::pack_cache::PackCache;
use crate::bake::batching::SpeciesShape;
use crate::bake::scene_write::safe_name;
use crate::input::gltf_import::ImportedModel;
use crate::out_dir::{create_dir, write_file};
use crate::pack::{build_pack, BuiltPack, PackOptions};

/// What the packs stage made.
pub struct Packs {
    /// Species entries of the manifest (tree counts still 0).
    pub entries: Vec<SpeciesEntry>,
    /// Each species' shape, for batch bounds.
    pub shapes: Vec<SpeciesShape>,
    /// Seconds spent.
    pub seconds: f64,
}

/// Builds and writes every species' pack into `dir/species/` (with `bake` false,
/// as a shard other than 0 does, only the entries and shapes). Packs in `cache`
/// are taken from it; packs built are added to it (not with `debug_dump`,
/// which needs the billboards as they are rendered).
pub fn bake_packs(
    species: &[(String, ImportedModel)],
    options: &PackOptions,
    bake: bool,
    cache: Option<&Path>,
    debug_dump: Option<&Path>,
    dir: &Path,
    log: &dyn Fn(&str),
) -> Result<Packs> {
    let t0 = Instant::now();
    create_dir(&dir.join("species"))?;
    if !bake {
        log("packs are baked by shard 0; this shard writes tiles only");
    }
    let cache = match cache {
        Some(c) if bake && debug_dump.is_none() => Some(PackCache::open(c)?),
        _ => None,
    };
    // The GPU is set up when the first pack is built (not at all when every
    // pack comes from the cache).
    let mut gpu_and_pipelines: Option<(GpuContext, CapturePipelines)> = None;
    let mut entries = Vec::new();
    let mut shapes = Vec::new();
    for (name, model) in species {
        shapes.push(shape_of(model));
        let file = format!("species/{}.pack", safe_name(name));
        if !bake {
            let (lo, hi) = model.bounds();
            entries.push(SpeciesEntry {
                name: name.clone(),
                pack: file,
                bytes: 0,
                height_m: model.height(),
                bounds: Bounds { min: lo.to_array(), max: hi.to_array() },
                trees: 0,
                head_bytes: None,
                variants: Vec::new(),
            });
            continue;
        }
        // (Held until the pack is written: another bake of it waits, then takes it.)
        let cached = match &cache {
            Some(c) => {
                let key = c.key(name, model, options);
                let lock = c.lock(&key)?;
                Some((c, key, lock))
            }
            None => None,
        };
        let mut from_cache = None;
        if let Some((c, key, _)) = &cached {
            if let Some(bytes) = c.get(key) {
                let meta = match sylva::format::decode_pack(&file, &bytes) {
                    Ok(pack) => Some(pack.meta),
                    Err(e) => {
                        log(&format!("  pack {name}: the cached copy does not decode ({e}): building it again"));
                        None
                    }
                };
                from_cache = meta.map(|meta| (bytes, meta));
            }
        }
        let (bytes, meta) = match from_cache {
            Some(hit) => {
                log(&format!("  pack {name}: from the pack cache ({:.2} MB)", hit.0.len() as f64 / 1e6));
                hit
            }
            None => {
                if gpu_and_pipelines.is_none() {
                    let gpu = GpuContext::new_headless_blocking()
                        .context("the billboard bake renders with the GPU (or lavapipe)")?;
                    log(&format!("rendering billboards on {}", gpu.adapter_summary()));
                    let pipelines = CapturePipelines::new(&gpu.device, wgpu::TextureFormat::Rgba8UnormSrgb);
                    gpu_and_pipelines = Some((gpu, pipelines));
                }
                let (gpu, pipelines) = gpu_and_pipelines.as_ref().expect("set up above");
                let built = build_pack(name, model, options, gpu, pipelines, log)
                    .with_context(|| format!("species {name:?}"))?;
                if let Some(dump) = debug_dump {
                    dump_billboards(dump, name, &built)?;
                }
                log(&format!(
                    "  pack {name}: {} triangles in level 0, {} mesh levels, {} billboard angles, {:.2} MB",
                    built.meta.mesh_levels[0].index_count / 3,
                    built.meta.mesh_levels.len(),
                    built.meta.billboards.as_ref().map_or(0, |b| b.angles),
                    built.bytes.len() as f64 / 1e6
                ));
                if let Some((c, key, _)) = &cached {
                    // A cache that cannot be written costs the next bake time, not this one its scene.
                    if let Err(e) = c.put(key, &built.bytes) {
                        log(&format!("  warning: {e:#}"));
                    }
                }
                (built.bytes, built.meta)
            }
        };
        // The block-compressed variants, from the cache where it has them
        // (under the pack's key and the encoding's name).
        let mut variants = Vec::new();
        for encoding in &options.gpu_textures {
            let started = Instant::now();
            let vkey = cached.as_ref().map(|(_, key, _)| format!("{key}-{}", encoding.name()));
            let hit = cached.as_ref().zip(vkey.as_ref()).and_then(|((c, _, _), k)| c.get(k));
            let hit = hit.filter(|b| sylva::format::decode_pack(&file, b).is_ok());
            let vbytes = match hit {
                Some(b) => b,
                None => {
                    let b = crate::pack::textures::block_encoded(&file, &bytes, *encoding)
                        .with_context(|| format!("the {} textures of species {name:?}", encoding.name()))?;
                    if let (Some((c, _, _)), Some(k)) = (&cached, &vkey) {
                        if let Err(e) = c.put(k, &b) {
                            log(&format!("  warning: {e:#}"));
                        }
                    }
                    b
                }
            };
            log(&format!(
                "  pack {name}: {} textures, {:.2} MB ({:.1} s)",
                encoding.name(),
                vbytes.len() as f64 / 1e6,
                started.elapsed().as_secs_f64()
            ));
            let vfile = format!("species/{}.{}.pack", safe_name(name), encoding.name());
            variants.push((encoding.name(), vfile, vbytes));
        }
        drop(cached);
        // Each part deflated: a far view fetches a tenth of the bytes (docs/FORMAT.md, "Stored packs").
        let store = |file: &str, bytes: Vec<u8>| -> Result<Vec<u8>> {
            if options.raw_packs {
                Ok(bytes)
            } else {
                sylva::format::stored::store_pack(file, &bytes).with_context(|| format!("storing {file}"))
            }
        };
        let stored = store(&file, bytes)?;
        let head = sylva::format::pack::PackHead::decode(&file, &stored)?;
        write_file(&dir.join(&file), &stored)?;
        let mut entry_variants = Vec::new();
        for (textures, vfile, vbytes) in variants {
            let vstored = store(&vfile, vbytes)?;
            let vhead = sylva::format::pack::PackHead::decode(&vfile, &vstored)?;
            write_file(&dir.join(&vfile), &vstored)?;
            entry_variants.push(PackVariant {
                textures: textures.into(),
                pack: vfile,
                bytes: vstored.len() as u64,
                head_bytes: Some(vhead.bytes.len() as u64),
            });
        }
        entries.push(SpeciesEntry {
            name: name.clone(),
            pack: file,
            bytes: stored.len() as u64,
            height_m: meta.height_m,
            bounds: Bounds { min: meta.bounds_min, max: meta.bounds_max },
            trees: 0,
            head_bytes: Some(head.bytes.len() as u64),
            variants: entry_variants,
        });
    }
    Ok(Packs { entries, shapes, seconds: t0.elapsed().as_secs_f64() })
}

/// Horizontal radius and z range of a model, for batch bounds.
fn shape_of(model: &ImportedModel) -> SpeciesShape {
    let (lo, hi) = model.bounds();
    // (Every variant's vertices: a tree may draw any.)
    let radius_xy = model
        .vertices
        .iter()
        .map(|v| v.position)
        .chain(model.variants.iter().flatten().map(|[p, _]| *p))
        .map(|p| p.truncate().length())
        .fold(0.0f32, f32::max);
    SpeciesShape { radius_xy, z_min: lo.z, z_max: hi.z }
}

/// Writes each billboard layer (colour and normals) as PNG for a look.
fn dump_billboards(dir: &Path, name: &str, built: &BuiltPack) -> Result<()> {
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
