//! `sylva-bake export-3dtiles`: a baked scene as an OGC 3D Tiles 1.1 tileset
//! that CesiumJS (or any 3D Tiles viewer) draws (`docs/FORMAT.md`,
//! "3D Tiles export").
//!
//! - `tileset.json`: the hierarchy of the scene's index (its nodes, then its
//!   tiles), each with a `region` bounding volume from its trees' crowns.
//! - Per Sylva tile, a local east-north-up frame at the tile's centre (its
//!   `transform`, to Earth-centred Earth-fixed metres on WGS84) and up to three
//!   GLBs in it, each refining the one before (`REPLACE`): `tiles/X_Y_far.glb`,
//!   the far tier (two crossed quads a tree with its species' side-view
//!   billboard: 4 triangles where a mesh has thousands) while the trees are a
//!   few pixels tall, `tiles/X_Y_coarse.glb` with each species' coarsest mesh
//!   level, and `tiles/X_Y.glb` with the full meshes. Every tree
//!   is an instance of its species' mesh (`EXT_mesh_gpu_instancing`:
//!   translation, rotation about the up axis, scale; the crown aspect widens
//!   the horizontal axes). Each tree's position goes through the scene CRS to
//!   WGS84 on its own, so grid convergence and scale factor are exact.
//! - `meshes/`: each species' mesh levels and far quads (one `.bin` each),
//!   material textures and billboard (PNG), shared by every GLB that uses them
//!   (external URIs).
//!
//! - `ground/`: the scene's terrain quadtree as draped meshes ([`ground`]).
//!
//! Heights are the scene's heights (the bake's terrain or the placements'),
//! taken as heights over the WGS84 ellipsoid, plus `--height-offset` (the
//! geoid's undulation, for heights over the geoid).

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{bail, Context, Result};
use glam::{DVec3, Vec3};
use image::ImageEncoder as _;
use serde_json::{json, Value};
use sylva::format::index::IndexNode;
use sylva::format::pack::{kind, MaterialKind, MeshVertex, PackMeta, Season};
use sylva::format::{decode_pack, Bounds, Manifest, Tile, TileEntry};
use sylva::geo::GeoFrame;

mod geodesy;
mod glb;
mod ground;

use geodesy::*;
use glb::*;

/// Cesium's default maximum screen-space error (px): what the geometric errors are scaled for.
const SSE_PX: f64 = 16.0;
/// Projected height (px) of a node's tallest tree from which its tiles are shown at all
/// (there is no canopy raster in the tileset).
const SHOWN_FROM_PX: f64 = 2.0;
/// The key of a species' far quads in [`SpeciesOut::levels`] (mesh levels are small numbers).
const FAR: u32 = u32::MAX;

/// How to export.
#[derive(Debug, Clone, Copy)]
pub struct ExportOptions {
    /// Export the scene's terrain (and its imagery) as ground tiles.
    pub ground: bool,
    /// Metres added to every height: the geoid's undulation at the scene, for
    /// heights above the geoid shown on an ellipsoidal terrain.
    pub height_offset_m: f64,
    /// The season deciduous species are exported in (one tileset per season:
    /// autumn recolours their leaf textures and far quads, leaf-off leaves
    /// their leaves out and shows the bare wood's billboard).
    pub season: Season,
}

impl Default for ExportOptions {
    fn default() -> Self {
        Self { ground: true, height_offset_m: 0.0, season: Season::LeafOn }
    }
}

/// What an export wrote.
#[derive(Debug, Clone, Default)]
pub struct ExportReport {
    /// Sylva tiles exported (each two or three GLBs).
    pub tiles: usize,
    /// GLB files written.
    pub glbs: usize,
    /// Trees exported (instances in the full GLBs).
    pub trees: u64,
    /// Ground tiles exported (a GLB each).
    pub ground_tiles: usize,
    /// Bytes written in all.
    pub bytes: u64,
}

/// One species' mesh level as glTF pieces in its shared `.bin` (y up).
struct MeshBin {
    /// `meshes/<file>.bin`, relative to the tileset.
    uri: String,
    bytes: u64,
    vertices: u32,
    /// (offset, length) of positions, normals, uvs, colours, indices.
    views: [(u64, u64); 5],
    pos_min: [f32; 3],
    pos_max: [f32; 3],
    /// (material index, first index, index count); the far quads' material is
    /// their billboard, not one of the pack's.
    draws: Vec<(usize, u32, u32)>,
}

/// Everything shared of one species.
struct SpeciesOut {
    meta: PackMeta,
    /// Mesh levels by level number (0 and the coarsest).
    levels: BTreeMap<u32, MeshBin>,
    /// PNG of each material texture layer used, relative to the tileset.
    layers: BTreeMap<u32, String>,
    /// PNG of the side-view billboard the far quads show (where the pack has billboards).
    billboard: Option<String>,
}

impl SpeciesOut {
    /// The level a GLB of the far tier draws: the crossed quads, else (a pack
    /// without billboards) the coarsest mesh level.
    fn far_level(&self) -> u32 {
        if self.levels.contains_key(&FAR) {
            FAR
        } else {
            self.meta.mesh_levels.len() as u32 - 1
        }
    }

    /// The projected tree height (px) from which Sylva's viewer draws meshes
    /// instead of the far tier: the coarsest mesh level's threshold (the
    /// bake's policy's where it has one).
    fn mesh_from_px(&self) -> f64 {
        let last = self.meta.mesh_levels.last().expect("a pack with mesh levels");
        f64::from(last.policy_px.unwrap_or(last.select_px))
    }
}

fn write_file(path: &Path, bytes: &[u8], report: &mut ExportReport) -> Result<()> {
    std::fs::write(path, bytes).with_context(|| format!("cannot write {}", path.display()))?;
    report.bytes += bytes.len() as u64;
    Ok(())
}

/// `meshes/<file>.bin` of mesh level `level`; `leaves` false: its leaf
/// materials' draws left out (a deciduous tree in leaf-off).
fn mesh_bin(
    pack: &sylva::format::pack::Pack<'_>,
    level: u32,
    leaves: bool,
    file: &str,
    out: &Path,
    report: &mut ExportReport,
) -> Result<MeshBin> {
    let m = &pack.meta.mesh_levels[level as usize];
    let verts: Vec<MeshVertex> = pack.mesh_vertices(level);
    let indices = pack.mesh_indices(level);
    if verts.len() != m.vertex_count as usize || indices.len() != m.index_count as usize {
        bail!("{file}: mesh level {level} is missing from its pack");
    }
    let (lo, hi) = (Vec3::from(m.pos_min), Vec3::from(m.pos_max));
    let (ulo, uhi) = (glam::Vec2::from(m.uv_min), glam::Vec2::from(m.uv_max));
    let mut bin = Vec::with_capacity(verts.len() * 36 + indices.len() * 4);
    let (mut pmin, mut pmax) = ([f32::MAX; 3], [f32::MIN; 3]);
    for v in &verts {
        let q = Vec3::new(v.position[0].into(), v.position[1].into(), v.position[2].into()) / 65535.0;
        let p = lo + (hi - lo) * q;
        let y_up = [p.x, p.z, -p.y];
        for k in 0..3 {
            pmin[k] = pmin[k].min(y_up[k]);
            pmax[k] = pmax[k].max(y_up[k]);
        }
        bin.extend_from_slice(bytemuck::cast_slice(&y_up));
    }
    for v in &verts {
        let n = crate::pack::cloud::oct_decode([v.normal_oct[0], v.normal_oct[1]]);
        let n = if n == Vec3::ZERO { Vec3::Z } else { n };
        bin.extend_from_slice(bytemuck::cast_slice(&[n.x, n.z, -n.y]));
    }
    for v in &verts {
        let uv = ulo + (uhi - ulo) * glam::Vec2::new(v.uv[0].into(), v.uv[1].into()) / 65535.0;
        bin.extend_from_slice(bytemuck::cast_slice(&[uv.x, uv.y]));
    }
    for v in &verts {
        bin.extend_from_slice(&v.color);
    }
    bin.extend_from_slice(bytemuck::cast_slice(&indices));
    let draws = m
        .draws
        .iter()
        .filter(|d| {
            leaves || pack.meta.materials.get(d.material as usize).is_some_and(|x| x.kind == MaterialKind::Branch)
        })
        .map(|d| (d.material as usize, d.first_index, d.index_count))
        .collect();
    write_mesh_bin(bin, verts.len(), indices.len(), [pmin, pmax], draws, file, out, report)
}

/// Writes `meshes/<file>.bin`: `bin` holds `vertices` positions (FLOAT VEC3,
/// y up), normals, uvs (FLOAT VEC2), colours (RGBA8), then `indices` u32.
#[allow(clippy::too_many_arguments)]
fn write_mesh_bin(
    bin: Vec<u8>,
    vertices: usize,
    indices: usize,
    [pos_min, pos_max]: [[f32; 3]; 2],
    draws: Vec<(usize, u32, u32)>,
    file: &str,
    out: &Path,
    report: &mut ExportReport,
) -> Result<MeshBin> {
    let n = vertices as u64;
    let views = [(0, 12 * n), (12 * n, 12 * n), (24 * n, 8 * n), (32 * n, 4 * n), (36 * n, 4 * indices as u64)];
    let uri = format!("meshes/{file}.bin");
    write_file(&out.join(&uri), &bin, report)?;
    Ok(MeshBin { uri, bytes: bin.len() as u64, vertices: vertices as u32, views, pos_min, pos_max, draws })
}

/// The far tier's mesh of a species (`meshes/<file>.bin`): two quads crossed
/// on the trunk's axis, each as wide and tall as the pack's billboard (its
/// centre's height, half width, half height), showing its side view (u along
/// model +x on one, +y on the other; v down). Normals point up: both quads and
/// every view of them are lit alike, as a crown seen from afar.
fn far_bin(
    bb: &sylva::format::pack::BillboardMeta,
    file: &str,
    out: &Path,
    report: &mut ExportReport,
) -> Result<MeshBin> {
    let (hw, hh, cz) = (bb.half_width, bb.half_height, bb.center[2]);
    // (model x or y along the quad, model z, u, v) per corner; model (x, y, z) is glTF (x, z, -y).
    let corners =
        [(-hw, cz - hh, 0.0, 1.0), (hw, cz - hh, 1.0, 1.0), (hw, cz + hh, 1.0, 0.0), (-hw, cz + hh, 0.0, 0.0)];
    let mut pos: Vec<[f32; 3]> = corners.iter().map(|&(a, z, _, _)| [a, z, 0.0]).collect();
    pos.extend(corners.iter().map(|&(a, z, _, _)| [0.0, z, -a]));
    let uv: Vec<[f32; 2]> = corners.iter().chain(corners.iter()).map(|&(_, _, u, v)| [u, v]).collect();
    let indices: [u32; 12] = [0, 1, 2, 0, 2, 3, 4, 5, 6, 4, 6, 7];
    let mut bin = Vec::with_capacity(8 * 36 + 48);
    bin.extend_from_slice(bytemuck::cast_slice(&pos));
    bin.extend_from_slice(bytemuck::cast_slice(&[[0.0f32, 1.0, 0.0]; 8]));
    bin.extend_from_slice(bytemuck::cast_slice(&uv));
    bin.extend_from_slice(&[255u8; 32]);
    bin.extend_from_slice(bytemuck::cast_slice(&indices));
    let bounds = [[-hw, cz - hh, -hw], [hw, cz + hh, hw]];
    write_mesh_bin(bin, 8, indices.len(), bounds, vec![(0, 0, 12)], file, out, report)
}

/// A change to each RGBA8 texel (by index) of a texture layer.
type TexelEdit<'a> = &'a dyn Fn(usize, &mut [u8]);

/// PNG of layer `layer` (mip 0) of an RGBA8 texture array stored mip-major,
/// each texel (by index) first changed by `edit` where given.
fn layer_png(data: &[u8], size: u32, layer: u32, what: &str, edit: Option<TexelEdit<'_>>) -> Result<Vec<u8>> {
    let layer_bytes = (size * size * 4) as usize;
    let at = layer as usize * layer_bytes;
    let Some(pixels) = data.get(at..at + layer_bytes) else { bail!("{what}: texture layer {layer} is missing") };
    let mut pixels = std::borrow::Cow::Borrowed(pixels);
    if let Some(edit) = edit {
        for (i, t) in pixels.to_mut().chunks_exact_mut(4).enumerate() {
            edit(i, t);
        }
    }
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png)
        .write_image(&pixels, size, size, image::ExtendedColorType::Rgba8)
        .with_context(|| format!("encoding {what}'s texture layer {layer}"))?;
    Ok(png)
}

/// An sRGB RGBA8 leaf texel in autumn (`autumn`: the species' colour, linear),
/// at a stand's mean progress (a tileset has one texture per species), as the
/// viewer recolours leaves.
fn autumn_texel(t: &mut [u8], autumn: [f32; 3]) {
    use sylva::render::mips::{linear_to_srgb, srgb_to_linear};
    use sylva::render::settings::{autumn_albedo, AUTUMN_MEAN_PROGRESS};
    let fall = autumn_albedo([0, 1, 2].map(|k| srgb_to_linear(t[k])), autumn, AUTUMN_MEAN_PROGRESS);
    t[..3].copy_from_slice(&fall.map(linear_to_srgb));
}

/// Reads species `s`'s pack and writes its meshes (level 0 and the coarsest)
/// and textures, as they look in `season` (a deciduous species'; an evergreen
/// looks the same in every one).
fn species_out(
    dir: &Path,
    m: &Manifest,
    s: usize,
    out: &Path,
    season: Season,
    report: &mut ExportReport,
) -> Result<SpeciesOut> {
    let entry = &m.species[s];
    let path = dir.join(&entry.pack);
    let bytes = sylva::paths::read_regular(&path, None, sylva::paths::MAX_SCENE_FILE_BYTES)
        .with_context(|| format!("cannot read pack {}", path.display()))?;
    let bytes = sylva::format::stored::unstore(&path.display().to_string(), bytes)?;
    let pack = decode_pack(&path.display().to_string(), &bytes)?;
    if let Some(e) = pack.meta.encodings().first() {
        anyhow::bail!(
            "{}: its textures are {} blocks; the export reads the plain pack's texels",
            path.display(),
            e.name()
        );
    }
    let meta = pack.meta.clone();
    if meta.mesh_levels.is_empty() {
        bail!("{}: the pack has no mesh level to export", path.display());
    }
    let stem: String = format!("{s}_{}", entry.name)
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() || c == '_' { c } else { '-' })
        .collect();
    // The season's state: a deciduous species' autumn colour, or its leaves off.
    let autumn = meta.season.as_ref().filter(|_| season == Season::Autumn).map(sylva::render::settings::autumn_linear);
    let leaves = !(season == Season::LeafOff && meta.season.is_some());
    let mut levels = BTreeMap::new();
    let coarsest = meta.mesh_levels.len() as u32 - 1;
    for level in [0, coarsest] {
        if let std::collections::btree_map::Entry::Vacant(e) = levels.entry(level) {
            e.insert(mesh_bin(&pack, level, leaves, &format!("{stem}_mesh{level}"), out, report)?);
        }
    }
    let mut layers = BTreeMap::new();
    if let (Some(t), Some(data)) = (&meta.material_texture, pack.section(kind::MATERIAL_TEXTURES, 0)) {
        for (layer, kind) in meta.materials.iter().filter_map(|mat| mat.texture_layer.map(|l| (l, mat.kind))) {
            if layers.contains_key(&layer) {
                continue;
            }
            let recolour =
                autumn.filter(|_| kind == MaterialKind::Leaf).map(|c| move |_: usize, t: &mut [u8]| autumn_texel(t, c));
            let edit = recolour.as_ref().map(|f| f as TexelEdit<'_>);
            let png = layer_png(data, t.size, layer, &path.display().to_string(), edit)?;
            let uri = format!("meshes/{stem}_layer{layer}.png");
            write_file(&out.join(&uri), &png, report)?;
            layers.insert(layer, uri);
        }
    }
    // The far quads show the billboard seen level (elevation 0, azimuth 0:
    // layer 0), of the bare wood in leaf-off where the pack has it (else its
    // leaf texels left out, as the viewer draws it); in autumn its leaf texels
    // recoloured.
    let mut billboard = None;
    let state = u32::from(!leaves && meta.season.as_ref().is_some_and(|x| x.bare_far));
    if let (Some(bb), Some(data)) = (&meta.billboards, pack.section(kind::BILLBOARD_COLOR, state)) {
        let normals = pack.section(kind::BILLBOARD_NORMAL, state).unwrap_or_default();
        let leaf = |i: usize| normals.get(i * 4 + 3).is_some_and(|a| *a > sylva::format::pack::LEAF_FLAG_MIN);
        let edit = |i: usize, t: &mut [u8]| {
            if leaf(i) {
                match autumn {
                    Some(c) => autumn_texel(t, c),
                    None if !leaves => t[3] = 0,
                    None => {}
                }
            }
        };
        let changes = autumn.is_some() || (!leaves && state == 0);
        let what = format!("{}'s billboards", path.display());
        let png = layer_png(data, bb.texture.size, 0, &what, changes.then_some(&edit as TexelEdit<'_>))?;
        let uri = format!("meshes/{stem}_billboard.png");
        write_file(&out.join(&uri), &png, report)?;
        billboard = Some(uri);
        levels.insert(FAR, far_bin(bb, &format!("{stem}_far"), out, report)?);
    }
    Ok(SpeciesOut { meta, levels, layers, billboard })
}

/// A `region` (radians, metres) around scene-relative bounds (`origin_z`: the
/// scene origin's height, which the content's heights include).
fn region(geo: &GeoFrame, b: &Bounds, origin_z: f64) -> Result<Value> {
    let (mut w, mut s, mut e, mut n) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for (i, j) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0), (0.5, 0.0), (0.5, 1.0), (0.0, 0.5), (1.0, 0.5)] {
        let x = f64::from(b.min[0]) + (f64::from(b.max[0]) - f64::from(b.min[0])) * i;
        let y = f64::from(b.min[1]) + (f64::from(b.max[1]) - f64::from(b.min[1])) * j;
        let (lon, lat, _) = geo.to_geo(DVec3::new(x, y, 0.0)).map_err(|e| anyhow::anyhow!("{e}"))?;
        (w, s, e, n) = (w.min(lon), s.min(lat), e.max(lon), n.max(lat));
    }
    // A metre's margin for the projection's curvature between the corners.
    let m = 1.0 / 111_000.0;
    Ok(json!([
        (w - m).to_radians(),
        (s - m).to_radians(),
        (e + m).to_radians(),
        (n + m).to_radians(),
        origin_z + f64::from(b.min[2]) - 1.0,
        origin_z + f64::from(b.max[2]) + 1.0
    ]))
}

/// What a tile of the tileset needs from one Sylva tile.
struct TileNode {
    json: Value,
    bounds: Bounds,
    tallest_m: f64,
}

/// What every tile's export reads.
struct Ctx<'a> {
    /// Index nodes read and tiles exported so far: a node or tile listed
    /// twice (a corrupt or hostile index) is refused, not read again.
    seen_nodes: std::cell::RefCell<std::collections::HashSet<String>>,
    seen_tiles: std::cell::RefCell<std::collections::HashSet<(i32, i32)>>,
    dir: &'a Path,
    m: &'a Manifest,
    geo: GeoFrame,
    species: Vec<SpeciesOut>,
    out: &'a Path,
    /// Property names of the attribute columns.
    names: Vec<String>,
    meta_schema: Value,
    /// Metres added to every height.
    height_offset_m: f64,
}

/// Exports tile `entry`: its GLBs and its tileset node.
fn export_tile(ctx: &Ctx<'_>, entry: &TileEntry, report: &mut ExportReport) -> Result<Option<TileNode>> {
    let Ctx { dir, m, geo, species, out, .. } = ctx;
    let (geo, species) = (geo, &species[..]);
    if !ctx.seen_tiles.borrow_mut().insert((entry.x, entry.y)) {
        bail!("{}: tile {},{} is listed twice", dir.join("scene.json").display(), entry.x, entry.y);
    }
    let path = dir.join(&entry.url);
    let bytes = sylva::paths::read_regular(&path, None, sylva::paths::MAX_SCENE_FILE_BYTES)
        .with_context(|| format!("cannot read tile {}", path.display()))?;
    let tile = Tile::decode(&path.display().to_string(), &bytes, m.species.len() as u32)?;
    let mid = DVec3::new(
        (f64::from(entry.bounds.min[0]) + f64::from(entry.bounds.max[0])) * 0.5,
        (f64::from(entry.bounds.min[1]) + f64::from(entry.bounds.max[1])) * 0.5,
        f64::from(entry.bounds.min[2]) + ctx.height_offset_m,
    );
    let (lon, lat, h) = geo.to_geo(mid).map_err(|e| anyhow::anyhow!("{}: {e}", entry.url))?;
    let frame = enu_frame(lon, lat, h);
    let mut placed = Placed::new();
    let (mut lo, mut hi) = ([f32::MAX; 3], [f32::MIN; 3]);
    let mut tallest = 0.0f64;
    let ids_path = dir.join(&entry.ids_url);
    let sylva::format::TreeIds { numbers: ids, texts } = sylva::format::decode_tree_ids(
        &ids_path.display().to_string(),
        &sylva::paths::read_regular(&ids_path, None, sylva::paths::MAX_SCENE_FILE_BYTES)
            .with_context(|| format!("cannot read tree ids {}", ids_path.display()))?,
    )?;
    if ids.len() != tile.instances.len() {
        bail!("{}: {} ids for {} trees", ids_path.display(), ids.len(), tile.instances.len());
    }
    let codes = match &m.attributes {
        Some(schema) => {
            let url = sylva::format::attributes::attributes_url(&entry.url);
            let p = dir.join(&url);
            let bytes = sylva::paths::read_regular(&p, None, sylva::paths::MAX_SCENE_FILE_BYTES)
                .with_context(|| format!("cannot read attributes {}", p.display()))?;
            let codes = sylva::format::attributes::decode_attributes(
                &p.display().to_string(),
                &bytes,
                schema,
                tile.instances.len(),
            )
            .map_err(|e| anyhow::anyhow!("{e}"))?;
            Some((schema, codes))
        }
        None => None,
    };
    let data =
        TreeData { ids, texts, codes, models: m.species.iter().map(|s| s.name.as_str()).collect(), names: &ctx.names };
    let mut at = 0usize;
    for b in &tile.batches {
        // The trees standing at the scene's latest date only (3D Tiles has no date).
        if b.flags & sylva::format::tile::BATCH_DATED != 0 {
            at += b.instance_count as usize;
            continue;
        }
        let sp = &species[b.species as usize];
        let half = Vec3::from(sp.meta.bounds_max).max(-Vec3::from(sp.meta.bounds_min));
        for (k, p) in tile.instances[at..at + b.instance_count as usize].iter().enumerate() {
            let i = p.decode(b);
            let local = DVec3::new(
                i.position_m[0].into(),
                i.position_m[1].into(),
                f64::from(i.position_m[2]) + ctx.height_offset_m,
            );
            let t = place(geo, &frame, local, f64::from(i.yaw_rad), i.scale, i.aspect)
                .with_context(|| format!("{}: a tree at {local}", entry.url))?;
            placed.entry(b.species).or_default().push(ExportedTree { index: (at + k) as u32, ..t });
            // (The crown turns with the yaw: the model box's corner radius.)
            let r = half.x.hypot(half.y) * i.scale * i.aspect;
            let top = sp.meta.bounds_max[2] * i.scale;
            tallest = tallest.max(f64::from(top));
            for k in 0..2 {
                lo[k] = lo[k].min(i.position_m[k] - r);
                hi[k] = hi[k].max(i.position_m[k] + r);
            }
            lo[2] = lo[2].min(i.position_m[2] + sp.meta.bounds_min[2] * i.scale);
            hi[2] = hi[2].max(i.position_m[2] + top);
        }
        at += b.instance_count as usize;
    }
    if placed.is_empty() {
        // Every tree of the tile gone by the latest date.
        if tile.batches.iter().any(|b| b.flags & sylva::format::tile::BATCH_DATED != 0) {
            return Ok(None);
        }
        bail!("{}: a tile without trees", entry.url);
    }
    let bounds = Bounds { min: lo, max: hi };
    let name = format!("{}_{}", entry.x, entry.y);
    let glb = |suffix: &str, level_of: &dyn Fn(&SpeciesOut) -> u32, report: &mut ExportReport| {
        let bytes = tile_glb(species, &placed, &data, &ctx.meta_schema, level_of);
        let uri = format!("tiles/{name}{suffix}.glb");
        write_file(&out.join(&uri), &bytes, report)?;
        report.glbs += 1;
        anyhow::Ok(uri)
    };
    let full = glb("", &|_| 0, report)?;
    report.trees += placed.values().map(|v| v.len() as u64).sum::<u64>();
    let region = region(geo, &bounds, m.origin_m[2] + ctx.height_offset_m)?;
    // Tiers, as Sylva's viewer picks them by the tallest tree's projected
    // height: the full meshes from the finest level's threshold, the coarsest
    // mesh level from where meshes start, the far quads below. (Each at least
    // the group's threshold: a child's error never exceeds its parent's.)
    let threshold = |px: &dyn Fn(&SpeciesOut) -> f64| {
        placed.keys().map(|&s| px(&species[s as usize])).fold(f64::MAX, f64::min).max(SHOWN_FROM_PX)
    };
    let full_px = threshold(&|sp| f64::from(sp.meta.mesh_levels[0].select_px));
    let mesh_px = threshold(&|sp| sp.mesh_from_px()).min(full_px);
    let mut below_far = json!({"boundingVolume": {"region": region}, "geometricError": 0.0, "content": {"uri": full}});
    let coarse_levels = placed.keys().any(|&s| species[s as usize].meta.mesh_levels.len() > 1);
    if coarse_levels && mesh_px < full_px {
        let coarse = glb("_coarse", &|sp| sp.meta.mesh_levels.len() as u32 - 1, report)?;
        below_far = json!({
            "boundingVolume": {"region": region},
            "geometricError": SSE_PX * tallest / full_px,
            "refine": "REPLACE",
            "content": {"uri": coarse},
            "children": [below_far],
        });
    }
    let far = glb("_far", &|sp| sp.far_level(), report)?;
    let json = json!({
        "boundingVolume": {"region": region},
        "geometricError": SSE_PX * tallest / mesh_px,
        "refine": "REPLACE",
        "transform": transform_json(&frame),
        "content": {"uri": far},
        "children": [below_far],
    });
    report.tiles += 1;
    Ok(Some(TileNode { json, bounds, tallest_m: tallest }))
}

/// A content-less tileset node over `children`: shown from where its tallest
/// tree is [`SHOWN_FROM_PX`] tall.
fn group(children: Vec<TileNode>) -> Option<TileNode> {
    let bounds = sylva::format::index::union_bounds(children.iter().map(|c| &c.bounds))?;
    let tallest = children.iter().map(|c| c.tallest_m).fold(0.0, f64::max);
    Some(TileNode {
        json: json!({
            "geometricError": SSE_PX * tallest / SHOWN_FROM_PX,
            "refine": "REPLACE",
            "children": children.into_iter().map(|c| c.json).collect::<Vec<_>>(),
        }),
        bounds,
        tallest_m: tallest,
    })
}

/// Exports the index node at `url` (and everything below it).
fn export_node(
    ctx: &Ctx<'_>,
    url: &str,
    depth: u32,
    report: &mut ExportReport,
    progress: &mut dyn FnMut(&ExportReport),
) -> Result<Option<TileNode>> {
    let most = ctx.m.index.as_ref().map_or(0, |i| i.depth);
    if depth >= most.max(1) {
        bail!("{}: deeper than the {most} levels the index declares", ctx.dir.join(url).display());
    }
    if !ctx.seen_nodes.borrow_mut().insert(url.to_string()) {
        bail!("{}: an index node listed twice", ctx.dir.join(url).display());
    }
    let path = ctx.dir.join(url);
    let bytes = sylva::paths::read_regular(&path, None, sylva::paths::MAX_SCENE_FILE_BYTES)
        .with_context(|| format!("cannot read index node {}", path.display()))?;
    let node = IndexNode::decode(&path.display().to_string(), &bytes)?;
    let mut children = Vec::new();
    for c in &node.children {
        children.extend(export_node(ctx, &c.url, depth + 1, report, progress)?);
    }
    for t in &node.tiles {
        children.extend(export_tile(ctx, t, report)?);
        progress(report);
    }
    Ok(group(children))
}

/// Exports the scene in `dir` as a 3D Tiles 1.1 tileset into `out` (a new or
/// empty folder).
///
/// # Errors
/// An unreadable or invalid scene, a CRS the projection library cannot take,
/// an `out` that holds files, a non-finite height offset, I/O errors.
pub fn export(
    dir: &Path,
    out: &Path,
    options: ExportOptions,
    progress: &mut dyn FnMut(&ExportReport),
) -> Result<ExportReport> {
    if !options.height_offset_m.is_finite() || options.height_offset_m.abs() > 1000.0 {
        bail!(
            "--height-offset {} m: give the geoid's undulation at the scene, within ±1000 m",
            options.height_offset_m
        );
    }
    let manifest = dir.join("scene.json");
    let bytes = sylva::paths::read_regular(&manifest, None, sylva::paths::MAX_SCENE_FILE_BYTES)
        .with_context(|| format!("cannot read {}", manifest.display()))?;
    let m = Manifest::decode(&manifest.display().to_string(), &bytes)?;
    if m.counts.trees == 0 {
        bail!("{}: the scene has no trees to export", manifest.display());
    }
    let dangling = std::fs::symlink_metadata(out).is_ok_and(|l| l.file_type().is_symlink()) && !out.exists();
    if dangling {
        bail!("--out {} is a symbolic link to a folder that does not exist", out.display());
    }
    if out.exists() && !out.is_dir() {
        bail!("--out {} exists and is not a folder", out.display());
    }
    if out.exists()
        && std::fs::read_dir(out).with_context(|| format!("cannot read {}", out.display()))?.next().is_some()
    {
        bail!("{}: not empty; export into a new or empty folder (nothing is overwritten)", out.display());
    }
    // What a failed export wrote goes again (the folder was new or empty), so a
    // retry after the cause is fixed finds it as it was.
    let created = !out.exists();
    let result = export_into(dir, out, &m, options, progress);
    if result.is_err() {
        let _ = if created {
            std::fs::remove_dir_all(out)
        } else {
            std::fs::read_dir(out).and_then(|entries| {
                for e in entries.flatten() {
                    let p = e.path();
                    if e.file_type().is_ok_and(|t| t.is_dir()) {
                        std::fs::remove_dir_all(&p)?;
                    } else {
                        std::fs::remove_file(&p)?;
                    }
                }
                Ok(())
            })
        };
    }
    result
}

/// [`export`] after its checks: writes the tileset into the new or empty `out`.
fn export_into(
    dir: &Path,
    out: &Path,
    m: &Manifest,
    options: ExportOptions,
    progress: &mut dyn FnMut(&ExportReport),
) -> Result<ExportReport> {
    let manifest = dir.join("scene.json");
    let ground = options.ground && m.terrain.is_some();
    let subs: &[&str] = if ground { &["tiles", "meshes", "ground/img"] } else { &["tiles", "meshes"] };
    for sub in subs {
        std::fs::create_dir_all(out.join(sub)).with_context(|| format!("cannot create {}", out.join(sub).display()))?;
    }
    let geo = GeoFrame::new(&m.crs.proj4, m.origin_m)
        .map_err(|e| anyhow::anyhow!("{}: the scene's CRS: {e}", manifest.display()))?;
    let mut report = ExportReport::default();
    let species: Vec<SpeciesOut> = (0..m.species.len())
        .map(|s| species_out(dir, m, s, out, options.season, &mut report))
        .collect::<Result<_>>()?;
    let names = property_names(m.attributes.as_ref());
    let meta_schema = metadata_schema(m.attributes.as_ref(), &names);
    let ctx = Ctx {
        seen_nodes: Default::default(),
        seen_tiles: Default::default(),
        dir,
        m,
        geo,
        species,
        out,
        names,
        meta_schema,
        height_offset_m: options.height_offset_m,
    };
    let root = if let Some(index) = &m.index {
        export_node(&ctx, &index.root, 0, &mut report, progress)?
    } else {
        let mut children = Vec::new();
        for t in &m.tiles {
            children.extend(export_tile(&ctx, t, &mut report)?);
            progress(&report);
        }
        group(children)
    };
    let Some(forest) = root else { bail!("{}: the scene lists no tiles", manifest.display()) };
    let ground = if ground {
        let g = ground::Ground { dir, m, geo: &ctx.geo, out, height_offset_m: options.height_offset_m };
        g.export(&mut report, progress)?
    } else {
        None
    };
    // With ground: a node adding the forest to it, refined (both shown) while
    // the terrain's square is more than Cesium's 16 px across.
    let mut root = match ground {
        Some(ground) => {
            let size = m.terrain.as_ref().map_or(0.0, |t| t.root_size_m);
            let error =
                [&ground, &forest.json].iter().filter_map(|n| n["geometricError"].as_f64()).fold(size, f64::max);
            let (mut ground, mut forest) = (ground, forest.json);
            ground["extras"] = json!({"sylva": "ground"});
            forest["extras"] = json!({"sylva": "forest"});
            json!({"geometricError": error, "refine": "ADD", "children": [ground, forest]})
        }
        None => forest.json,
    };
    fill_regions(&mut root);
    let tileset = json!({
        "asset": {"version": "1.1", "generator": "sylva-bake export-3dtiles", "tilesetVersion": m.counts.trees.to_string()},
        "geometricError": root["geometricError"],
        "root": root,
    });
    let text = serde_json::to_vec_pretty(&tileset)?;
    write_file(&out.join("tileset.json"), &text, &mut report)?;
    Ok(report)
}

/// Gives every content-less node a region around its children's (the tiles have theirs).
fn fill_regions(node: &mut Value) -> [f64; 6] {
    let mut r = [f64::MAX, f64::MAX, f64::MIN, f64::MIN, f64::MAX, f64::MIN];
    if let Some(children) = node.get_mut("children").and_then(Value::as_array_mut) {
        for c in children {
            let cr = fill_regions(c);
            for k in [0, 1, 4] {
                r[k] = r[k].min(cr[k]);
            }
            for k in [2, 3, 5] {
                r[k] = r[k].max(cr[k]);
            }
        }
    }
    if let Some(own) = node.pointer("/boundingVolume/region").and_then(Value::as_array) {
        let own: Vec<f64> = own.iter().filter_map(Value::as_f64).collect();
        if own.len() == 6 && node.get("content").is_some() {
            return [own[0], own[1], own[2], own[3], own[4], own[5]];
        }
    }
    node["boundingVolume"] = json!({"region": r});
    r
}

#[cfg(test)]
mod tests;
