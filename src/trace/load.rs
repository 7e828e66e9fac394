//! A scene directory as the tracer holds it for one view: every species'
//! full mesh once, each library variant a tree within reach draws its own
//! shape ([`TraceSpecies::of_pack_variants`]), and the trees within reach of
//! the eye placed relative to it (the top level for a view, not for the whole
//! scene: memory bounded by `reach_m`).

#[cfg(not(target_arch = "wasm32"))]
use std::path::Path;

use glam::{DVec3, Vec3};

use super::scene::{Instance, TraceScene, TraceSpecies};
use crate::format::mesh::variant_of;
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

/// The files a load reads, by path relative to the scene directory: each
/// file's bytes, or `None` where it is not at hand yet (the browser fetches
/// what a load asked for, then loads again: [`load_with`]).
pub trait SceneFiles {
    /// A file as it is stored.
    ///
    /// # Errors
    /// A file that cannot be read, named.
    fn file(&mut self, rel: &str) -> Result<Option<Vec<u8>>, String>;
    /// A species pack with its stored (deflated) parts inflated
    /// ([`crate::format::stored::unstore`]).
    ///
    /// # Errors
    /// A pack that cannot be read or inflated, named.
    fn pack(&mut self, rel: &str) -> Result<Option<Vec<u8>>, String>;
}

/// A scene directory on disk.
#[cfg(not(target_arch = "wasm32"))]
pub struct DirFiles<'a>(pub &'a Path);

#[cfg(not(target_arch = "wasm32"))]
impl SceneFiles for DirFiles<'_> {
    fn file(&mut self, rel: &str) -> Result<Option<Vec<u8>>, String> {
        let p = self.0.join(rel);
        crate::paths::read_regular(&p, None, crate::paths::MAX_SCENE_FILE_BYTES)
            .map(Some)
            .map_err(|e| format!("cannot read {}: {e}", p.display()))
    }

    fn pack(&mut self, rel: &str) -> Result<Option<Vec<u8>>, String> {
        let Some(bytes) = self.file(rel)? else { return Ok(None) };
        crate::format::stored::unstore(rel, bytes).map(Some).map_err(|e| e.to_string())
    }
}

/// Loads the scene in `dir` for a view from `eye` (scene frame, metres from
/// the origin): trees whose base is within `reach_m` horizontally, placed
/// relative to the eye, and — with `ground` (an albedo) — the scene's terrain
/// within reach as one more traced "species" of triangles ([`terrain_species`]).
///
/// # Errors
/// Unreadable or invalid files, named.
#[cfg(not(target_arch = "wasm32"))]
pub fn load_dir(
    dir: &Path,
    eye: DVec3,
    reach_m: f64,
    ground: Option<Vec3>,
) -> Result<(TraceScene, LoadReport), String> {
    load_with(&mut DirFiles(dir), eye, reach_m, ground)?
        .ok_or_else(|| format!("{}: a file was not at hand", dir.display()))
}

/// [`load_dir`] over any [`SceneFiles`]: `Ok(None)` where files it needs are
/// not at hand yet (each asked for once in this call; in phases — the index,
/// the tiles within reach, the terrain a level at a time, the packs of the
/// species placed — so a browser fetches a phase's files together and loads
/// again, and decodes the packs once, in the last call).
///
/// # Errors
/// Unreadable or invalid files, named.
pub fn load_with(
    files: &mut dyn SceneFiles,
    eye: DVec3,
    reach_m: f64,
    ground: Option<Vec3>,
) -> Result<Option<(TraceScene, LoadReport)>, String> {
    let Some(manifest) = files.file("scene.json")? else { return Ok(None) };
    let m = Manifest::decode("scene.json", &manifest).map_err(|e| e.to_string())?;
    // The index, node by node.
    let mut walk = crate::format::index::TileWalk::new(&m);
    while let Some(url) = walk.next_url()?.map(str::to_string) {
        let Some(bytes) = files.file(&url)? else {
            // Every node the walk will fetch asked for together: a round a level.
            let pending: Vec<String> = walk.pending_urls().map(str::to_string).collect();
            for p in pending {
                files.file(&p)?;
            }
            return Ok(None);
        };
        walk.feed(&bytes).map_err(|e| format!("{url}: {e}"))?;
    }
    // The tiles whose bounds come within reach, together.
    let near = |b: &crate::format::Bounds| {
        let dx = (eye.x - f64::from(b.max[0])).max(f64::from(b.min[0]) - eye.x).max(0.0);
        let dy = (eye.y - f64::from(b.max[1])).max(f64::from(b.min[1]) - eye.y).max(0.0);
        dx.hypot(dy) <= reach_m
    };
    let entries = walk.finish();
    let mut tiles = Vec::new();
    let mut missing = false;
    let mut trees_in_scene = 0;
    for t in &entries {
        trees_in_scene += t.trees as usize;
        if !near(&t.bounds) {
            continue;
        }
        match files.file(&t.url)? {
            Some(bytes) => tiles.push(Tile::decode(&t.url, &bytes, m.species.len() as u32).map_err(|e| e.to_string())?),
            None => missing = true,
        }
    }
    if missing {
        return Ok(None);
    }
    let mut instances = Vec::new();
    let mut bases = Vec::new();
    for tile in &tiles {
        for b in &tile.batches {
            if b.flags & BATCH_DATED != 0 {
                continue;
            }
            let run = b.instance_offset as usize..(b.instance_offset + b.instance_count) as usize;
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
                    tint: d.variation.min(31) + 1,
                });
            }
        }
    }
    let ground_z = bases.iter().copied().reduce(f32::min).unwrap_or(0.0);
    let terrain = match (ground, &m.terrain) {
        (Some(albedo), Some(t)) => match terrain_species(t, files, eye, reach_m, albedo)? {
            Some(terrain) => Some(terrain),
            None => return Ok(None),
        },
        _ => None,
    };
    // The packs of the species placed, together (a species no tree within
    // reach uses is not read: it traces as nothing).
    let mut used = vec![false; m.species.len()];
    for i in &instances {
        if let Some(u) = used.get_mut(i.species as usize) {
            *u = true;
        }
    }
    let mut packs = Vec::new();
    for (s, &used) in m.species.iter().zip(&used) {
        packs.push(if used { files.pack(&s.pack)?.map(Some) } else { Some(None) });
    }
    if packs.iter().any(Option::is_none) {
        return Ok(None);
    }
    // Each species' shapes its trees draw (the library's variants: a tree
    // draws `variant_of(variation, variants)` of the full mesh, as the raster
    // does), each one traced "species"; `entry[s][v]` its place in the list.
    let mut species = Vec::new();
    let mut species_triangles = Vec::new();
    let mut entry: Vec<Vec<Option<u32>>> = Vec::new();
    // Per species the variations (0–31) its trees within reach have, a bit each.
    let mut variations = vec![0u32; m.species.len()];
    for i in &instances {
        if let Some(v) = variations.get_mut(i.species as usize) {
            *v |= 1 << (u32::from(i.tint.saturating_sub(1)) & 31);
        }
    }
    for (si, (s, bytes)) in m.species.iter().zip(packs.into_iter().flatten()).enumerate() {
        let pack = match &bytes {
            Some(bytes) => Some(decode_pack(&s.pack, bytes).map_err(|e| e.to_string())?),
            None => None,
        };
        // A pack without a mesh (the format allows one) traces nothing: its
        // trees are left out, the rest traced.
        let Some(pack) = pack.filter(|p| !p.meta.mesh_levels.is_empty()) else {
            species_triangles.push((s.name.clone(), 0));
            entry.push(Vec::new());
            continue;
        };
        let used = variations[si];
        let shapes = TraceSpecies::of_pack_variants(&pack, |v, extra| {
            (0..32).any(|var| used >> var & 1 == 1 && variant_of(var, extra) == v)
        })?;
        species_triangles.push((s.name.clone(), shapes.iter().flatten().next().map_or(0, |t| t.bvh.triangles.len())));
        entry.push(
            shapes
                .into_iter()
                .map(|shape| {
                    shape.map(|t| {
                        species.push(t);
                        species.len() as u32 - 1
                    })
                })
                .collect(),
        );
    }
    for i in &mut instances {
        let extra = entry.get(i.species as usize).map_or(0, |e| e.len().saturating_sub(1) as u32);
        let v = variant_of(u32::from(i.tint.saturating_sub(1)), extra);
        // (No shape: a species index past every list, left out by `place`.)
        i.species =
            entry.get(i.species as usize).and_then(|e| e.get(v as usize).copied().flatten()).unwrap_or(u32::MAX);
    }
    let mut terrain_triangles = 0;
    if let Some(terrain) = terrain.filter(|t| !t.bvh.triangles.is_empty()) {
        terrain_triangles = terrain.bvh.triangles.len();
        instances.push(Instance {
            position: Vec3::ZERO,
            yaw: 0.0,
            scale: 1.0,
            aspect: 1.0,
            species: species.len() as u32,
            tint: 0,
        });
        species.push(terrain);
    }
    let scene = TraceScene::place(species, &instances);
    // (Trees only: the terrain, the one instance without a tint, is not a tree.)
    let instanced_triangles = scene
        .instances
        .iter()
        .filter(|i| i.tint() > 0)
        .map(|i| scene.species[i.species_index() as usize].bvh.triangles.len() as u64)
        .sum();
    let bytes = scene.gpu_bytes();
    let report = LoadReport {
        trees: scene.instances.iter().filter(|i| i.tint() > 0).count(),
        trees_in_scene,
        species_triangles,
        instanced_triangles,
        bytes,
        ground_z,
        terrain_triangles,
    };
    Ok(Some((scene, report)))
}

/// The raster's light on flat ground by day (`DAY_FLAT_LIGHT` in
/// `shaders/terrain.wgsl`), by which a ground image is relit: its colour over
/// this is the ground's albedo.
const DAY_FLAT_LIGHT: [f32; 3] = [1.159, 1.184, 1.227];

/// Texels of a ground image (`origin`, `side` metres; row 0 north) whose
/// centre lies outside the imagery's `extent` become the plain ground of
/// `albedo` (encoded so that over [`DAY_FLAT_LIGHT`] it is that albedo).
fn outside_extent_plain(
    img: &mut crate::format::imagery::Rgba8,
    origin: [f64; 2],
    side: f64,
    extent: [f64; 4],
    albedo: Vec3,
) {
    let enc = |c: f32| (crate::format::cluster::linear_to_srgb(c) * 255.0 + 0.5) as u8;
    let plain =
        [enc(albedo.x * DAY_FLAT_LIGHT[0]), enc(albedo.y * DAY_FLAT_LIGHT[1]), enc(albedo.z * DAY_FLAT_LIGHT[2]), 255];
    let (w, h) = (img.width as usize, img.height as usize);
    for j in 0..h {
        let y = origin[1] + side * (1.0 - (j as f64 + 0.5) / h as f64);
        for i in 0..w {
            let x = origin[0] + side * (i as f64 + 0.5) / w as f64;
            if x < extent[0] || x > extent[2] || y < extent[1] || y > extent[3] {
                img.pixels[(j * w + i) * 4..(j * w + i) * 4 + 4].copy_from_slice(&plain);
            }
        }
    }
}

/// Most ground images traced (256² texels each: 16 MB).
pub const IMAGERY_TILES: usize = 64;

/// Most terrain cells traced (two triangles each, 64 bytes a triangle).
const MAX_TERRAIN_CELLS: f64 = 200_000.0;

/// The scene's terrain within `reach_m` of the eye as one traced "species":
/// the quadtree's tiles over the reach's square at the coarsest level whose
/// cells are at most the reach's side over √[`MAX_TERRAIN_CELLS`] (or the
/// finest there is), two triangles a cell with both corners' heights, placed
/// relative to the eye, one opaque material of `albedo` — and where the
/// scene has ground imagery, each tile its image as the raster drapes it
/// ([`IMAGERY_TILES`] images at most: coarser ones over a wide reach), the
/// photograph's colour over the raster's `DAY_FLAT_LIGHT` as its albedo (as
/// `shaders/terrain.wgsl` relights it). Tiles that do not exist (no data
/// there) leave holes; tiles of different levels meet with the cracks the
/// raster hides with skirts (not traced yet).
///
/// # Errors
/// Unreadable or invalid terrain tiles, named; `Ok(None)` where tiles are
/// not at hand yet (those of the level reached, each asked for).
pub fn terrain_species(
    t: &crate::format::terrain::TerrainEntry,
    files: &mut dyn SceneFiles,
    eye: DVec3,
    reach_m: f64,
    albedo: Vec3,
) -> Result<Option<TraceSpecies>, String> {
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
    let mut missing = false;
    // The images: (level, x, y) → material (0: the plain ground), and the
    // coarsest-enough level so that the reach takes at most IMAGERY_TILES.
    let imagery = t.imagery.as_ref().filter(|i| i.levels > 0);
    let image_level_cap = imagery.map_or(0, |i| {
        (0..i.levels)
            .rev()
            .find(|&l| ((2.0 * reach_m / t.tile_size_m(l)).ceil() + 1.0).powi(2) <= IMAGERY_TILES as f64)
            .unwrap_or(0)
    });
    let mut images: std::collections::HashMap<(u8, u32, u32), u32> = std::collections::HashMap::new();
    let mut materials = vec![GpuTraceMaterial {
        base_color: [albedo.x, albedo.y, albedo.z, 1.0],
        alpha_cutoff: 0.0,
        texel_base: NO_TEXTURE,
        size: 0,
        kind: 1,
    }];
    let mut texels: Vec<u32> = Vec::new();
    let mut surfaces = Vec::new();
    while let Some((level, x, y)) = stack.pop() {
        if !overlaps(level, x, y) {
            continue;
        }
        let url = t.tile_url(level, x, y);
        let Some(bytes) = files.file(&url)? else {
            missing = true;
            continue;
        };
        let tile = TerrainTile::decode(&url, &bytes).map_err(|e| e.to_string())?;
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
        // This tile's image (or an ancestor's, coarser), and where it lies.
        let mut image = None;
        if let Some(im) = imagery {
            let l = level.min(im.levels - 1).min(image_level_cap);
            let (ix, iy) = (x >> (level - l), y >> (level - l));
            let o = t.tile_origin_m(l, ix, iy);
            let s = t.tile_size_m(l);
            let inside = o[0] < im.extent_m[2]
                && o[0] + s > im.extent_m[0]
                && o[1] < im.extent_m[3]
                && o[1] + s > im.extent_m[1];
            let material = match images.get(&(l, ix, iy)) {
                Some(&m) => Some(m),
                None if inside => {
                    let url = im.tile_url(l, ix, iy);
                    // (An image that cannot be read leaves the plain ground there.)
                    match files.file(&url) {
                        Ok(Some(bytes)) => {
                            let px = crate::format::terrain::IMAGERY_PX;
                            let m = crate::format::imagery::decode_image(&url, &bytes, px)
                                .ok()
                                .filter(|img| img.width == px && img.height == px)
                                .map(|mut img| {
                                    // Outside the imagery's extent the image holds its mean
                                    // colour (docs/FORMAT.md): the plain ground there, as the
                                    // raster shows its own ground.
                                    outside_extent_plain(&mut img, o, s, im.extent_m, albedo);
                                    let px = img;
                                    let material = materials.len() as u32;
                                    materials.push(GpuTraceMaterial {
                                        base_color: [
                                            1.0 / DAY_FLAT_LIGHT[0],
                                            1.0 / DAY_FLAT_LIGHT[1],
                                            1.0 / DAY_FLAT_LIGHT[2],
                                            1.0,
                                        ],
                                        alpha_cutoff: 0.0,
                                        texel_base: texels.len() as u32,
                                        size: px.width,
                                        kind: 1,
                                    });
                                    texels.extend(
                                        px.pixels.chunks_exact(4).map(|p| u32::from_le_bytes([p[0], p[1], p[2], p[3]])),
                                    );
                                    material
                                })
                                .unwrap_or(0);
                            images.insert((l, ix, iy), m);
                            Some(m)
                        }
                        Ok(None) => {
                            missing = true;
                            None
                        }
                        Err(_) => {
                            images.insert((l, ix, iy), 0);
                            None
                        }
                    }
                }
                None => None,
            };
            if let Some(m) = material.filter(|&m| m > 0) {
                image = Some((m, o, s, materials[m as usize].size));
            }
        }
        // Texture coordinates over the image (north row first), texel centres
        // at its edges (the tracer's lookups wrap).
        let uv = |p: Vec3| -> u32 {
            let Some((_, o, s, n)) = image else { return 0 };
            let n = f64::from(n.max(2));
            let u = ((f64::from(p.x) + eye.x - o[0]) / s).clamp(0.0, 1.0);
            let v = 1.0 - ((f64::from(p.y) + eye.y - o[1]) / s).clamp(0.0, 1.0);
            let q = |c: f64| (((0.5 + c * (n - 1.0)) / n) * 65535.0).round() as u32;
            q(u) | (q(v) << 16)
        };
        let surface = |a: Vec3, b: Vec3, c: Vec3| TriangleSurface {
            material: image.map_or(0, |i| i.0),
            uv: [uv(a), uv(b), uv(c)],
            color: u32::MAX,
        };
        for j in 0..side - 1 {
            for i in 0..side - 1 {
                let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
                if let (Some(a), Some(b), Some(c)) = (a, b, c) {
                    triangles.push(Triangle::new(a, b, c));
                    surfaces.push(surface(a, b, c));
                }
                if let (Some(a), Some(c), Some(d)) = (a, c, d) {
                    triangles.push(Triangle::new(a, c, d));
                    surfaces.push(surface(a, c, d));
                }
            }
        }
    }
    if missing {
        return Ok(None);
    }
    Ok(Some(TraceSpecies {
        bvh: Bvh::build_with(&triangles, &surfaces),
        materials,
        texels: texels.into(),
        uv_min: [0.0; 2],
        uv_extent: [1.0; 2],
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scene directory whose files are at hand only once asked for and
    /// "fetched" (as the browser's): each round fetches what the last load asked.
    struct Rounds<'a> {
        dir: DirFiles<'a>,
        fetched: std::collections::HashSet<(String, bool)>,
        wanted: Vec<(String, bool)>,
    }

    impl Rounds<'_> {
        fn get(&mut self, rel: &str, pack: bool) -> Result<Option<Vec<u8>>, String> {
            if self.fetched.contains(&(rel.to_string(), pack)) {
                return if pack { self.dir.pack(rel) } else { self.dir.file(rel) };
            }
            self.wanted.push((rel.to_string(), pack));
            Ok(None)
        }
    }

    /// The fixture with a squat second shape added to the beech's pack.
    struct SquatBeech<'a>(DirFiles<'a>);

    impl SceneFiles for SquatBeech<'_> {
        fn file(&mut self, rel: &str) -> Result<Option<Vec<u8>>, String> {
            self.0.file(rel)
        }
        fn pack(&mut self, rel: &str) -> Result<Option<Vec<u8>>, String> {
            let bytes = self.0.pack(rel)?;
            Ok(if rel.ends_with("beech.pack") {
                bytes.map(|b| crate::trace::scene::with_a_squat_variant(&b))
            } else {
                bytes
            })
        }
    }

    /// Each tree takes the shape of its species the raster draws for it:
    /// `variant_of(variation, variants)`.
    #[test]
    fn a_tree_is_traced_in_the_shape_its_variation_draws() {
        let dir = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/forest-small"));
        let m = Manifest::decode("scene.json", &std::fs::read(dir.join("scene.json")).unwrap()).unwrap();
        let beech = m.species.iter().position(|s| s.name == "beech").unwrap() as u32;
        let eye = DVec3::new(0.0, 0.0, 0.0);
        let (plain, _) = load_dir(dir, eye, 5000.0, None).unwrap();
        let (squat, _) = load_with(&mut SquatBeech(DirFiles(dir)), eye, 5000.0, None).unwrap().unwrap();
        // Every species placed (no variants: a traced species each, in the manifest's order).
        assert_eq!(plain.species.len(), m.species.len());
        assert_eq!(squat.species.len(), m.species.len() + 1);
        assert_eq!(plain.instances.len(), squat.instances.len());
        let height = |s: &TraceScene, i: &crate::trace::scene::GpuInstance| {
            let n = s.species[i.species_index() as usize].bvh.nodes[0];
            n.max[2] - n.min[2]
        };
        let (mut own, mut low) = (0, 0);
        for (p, q) in plain.instances.iter().zip(&squat.instances) {
            assert_eq!(p.id, q.id);
            if p.species_index() != beech {
                assert_eq!(height(&plain, p), height(&squat, q));
                continue;
            }
            let variant = variant_of(p.tint() - 1, 1);
            let ratio = height(&squat, q) / height(&plain, p);
            if variant == 1 {
                assert!((ratio - 0.5).abs() < 0.05, "tree {}: {ratio}", p.id);
                low += 1;
            } else {
                assert_eq!(ratio, 1.0, "tree {}", p.id);
                own += 1;
            }
        }
        assert!(own > 10 && low > 10, "{own} beeches in their own shape, {low} squat");
    }

    impl SceneFiles for Rounds<'_> {
        fn file(&mut self, rel: &str) -> Result<Option<Vec<u8>>, String> {
            self.get(rel, false)
        }
        fn pack(&mut self, rel: &str) -> Result<Option<Vec<u8>>, String> {
            self.get(rel, true)
        }
    }

    #[test]
    fn a_load_in_rounds_of_fetches_is_the_load_from_disk() {
        let dir = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/forest-small"));
        let m = Manifest::decode("scene.json", &std::fs::read(dir.join("scene.json")).unwrap()).unwrap();
        let eye = DVec3::new(0.0, -190.0, 90.0);
        let ground = Some(Vec3::splat(0.2));
        let (whole, report) = load_dir(dir, eye, 150.0, ground).unwrap();
        let mut files = Rounds { dir: DirFiles(dir), fetched: Default::default(), wanted: Vec::new() };
        let mut rounds = Vec::new();
        let (scene, r) = loop {
            if let Some(done) = load_with(&mut files, eye, 150.0, ground).unwrap() {
                break done;
            }
            let wanted = std::mem::take(&mut files.wanted);
            assert!(!wanted.is_empty(), "a load that waits asks for something");
            files.fetched.extend(wanted.iter().cloned());
            rounds.push(wanted);
            assert!(rounds.len() < 32);
        };
        assert_eq!(r, report);
        assert_eq!(scene.instances, whole.instances);
        assert!(scene.top.is_empty() && whole.top.is_empty(), "the top level is the GPU's to build");
        assert!(report.trees > 0 && report.terrain_triangles > 0, "{report:?}");
        // In phases: the manifest alone first; the packs together, last, and only
        // those of species placed within reach.
        assert_eq!(rounds[0], vec![("scene.json".to_string(), false)]);
        let last = rounds.last().unwrap();
        assert!(last.iter().all(|(_, pack)| *pack), "{last:?}");
        assert!(rounds[..rounds.len() - 1].iter().flatten().all(|(_, pack)| !pack));
        // (The fixture's species have no variants: a traced species for each
        // species a tree within reach stands of.)
        let placed: std::collections::HashSet<u32> =
            whole.instances.iter().filter(|i| i.tint() > 0).map(|i| i.species_index()).collect();
        let placed = placed.len();
        assert_eq!(last.len(), placed);
        // A round a level: the index's nodes of a level together (not one
        // node a round), the tiles, the terrain's levels, its images, the packs.
        let depth = m.index.as_ref().map_or(0, |i| i.depth as usize);
        let levels = m.terrain.as_ref().map_or(0, |t| t.levels as usize);
        assert!(rounds.len() <= 1 + depth + 1 + levels + 2, "{} rounds: {rounds:?}", rounds.len());
        if let Some(index) = &m.index {
            assert!(index.nodes as usize > depth, "the fixture's index has levels with several nodes");
        }
        // Tiles beyond reach are not fetched.
        let tiles = rounds.iter().flatten().filter(|(f, _)| f.ends_with(".tile")).count();
        let entries = crate::format::index::read_all_tiles(dir, &m).unwrap();
        assert!(tiles < entries.len(), "{tiles} of {} tiles fetched", entries.len());
    }
}
