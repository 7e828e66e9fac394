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
use sylva::format::pack::{kind, MeshVertex, PackMeta};
use sylva::format::{decode_pack, Bounds, Manifest, Tile, TileEntry};
use sylva::geo::GeoFrame;

mod ground;

/// WGS84 semi-major axis, metres.
const WGS84_A: f64 = 6_378_137.0;
/// WGS84 flattening.
const WGS84_F: f64 = 1.0 / 298.257_223_563;
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
}

impl Default for ExportOptions {
    fn default() -> Self {
        Self { ground: true, height_offset_m: 0.0 }
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

/// Earth-centred, Earth-fixed metres of a WGS84 point (degrees, metres).
#[must_use]
pub fn geodetic_to_ecef(lon_deg: f64, lat_deg: f64, h: f64) -> DVec3 {
    let e2 = WGS84_F * (2.0 - WGS84_F);
    let (sl, cl) = lat_deg.to_radians().sin_cos();
    let (so, co) = lon_deg.to_radians().sin_cos();
    let n = WGS84_A / (1.0 - e2 * sl * sl).sqrt();
    DVec3::new((n + h) * cl * co, (n + h) * cl * so, (n * (1.0 - e2) + h) * sl)
}

/// (lon, lat in degrees, height in metres) of an Earth-centred, Earth-fixed point.
#[cfg(test)]
fn ecef_to_geodetic(p: DVec3) -> (f64, f64, f64) {
    let e2 = WGS84_F * (2.0 - WGS84_F);
    let lon = p.y.atan2(p.x);
    let r = p.x.hypot(p.y);
    let mut lat = p.z.atan2(r * (1.0 - e2));
    let mut h = 0.0;
    for _ in 0..8 {
        let s = lat.sin();
        let n = WGS84_A / (1.0 - e2 * s * s).sqrt();
        h = r / lat.cos() - n;
        lat = p.z.atan2(r * (1.0 - e2 * n / (n + h)));
    }
    (lon.to_degrees(), lat.to_degrees(), h)
}

/// The east-north-up frame at a WGS84 point: (origin, east, north, up) in ECEF.
#[must_use]
pub fn enu_frame(lon_deg: f64, lat_deg: f64, h: f64) -> [DVec3; 4] {
    let (sl, cl) = lat_deg.to_radians().sin_cos();
    let (so, co) = lon_deg.to_radians().sin_cos();
    [
        geodetic_to_ecef(lon_deg, lat_deg, h),
        DVec3::new(-so, co, 0.0),
        DVec3::new(-sl * co, -sl * so, cl),
        DVec3::new(cl * co, cl * so, sl),
    ]
}

/// The frame as a 3D Tiles `transform` (column-major 4×4, ENU → ECEF).
fn transform_json(f: &[DVec3; 4]) -> Value {
    let [o, e, n, u] = f;
    json!([e.x, e.y, e.z, 0.0, n.x, n.y, n.z, 0.0, u.x, u.y, u.z, 0.0, o.x, o.y, o.z, 1.0])
}

/// A tree in its tile's frame, as glTF (y up): translation, rotation about +y, scale.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExportedTree {
    /// glTF translation (x east, y up, z south), metres.
    pub translation: [f32; 3],
    /// Quaternion `[x, y, z, w]` about +y.
    pub rotation: [f32; 4],
    /// Scale `[horizontal, vertical, horizontal]`.
    pub scale: [f32; 3],
    /// The tree's index in its tile (the order of `.ids` and `.attr`).
    pub index: u32,
}

/// Places a tree (`local`: trunk base relative to the scene origin; yaw in the
/// scene's grid) in the frame `f` through WGS84.
fn place(geo: &GeoFrame, f: &[DVec3; 4], local: DVec3, yaw: f64, scale: f32, aspect: f32) -> Result<ExportedTree> {
    let enu = |p: DVec3| -> Result<DVec3> {
        let (lon, lat, h) = geo.to_geo(p).map_err(|e| anyhow::anyhow!("{e}"))?;
        let d = geodetic_to_ecef(lon, lat, h) - f[0];
        Ok(DVec3::new(d.dot(f[1]), d.dot(f[2]), d.dot(f[3])))
    };
    let t = enu(local)?;
    // The model's x axis, one metre along the grid's yaw, as the frame sees it (grid convergence).
    let ahead = enu(local + DVec3::new(yaw.cos(), yaw.sin(), 0.0))? - t;
    let theta = ahead.y.atan2(ahead.x);
    let (s, c) = (theta * 0.5).sin_cos();
    Ok(ExportedTree {
        translation: [t.x as f32, t.z as f32, -t.y as f32],
        rotation: [0.0, s as f32, 0.0, c as f32],
        scale: [scale * aspect, scale, scale * aspect],
        index: 0,
    })
}

/// The scene-relative trunk position a glTF translation in frame `f` maps back to.
///
/// # Errors
/// Points the scene's projection cannot take.
#[cfg(test)]
fn unplace(geo: &GeoFrame, f: &[DVec3; 4], translation: [f32; 3]) -> Result<DVec3> {
    let t = DVec3::new(f64::from(translation[0]), -f64::from(translation[2]), f64::from(translation[1]));
    let p = f[0] + f[1] * t.x + f[2] * t.y + f[3] * t.z;
    let (lon, lat, h) = ecef_to_geodetic(p);
    geo.to_local(lon, lat, h).map_err(|e| anyhow::anyhow!("{e}"))
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

fn mesh_bin(
    pack: &sylva::format::pack::Pack<'_>,
    level: u32,
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
    let draws = m.draws.iter().map(|d| (d.material as usize, d.first_index, d.index_count)).collect();
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

/// PNG of layer `layer` (mip 0) of an RGBA8 texture array stored mip-major.
fn layer_png(data: &[u8], size: u32, layer: u32, what: &str) -> Result<Vec<u8>> {
    let layer_bytes = (size * size * 4) as usize;
    let at = layer as usize * layer_bytes;
    let Some(pixels) = data.get(at..at + layer_bytes) else { bail!("{what}: texture layer {layer} is missing") };
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png)
        .write_image(pixels, size, size, image::ExtendedColorType::Rgba8)
        .with_context(|| format!("encoding {what}'s texture layer {layer}"))?;
    Ok(png)
}

/// Reads species `s`'s pack and writes its meshes (level 0 and the coarsest) and textures.
fn species_out(dir: &Path, m: &Manifest, s: usize, out: &Path, report: &mut ExportReport) -> Result<SpeciesOut> {
    let entry = &m.species[s];
    let path = dir.join(&entry.pack);
    let bytes = sylva::paths::read_regular(&path, None, sylva::paths::MAX_SCENE_FILE_BYTES)
        .with_context(|| format!("cannot read pack {}", path.display()))?;
    let pack = decode_pack(&path.display().to_string(), &bytes)?;
    let meta = pack.meta.clone();
    if meta.mesh_levels.is_empty() {
        bail!("{}: the pack has no mesh level to export", path.display());
    }
    let stem: String = format!("{s}_{}", entry.name)
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() || c == '_' { c } else { '-' })
        .collect();
    let mut levels = BTreeMap::new();
    let coarsest = meta.mesh_levels.len() as u32 - 1;
    for level in [0, coarsest] {
        if let std::collections::btree_map::Entry::Vacant(e) = levels.entry(level) {
            e.insert(mesh_bin(&pack, level, &format!("{stem}_mesh{level}"), out, report)?);
        }
    }
    let mut layers = BTreeMap::new();
    if let (Some(t), Some(data)) = (&meta.material_texture, pack.section(kind::MATERIAL_TEXTURES, 0)) {
        for layer in meta.materials.iter().filter_map(|mat| mat.texture_layer) {
            if layers.contains_key(&layer) {
                continue;
            }
            let png = layer_png(data, t.size, layer, &path.display().to_string())?;
            let uri = format!("meshes/{stem}_layer{layer}.png");
            write_file(&out.join(&uri), &png, report)?;
            layers.insert(layer, uri);
        }
    }
    // The far quads show the billboard seen level (elevation 0, azimuth 0: layer 0).
    let mut billboard = None;
    if let (Some(bb), Some(data)) = (&meta.billboards, pack.section(kind::BILLBOARD_COLOR, 0)) {
        let png = layer_png(data, bb.texture.size, 0, &format!("{}'s billboards", path.display()))?;
        let uri = format!("meshes/{stem}_billboard.png");
        write_file(&out.join(&uri), &png, report)?;
        billboard = Some(uri);
        levels.insert(FAR, far_bin(bb, &format!("{stem}_far"), out, report)?);
    }
    Ok(SpeciesOut { meta, levels, layers, billboard })
}

/// A glTF document being built: arrays by name, and the GLB's own binary chunk.
#[derive(Default)]
struct Gltf {
    arrays: BTreeMap<&'static str, Vec<Value>>,
    bin: Vec<u8>,
    /// Top-level extensions (`EXT_structural_metadata`).
    extensions: serde_json::Map<String, Value>,
}

impl Gltf {
    fn push(&mut self, array: &'static str, v: Value) -> usize {
        let a = self.arrays.entry(array).or_default();
        a.push(v);
        a.len() - 1
    }

    /// A texture of the shared image `uri` (relative to the tileset): sampled
    /// linearly with trilinear mips, or (`mips` false) without mips — an
    /// alpha-tested billboard's mips average its sparse leaves' coverage below
    /// the cutoff, and a far tree would vanish; repeated, or (`clamp`) clamped
    /// to its edges (a ground image: its edge must not blend with the opposite one).
    fn texture(&mut self, uri: &str, mips: bool, clamp: bool) -> usize {
        let image = self.push("images", json!({"uri": format!("../{uri}")}));
        let min_filter = if mips { 9987 } else { 9729 };
        let wrap = if clamp { 33071 } else { 10497 };
        let samplers = self.arrays.get("samplers").map_or(&[][..], |v| &v[..]);
        let sampler = match samplers.iter().position(|v| v["minFilter"] == min_filter && v["wrapS"] == wrap) {
            Some(i) => i,
            None => {
                self.push("samplers", json!({"magFilter": 9729, "minFilter": min_filter, "wrapS": wrap, "wrapT": wrap}))
            }
        };
        self.push("textures", json!({"source": image, "sampler": sampler}))
    }

    /// Appends `data` to the GLB's chunk as a buffer view (8-byte aligned, as
    /// 64-bit metadata values need).
    fn own_view(&mut self, data: &[u8]) -> usize {
        while !self.bin.len().is_multiple_of(8) {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(data);
        self.push("bufferViews", json!({"buffer": 0, "byteOffset": offset, "byteLength": data.len()}))
    }

    /// The GLB: header, JSON chunk (space-padded), binary chunk (zero-padded).
    fn glb(mut self, used: &[&str], required: &[&str]) -> Vec<u8> {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let mut doc = json!({
            "asset": {"version": "2.0", "generator": "sylva-bake export-3dtiles"},
            "scene": 0,
            "extensionsUsed": used,
        });
        if !required.is_empty() {
            doc["extensionsRequired"] = json!(required);
        }
        if !self.extensions.is_empty() {
            doc["extensions"] = Value::Object(std::mem::take(&mut self.extensions));
        }
        let mut buffers = vec![json!({"byteLength": self.bin.len()})];
        buffers.extend(self.arrays.remove("buffers").unwrap_or_default());
        doc["buffers"] = Value::Array(buffers);
        for (k, v) in self.arrays {
            doc[k] = Value::Array(v);
        }
        let mut js = serde_json::to_vec(&doc).expect("JSON");
        while !js.len().is_multiple_of(4) {
            js.push(b' ');
        }
        let total = 12 + 8 + js.len() + 8 + self.bin.len();
        let mut out = Vec::with_capacity(total);
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(js.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&js);
        out.extend_from_slice(&(self.bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&self.bin);
        out
    }
}

/// Adds species `sp`'s mesh level `level` (its shared buffer, materials,
/// textures) to `g`; returns the mesh index.
fn add_mesh(g: &mut Gltf, sp: &SpeciesOut, level: u32) -> usize {
    let mb = &sp.levels[&level];
    let buffer = g.push("buffers", json!({"uri": format!("../{}", mb.uri), "byteLength": mb.bytes})) + 1;
    let view = |g: &mut Gltf, k: usize, target: u32| {
        let (o, l) = mb.views[k];
        g.push("bufferViews", json!({"buffer": buffer, "byteOffset": o, "byteLength": l, "target": target}))
    };
    let (vp, vn, vu, vc, vi) =
        (view(g, 0, 34962), view(g, 1, 34962), view(g, 2, 34962), view(g, 3, 34962), view(g, 4, 34963));
    let n = mb.vertices;
    let pos = g.push(
        "accessors",
        json!({"bufferView": vp, "componentType": 5126, "count": n, "type": "VEC3", "min": mb.pos_min, "max": mb.pos_max}),
    );
    let nrm = g.push("accessors", json!({"bufferView": vn, "componentType": 5126, "count": n, "type": "VEC3"}));
    let uv = g.push("accessors", json!({"bufferView": vu, "componentType": 5126, "count": n, "type": "VEC2"}));
    let col = g.push(
        "accessors",
        json!({"bufferView": vc, "componentType": 5121, "normalized": true, "count": n, "type": "VEC4"}),
    );
    let mut materials: BTreeMap<usize, usize> = BTreeMap::new();
    let mut primitives = Vec::new();
    for &(mat, first, count) in &mb.draws {
        if count == 0 {
            continue;
        }
        let material = *materials.entry(mat).or_insert_with(|| {
            if level == FAR {
                return far_material(g, sp);
            }
            let m = &sp.meta.materials[mat];
            let mut pbr = json!({"baseColorFactor": m.base_color, "metallicFactor": 0.0, "roughnessFactor": 1.0});
            if let Some(uri) = m.texture_layer.and_then(|l| sp.layers.get(&l)) {
                pbr["baseColorTexture"] = json!({"index": g.texture(uri, true, false)});
            }
            let mut v = json!({"name": m.name, "pbrMetallicRoughness": pbr, "doubleSided": m.double_sided});
            if m.alpha_cutoff > 0.0 {
                v["alphaMode"] = json!("MASK");
                v["alphaCutoff"] = json!(m.alpha_cutoff);
            }
            g.push("materials", v)
        });
        let idx = g.push(
            "accessors",
            json!({"bufferView": vi, "byteOffset": u64::from(first) * 4, "componentType": 5125, "count": count, "type": "SCALAR"}),
        );
        primitives.push(json!({
            "attributes": {"POSITION": pos, "NORMAL": nrm, "TEXCOORD_0": uv, "COLOR_0": col},
            "indices": idx,
            "material": material,
        }));
    }
    g.push("meshes", json!({"name": sp.meta.name, "primitives": primitives}))
}

/// The far quads' material: the species' billboard, alpha-tested at ½ as
/// Sylva's viewer tests it, both faces, unlit colour × the sun's light.
fn far_material(g: &mut Gltf, sp: &SpeciesOut) -> usize {
    let mut pbr = json!({"baseColorFactor": [1.0, 1.0, 1.0, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0});
    if let Some(uri) = &sp.billboard {
        pbr["baseColorTexture"] = json!({"index": g.texture(uri, false, false)});
    }
    g.push(
        "materials",
        json!({
            "name": format!("{} far", sp.meta.name),
            "pbrMetallicRoughness": pbr,
            "doubleSided": true,
            "alphaMode": "MASK",
            "alphaCutoff": 0.5,
        }),
    )
}

/// A tile's trees by species, placed in the tile's frame.
type Placed = BTreeMap<u32, Vec<ExportedTree>>;

/// What the property table says of a tile's trees: ids, and the inventory's
/// attributes where the scene has them.
struct TreeData<'a> {
    ids: Vec<u64>,
    /// Text ids of the trees that have one (`.ids` version 2), by tile index.
    texts: Vec<(u32, String)>,
    codes: Option<(&'a sylva::format::attributes::AttributeSchema, sylva::format::attributes::AttributeCodes)>,
    /// Species model names (the `model` property).
    models: Vec<&'a str>,
    /// Property names of the attribute columns (identifiers, unique).
    names: &'a [String],
}

/// Property identifiers for the attribute columns: `[A-Za-z_][A-Za-z0-9_]*`,
/// unique, none of them `id`, `id_text` or `model`.
fn property_names(schema: Option<&sylva::format::attributes::AttributeSchema>) -> Vec<String> {
    let mut taken: std::collections::BTreeSet<String> =
        ["id".to_string(), "id_text".to_string(), "model".to_string()].into();
    let mut out = Vec::new();
    for c in schema.map_or(&[][..], |s| &s.columns[..]) {
        let mut base: String = c.name.chars().map(|ch| if ch.is_ascii_alphanumeric() { ch } else { '_' }).collect();
        if base.is_empty() || base.starts_with(|ch: char| ch.is_ascii_digit()) {
            base.insert(0, '_');
        }
        let mut name = base.clone();
        let mut k = 2;
        while !taken.insert(name.clone()) {
            name = format!("{base}_{k}");
            k += 1;
        }
        out.push(name);
    }
    out
}

/// `EXT_structural_metadata`'s schema: one class, `tree`.
fn metadata_schema(schema: Option<&sylva::format::attributes::AttributeSchema>, names: &[String]) -> Value {
    use sylva::format::attributes::AttributeType;
    let mut props = serde_json::Map::new();
    props.insert("id".into(), json!({"type": "SCALAR", "componentType": "UINT64", "description": "the tree's id"}));
    props.insert(
        "id_text".into(),
        json!({"type": "STRING", "noData": "", "description": "the tree's id as its inventory wrote it, where that is text (then `id` is 2^63 + its row); in the tiles that have such trees"}),
    );
    props.insert("model".into(), json!({"type": "STRING", "description": "the species model it is drawn with"}));
    for (c, name) in schema.map_or(&[][..], |s| &s.columns[..]).iter().zip(names) {
        let p = match c.kind {
            AttributeType::Number => json!({"type": "SCALAR", "componentType": "FLOAT64", "noData": NO_NUMBER}),
            AttributeType::Integer => json!({"type": "SCALAR", "componentType": "INT64", "noData": i64::MIN}),
            AttributeType::Category | AttributeType::Date => json!({"type": "STRING", "noData": ""}),
        };
        let mut p = p;
        p["name"] = json!(c.name);
        props.insert(name.clone(), p);
    }
    json!({"id": "sylva", "classes": {"tree": {"name": "Tree", "properties": props}}})
}

/// The `noData` of number attributes (a tree without a value).
const NO_NUMBER: f64 = -1.0e300;

/// A property table of `rows` (tile indices, GLB order) in `g`.
fn property_table(g: &mut Gltf, data: &TreeData<'_>, placed: &Placed, rows: &[u32]) -> Value {
    use sylva::format::attributes::AttributeValue;
    let mut props = serde_json::Map::new();
    let ids: Vec<u64> = rows.iter().map(|&i| data.ids.get(i as usize).copied().unwrap_or(0)).collect();
    let v = g.own_view(bytemuck::cast_slice(&ids));
    props.insert("id".into(), json!({"values": v}));
    let strings = |g: &mut Gltf, texts: &mut dyn Iterator<Item = String>| {
        let (mut bytes, mut offsets) = (Vec::new(), vec![0u32]);
        for t in texts {
            bytes.extend_from_slice(t.as_bytes());
            offsets.push(bytes.len() as u32);
        }
        let values = g.own_view(&bytes);
        let offsets = g.own_view(bytemuck::cast_slice(&offsets));
        json!({"values": values, "stringOffsets": offsets, "stringOffsetType": "UINT32"})
    };
    let models: Vec<String> = placed
        .iter()
        .flat_map(|(&s, trees)| std::iter::repeat_n(data.models[s as usize].to_string(), trees.len()))
        .collect();
    props.insert("model".into(), strings(g, &mut models.into_iter()));
    if !data.texts.is_empty() {
        let text = |i: u32| data.texts.binary_search_by_key(&i, |(k, _)| *k).map_or("", |k| data.texts[k].1.as_str());
        props.insert("id_text".into(), strings(g, &mut rows.iter().map(|&i| text(i).to_string())));
    }
    if let Some((schema, codes)) = &data.codes {
        for (c, name) in data.names.iter().enumerate() {
            let value = |i: u32| codes.value(schema, c, i as usize);
            let p = match schema.columns[c].kind {
                sylva::format::attributes::AttributeType::Number => {
                    let vals: Vec<f64> = rows
                        .iter()
                        .map(|&i| match value(i) {
                            Some(AttributeValue::Number(x)) => x,
                            _ => NO_NUMBER,
                        })
                        .collect();
                    json!({"values": g.own_view(bytemuck::cast_slice(&vals))})
                }
                sylva::format::attributes::AttributeType::Integer => {
                    let vals: Vec<i64> = rows
                        .iter()
                        .map(|&i| match value(i) {
                            Some(AttributeValue::Integer(x)) => x,
                            _ => i64::MIN,
                        })
                        .collect();
                    json!({"values": g.own_view(bytemuck::cast_slice(&vals))})
                }
                _ => strings(
                    g,
                    &mut rows.iter().map(|&i| {
                        value(i).map_or(String::new(), |v| v.to_json().as_str().map_or(String::new(), str::to_string))
                    }),
                ),
            };
            props.insert(name.clone(), p);
        }
    }
    json!({"class": "tree", "count": rows.len(), "properties": props})
}

/// The GLB of a tile's trees with each species' mesh level `level_of(species)`:
/// one node per species, its trees instances of its mesh, each a feature of
/// one property table (`EXT_instance_features`, `EXT_structural_metadata`).
fn tile_glb(
    species: &[SpeciesOut],
    placed: &Placed,
    data: &TreeData<'_>,
    meta_schema: &Value,
    level_of: &dyn Fn(&SpeciesOut) -> u32,
) -> Vec<u8> {
    let mut g = Gltf::default();
    let mut nodes = Vec::new();
    let mut rows: Vec<u32> = Vec::new();
    for (&s, trees) in placed {
        let sp = &species[s as usize];
        let mesh = add_mesh(&mut g, sp, level_of(sp));
        let t: Vec<[f32; 3]> = trees.iter().map(|t| t.translation).collect();
        let r: Vec<[f32; 4]> = trees.iter().map(|t| t.rotation).collect();
        let sc: Vec<[f32; 3]> = trees.iter().map(|t| t.scale).collect();
        // Feature ids: rows of the property table (exact in f32 below 2^24).
        let f: Vec<f32> = (rows.len()..rows.len() + trees.len()).map(|i| i as f32).collect();
        rows.extend(trees.iter().map(|t| t.index));
        let n = trees.len();
        let vt = g.own_view(bytemuck::cast_slice(&t));
        let vr = g.own_view(bytemuck::cast_slice(&r));
        let vs = g.own_view(bytemuck::cast_slice(&sc));
        let vf = g.own_view(bytemuck::cast_slice(&f));
        let at = g.push("accessors", json!({"bufferView": vt, "componentType": 5126, "count": n, "type": "VEC3"}));
        let ar = g.push("accessors", json!({"bufferView": vr, "componentType": 5126, "count": n, "type": "VEC4"}));
        let asc = g.push("accessors", json!({"bufferView": vs, "componentType": 5126, "count": n, "type": "VEC3"}));
        let af = g.push("accessors", json!({"bufferView": vf, "componentType": 5126, "count": n, "type": "SCALAR"}));
        nodes.push(g.push(
            "nodes",
            json!({
                "name": sp.meta.name,
                "mesh": mesh,
                "extensions": {
                    "EXT_mesh_gpu_instancing": {
                        "attributes": {"TRANSLATION": at, "ROTATION": ar, "SCALE": asc, "_FEATURE_ID_0": af},
                    },
                    "EXT_instance_features": {
                        "featureIds": [{"featureCount": n, "attribute": 0, "propertyTable": 0, "label": "tree"}],
                    },
                },
            }),
        ));
    }
    let table = property_table(&mut g, data, placed, &rows);
    g.extensions.insert("EXT_structural_metadata".into(), json!({"schema": meta_schema, "propertyTables": [table]}));
    g.push("scenes", json!({"nodes": nodes}));
    g.glb(
        &["EXT_mesh_gpu_instancing", "EXT_instance_features", "EXT_structural_metadata"],
        &["EXT_mesh_gpu_instancing"],
    )
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
fn export_tile(ctx: &Ctx<'_>, entry: &TileEntry, report: &mut ExportReport) -> Result<TileNode> {
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
    Ok(TileNode { json, bounds, tallest_m: tallest })
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
        children.push(export_tile(ctx, t, report)?);
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
    let species: Vec<SpeciesOut> =
        (0..m.species.len()).map(|s| species_out(dir, m, s, out, &mut report)).collect::<Result<_>>()?;
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
            children.push(export_tile(&ctx, t, &mut report)?);
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
mod tests {
    use super::*;

    fn fixture() -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/forest-small")
    }

    /// The JSON chunk and binary chunk of a GLB.
    fn glb_parts(bytes: &[u8]) -> (Value, Vec<u8>) {
        assert_eq!(&bytes[0..4], b"glTF");
        assert_eq!(u32::from_le_bytes(bytes[8..12].try_into().unwrap()) as usize, bytes.len());
        let jlen = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
        assert_eq!(&bytes[16..20], b"JSON");
        let doc: Value = serde_json::from_slice(&bytes[20..20 + jlen]).unwrap();
        let at = 20 + jlen;
        let blen = u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
        assert_eq!(&bytes[at + 4..at + 8], b"BIN\0");
        (doc, bytes[at + 8..at + 8 + blen].to_vec())
    }

    /// The floats of accessor `a` (in the GLB's own chunk).
    fn floats(doc: &Value, bin: &[u8], a: u64) -> Vec<f32> {
        let acc = &doc["accessors"][a as usize];
        let view = &doc["bufferViews"][acc["bufferView"].as_u64().unwrap() as usize];
        assert_eq!(view["buffer"], 0, "instance data lies in the GLB");
        let per = match acc["type"].as_str().unwrap() {
            "SCALAR" => 1,
            "VEC2" => 2,
            "VEC3" => 3,
            "VEC4" => 4,
            t => panic!("{t}"),
        };
        let start = view["byteOffset"].as_u64().unwrap() as usize;
        let n = acc["count"].as_u64().unwrap() as usize * per;
        bytemuck::pod_collect_to_vec(&bin[start..start + n * 4])
    }

    #[test]
    fn wgs84_round_trips() {
        for (lon, lat, h) in [(15.0, 52.0, 100.0), (-120.5, 37.1, 2000.0), (4.9, 52.37, -3.0), (170.0, -45.0, 0.0)] {
            let (lo, la, hh) = ecef_to_geodetic(geodetic_to_ecef(lon, lat, h));
            assert!((lo - lon).abs() < 1e-9 && (la - lat).abs() < 1e-9 && (hh - h).abs() < 1e-4, "{lon} {lat} {h}");
        }
        // The frame is orthonormal and up is away from the centre.
        let [o, e, n, u] = enu_frame(15.0, 52.0, 0.0);
        assert!(e.dot(n).abs() < 1e-12 && e.dot(u).abs() < 1e-12 && n.dot(u).abs() < 1e-12);
        assert!((e.cross(n) - u).length() < 1e-12 && u.dot(o) > 0.0);
    }

    /// Every exported instance maps back to its tree within a centimetre, with
    /// its yaw and scale; the tileset's hierarchy holds every tile once.
    /// The fixture exported with heights 30 m up (the geoid's undulation a
    /// portal would add) into a fresh temporary folder named after `name`:
    /// (the folder, the report, the fixture's manifest and geographic frame).
    fn export_fixture(name: &str) -> (std::path::PathBuf, ExportReport, Manifest, GeoFrame) {
        let out = std::env::temp_dir().join(format!("sylva-3dtiles-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&out);
        let report = export(&fixture(), &out, OFFSET_30, &mut |_| {}).unwrap();
        let m = Manifest::decode("m", &std::fs::read(fixture().join("scene.json")).unwrap()).unwrap();
        let geo = GeoFrame::new(&m.crs.proj4, m.origin_m).unwrap();
        (out, report, m, geo)
    }

    const OFFSET_30: ExportOptions = ExportOptions { ground: true, height_offset_m: 30.0 };

    #[test]
    fn every_exported_tree_maps_back_to_its_tree_within_a_centimetre() {
        let dir = fixture();
        let (out, report, m, geo) = export_fixture("trees");
        assert_eq!(report.trees, m.counts.trees);
        assert_eq!(report.tiles as u64, m.counts.tiles);
        let tileset: Value = serde_json::from_slice(&std::fs::read(out.join("tileset.json")).unwrap()).unwrap();
        assert_eq!(tileset["asset"]["version"], "1.1");
        // Walk the tileset: each tile's transform and its full GLB.
        let mut stack = vec![tileset["root"].clone()];
        let (mut worst, mut checked, mut tiles) = (0.0f64, 0u64, 0);
        while let Some(node) = stack.pop() {
            let r: Vec<f64> =
                node["boundingVolume"]["region"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
            assert!(r[0] < r[2] && r[1] < r[3] && r[4] < r[5], "a region: {r:?}");
            if let Some(c) = node["children"].as_array() {
                stack.extend(c.iter().cloned());
            }
            let Some(t) = node["transform"].as_array() else { continue };
            if node["content"]["uri"].as_str().is_some_and(|u| u.starts_with("ground/")) {
                continue;
            }
            tiles += 1;
            let t: Vec<f64> = t.iter().map(|v| v.as_f64().unwrap()).collect();
            let frame = [
                DVec3::new(t[12], t[13], t[14]),
                DVec3::new(t[0], t[1], t[2]),
                DVec3::new(t[4], t[5], t[6]),
                DVec3::new(t[8], t[9], t[10]),
            ];
            // The tiers: far quads, (coarse meshes,) full meshes, each refining the one before.
            let mut tiers = vec![node.clone()];
            while let Some(c) = tiers.last().unwrap()["children"].get(0).cloned() {
                tiers.push(c);
            }
            let uris: Vec<&str> = tiers.iter().map(|t| t["content"]["uri"].as_str().unwrap()).collect();
            assert!(uris.len() >= 2 && uris[0].ends_with("_far.glb"), "{uris:?}");
            assert!(uris.len() == 2 || uris[1].ends_with("_coarse.glb"), "{uris:?}");
            let errors: Vec<f64> = tiers.iter().map(|t| t["geometricError"].as_f64().unwrap()).collect();
            assert!(errors.windows(2).all(|e| e[0] > e[1]) && errors[errors.len() - 1] == 0.0, "{errors:?}");
            let full = *uris.last().unwrap();
            let name = full.trim_start_matches("tiles/").trim_end_matches(".glb");
            let tile_path = dir.join(format!("tiles/{name}.tile"));
            let tile = Tile::decode("t", &std::fs::read(&tile_path).unwrap(), 3).unwrap();
            let ids_path = dir.join(format!("tiles/{name}.ids"));
            let ids = sylva::format::decode_ids("i", &std::fs::read(&ids_path).unwrap()).unwrap();
            // The far tier: the same trees in the same rows, each two crossed
            // quads with its species' billboard, alpha-tested, both faces.
            let (far, far_bin) = glb_parts(&std::fs::read(out.join(uris[0])).unwrap());
            let far_rows = &far["extensions"]["EXT_structural_metadata"]["propertyTables"][0]["count"];
            assert_eq!(far_rows.as_u64().unwrap() as usize, tile.instances.len());
            for mesh in far["meshes"].as_array().unwrap() {
                let prim = &mesh["primitives"][0];
                assert_eq!(far["accessors"][prim["attributes"]["POSITION"].as_u64().unwrap() as usize]["count"], 8);
                assert_eq!(far["accessors"][prim["indices"].as_u64().unwrap() as usize]["count"], 12);
                let mat = &far["materials"][prim["material"].as_u64().unwrap() as usize];
                assert_eq!((mat["alphaMode"].as_str(), mat["doubleSided"].as_bool()), (Some("MASK"), Some(true)));
                let tex = mat["pbrMetallicRoughness"]["baseColorTexture"]["index"].as_u64().unwrap() as usize;
                // Sampled without mips (mips of sparse leaves fall under the cutoff).
                let sampler = &far["samplers"][far["textures"][tex]["sampler"].as_u64().unwrap() as usize];
                assert_eq!(sampler["minFilter"], 9729);
                let img =
                    far["images"][far["textures"][tex]["source"].as_u64().unwrap() as usize]["uri"].as_str().unwrap();
                let png = image::open(out.join("tiles").join(img)).unwrap().to_rgba8();
                let covered =
                    png.pixels().filter(|p| p[3] >= 128).count() as f64 / f64::from(png.width() * png.height());
                assert!(covered > 0.1 && covered < 0.95, "{img}: {covered} of the billboard is the tree");
            }
            let far_ids: Vec<u64> = {
                let t = &far["extensions"]["EXT_structural_metadata"]["propertyTables"][0];
                let view = &far["bufferViews"][t["properties"]["id"]["values"].as_u64().unwrap() as usize];
                let start = view["byteOffset"].as_u64().unwrap() as usize;
                bytemuck::pod_collect_to_vec(&far_bin[start..start + 8 * tile.instances.len()])
            };
            let (doc, bin) = glb_parts(&std::fs::read(out.join(full)).unwrap());
            assert_eq!(doc["extensionsRequired"][0], "EXT_mesh_gpu_instancing");
            // The property table: a row per tree in GLB order, its id the tree's.
            let table = &doc["extensions"]["EXT_structural_metadata"]["propertyTables"][0];
            let view = &doc["bufferViews"][table["properties"]["id"]["values"].as_u64().unwrap() as usize];
            let start = view["byteOffset"].as_u64().unwrap() as usize;
            assert_eq!(start % 8, 0, "64-bit values aligned");
            let table_ids: Vec<u64> = bytemuck::pod_collect_to_vec(&bin[start..start + 8 * ids.len()]);
            assert_eq!(far_ids, table_ids, "the far tier's rows are the full tier's");
            assert_eq!(table["count"].as_u64().unwrap() as usize, ids.len());
            let mut exported: Vec<(String, DVec3, f32, f32)> = Vec::new();
            for n in doc["nodes"].as_array().unwrap() {
                let a = &n["extensions"]["EXT_mesh_gpu_instancing"]["attributes"];
                let tr = floats(&doc, &bin, a["TRANSLATION"].as_u64().unwrap());
                let ro = floats(&doc, &bin, a["ROTATION"].as_u64().unwrap());
                let sc = floats(&doc, &bin, a["SCALE"].as_u64().unwrap());
                for k in 0..tr.len() / 3 {
                    let p = unplace(&geo, &frame, [tr[3 * k], tr[3 * k + 1], tr[3 * k + 2]]).unwrap();
                    let yaw = 2.0 * ro[4 * k + 1].atan2(ro[4 * k + 3]);
                    exported.push((n["name"].as_str().unwrap().to_string(), p, yaw, sc[3 * k + 1]));
                }
            }
            let mut at = 0;
            let mut k = 0;
            // Trees come species after species in the GLB, batch order within each.
            let mut by_species: BTreeMap<u32, Vec<(usize, sylva::format::tile::Instance)>> = BTreeMap::new();
            for b in &tile.batches {
                for (j, p) in tile.instances[at..at + b.instance_count as usize].iter().enumerate() {
                    by_species.entry(b.species).or_default().push((at + j, p.decode(b)));
                }
                at += b.instance_count as usize;
            }
            for (s, trees) in &by_species {
                for (index, i) in trees {
                    assert_eq!(table_ids[k], ids[*index], "row {k} is tree {index}");
                    let (name, p, _yaw, scale) = &exported[k];
                    assert_eq!(name, &m.species[*s as usize].name);
                    let want =
                        DVec3::new(i.position_m[0].into(), i.position_m[1].into(), f64::from(i.position_m[2]) + 30.0);
                    worst = worst.max((*p - want).length());
                    assert!((scale - i.scale).abs() < 1e-5);
                    k += 1;
                    checked += 1;
                }
            }
            assert_eq!(k, exported.len());
        }
        assert_eq!(tiles, m.counts.tiles);
        assert_eq!(checked, m.counts.trees);
        assert!(worst < 0.01, "an exported tree is {worst} m from its tree");
        // Nothing is overwritten: a second export into the same folder is refused.
        let again = export(&dir, &out, ExportOptions::default(), &mut |_| {}).unwrap_err().to_string();
        assert!(again.contains("not empty"), "{again}");
        std::fs::remove_dir_all(&out).unwrap();
    }

    #[test]
    fn a_failed_export_leaves_nothing_behind_and_the_retry_works() {
        let base = std::env::temp_dir().join(format!("sylva-3dtiles-failed-{}", std::process::id()));
        let scene = base.join("scene");
        std::fs::create_dir_all(&base).unwrap();
        assert!(std::process::Command::new("cp").arg("-r").arg(fixture()).arg(&scene).status().unwrap().success());
        // The last tile in the index's order corrupt: the export fails after writing others.
        let m = Manifest::decode("m", &std::fs::read(scene.join("scene.json")).unwrap()).unwrap();
        let tiles = sylva::format::index::read_all_tiles(&scene, &m).unwrap();
        let last = scene.join(&tiles.last().unwrap().url);
        let good = std::fs::read(&last).unwrap();
        std::fs::write(&last, b"not a tile").unwrap();
        for existed in [false, true] {
            let out = base.join(format!("out-{existed}"));
            if existed {
                std::fs::create_dir_all(&out).unwrap();
            }
            let e = export(&scene, &out, ExportOptions::default(), &mut |_| {}).unwrap_err();
            assert!(format!("{e:#}").contains(last.file_name().unwrap().to_str().unwrap()), "{e:#}");
            assert_eq!(out.exists(), existed, "a new folder goes, an empty one stays");
            if existed {
                assert_eq!(std::fs::read_dir(&out).unwrap().count(), 0, "the empty folder is empty again");
            }
        }
        std::fs::write(&last, good).unwrap();
        export(&scene, &base.join("out-true"), ExportOptions::default(), &mut |_| {}).unwrap();
        // A dangling link, or a file, as --out: said so.
        let link = base.join("dangling");
        std::os::unix::fs::symlink(base.join("nowhere"), &link).unwrap();
        let e = export(&scene, &link, ExportOptions::default(), &mut |_| {}).unwrap_err().to_string();
        assert!(e.contains("symbolic link to a folder that does not exist"), "{e}");
        let file = base.join("file");
        std::fs::write(&file, "x").unwrap();
        let e = export(&scene, &file, ExportOptions::default(), &mut |_| {}).unwrap_err().to_string();
        assert!(e.contains("is not a folder"), "{e}");
        std::fs::remove_dir_all(&base).unwrap();
    }

    /// The ground: every terrain tile a GLB in the quadtree's hierarchy, each
    /// vertex on its grid point at the terrain's height (skirts below it) within
    /// a centimetre through the chained transforms, facing up, draped with its
    /// image's part; none with `ground: false`.
    #[test]
    fn the_ground_is_the_terrain_draped_with_its_images() {
        let dir = fixture();
        let (out, report, m, geo) = export_fixture("ground");
        let e = m.terrain.as_ref().unwrap();
        let options = OFFSET_30;
        assert_eq!(report.ground_tiles as u64, e.tiles);
        let images = std::fs::read_dir(out.join("ground/img")).unwrap().count() as u64;
        assert_eq!(images, e.imagery.as_ref().unwrap().tiles);
        let tileset: Value = serde_json::from_slice(&std::fs::read(out.join("tileset.json")).unwrap()).unwrap();
        let root = &tileset["root"];
        assert_eq!(root["refine"], "ADD", "the forest is added to the ground");
        let mat = |t: &Value| glam::DMat4::from_cols_array(&std::array::from_fn(|k| t[k].as_f64().unwrap()));
        let mut stack = vec![(root["children"][0].clone(), glam::DMat4::IDENTITY, f64::INFINITY)];
        let (mut worst, mut vertices, mut tiles, mut up, mut textured) = (0.0f64, 0, 0, 0, 0);
        let (mut want_vertices, mut want_up) = (0, 0);
        while let Some((node, parent, parent_error)) = stack.pop() {
            let abs = parent * mat(&node["transform"]);
            let error = node["geometricError"].as_f64().unwrap();
            assert!(error <= parent_error, "a ground tile's error exceeds its parent's");
            for c in node["children"].as_array().into_iter().flatten() {
                stack.push((c.clone(), abs, error));
            }
            let uri = node["content"]["uri"].as_str().unwrap();
            let (l, x, y) = {
                let k: Vec<u32> = uri
                    .trim_start_matches("ground/")
                    .trim_end_matches(".glb")
                    .split('_')
                    .map(|v| v.parse().unwrap())
                    .collect();
                (k[0] as u8, k[1], k[2])
            };
            tiles += 1;
            let tile = sylva::format::terrain::TerrainTile::decode(
                "t",
                &std::fs::read(dir.join(e.tile_url(l, x, y))).unwrap(),
            )
            .unwrap();
            let (o, size) = (e.tile_origin_m(l, x, y), e.tile_size_m(l));
            let step = size / f64::from(tile.grid);
            let (doc, bin) = glb_parts(&std::fs::read(out.join(uri)).unwrap());
            assert_eq!(doc["extensionsUsed"][0], "KHR_materials_unlit");
            let prim = &doc["meshes"][0]["primitives"][0];
            let pos = floats(&doc, &bin, prim["attributes"]["POSITION"].as_u64().unwrap());
            // (UVs normalized u16, indices u16: a tile has fewer than 65,536 vertices.)
            let shorts = |a: u64| -> Vec<u16> {
                let acc = &doc["accessors"][a as usize];
                assert_eq!(acc["componentType"], 5123);
                let view = &doc["bufferViews"][acc["bufferView"].as_u64().unwrap() as usize];
                let start = view["byteOffset"].as_u64().unwrap() as usize;
                let per = if acc["type"] == "VEC2" { 2 } else { 1 };
                bytemuck::pod_collect_to_vec(&bin[start..start + 2 * per * acc["count"].as_u64().unwrap() as usize])
            };
            let uv: Vec<f32> = shorts(prim["attributes"]["TEXCOORD_0"].as_u64().unwrap())
                .iter()
                .map(|&v| f32::from(v) / 65535.0)
                .collect();
            let idx: Vec<u32> = shorts(prim["indices"].as_u64().unwrap()).iter().map(|&i| u32::from(i)).collect();
            let material = &doc["materials"][prim["material"].as_u64().unwrap() as usize];
            let image = material["pbrMetallicRoughness"]["baseColorTexture"]["index"].as_u64().map(|t| {
                let src = doc["textures"][t as usize]["source"].as_u64().unwrap() as usize;
                doc["images"][src]["uri"].as_str().unwrap().to_string()
            });
            // The scene point of each vertex, through the chain of transforms and WGS84.
            let scene: Vec<DVec3> = (0..pos.len() / 3)
                .map(|k| {
                    let enu = glam::DVec4::new(pos[3 * k].into(), (-pos[3 * k + 2]).into(), pos[3 * k + 1].into(), 1.0);
                    let (lon, lat, h) = ecef_to_geodetic((abs * enu).truncate());
                    geo.to_local(lon, lat, h).unwrap()
                })
                .collect();
            for (k, p) in scene.iter().enumerate() {
                let (fi, fj) = ((p.x - o[0]) / step, (p.y - o[1]) / step);
                let (i, j) = (fi.round() as usize, fj.round() as usize);
                worst = worst.max((fi - i as f64).abs().max((fj - j as f64).abs()) * step);
                let Some(h) = tile.height(i, j) else { continue };
                let h = f64::from(h) + 30.0;
                // On the terrain, or a skirt below it.
                let dz = p.z - h;
                assert!(dz.abs() < 0.01 || dz < -0.5, "{uri}: a vertex {dz} m off the terrain");
                if dz.abs() < 0.01 {
                    worst = worst.max(dz.abs());
                    vertices += 1;
                }
                if let Some(img) = &image {
                    let k2: Vec<u32> = img
                        .trim_start_matches("../ground/img/")
                        .trim_end_matches(".jpg")
                        .split('_')
                        .map(|v| v.parse().unwrap())
                        .collect();
                    let (io, is) = (e.tile_origin_m(k2[0] as u8, k2[1], k2[2]), e.tile_size_m(k2[0] as u8));
                    assert!(k2[0] as u8 <= l, "an image from a finer level");
                    let want = [(p.x - io[0]) / is, 1.0 - (p.y - io[1]) / is];
                    assert!((f64::from(uv[2 * k]) - want[0]).abs() < 1e-4, "{uri}: u");
                    assert!((f64::from(uv[2 * k + 1]) - want[1]).abs() < 1e-4, "{uri}: v");
                }
            }
            textured += usize::from(image.is_some());
            // Its own image where it has one, else its nearest ancestor's.
            let mut want = (l, x, y);
            while !e.has_imagery(want.0, want.1, want.2) && want.0 > 0 {
                want = (want.0 - 1, want.1 / 2, want.2 / 2);
            }
            let want = e
                .has_imagery(want.0, want.1, want.2)
                .then(|| format!("../ground/img/{}_{}_{}.jpg", want.0, want.1, want.2));
            assert_eq!(image, want, "{uri}: the image it drapes");
            // Clamped to its edges (a repeated image blends each edge with the opposite one).
            if let Some(t) = material["pbrMetallicRoughness"]["baseColorTexture"]["index"].as_u64() {
                let sampler = &doc["samplers"][doc["textures"][t as usize]["sampler"].as_u64().unwrap() as usize];
                assert_eq!((sampler["wrapS"].as_u64(), sampler["wrapT"].as_u64()), (Some(33071), Some(33071)));
            }
            // What the tile should give: its vertices with data, two triangles a cell of them.
            let n = tile.side();
            want_vertices += tile.heights.iter().filter(|&&q| q != sylva::format::terrain::TERRAIN_HOLE).count();
            for j in 0..n - 1 {
                for i in 0..n - 1 {
                    let cell = [(i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)];
                    want_up += 2 * usize::from(cell.iter().all(|&(i, j)| tile.height(i, j).is_some()));
                }
            }
            // Every triangle that is not a skirt faces up.
            for t in idx.chunks(3) {
                let [a, b, c] = [scene[t[0] as usize], scene[t[1] as usize], scene[t[2] as usize]];
                let n = (b - a).cross(c - a);
                if n.z.abs() > 0.1 * n.length() {
                    assert!(n.z > 0.0, "{uri}: a triangle faces down");
                    up += 1;
                }
            }
        }
        assert_eq!(tiles, e.tiles);
        assert!(want_vertices > 20_000 && want_up > 20_000, "a fixture without ground: {want_vertices}");
        assert_eq!(vertices, want_vertices, "the vertices on the terrain");
        assert_eq!(up, want_up, "the triangles facing up");
        assert!(textured > 0, "no ground tile draped with an image");
        assert!(worst < 0.01, "a ground vertex {worst} m off its grid point");
        std::fs::remove_dir_all(&out).unwrap();
        // Without the ground: the forest alone, no ground files.
        let report = export(&dir, &out, ExportOptions { ground: false, ..options }, &mut |_| {}).unwrap();
        assert_eq!(report.ground_tiles, 0);
        assert!(!out.join("ground").exists());
        let tileset: Value = serde_json::from_slice(&std::fs::read(out.join("tileset.json")).unwrap()).unwrap();
        assert_eq!(tileset["root"]["refine"], "REPLACE");
        std::fs::remove_dir_all(&out).unwrap();
        // A terrain tile that is all holes (a DEM touching it along an edge): left
        // out, and every region stays a region.
        let scene = std::env::temp_dir().join(format!("sylva-3dtiles-holes-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&scene);
        copy_dir(&dir, &scene);
        let path = scene.join(e.tile_url(2, 0, 0));
        let mut holes = sylva::format::terrain::TerrainTile::decode("t", &std::fs::read(&path).unwrap()).unwrap();
        holes.heights.fill(sylva::format::terrain::TERRAIN_HOLE);
        std::fs::write(&path, holes.encode()).unwrap();
        let report = export(&scene, &out, options, &mut |_| {}).unwrap();
        assert_eq!(report.ground_tiles as u64, e.tiles - 1);
        let text = std::fs::read_to_string(out.join("tileset.json")).unwrap();
        assert!(!text.contains("ground/2_0_0.glb"), "a tile without ground is exported");
        let tileset: Value = serde_json::from_str(&text).unwrap();
        let mut stack = vec![tileset["root"].clone()];
        while let Some(n) = stack.pop() {
            let r: Vec<f64> =
                n["boundingVolume"]["region"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
            assert!(r[0] < r[2] && r[1] < r[3] && r[4] < r[5] && r[2] - r[0] < 0.1, "a region: {r:?}");
            stack.extend(n["children"].as_array().into_iter().flatten().cloned());
        }
        std::fs::remove_dir_all(&out).unwrap();
        std::fs::remove_dir_all(&scene).unwrap();
    }

    /// An index node listed twice (a hostile or corrupt index) is refused, not
    /// read (and written) again.
    #[test]
    fn a_node_listed_twice_is_refused() {
        let dir = std::env::temp_dir().join(format!("sylva-3dtiles-twice-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        copy_dir(&fixture(), &dir.join("scene"));
        let root_path = dir.join("scene/index/r.json");
        let mut root: Value = serde_json::from_slice(&std::fs::read(&root_path).unwrap()).unwrap();
        root["children"][1] = root["children"][0].clone();
        let trees: u64 = root["children"].as_array().unwrap().iter().map(|c| c["trees"].as_u64().unwrap()).sum();
        root["trees"] = json!(trees);
        std::fs::write(&root_path, serde_json::to_vec(&root).unwrap()).unwrap();
        let e = export(&dir.join("scene"), &dir.join("out"), ExportOptions::default(), &mut |_| {})
            .unwrap_err()
            .to_string();
        assert!(e.contains("listed twice"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    fn copy_dir(from: &Path, to: &Path) {
        std::fs::create_dir_all(to).unwrap();
        for e in std::fs::read_dir(from).unwrap() {
            let e = e.unwrap();
            if e.file_type().unwrap().is_dir() {
                copy_dir(&e.path(), &to.join(e.file_name()));
            } else {
                std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
            }
        }
    }

    /// The tree's yaw survives (grid convergence corrected, so within a degree of the grid's here).
    #[test]
    fn yaw_follows_the_grid_through_the_frame() {
        let geo =
            GeoFrame::new("+proj=utm +zone=33 +datum=WGS84 +units=m +no_defs", [500_000.0, 5_800_000.0, 0.0]).unwrap();
        let (lon, lat, h) = geo.to_geo(DVec3::ZERO).unwrap();
        let f = enu_frame(lon, lat, h);
        for yaw in [0.0f64, 0.7, 2.0, 4.5] {
            let t = place(&geo, &f, DVec3::new(30.0, -20.0, 5.0), yaw, 1.0, 1.0).unwrap();
            let got = 2.0 * f64::from(t.rotation[1]).atan2(f64::from(t.rotation[3]));
            let d = (got - yaw).rem_euclid(std::f64::consts::TAU);
            assert!(d.min(std::f64::consts::TAU - d) < 0.01, "yaw {yaw} -> {got}");
        }
    }
}
