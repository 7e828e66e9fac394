//! A scene directory as the tracer holds it for one view: every species'
//! full mesh once ([`TraceSpecies::of_pack`]), and the trees within reach of
//! the eye placed relative to it (the top level for a view, not for the whole
//! scene: memory bounded by `reach_m`).

use std::path::Path;

use glam::DVec3;

use super::scene::{Instance, TraceScene, TraceSpecies};
use crate::format::pack::decode_pack;
use crate::format::tile::{Tile, BATCH_DATED};
use crate::format::Manifest;

/// What was loaded.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadReport {
    /// Trees placed (within reach, standing at the scene's latest date).
    pub trees: usize,
    /// Trees in the scene's tiles.
    pub trees_in_scene: usize,
    /// Triangles per species' full mesh.
    pub species_triangles: Vec<(String, usize)>,
    /// Triangles the view's trees instance (Σ per tree of its species').
    pub instanced_triangles: u64,
    /// Bytes of the two levels as the GPU holds them.
    pub bytes: u64,
    /// The lowest of the placed trees' bases (scene frame): where the tracer's
    /// ground plane lies until the terrain is traced (no tree buried under it).
    pub ground_z: f32,
}

/// Loads the scene in `dir` for a view from `eye` (scene frame, metres from
/// the origin): trees whose base is within `reach_m` horizontally, placed
/// relative to the eye.
///
/// # Errors
/// Unreadable or invalid files, named.
pub fn load_dir(dir: &Path, eye: DVec3, reach_m: f64) -> Result<(TraceScene, LoadReport), String> {
    let read = |rel: &str| {
        let p = dir.join(rel);
        crate::paths::read_regular(&p, None, crate::paths::MAX_SCENE_FILE_BYTES)
            .map_err(|e| format!("cannot read {}: {e}", p.display()))
    };
    let m = Manifest::decode("scene.json", &read("scene.json")?).map_err(|e| e.to_string())?;
    let mut species = Vec::new();
    let mut species_triangles = Vec::new();
    for s in &m.species {
        let bytes = crate::format::stored::unstore(&s.pack, read(&s.pack)?).map_err(|e| e.to_string())?;
        let pack = decode_pack(&s.pack, &bytes).map_err(|e| e.to_string())?;
        // A pack without a mesh (the format allows one) traces nothing: its
        // trees are left out, the rest traced.
        let traced =
            if pack.meta.mesh_levels.is_empty() { TraceSpecies::default() } else { TraceSpecies::of_pack(&pack)? };
        species_triangles.push((s.name.clone(), traced.bvh.triangles.len()));
        species.push(traced);
    }
    let tiles = crate::format::index::read_all_tiles(dir, &m)?;
    let mut instances = Vec::new();
    let mut trees_in_scene = 0;
    let mut bases = Vec::new();
    for t in &tiles {
        let tile = Tile::decode(&t.url, &read(&t.url)?, m.species.len() as u32).map_err(|e| e.to_string())?;
        for b in &tile.batches {
            let run = b.instance_offset as usize..(b.instance_offset + b.instance_count) as usize;
            trees_in_scene += run.len();
            if b.flags & BATCH_DATED != 0 {
                continue;
            }
            for p in tile.instances.get(run).unwrap_or_default() {
                let d = p.decode(b);
                let pos =
                    DVec3::new(f64::from(d.position_m[0]), f64::from(d.position_m[1]), f64::from(d.position_m[2]));
                if (pos - eye).truncate().length() > reach_m {
                    continue;
                }
                bases.push(d.position_m[2]);
                instances.push(Instance {
                    position: (pos - eye).as_vec3(),
                    yaw: d.yaw_rad,
                    scale: d.scale,
                    aspect: d.aspect,
                    species: b.species,
                });
            }
        }
    }
    let ground_z = bases.iter().copied().reduce(f32::min).unwrap_or(0.0);
    let scene = TraceScene::build(species, &instances);
    let instanced_triangles =
        scene.instances.iter().map(|i| scene.species[i.species as usize].bvh.triangles.len() as u64).sum();
    let a = scene.arrays();
    let bytes = (std::mem::size_of_val(&a.nodes[..])
        + std::mem::size_of_val(&a.triangles[..])
        + std::mem::size_of_val(&a.materials[..])
        + a.texels.len() * 4
        + std::mem::size_of_val(&scene.instances[..])) as u64;
    let report = LoadReport {
        trees: scene.instances.len(),
        trees_in_scene,
        species_triangles,
        instanced_triangles,
        bytes,
        ground_z,
    };
    Ok((scene, report))
}
