//! A scene directory as the tracer holds it for one view: every species'
//! full mesh once ([`TraceSpecies::of_pack`]), and the trees within reach of
//! the eye placed relative to it (the top level for a view, not for the whole
//! scene: memory bounded by `reach_m`).

use std::path::Path;

use glam::{DVec3, Vec3};

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
    /// ground plane lies in a scene without terrain (no tree buried under it).
    pub ground_z: f32,
    /// Triangles of the terrain traced (0: none; the ground plane then).
    pub terrain_triangles: usize,
}

/// Loads the scene in `dir` for a view from `eye` (scene frame, metres from
/// the origin): trees whose base is within `reach_m` horizontally, placed
/// relative to the eye, and — with `ground` (an albedo) — the scene's terrain
/// within reach as one more traced "species" of triangles ([`terrain_species`]).
///
/// # Errors
/// Unreadable or invalid files, named.
pub fn load_dir(
    dir: &Path,
    eye: DVec3,
    reach_m: f64,
    ground: Option<Vec3>,
) -> Result<(TraceScene, LoadReport), String> {
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
    let mut terrain_triangles = 0;
    if let (Some(albedo), Some(t)) = (ground, &m.terrain) {
        let terrain = terrain_species(t, &read, eye, reach_m, albedo)?;
        terrain_triangles = terrain.bvh.triangles.len();
        if terrain_triangles > 0 {
            instances.push(Instance {
                position: Vec3::ZERO,
                yaw: 0.0,
                scale: 1.0,
                aspect: 1.0,
                species: species.len() as u32,
            });
            species.push(terrain);
        }
    }
    let scene = TraceScene::build(species, &instances);
    // (Trees only: the terrain is not a tree.)
    let tree_species = m.species.len() as u32;
    let instanced_triangles = scene
        .instances
        .iter()
        .filter(|i| i.species < tree_species)
        .map(|i| scene.species[i.species as usize].bvh.triangles.len() as u64)
        .sum();
    let bytes = scene.gpu_bytes();
    let report = LoadReport {
        trees: scene.instances.iter().filter(|i| i.species < tree_species).count(),
        trees_in_scene,
        species_triangles,
        instanced_triangles,
        bytes,
        ground_z,
        terrain_triangles,
    };
    Ok((scene, report))
}

/// Most terrain cells traced (two triangles each, 64 bytes a triangle).
const MAX_TERRAIN_CELLS: f64 = 200_000.0;

/// The scene's terrain within `reach_m` of the eye as one traced "species":
/// the quadtree's tiles over the reach's square at the coarsest level whose
/// cells are at most the reach's side over √[`MAX_TERRAIN_CELLS`] (or the
/// finest there is), two triangles a cell with both corners' heights, placed
/// relative to the eye, one opaque material of `albedo`. Tiles that do not
/// exist (no data there) leave holes; tiles of different levels meet with
/// the cracks the raster hides with skirts (not traced yet).
///
/// # Errors
/// Unreadable or invalid terrain tiles, named.
pub fn terrain_species(
    t: &crate::format::terrain::TerrainEntry,
    read: &dyn Fn(&str) -> Result<Vec<u8>, String>,
    eye: DVec3,
    reach_m: f64,
    albedo: Vec3,
) -> Result<TraceSpecies, String> {
    use crate::format::terrain::TerrainTile;
    use crate::trace::bvh::{Bvh, TriangleSurface};
    use crate::trace::scene::{GpuTraceMaterial, NO_TEXTURE};
    use crate::trace::Triangle;
    let (lo, hi) = ([eye.x - reach_m, eye.y - reach_m], [eye.x + reach_m, eye.y + reach_m]);
    let cell_goal = (2.0 * reach_m / MAX_TERRAIN_CELLS.sqrt()).max(t.resolution_m);
    let overlaps = |level: u8, x: u32, y: u32| {
        let o = t.tile_origin_m(level, x, y);
        let s = t.tile_size_m(level);
        o[0] < hi[0] && o[0] + s > lo[0] && o[1] < hi[1] && o[1] + s > lo[1]
    };
    let mut triangles = Vec::new();
    // Depth first from the root: a tile is traced when its cells are fine
    // enough, it is the last level, or none of its children overlapping the
    // reach exists.
    let mut stack = vec![(0u8, 0u32, 0u32)];
    while let Some((level, x, y)) = stack.pop() {
        if !overlaps(level, x, y) {
            continue;
        }
        let url = t.tile_url(level, x, y);
        let tile = TerrainTile::decode(&url, &read(&url)?).map_err(|e| e.to_string())?;
        let cell = t.tile_size_m(level) / f64::from(tile.grid.max(1));
        let children: Vec<(u8, u32, u32)> = (0..4)
            .filter(|&q| tile.children[q].exists)
            .map(|q| (level + 1, 2 * x + (q as u32 & 1), 2 * y + (q as u32 >> 1)))
            .filter(|&(l, cx, cy)| overlaps(l, cx, cy))
            .collect();
        if cell > cell_goal && level + 1 < t.levels && !children.is_empty() {
            stack.extend(children);
            continue;
        }
        let origin = t.tile_origin_m(level, x, y);
        let side = tile.side();
        let at = |i: usize, j: usize| {
            tile.height(i, j).map(|h| {
                Vec3::new(
                    (origin[0] + i as f64 * cell - eye.x) as f32,
                    (origin[1] + j as f64 * cell - eye.y) as f32,
                    (f64::from(h) - eye.z) as f32,
                )
            })
        };
        for j in 0..side - 1 {
            for i in 0..side - 1 {
                let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
                if let (Some(a), Some(b), Some(c)) = (a, b, c) {
                    triangles.push(Triangle::new(a, b, c));
                }
                if let (Some(a), Some(c), Some(d)) = (a, c, d) {
                    triangles.push(Triangle::new(a, c, d));
                }
            }
        }
    }
    let surfaces = vec![TriangleSurface::default(); triangles.len()];
    let material = GpuTraceMaterial {
        base_color: [albedo.x, albedo.y, albedo.z, 1.0],
        alpha_cutoff: 0.0,
        texel_base: NO_TEXTURE,
        size: 0,
        kind: 1,
    };
    Ok(TraceSpecies {
        bvh: Bvh::build_with(&triangles, &surfaces),
        materials: vec![material],
        texels: Vec::new(),
        uv_min: [0.0; 2],
        uv_extent: [1.0; 2],
    })
}
