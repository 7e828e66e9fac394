//! `sylva-bake inspect`: summarises a scene directory, manifest, pack, tile or id
//! file, or a placements file (which columns are used for what, where the trees
//! are, and per species the counts and ranges a forester checks).
//! The JSON keys are documented in `docs/FORMAT.md`.

use std::path::Path;

use anyhow::{bail, Context, Result};
use serde_json::{json, Value};
use sylva::format::pack::PackMeta;
use sylva::format::{decode_pack, Manifest, Tile};

/// Inspects `path` and returns the summary as JSON.
pub fn inspect(path: &Path) -> Result<Value> {
    let (path, is_scene) = if path.is_dir() { (path.join("scene.json"), true) } else { (path.to_path_buf(), false) };
    let lower = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_lowercase();
    if matches!(lower.as_str(), "csv" | "tsv" | "txt" | "geojson" | "shp" | "gpkg" | "fgb") {
        return inspect_placements(&path);
    }
    if matches!(lower.as_str(), "tif" | "tiff") {
        return inspect_dem(&path);
    }
    let name = path.display().to_string();
    let bytes = sylva::paths::read_regular(&path, None, sylva::paths::MAX_SCENE_FILE_BYTES)
        .with_context(|| format!("cannot read {name}"))?;
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
    match (is_scene, ext) {
        (true, _) | (_, "json") => inspect_scene(&path, &bytes),
        (_, "pack") => {
            let file_bytes = bytes.len() as u64;
            let parts = parts_json(&name, &bytes)?;
            let bytes = sylva::format::stored::unstore(&name, bytes)?;
            let pack = decode_pack(&name, &bytes)?;
            let mut j = pack_json(&pack.meta, file_bytes, &pack);
            j["parts"] = parts;
            Ok(j)
        }
        (_, "tile") => {
            // Without the manifest, accept any species index.
            let tile = Tile::decode(&name, &bytes, u32::MAX)?;
            Ok(tile_json(&tile, bytes.len() as u64))
        }
        (_, "ids") => {
            let ids = sylva::format::decode_tree_ids(&name, &bytes)?;
            let version = if ids.texts.is_empty() { 1 } else { 2 };
            Ok(json!({"kind": "ids", "version": version, "count": ids.numbers.len(), "text_ids": ids.texts.len(),
                "bytes": bytes.len()}))
        }
        _ => bail!(
            "{name}: not a scene directory, scene.json, .pack, .tile, .ids, placements (.csv, .geojson) or DEM (.tif) file"
        ),
    }
}

/// A GeoTIFF DEM as `bake --dem` reads it; one that looks like a canopy
/// height model (heights above ground: −2 … 130 m, a tenth or more of it
/// under 2 m) also says how many trees `bake --chm` would find in it.
fn inspect_dem(path: &Path) -> Result<Value> {
    let dem = crate::input::dem::Dem::open(path)?;
    let s = dem.summary();
    let low = dem.heights.iter().filter(|h| h.is_finite() && **h < 2.0).count();
    let looks_chm = s.range.is_some_and(|(a, b)| a >= -2.0 && b <= 130.0) && low * 10 >= dem.heights.len();
    let chm_trees = (looks_chm && u64::from(dem.width) * u64::from(dem.height) <= 25_000_000)
        .then(|| crate::input::chm::find_trees(&dem, &crate::input::chm::ChmOptions::default()).ok().map(|t| t.len()))
        .flatten();
    Ok(json!({
        "looks_like_chm": looks_chm,
        "chm_trees": chm_trees,
        "kind": "dem",
        "width": dem.width,
        "height": dem.height,
        "epsg": dem.epsg,
        "layout": dem.layout,
        "extent": s.extent,
        "resolution": s.resolution,
        "height_range": s.range.map(|(a, b)| [a, b]),
        "nodata": dem.nodata,
        "holes": s.holes,
    }))
}

/// A placements file as the bake would read it (default options).
fn inspect_placements(path: &Path) -> Result<Value> {
    use crate::input::placements::{PlacementSource, ReadOptions};
    let source = PlacementSource::open(path, &ReadOptions::default())?;
    let allometry = crate::input::allometry::Allometry::built_in();
    let mut species: std::collections::BTreeMap<String, [Option<(f32, f32)>; 3]> = Default::default();
    let mut counts: std::collections::BTreeMap<String, u64> = Default::default();
    let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
    let (mut xs, mut ys) = (Vec::new(), Vec::new());
    let widen = |r: &mut Option<(f32, f32)>, v: Option<f32>| {
        if let Some(v) = v {
            *r = Some(r.map_or((v, v), |(a, b)| (a.min(v), b.max(v))));
        }
    };
    let report = source.for_each(&mut |p| {
        lo = [lo[0].min(p.x), lo[1].min(p.y)];
        hi = [hi[0].max(p.x), hi[1].max(p.y)];
        if xs.len() < 1_000_000 {
            xs.push(p.x);
            ys.push(p.y);
        }
        let label = p.species.clone().unwrap_or_else(|| "(no species)".into());
        let r = species.entry(label.clone()).or_default();
        widen(&mut r[0], p.height_m);
        widen(&mut r[1], p.dbh_cm);
        widen(&mut r[2], p.crown_m);
        *counts.entry(label).or_default() += 1;
        Ok(())
    })?;
    let median = |v: &mut Vec<f64>| {
        if v.is_empty() {
            return None;
        }
        let n = v.len() / 2;
        Some(*v.select_nth_unstable_by(n, f64::total_cmp).1)
    };
    let range = |r: Option<(f32, f32)>| r.map(|(a, b)| json!([a, b]));
    let mut rows: Vec<Value> = species
        .iter()
        .map(|(label, r)| {
            let e = allometry.for_label(label);
            // The built-in library's tree for the label (a bake without --model draws it).
            let (tree, why) =
                crate::library::choose::choose(if label == "(no species)" { "" } else { label }, &allometry);
            json!({
                "label": label,
                "trees": counts[label],
                "height_m": range(r[0]),
                "dbh_cm": range(r[1]),
                "crown_m": range(r[2]),
                "genus": e.genus,
                "library": format!("library:{}", tree.name),
                "library_why": why.to_string(),
            })
        })
        .collect();
    rows.sort_by(|a, b| b["trees"].as_u64().cmp(&a["trees"].as_u64()));
    Ok(json!({
        "kind": "placements",
        "coordinates": if source.kind == crate::input::placements::CoordKind::LonLat { "lon/lat" } else { "projected" },
        "crs": source.declared_epsg.map(|c| format!("EPSG:{c}"))
            .or_else(|| source.declared_proj4.as_ref().map(|(name, proj4)| format!("{name} ({proj4})"))),
        "notes": source.notes,
        "rows": report.rows,
        "kept": report.kept,
        "report": report.lines(),
        "bounds": {"min": lo, "max": hi},
        "median": [median(&mut xs), median(&mut ys)],
        "species": rows,
    }))
}

fn inspect_scene(path: &Path, bytes: &[u8]) -> Result<Value> {
    let name = path.display().to_string();
    let m = Manifest::decode(&name, bytes)?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let mut instance_bytes = 0u64;
    let mut tile_bytes = 0u64;
    let mut attribute_bytes = 0u64;
    let tiles = sylva::format::index::read_all_tiles(dir, &m).map_err(anyhow::Error::msg)?;
    for t in &tiles {
        let p = dir.join(&t.url);
        let b = sylva::paths::read_regular(&p, None, sylva::paths::MAX_SCENE_FILE_BYTES)
            .with_context(|| format!("cannot read tile {}", p.display()))?;
        let tile = Tile::decode(&p.display().to_string(), &b, m.species.len() as u32)?;
        if tile.instances.len() as u64 != t.trees {
            bail!("{}: holds {} trees, the manifest says {}", p.display(), tile.instances.len(), t.trees);
        }
        instance_bytes += tile.instance_bytes() as u64;
        tile_bytes += b.len() as u64;
        if let Some(schema) = &m.attributes {
            let url = sylva::format::attributes::attributes_url(&t.url);
            let p = dir.join(&url);
            let b = sylva::paths::read_regular(&p, None, sylva::paths::MAX_SCENE_FILE_BYTES)
                .with_context(|| format!("cannot read attributes {}", p.display()))?;
            sylva::format::attributes::decode_attributes(&p.display().to_string(), &b, schema, tile.instances.len())?;
            attribute_bytes += b.len() as u64;
        }
    }
    let mut species = Vec::new();
    for s in &m.species {
        let p = dir.join(&s.pack);
        let b = sylva::paths::read_regular(&p, None, sylva::paths::MAX_SCENE_FILE_BYTES)
            .with_context(|| format!("cannot read pack {}", p.display()))?;
        let file_bytes = b.len() as u64;
        let parts = parts_json(&p.display().to_string(), &b)?;
        let b = sylva::format::stored::unstore(&p.display().to_string(), b)?;
        let pack = decode_pack(&p.display().to_string(), &b)?;
        let mut j = pack_json(&pack.meta, file_bytes, &pack);
        j["parts"] = parts;
        j["trees"] = json!(s.trees);
        species.push(j);
    }
    let trees = m.counts.trees.max(1) as f64;
    // Where the trees are: the views' first target (the largest group of touching tiles).
    let focus = m.focus();
    let centre = [
        m.origin_m[0] + f64::from(focus.min[0] + focus.max[0]) * 0.5,
        m.origin_m[1] + f64::from(focus.min[1] + focus.max[1]) * 0.5,
    ];
    let lonlat = crate::input::reproject::Crs::from_epsg(m.crs.epsg)
        .and_then(|src| crate::input::reproject::Reprojector::new(src, &crate::input::reproject::Crs::from_epsg(4326)?))
        .and_then(|r| r.apply(centre[0], centre[1]))
        .ok();
    let home_trees =
        m.home.or_else(|| sylva::format::manifest::densest_group(&tiles)).map_or(m.counts.trees, |h| h.trees);
    Ok(json!({
        "trees_at": {
            "bounds": {"min": focus.min, "max": focus.max},
            "centre": centre,
            "centre_lonlat": lonlat.map(|(lon, lat)| [lon, lat]),
            "extent_m": [focus.max[0] - focus.min[0], focus.max[1] - focus.min[1]],
            "trees": home_trees,
        },
        "kind": "scene",
        "format": m.format,
        "version": m.version,
        "crs": {"epsg": m.crs.epsg, "proj4": m.crs.proj4},
        "origin_m": m.origin_m,
        "bounds": {"min": m.bounds.min, "max": m.bounds.max},
        "cell_size_m": m.cell_size_m,
        "tile_cells": m.tile_cells,
        "trees_total": m.counts.trees,
        "species_count": m.species.len(),
        "batches": m.counts.batches,
        "tiles": m.counts.tiles,
        "index_nodes": m.index.as_ref().map_or(0, |i| i.nodes),
        "index_depth": m.index.as_ref().map_or(0, |i| i.depth),
        "bytes_per_tree": instance_bytes as f64 / trees,
        "tile_bytes_per_tree": tile_bytes as f64 / trees,
        "tile_bytes": tile_bytes,
        "pack_bytes": m.species.iter().map(|s| s.bytes).sum::<u64>(),
        "variant_pack_bytes": m.species.iter().flat_map(|s| &s.variants).map(|v| v.bytes).sum::<u64>(),
        "species": species,
        "attributes": m.attributes.as_ref().map(|a| json!({
            "columns": a.columns.iter().map(|c| json!({
                "name": c.name,
                "type": c.kind,
                "width": c.width,
                "min": c.min,
                "max": c.max,
                "categories": c.categories.len(),
                "trees_with_value": c.count,
            })).collect::<Vec<_>>(),
            "bytes": attribute_bytes,
            "bytes_per_tree": attribute_bytes as f64 / trees,
        })),
        "terrain": m.terrain.as_ref().map(|t| json!({
            "extent": [t.origin_m[0], t.origin_m[1], t.origin_m[0] + t.root_size_m, t.origin_m[1] + t.root_size_m],
            "resolution_m": t.resolution_m,
            "height_range_m": t.height_range_m,
            "levels": t.levels,
            "grid": t.grid,
            "tiles": t.tiles,
            "bytes": t.bytes,
            "source": t.source,
            "imagery": t.imagery.as_ref().map(|i| json!({
                "extent": i.extent_m,
                "resolution_m": i.resolution_m,
                "levels": i.levels,
                "tile_px": i.tile_px,
                "tiles": i.tiles,
                "bytes": i.bytes,
                "source": i.source,
            })),
        })),
        "canopy": m.canopy.as_ref().map(|c| json!({
            "extent": [c.origin_m[0], c.origin_m[1], c.origin_m[0] + c.root_size_m, c.origin_m[1] + c.root_size_m],
            "levels": c.levels,
            "finest_cell_m": c.size_m(c.levels - 1) / f64::from(c.cells),
            "rasters": c.rasters,
            "bytes": c.bytes,
        })),
    }))
}

/// The `inspect --json` object of a decoded pack of `bytes` bytes.
pub fn pack_summary(pack: &sylva::format::Pack<'_>, bytes: u64) -> Value {
    pack_json(&pack.meta, bytes, pack)
}

/// Each part a viewer fetches on its own: its bytes in memory and as fetched
/// (deflated in a stored pack).
fn parts_json(name: &str, file: &[u8]) -> Result<Value> {
    use sylva::format::pack::{PackHead, PackPart};
    let head = PackHead::decode(name, file)?;
    let names =
        ["billboards", "impostors", "clusters", "coarse meshes", "full mesh", "bare billboards", "bare impostors"];
    let parts: Vec<Value> = PackPart::ALL
        .iter()
        .zip(names)
        .filter(|(p, _)| head.part_range(**p).is_some())
        .map(|(p, n)| json!({ "part": n, "bytes": head.part_bytes(*p), "fetched": head.fetch_bytes(*p) }))
        .collect();
    Ok(json!({ "stored": !head.stored.is_empty(), "list": parts }))
}

fn pack_json(meta: &PackMeta, bytes: u64, pack: &sylva::format::Pack<'_>) -> Value {
    use sylva::format::pack::kind;
    let mut levels = Vec::new();
    for (i, l) in meta.mesh_levels.iter().enumerate() {
        let b = pack.section(kind::MESH_VERTICES, i as u32).map_or(0, <[u8]>::len)
            + pack.section(kind::MESH_INDICES, i as u32).map_or(0, <[u8]>::len);
        let variant_bytes = pack.section(kind::MESH_VARIANTS, i as u32).map_or(0, <[u8]>::len);
        levels.push(json!({
            "kind": "mesh",
            "level": i,
            "count": l.index_count / 3,
            "vertices": l.vertex_count,
            "bytes": b + variant_bytes,
            "variants": l.variants + 1,
            "variant_bytes": variant_bytes,
            "select_px": l.select_px,
        }));
    }
    if let Some(c) = &meta.clusters {
        for (name, k, list) in
            [("ellipsoids", kind::ELLIPSOIDS, &c.ellipsoid_levels), ("lines", kind::LINES, &c.line_levels)]
        {
            for (i, l) in list.iter().enumerate() {
                let b = pack.section(k, i as u32).map_or(0, <[u8]>::len);
                let mut v = json!({
                    "kind": name,
                    "level": i,
                    "count": l.count,
                    "bytes": b,
                    "bytes_per_primitive": if l.count > 0 { b as f64 / f64::from(l.count) } else { 0.0 },
                    "select_px": l.select_px,
                    "error": l.error,
                });
                if name == "ellipsoids" {
                    v["noise_threshold"] = json!(l.noise_threshold);
                    v["normal_blend"] = json!(l.normal_blend);
                }
                levels.push(v);
            }
        }
    }
    if let Some(bb) = &meta.billboards {
        let b = pack.section(kind::BILLBOARD_COLOR, 0).map_or(0, <[u8]>::len)
            + pack.section(kind::BILLBOARD_NORMAL, 0).map_or(0, <[u8]>::len)
            + pack.section(kind::BILLBOARD_AO, 0).map_or(0, <[u8]>::len);
        levels.push(json!({
            "kind": "billboards",
            "count": bb.angles * bb.azimuths,
            "variants": bb.variants.unwrap_or(1),
            "angles": bb.angles,
            "azimuths": bb.azimuths,
            "resolution": bb.texture.size,
            "mips": bb.texture.mips,
            "texels": bb.texture.encoding.map_or("rgba8", |e| e.name()),
            "bytes": b,
            "select_px": bb.select_px,
        }));
    }
    if let Some(imp) = &meta.impostors {
        let b = pack.section(kind::IMPOSTOR_COLOR, 0).map_or(0, <[u8]>::len)
            + pack.section(kind::IMPOSTOR_SURFACE, 0).map_or(0, <[u8]>::len);
        levels.push(json!({
            "kind": "impostors",
            "count": imp.grid * imp.grid,
            "variants": imp.variants.unwrap_or(1),
            "grid": imp.grid,
            "resolution": imp.texture.size,
            "mips": imp.texture.mips,
            "texels": imp.texture.encoding.map_or("rgba8", |e| e.name()),
            "radius": imp.radius,
            "bytes": b,
        }));
    }
    // The tree's own ambient occlusion: where it is baked, and its range over the full mesh.
    let vertex_ao: Vec<f32> = pack
        .mesh_vertices(0)
        .iter()
        .filter(|v| v.normal_oct[2] > 0)
        .map(|v| sylva::format::pack::ao_from_snorm8(v.normal_oct[2]))
        .collect();
    let ao = json!({
        "mesh_vertices": !vertex_ao.is_empty(),
        "billboards": pack.section(kind::BILLBOARD_AO, 0).is_some(),
        "clusters": pack.section(kind::AO_FIELD, 0).is_some(),
        "sky_visibility": (!vertex_ao.is_empty()).then(|| {
            json!([vertex_ao.iter().copied().fold(1.0f32, f32::min), vertex_ao.iter().copied().fold(0.0f32, f32::max)])
        }),
    });
    // A deciduous species' seasons: its autumn colour and the bare far tiers' bytes.
    let bare_bytes: usize = kind::FAR_TIERS.iter().map(|k| pack.section(*k, 1).map_or(0, <[u8]>::len)).sum();
    let seasons = meta.season.as_ref().map(|x| {
        json!({
            "autumn": format!("#{:02x}{:02x}{:02x}", x.autumn[0], x.autumn[1], x.autumn[2]),
            "bare_far": x.bare_far,
            "bare_far_bytes": bare_bytes,
            "bare_cover": x.bare_cover,
        })
    });
    json!({
        "kind": "pack",
        "name": meta.name,
        "bytes": bytes,
        "height_m": meta.height_m,
        "seasons": seasons,
        "bounds": {"min": meta.bounds_min, "max": meta.bounds_max},
        "materials": meta.materials.iter().map(|m| json!({"name": m.name, "kind": m.kind, "alpha_cutoff": m.alpha_cutoff, "textured": m.texture_layer.is_some()})).collect::<Vec<_>>(),
        "material_texture": meta.material_texture.map(|t| json!({"size": t.size, "layers": t.layers, "mips": t.mips, "texels": t.encoding.map_or("rgba8", |e| e.name()), "bytes": t.byte_len()})),
        "levels": levels,
        "ambient_occlusion": ao,
    })
}

fn tile_json(tile: &Tile, bytes: u64) -> Value {
    json!({
        "kind": "tile",
        "tile_x": tile.tile_x,
        "tile_y": tile.tile_y,
        "batches": tile.batches.len(),
        "trees": tile.instances.len(),
        "bytes": bytes,
        "bytes_per_tree": tile.instance_bytes() as f64 / tile.instances.len().max(1) as f64,
    })
}

/// A human-readable rendering of [`inspect`]'s JSON.
pub fn to_text(v: &Value) -> String {
    let mut out = String::new();
    let f = |v: &Value| v.to_string();
    match v["kind"].as_str() {
        Some("scene") => {
            out += &format!("Sylva scene, {} v{}\n", v["format"].as_str().unwrap_or("?"), v["version"]);
            out += &format!("CRS EPSG:{}  origin {}\n", v["crs"]["epsg"], f(&v["origin_m"]));
            out += &format!(
                "bounds {} .. {} (m, relative to the origin)\n",
                f(&v["bounds"]["min"]),
                f(&v["bounds"]["max"])
            );
            let at = &v["trees_at"];
            let ll = &at["centre_lonlat"];
            out += &format!(
                "trees are at {} {} of them in {:.0} × {:.0} m around {:.1}, {:.1} (scene CRS){}\n",
                if at["trees"] == v["trees_total"] { "one place:" } else { "several places; the largest group:" },
                at["trees"],
                at["extent_m"][0].as_f64().unwrap_or(0.0),
                at["extent_m"][1].as_f64().unwrap_or(0.0),
                at["centre"][0].as_f64().unwrap_or(0.0),
                at["centre"][1].as_f64().unwrap_or(0.0),
                match (ll[0].as_f64(), ll[1].as_f64()) {
                    (Some(lon), Some(lat)) => format!(
                        " = {:.5}°{} {:.5}°{}",
                        lat.abs(),
                        if lat >= 0.0 { "N" } else { "S" },
                        lon.abs(),
                        if lon >= 0.0 { "E" } else { "W" }
                    ),
                    _ => String::new(),
                }
            );
            out += &format!(
                "{} trees, {} species, {} batches, {} tiles; cell {} m, {} cells per tile side\n",
                v["trees_total"], v["species_count"], v["batches"], v["tiles"], v["cell_size_m"], v["tile_cells"]
            );
            if v["index_nodes"].as_u64().unwrap_or(0) > 0 {
                out += &format!("hierarchical tile index: {} nodes, depth {}\n", v["index_nodes"], v["index_depth"]);
            }
            let variants = v["variant_pack_bytes"].as_f64().unwrap_or(0.0);
            out += &format!(
                "instance bytes per tree {:.2} (tile files incl. batch records: {:.2}); tiles {:.2} MB, packs {:.2} MB{}\n",
                v["bytes_per_tree"].as_f64().unwrap_or(0.0),
                v["tile_bytes_per_tree"].as_f64().unwrap_or(0.0),
                v["tile_bytes"].as_f64().unwrap_or(0.0) / 1e6,
                v["pack_bytes"].as_f64().unwrap_or(0.0) / 1e6,
                if variants > 0.0 {
                    format!(" (and {:.2} MB of BC7 variants, what a desktop GPU fetches instead)", variants / 1e6)
                } else {
                    String::new()
                }
            );
            let a = &v["attributes"];
            if let Some(columns) = a["columns"].as_array() {
                let list: Vec<String> = columns
                    .iter()
                    .map(|c| match c["type"].as_str() {
                        Some("category") => {
                            format!("{} (category, {} values)", c["name"].as_str().unwrap_or("?"), c["categories"])
                        }
                        Some(kind) => {
                            format!("{} ({kind} {}–{})", c["name"].as_str().unwrap_or("?"), c["min"], c["max"])
                        }
                        None => String::new(),
                    })
                    .collect();
                out += &format!(
                    "attributes: {}; {:.2} bytes per tree in .attr sidecars\n",
                    list.join(", "),
                    a["bytes_per_tree"].as_f64().unwrap_or(0.0)
                );
            }
            let t = &v["terrain"];
            if t.is_object() {
                let n = |k: &str, i: usize| t[k][i].as_f64().unwrap_or(0.0);
                out += &format!(
                    "terrain from {}: {} tiles in {} levels, {:.2} m finest spacing, heights {:.1}–{:.1} m, {:.2} MB; \
                     root square x {:.0}–{:.0}, y {:.0}–{:.0} (m, relative to the origin)\n",
                    t["source"].as_str().unwrap_or("?"),
                    t["tiles"],
                    t["levels"],
                    t["resolution_m"].as_f64().unwrap_or(0.0),
                    n("height_range_m", 0),
                    n("height_range_m", 1),
                    t["bytes"].as_f64().unwrap_or(0.0) / 1e6,
                    n("extent", 0),
                    n("extent", 2),
                    n("extent", 1),
                    n("extent", 3)
                );
                let i = &t["imagery"];
                if i.is_object() {
                    out += &format!(
                        "ground imagery from {}: {} images of {}² in {} levels (source {:.2} m per pixel), {:.2} MB\n",
                        i["source"].as_str().unwrap_or("?"),
                        i["tiles"],
                        i["tile_px"],
                        i["levels"],
                        i["resolution_m"].as_f64().unwrap_or(0.0),
                        i["bytes"].as_f64().unwrap_or(0.0) / 1e6
                    );
                } else {
                    out += "no ground imagery (bake with --ortho, or without --plain-ground)\n";
                }
            } else {
                out += "no terrain (bake with --dem for one)\n";
            }
            let c = &v["canopy"];
            if c.is_object() {
                out += &format!(
                    "canopy rasters: {} in {} levels, finest cells {:.1} m, {:.2} MB\n",
                    c["rasters"],
                    c["levels"],
                    c["finest_cell_m"].as_f64().unwrap_or(0.0),
                    c["bytes"].as_f64().unwrap_or(0.0) / 1e6
                );
            }
            for s in v["species"].as_array().into_iter().flatten() {
                out += &pack_text(s);
            }
        }
        Some("pack") => out += &pack_text(v),
        Some("dem") => {
            let e = |i: usize| v["extent"][i].as_f64().unwrap_or(0.0);
            out += &format!(
                "DEM {}×{} pixels of {} × {} (map units), {}, {}\n",
                v["width"],
                v["height"],
                v["resolution"][0],
                v["resolution"][1],
                v["epsg"]
                    .as_u64()
                    .map_or("no EPSG code in its GeoKeys (pass --dem-crs)".to_string(), |c| format!("EPSG:{c}")),
                v["layout"].as_str().unwrap_or("?")
            );
            out += &format!("extent x {:.2}–{:.2}, y {:.2}–{:.2}\n", e(0), e(2), e(1), e(3));
            out += &match v["height_range"].as_array() {
                Some(r) => format!(
                    "heights {:.2}–{:.2} m, {} pixels without data\n",
                    r[0].as_f64().unwrap_or(0.0),
                    r[1].as_f64().unwrap_or(0.0),
                    v["holes"]
                ),
                None => "no heights: every pixel is nodata\n".to_string(),
            };
            if v["looks_like_chm"].as_bool() == Some(true) {
                out += &match v["chm_trees"].as_u64() {
                    Some(n) => format!(
                        "heights above ground: a canopy height model? `bake --chm` finds {n} trees in it (tops ≥ 2 m)\n"
                    ),
                    None => "heights above ground: a canopy height model? (too large to count its trees here)\n".into(),
                };
            }
        }
        Some("placements") => {
            out += &format!(
                "placements ({}), {} rows, {} usable\n",
                v["coordinates"].as_str().unwrap_or("?"),
                v["rows"],
                v["kept"]
            );
            for n in v["notes"].as_array().into_iter().flatten().chain(v["report"].as_array().into_iter().flatten()) {
                out += &format!("  {}\n", n.as_str().unwrap_or(""));
            }
            out += &format!(
                "trees from {} to {}, half of them around {} (x/lon, y/lat)\n",
                f(&v["bounds"]["min"]),
                f(&v["bounds"]["max"]),
                f(&v["median"])
            );
            out += "label | trees | height m | DBH cm | crown m | allometry genus | library tree (why)\n";
            let r = |x: &Value| {
                x.as_array().map_or("-".to_string(), |a| {
                    format!("{:.1}–{:.1}", a[0].as_f64().unwrap_or(0.0), a[1].as_f64().unwrap_or(0.0))
                })
            };
            for s in v["species"].as_array().into_iter().flatten().take(60) {
                out += &format!(
                    "{} | {} | {} | {} | {} | {} | {} ({})\n",
                    s["label"].as_str().unwrap_or("?"),
                    s["trees"],
                    r(&s["height_m"]),
                    r(&s["dbh_cm"]),
                    r(&s["crown_m"]),
                    s["genus"].as_str().unwrap_or("?"),
                    s["library"].as_str().unwrap_or("?"),
                    s["library_why"].as_str().unwrap_or("?")
                );
            }
        }
        _ => out += &serde_json::to_string_pretty(v).unwrap_or_default(),
    }
    out
}

fn pack_text(s: &Value) -> String {
    let mut out = format!(
        "species {}: {:.2} MB, height {:.1} m{}\n",
        s["name"].as_str().unwrap_or("?"),
        s["bytes"].as_f64().unwrap_or(0.0) / 1e6,
        s["height_m"].as_f64().unwrap_or(0.0),
        s.get("trees").map_or(String::new(), |t| format!(", {t} trees"))
    );
    for l in s["levels"].as_array().into_iter().flatten() {
        match l["kind"].as_str() {
            Some("mesh") => {
                let variants = l["variants"].as_u64().unwrap_or(1);
                out += &format!(
                    "  mesh level {}: {} triangles, {} vertices, {:.1} KB{}, from {} px\n",
                    l["level"],
                    l["count"],
                    l["vertices"],
                    l["bytes"].as_f64().unwrap_or(0.0) / 1e3,
                    if variants > 1 {
                        format!(
                            " ({variants} variants, {:.1} KB of them)",
                            l["variant_bytes"].as_f64().unwrap_or(0.0) / 1e3
                        )
                    } else {
                        String::new()
                    },
                    l["select_px"]
                )
            }
            Some(kind @ ("ellipsoids" | "lines")) => {
                out += &format!(
                    "  {kind} level {}: {} × {} B, from {:.0} px, error {:.4}\n",
                    l["level"],
                    l["count"],
                    l["bytes_per_primitive"],
                    l["select_px"].as_f64().unwrap_or(0.0),
                    l["error"].as_f64().unwrap_or(0.0)
                )
            }
            Some("billboards") => {
                out += &format!(
                    "  billboards: {} angles × {} azimuths at {}², {} mips, {}, {:.1} KB\n",
                    l["angles"],
                    l["azimuths"],
                    l["resolution"],
                    l["mips"],
                    l["texels"].as_str().unwrap_or("rgba8").to_uppercase(),
                    l["bytes"].as_f64().unwrap_or(0.0) / 1e3
                )
            }
            Some("impostors") => {
                out += &format!(
                    "  impostors: {0}×{0} hemi-octahedral views at {1}², {2} mips, {3}, {4:.1} KB\n",
                    l["grid"],
                    l["resolution"],
                    l["mips"],
                    l["texels"].as_str().unwrap_or("rgba8").to_uppercase(),
                    l["bytes"].as_f64().unwrap_or(0.0) / 1e3
                )
            }
            _ => {}
        }
    }
    match s["seasons"].as_object() {
        Some(x) => {
            out += &format!(
                "  seasons: deciduous — leaf-on, autumn ({}), leaf-off{}\n",
                x["autumn"].as_str().unwrap_or("?"),
                if x["bare_far"].as_bool() == Some(true) {
                    format!(
                        " (the bare wood's far tiers {:.1} KB, fetched in leaf-off only; it covers {:.0} % of the crown's far views)",
                        x["bare_far_bytes"].as_f64().unwrap_or(0.0) / 1e3,
                        x["bare_cover"].as_f64().unwrap_or(0.0) * 100.0
                    )
                } else {
                    String::new()
                }
            );
        }
        None => out += "  seasons: one state (evergreen, or baked without seasons)\n",
    }
    if let Some(list) = s["parts"]["list"].as_array() {
        let mb = |v: &Value| v.as_f64().unwrap_or(0.0) / 1e6;
        let each: Vec<String> = list
            .iter()
            .map(|p| {
                format!("{} {:.2} of {:.2}", p["part"].as_str().unwrap_or("?"), mb(&p["fetched"]), mb(&p["bytes"]))
            })
            .collect();
        let how = if s["parts"]["stored"].as_bool() == Some(true) { "deflated" } else { "as they are" };
        out += &format!("  fetched by part ({how}, MB): {}\n", each.join(", "));
    }
    let ao = &s["ambient_occlusion"];
    let baked: Vec<&str> =
        ["mesh_vertices", "billboards", "clusters"].into_iter().filter(|k| ao[*k].as_bool() == Some(true)).collect();
    match ao["sky_visibility"].as_array() {
        Some(r) if !baked.is_empty() => {
            out += &format!(
                "  ambient occlusion: sky visibility {:.2}–{:.2} at the full mesh's vertices; in {}\n",
                r[0].as_f64().unwrap_or(0.0),
                r[1].as_f64().unwrap_or(0.0),
                baked.join(", ").replace('_', " ")
            );
        }
        _ => out += "  ambient occlusion: not baked (crowns drawn unoccluded)\n",
    }
    out
}
