//! The ground of a 3D Tiles export: the scene's terrain quadtree as tiles of
//! textured triangle meshes (`ground/L_X_Y.glb`), each draped with its ground
//! image (or its nearest ancestor's), refining as Sylva's viewer refines its
//! terrain (`docs/FORMAT.md`, "3D Tiles export").

use gltf::json::accessor::{ComponentType, Type};
use gltf::json::buffer::Target;
use gltf::json::mesh::Semantic;
use std::path::Path;

use anyhow::{bail, Context, Result};
use glam::{DMat4, DVec3};
use serde_json::{json, Value};
use sylva::format::terrain::{TerrainEntry, TerrainTile, IMAGERY_PX};
use sylva::format::{Bounds, Manifest};
use sylva::geo::GeoFrame;

use super::{enu_frame, geodetic_to_ecef, region, write_file, Elements, ExportReport, Gltf, Look, SSE_PX};

/// Pixels of height error (or of a ground image's texel) at which Sylva's
/// viewer refines its terrain (`StreamConfig::terrain_error_px`): a tile's
/// geometric error is scaled from its metres by [`SSE_PX`] / this.
const TERRAIN_PX: f64 = 2.0;
/// The colour of ground without imagery (linear RGB): the viewer's forest-floor litter.
const LITTER: [f32; 4] = [0.17, 0.155, 0.09, 1.0];

/// What the ground's export reads.
pub(super) struct Ground<'a> {
    pub dir: &'a Path,
    pub m: &'a Manifest,
    pub geo: &'a GeoFrame,
    pub out: &'a Path,
    /// Metres added to every height (`--height-offset`).
    pub height_offset_m: f64,
}

/// A terrain tile's (level, column, row from the south).
type Key = (u8, u32, u32);

impl Ground<'_> {
    fn entry(&self) -> &TerrainEntry {
        self.m.terrain.as_ref().expect("ground export without terrain")
    }

    /// The ground as a tileset node (the terrain's root tile and everything
    /// below it), or None for a scene without terrain.
    pub fn export(&self, report: &mut ExportReport, progress: &mut dyn FnMut(&ExportReport)) -> Result<Option<Value>> {
        if self.m.terrain.is_none() {
            return Ok(None);
        }
        let root = self.read((0, 0, 0))?;
        // Skirts as deep as the largest error anywhere: the gap at an edge
        // between tiles of any two levels is at most the coarser one's error.
        let skirt_m = f64::from(root.error_m) + 1.0;
        self.tile(&root, None, skirt_m, report, progress)
    }

    fn read(&self, (level, x, y): Key) -> Result<TerrainTile> {
        let e = self.entry();
        let path = self.dir.join(e.tile_url(level, x, y));
        let bytes = sylva::paths::read_regular(&path, None, sylva::paths::MAX_SCENE_FILE_BYTES)
            .with_context(|| format!("cannot read terrain tile {}", path.display()))?;
        let t = TerrainTile::decode(&path.display().to_string(), &bytes)?;
        if (t.level, t.x, t.y) != (level, x, y) || t.grid != e.grid {
            bail!(
                "{}: the tile says it is ({}, {}, {}) of grid {}, not ({level}, {x}, {y}) of grid {}",
                path.display(),
                t.level,
                t.x,
                t.y,
                t.grid,
                e.grid
            );
        }
        Ok(t)
    }

    /// The tile that drapes its image over `key`: itself or its nearest
    /// ancestor with an image (None: no imagery there).
    fn image_of(&self, (mut level, mut x, mut y): Key) -> Option<Key> {
        let e = self.entry();
        loop {
            if e.has_imagery(level, x, y) {
                return Some((level, x, y));
            }
            if level == 0 {
                return None;
            }
            (level, x, y) = (level - 1, x / 2, y / 2);
        }
    }

    /// Copies the image of `key` into the export (checked as a ground image
    /// of the format's size) as `ground/img/L_X_Y.jpg`.
    fn copy_image(&self, (level, x, y): Key, report: &mut ExportReport) -> Result<()> {
        let imagery = self.entry().imagery.as_ref().expect("an image without imagery");
        let path = self.dir.join(imagery.tile_url(level, x, y));
        let bytes = sylva::paths::read_regular(&path, None, sylva::paths::MAX_SCENE_FILE_BYTES)
            .with_context(|| format!("cannot read ground image {}", path.display()))?;
        let img = sylva::format::imagery::decode_image(&path.display().to_string(), &bytes, IMAGERY_PX)?;
        if (img.width, img.height) != (IMAGERY_PX, IMAGERY_PX) {
            bail!("{}: {}×{} pixels, not {IMAGERY_PX}²", path.display(), img.width, img.height);
        }
        write_file(&self.out.join(format!("ground/img/{level}_{x}_{y}.jpg")), &bytes, report)
    }

    /// Exports `t` (its GLB, then its children's) as a tileset node whose
    /// transform is relative to `parent` (the absolute frame of the parent
    /// tile and its error in metres; None at the root); None for a tile
    /// with nothing to draw (every cell touches a hole) and no children.
    fn tile(
        &self,
        t: &TerrainTile,
        parent: Option<(&DMat4, f64)>,
        skirt_m: f64,
        report: &mut ExportReport,
        progress: &mut dyn FnMut(&ExportReport),
    ) -> Result<Option<Value>> {
        let e = self.entry();
        let key = (t.level, t.x, t.y);
        let (o, s) = (e.tile_origin_m(t.level, t.x, t.y), e.tile_size_m(t.level));
        let mid = DVec3::new(o[0] + s * 0.5, o[1] + s * 0.5, f64::from(t.min_m + t.max_m) * 0.5 + self.height_offset_m);
        let (lon, lat, h) = self.geo.to_geo(mid).map_err(|err| anyhow::anyhow!("terrain tile {key:?}: {err}"))?;
        let f = enu_frame(lon, lat, h);
        let abs = DMat4::from_cols(f[1].extend(0.0), f[2].extend(0.0), f[3].extend(0.0), f[0].extend(1.0));
        let rel = parent.map_or(abs, |(p, _)| p.inverse() * abs);
        if e.has_imagery(t.level, t.x, t.y) {
            self.copy_image(key, report)?;
        }
        let content = self.glb(t, &f, self.image_of(key), skirt_m)?;
        let mut node = json!({
            "boundingVolume": {"region": self.region(t, skirt_m)?},
            "transform": rel.to_cols_array(),
        });
        if let Some(bytes) = content {
            let uri = format!("ground/{}_{}_{}.glb", t.level, t.x, t.y);
            write_file(&self.out.join(&uri), &bytes, report)?;
            report.glbs += 1;
            report.ground_tiles += 1;
            node["content"] = json!({"uri": uri});
            progress(report);
        }
        // Refined, as the viewer refines, while its height error or (where its
        // children have images of their own) a texel of its image is above the
        // viewer's pixels; never more than its parent's (errors fall along
        // every path, whatever a corrupt tile says).
        let texel_m = if e.has_finer_imagery_below(t.level, t.x, t.y) { s / f64::from(IMAGERY_PX) } else { 0.0 };
        let error_m = f64::from(t.error_m).max(texel_m).min(parent.map_or(f64::INFINITY, |(_, e)| e));
        let mut children = Vec::new();
        // (An error of 0 is never refined: nothing below it would be shown.)
        if error_m > 0.0 {
            for (k, c) in t.children.iter().enumerate() {
                if c.exists && t.level + 1 < e.levels {
                    let ck = (t.level + 1, 2 * t.x + (k as u32 & 1), 2 * t.y + (k as u32 >> 1));
                    let child = self.read(ck)?;
                    children.extend(self.tile(&child, Some((&abs, error_m)), skirt_m, report, progress)?);
                }
            }
        }
        if node.get("content").is_none() && children.is_empty() {
            return Ok(None);
        }
        let error_m = if children.is_empty() { 0.0 } else { error_m };
        node["geometricError"] = json!(SSE_PX / TERRAIN_PX * error_m);
        if !children.is_empty() {
            node["refine"] = json!("REPLACE");
            node["children"] = Value::Array(children);
        }
        Ok(Some(node))
    }

    /// The tile's region: its square, its heights (and skirts).
    fn region(&self, t: &TerrainTile, skirt_m: f64) -> Result<Value> {
        let e = self.entry();
        let (o, s) = (e.tile_origin_m(t.level, t.x, t.y), e.tile_size_m(t.level));
        let b = Bounds {
            min: [o[0] as f32, o[1] as f32, t.min_m - skirt_m as f32],
            max: [(o[0] + s) as f32, (o[1] + s) as f32, t.max_m],
        };
        region(self.geo, &b, self.m.origin_m[2] + self.height_offset_m)
    }

    /// The tile's GLB: its grid in frame `f` (glTF y up), two triangles a
    /// cell split along its south-west–north-east diagonal as the viewer
    /// draws them, skirts down its edges, draped with `image`'s part over it;
    /// None where every vertex is a hole.
    fn glb(&self, t: &TerrainTile, f: &[DVec3; 4], image: Option<Key>, skirt_m: f64) -> Result<Option<Vec<u8>>> {
        let e = self.entry();
        let (o, s) = (e.tile_origin_m(t.level, t.x, t.y), e.tile_size_m(t.level));
        let n = t.side();
        let step = s / f64::from(t.grid);
        let (io, is) = match image {
            Some((l, x, y)) => (e.tile_origin_m(l, x, y), e.tile_size_m(l)),
            None => (o, s),
        };
        let mut pos: Vec<[f32; 3]> = Vec::with_capacity(n * n * 2);
        // (UVs as normalized u16, which core glTF allows: 1/65535 of an image
        // is 0.004 of its pixels.)
        let mut uv: Vec<[u16; 2]> = Vec::with_capacity(n * n * 2);
        let unorm = |v: f64| (v.clamp(0.0, 1.0) * 65535.0).round() as u16;
        let mut put = |i: usize, j: usize, h: f64| -> Result<u32> {
            let p = DVec3::new(o[0] + i as f64 * step, o[1] + j as f64 * step, h + self.height_offset_m);
            let (lon, lat, hh) = self.geo.to_geo(p).map_err(|err| anyhow::anyhow!("terrain tile: {err}"))?;
            let d = geodetic_to_ecef(lon, lat, hh) - f[0];
            let (x, y, z) = (d.dot(f[1]), d.dot(f[2]), d.dot(f[3]));
            pos.push([x as f32, z as f32, -y as f32]);
            uv.push([unorm((p.x - io[0]) / is), unorm(1.0 - (p.y - io[1]) / is)]);
            Ok(pos.len() as u32 - 1)
        };
        // The surface: a vertex per grid point with data (none for a hole).
        let mut at = vec![None; n * n];
        for j in 0..n {
            for i in 0..n {
                at[j * n + i] = match t.height(i, j) {
                    Some(h) => Some(put(i, j, f64::from(h))?),
                    None => None,
                };
            }
        }
        let mut idx: Vec<u32> = Vec::with_capacity(t.side() * t.side() * 6);
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                let (a, b, c, d) = (at[j * n + i], at[j * n + i + 1], at[(j + 1) * n + i], at[(j + 1) * n + i + 1]);
                if let (Some(a), Some(b), Some(c), Some(d)) = (a, b, c, d) {
                    // Counter-clockwise seen from above: SW, SE, NE and SW, NE, NW.
                    idx.extend_from_slice(&[a, b, d, a, d, c]);
                }
            }
        }
        if idx.is_empty() {
            return Ok(None);
        }
        // Skirts: each edge's vertices again, `skirt_m` lower, joined to them.
        let edges: [Vec<(usize, usize)>; 4] = [
            (0..n).map(|i| (i, 0)).collect(),
            (0..n).map(|i| (i, n - 1)).collect(),
            (0..n).map(|j| (0, j)).collect(),
            (0..n).map(|j| (n - 1, j)).collect(),
        ];
        for edge in &edges {
            let mut prev: Option<(u32, u32)> = None;
            for &(i, j) in edge {
                let top = at[j * n + i];
                let cur = match (top, t.height(i, j)) {
                    (Some(top), Some(h)) => Some((top, put(i, j, f64::from(h) - skirt_m)?)),
                    _ => None,
                };
                if let (Some((a, a_low)), Some((b, b_low))) = (prev, cur) {
                    idx.extend_from_slice(&[a, a_low, b_low, a, b_low, b]);
                }
                prev = cur;
            }
        }
        let mut g = Gltf::default();
        let (mut lo, mut hi) = ([f32::MAX; 3], [f32::MIN; 3]);
        for p in &pos {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let count = pos.len();
        let vp = g.own_view_for(bytemuck::cast_slice(&pos), Some(Target::ArrayBuffer));
        let vu = g.own_view_for(bytemuck::cast_slice(&uv), Some(Target::ArrayBuffer));
        // (Indices as u16 where the vertices allow: a 64-cell tile has 4,485.)
        let short = pos.len() <= usize::from(u16::MAX);
        let vi = if short {
            let idx16: Vec<u16> = idx.iter().map(|&i| i as u16).collect();
            g.own_view_for(bytemuck::cast_slice(&idx16), Some(Target::ElementArrayBuffer))
        } else {
            g.own_view_for(bytemuck::cast_slice(&idx), Some(Target::ElementArrayBuffer))
        };
        let a_pos = g.accessor(Elements::of(vp, count, Type::Vec3), Some((lo, hi)));
        let uvs = Elements { component: ComponentType::U16, normalized: true, ..Elements::of(vu, count, Type::Vec2) };
        let a_uv = g.accessor(uvs, None);
        let index_type = if short { ComponentType::U16 } else { ComponentType::U32 };
        let a_idx = g.accessor(Elements { component: index_type, ..Elements::of(vi, idx.len(), Type::Scalar) }, None);
        let texture = image.map(|(l, x, y)| g.texture(&format!("ground/img/{l}_{x}_{y}.jpg"), true, true));
        // Unlit, as imagery draped on a globe is (the photo has its own light).
        let material = g.material(Look {
            name: "ground".into(),
            base_color: if texture.is_some() { [1.0; 4] } else { LITTER },
            texture,
            double_sided: true,
            alpha_cutoff: None,
            unlit: true,
        });
        let attributes = vec![(Semantic::Positions, a_pos), (Semantic::TexCoords(0), a_uv)];
        let mesh = g.mesh("ground", vec![(attributes, a_idx, material)]);
        g.scene(vec![(format!("ground {}_{}_{}", t.level, t.x, t.y), mesh, serde_json::Map::new())]);
        Ok(Some(g.glb(&["KHR_materials_unlit"], &[])))
    }
}
