//! glTF 2.0 / GLB import: one tree model as a flat triangle list with materials.
//!
//! Handles what real exporters write: node hierarchies with transforms, several
//! meshes and several primitives per mesh, interleaved buffers with byteStride
//! (via the gltf crate's accessor reader), u8/u16/u32 indices, vertex colours,
//! images embedded in the GLB, as data URIs or as external PNG/JPEG/WebP files,
//! alpha modes MASK/BLEND/OPAQUE and double-sided materials. glTF is Y-up; Sylva
//! is Z-up, so (x, y, z) → (x, −z, y). The model is moved so its trunk base is
//! at the origin.

use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use base64::Engine as _;
use glam::{Mat4, Vec2, Vec3};
use sylva::format::pack::MaterialKind;

/// A material of an imported model.
#[derive(Debug, Clone)]
pub struct ImportedMaterial {
    /// Material name (or `material<i>`).
    pub name: String,
    /// Leaf or branch.
    pub kind: MaterialKind,
    /// Linear RGBA base colour factor.
    pub base_color: [f32; 4],
    /// Alpha test threshold (0 for opaque).
    pub alpha_cutoff: f32,
    /// Whether back faces are visible.
    pub double_sided: bool,
    /// Base colour texture (sRGB RGBA8), if any.
    pub texture: Option<image::RgbaImage>,
}

/// One imported vertex (Z up, model units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImportedVertex {
    /// Position.
    pub position: Vec3,
    /// Unit normal.
    pub normal: Vec3,
    /// Texture coordinate (set 0).
    pub uv: Vec2,
    /// Linear RGBA vertex colour (white when absent).
    pub color: [f32; 4],
    /// Material index.
    pub material: u16,
}

/// A whole tree model.
#[derive(Debug, Clone, Default)]
pub struct ImportedModel {
    /// Materials, indexed by `ImportedVertex::material`.
    pub materials: Vec<ImportedMaterial>,
    /// Vertices.
    pub vertices: Vec<ImportedVertex>,
    /// Triangles (indices into `vertices`).
    pub triangles: Vec<[u32; 3]>,
}

impl ImportedModel {
    /// Bounds (min, max) of all vertices.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.vertices.iter().fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(lo, hi), v| {
            (lo.min(v.position), hi.max(v.position))
        })
    }

    /// Height (z extent).
    pub fn height(&self) -> f32 {
        let (lo, hi) = self.bounds();
        hi.z - lo.z
    }

    /// Triangles per material kind (leaf, branch).
    pub fn triangle_counts(&self) -> (usize, usize) {
        let mut leaf = 0;
        for t in &self.triangles {
            if self.materials[usize::from(self.vertices[t[0] as usize].material)].kind == MaterialKind::Leaf {
                leaf += 1;
            }
        }
        (leaf, self.triangles.len() - leaf)
    }
}

/// How leaves and branches are told apart.
#[derive(Debug, Clone, Default)]
pub struct Classifier {
    /// Substrings (case-insensitive) of material/mesh/node names forcing "leaf".
    pub leaf_patterns: Vec<String>,
    /// Substrings forcing "branch".
    pub branch_patterns: Vec<String>,
}

const LEAF_WORDS: &[&str] = &["leaf", "leaves", "needle", "foliage", "frond", "blatt", "laub", "canopy", "crown"];
const BRANCH_WORDS: &[&str] = &["bark", "trunk", "branch", "wood", "stem", "twig", "stamm", "rinde"];

impl Classifier {
    /// Explicit patterns first, then well-known words in the names, then the alpha mode
    /// (MASK and BLEND are leaf cards; OPAQUE is wood).
    pub fn classify(&self, names: &[&str], alpha_mode: gltf::material::AlphaMode) -> MaterialKind {
        let lower: Vec<String> = names.iter().map(|n| n.to_lowercase()).collect();
        let any = |pats: &[String]| pats.iter().any(|p| lower.iter().any(|n| n.contains(&p.to_lowercase())));
        if any(&self.leaf_patterns) {
            return MaterialKind::Leaf;
        }
        if any(&self.branch_patterns) {
            return MaterialKind::Branch;
        }
        // Names are checked material first: a "bark" material on a "leaves" node is bark.
        for n in &lower {
            if LEAF_WORDS.iter().any(|w| n.contains(w)) {
                return MaterialKind::Leaf;
            }
            if BRANCH_WORDS.iter().any(|w| n.contains(w)) {
                return MaterialKind::Branch;
            }
        }
        match alpha_mode {
            gltf::material::AlphaMode::Opaque => MaterialKind::Branch,
            _ => MaterialKind::Leaf,
        }
    }
}

/// Imports a `.glb` or `.gltf` file.
pub fn import(path: &Path, classifier: &Classifier) -> Result<ImportedModel> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read model {}", path.display()))?;
    let base = path.parent().unwrap_or(Path::new("."));
    // The gltf crate validates the JSON; accessor reads of hostile files have
    // panicked in the past, so a panic is turned into an error for this file.
    let result = std::panic::catch_unwind(|| import_slice(&bytes, Some(base), classifier));
    match result {
        Ok(r) => r.with_context(|| format!("model {}", path.display())),
        Err(_) => bail!("model {}: malformed glTF data (the importer could not read an accessor)", path.display()),
    }
}

/// Imports glTF/GLB bytes; external files are resolved against `base`.
pub fn import_slice(bytes: &[u8], base: Option<&Path>, classifier: &Classifier) -> Result<ImportedModel> {
    let gltf = gltf::Gltf::from_slice(bytes).map_err(|e| anyhow!("not a valid glTF/GLB file: {e}"))?;
    let buffers = gltf::import_buffers(&gltf.document, base, gltf.blob.clone())
        .map_err(|e| anyhow!("cannot load the glTF buffers: {e}"))?;
    let doc = &gltf.document;
    let mut images: Vec<Option<image::RgbaImage>> = vec![None; doc.images().len()];
    let mut model = ImportedModel::default();
    // Materials are created on first use, with index `materials.len()` for the default one.
    let mut material_slot: Vec<Option<u16>> = vec![None; doc.materials().len() + 1];
    let scene = doc.default_scene().or_else(|| doc.scenes().next());
    let roots: Vec<gltf::Node<'_>> = match &scene {
        Some(s) => s.nodes().collect(),
        None => doc.nodes().collect(),
    };
    let mut stack: Vec<(gltf::Node<'_>, Mat4, Vec<String>)> =
        roots.into_iter().map(|n| (n, Mat4::IDENTITY, Vec::new())).collect();
    let mut visited = 0usize;
    while let Some((node, parent, mut names)) = stack.pop() {
        visited += 1;
        if visited > 1_000_000 {
            bail!("the node hierarchy is too deep or cyclic");
        }
        let local = Mat4::from_cols_array_2d(&node.transform().matrix());
        let world = parent * local;
        if let Some(n) = node.name() {
            names.push(n.to_string());
        }
        if let Some(mesh) = node.mesh() {
            let mut mesh_names = names.clone();
            if let Some(n) = mesh.name() {
                mesh_names.push(n.to_string());
            }
            for prim in mesh.primitives() {
                if prim.mode() != gltf::mesh::Mode::Triangles {
                    continue;
                }
                let mat = prim.material();
                let slot_index = mat.index().unwrap_or(doc.materials().len());
                let material = match material_slot[slot_index] {
                    Some(m) => m,
                    None => {
                        let m = import_material(&mat, &mesh_names, classifier, doc, &buffers, base, &mut images)?;
                        model.materials.push(m);
                        let idx = u16::try_from(model.materials.len() - 1)
                            .map_err(|_| anyhow!("more than 65535 materials"))?;
                        material_slot[slot_index] = Some(idx);
                        idx
                    }
                };
                append_primitive(&mut model, &prim, &buffers, world, material)
                    .with_context(|| format!("mesh {:?} primitive {}", mesh.name().unwrap_or("?"), prim.index()))?;
            }
        }
        for child in node.children() {
            stack.push((child, world, names.clone()));
        }
    }
    if model.triangles.is_empty() {
        bail!("the model has no triangle meshes");
    }
    if !model.materials.iter().any(|m| m.kind == MaterialKind::Leaf) {
        bail!("the model has no leaves: no material is alpha-masked/blended or named like leaves; name them with --leaf-material PATTERN");
    }
    recenter(&mut model);
    Ok(model)
}

fn import_material(
    mat: &gltf::Material<'_>,
    names: &[String],
    classifier: &Classifier,
    doc: &gltf::Document,
    buffers: &[gltf::buffer::Data],
    base: Option<&Path>,
    images: &mut [Option<image::RgbaImage>],
) -> Result<ImportedMaterial> {
    let name = mat.name().map_or_else(|| format!("material{}", mat.index().map_or(-1, |i| i as i64)), str::to_string);
    let mut all_names: Vec<&str> = vec![name.as_str()];
    all_names.extend(names.iter().rev().map(String::as_str));
    let kind = classifier.classify(&all_names, mat.alpha_mode());
    let pbr = mat.pbr_metallic_roughness();
    let texture = match pbr.base_color_texture() {
        Some(info) => {
            let image = info.texture().source();
            let idx = image.index();
            if images[idx].is_none() {
                images[idx] = Some(
                    load_image(&image, doc, buffers, base)
                        .with_context(|| format!("image {idx} of material {name:?}"))?,
                );
            }
            images[idx].clone()
        }
        None => None,
    };
    let alpha_cutoff = match mat.alpha_mode() {
        gltf::material::AlphaMode::Opaque => 0.0,
        gltf::material::AlphaMode::Mask => mat.alpha_cutoff().unwrap_or(0.5),
        // Blended leaves are drawn alpha-tested: no sorting in a forest.
        gltf::material::AlphaMode::Blend => 0.5,
    };
    Ok(ImportedMaterial {
        name,
        kind,
        base_color: pbr.base_color_factor(),
        alpha_cutoff,
        double_sided: mat.double_sided(),
        texture,
    })
}

fn load_image(
    image: &gltf::Image<'_>,
    _doc: &gltf::Document,
    buffers: &[gltf::buffer::Data],
    base: Option<&Path>,
) -> Result<image::RgbaImage> {
    let encoded: Vec<u8> = match image.source() {
        gltf::image::Source::View { view, .. } => {
            let data = buffers.get(view.buffer().index()).ok_or_else(|| anyhow!("missing buffer"))?;
            let end = view.offset().checked_add(view.length()).ok_or_else(|| anyhow!("bad buffer view"))?;
            data.0
                .get(view.offset()..end)
                .ok_or_else(|| anyhow!("buffer view {}..{end} is outside its buffer", view.offset()))?
                .to_vec()
        }
        gltf::image::Source::Uri { uri, .. } => {
            if let Some(rest) = uri.strip_prefix("data:") {
                let (_, b64) = rest.split_once(";base64,").ok_or_else(|| anyhow!("data URI is not base64"))?;
                base64::engine::general_purpose::STANDARD.decode(b64).map_err(|e| anyhow!("data URI: {e}"))?
            } else {
                let base = base.ok_or_else(|| anyhow!("external image {uri:?} needs a base directory"))?;
                let decoded = percent_decode(uri);
                if decoded.contains("..") || decoded.starts_with('/') {
                    bail!("external image {uri:?} points outside the model's directory");
                }
                let p = base.join(&decoded);
                std::fs::read(&p).with_context(|| format!("cannot read external image {}", p.display()))?
            }
        }
    };
    let img = image::load_from_memory(&encoded).map_err(|e| anyhow!("cannot decode image (PNG/JPEG/WebP): {e}"))?;
    Ok(img.to_rgba8())
}

fn percent_decode(s: &str) -> String {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' && i + 2 < bytes.len() {
            if let Ok(v) = u8::from_str_radix(&s[i + 1..i + 3], 16) {
                out.push(v);
                i += 3;
                continue;
            }
        }
        out.push(bytes[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// glTF Y-up to Sylva Z-up.
fn y_up_to_z_up(v: Vec3) -> Vec3 {
    Vec3::new(v.x, -v.z, v.y)
}

fn append_primitive(
    model: &mut ImportedModel,
    prim: &gltf::Primitive<'_>,
    buffers: &[gltf::buffer::Data],
    world: Mat4,
    material: u16,
) -> Result<()> {
    let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
    let positions: Vec<[f32; 3]> = reader.read_positions().ok_or_else(|| anyhow!("no POSITION attribute"))?.collect();
    let n = positions.len();
    let normals: Option<Vec<[f32; 3]>> = reader.read_normals().map(Iterator::collect);
    let uvs: Option<Vec<[f32; 2]>> = reader.read_tex_coords(0).map(|t| t.into_f32().collect());
    let colors: Option<Vec<[f32; 4]>> = reader.read_colors(0).map(|c| c.into_rgba_f32().collect());
    let indices: Vec<u32> = match reader.read_indices() {
        Some(i) => i.into_u32().collect(),
        None => (0..n as u32).collect(),
    };
    if indices.iter().any(|&i| i as usize >= n) {
        bail!("an index is out of range of the {n} vertices");
    }
    let normal_matrix = world.inverse().transpose();
    let first = u32::try_from(model.vertices.len()).map_err(|_| anyhow!("too many vertices"))?;
    let flip = world.determinant() < 0.0;
    for (i, &position) in positions.iter().enumerate() {
        let p = world.transform_point3(Vec3::from(position));
        let nrm = normals
            .as_ref()
            .and_then(|ns| ns.get(i))
            .map(|&v| normal_matrix.transform_vector3(Vec3::from(v)).normalize_or_zero())
            .unwrap_or(Vec3::ZERO);
        let uv = uvs.as_ref().and_then(|u| u.get(i)).copied().unwrap_or([0.0, 0.0]);
        let color = colors.as_ref().and_then(|c| c.get(i)).copied().unwrap_or([1.0; 4]);
        if !p.is_finite() || !Vec2::from(uv).is_finite() || color.iter().any(|c| !c.is_finite()) {
            bail!("vertex {i} has a non-finite position, texture coordinate or colour");
        }
        model.vertices.push(ImportedVertex {
            position: y_up_to_z_up(p),
            normal: y_up_to_z_up(nrm),
            uv: Vec2::from(uv),
            color,
            material,
        });
    }
    let before = model.triangles.len();
    for t in indices.chunks_exact(3) {
        let tri = if flip { [t[0], t[2], t[1]] } else { [t[0], t[1], t[2]] };
        model.triangles.push(tri.map(|i| first + i));
    }
    if normals.is_none() {
        compute_normals(model, first as usize, before);
    }
    Ok(())
}

/// Area-weighted vertex normals for the vertices from `first_vertex` used by triangles from `first_tri`.
fn compute_normals(model: &mut ImportedModel, first_vertex: usize, first_tri: usize) {
    let mut acc = vec![Vec3::ZERO; model.vertices.len() - first_vertex];
    for t in &model.triangles[first_tri..] {
        let [a, b, c] = t.map(|i| model.vertices[i as usize].position);
        let n = (b - a).cross(c - a);
        for &i in t {
            acc[i as usize - first_vertex] += n;
        }
    }
    for (v, n) in model.vertices[first_vertex..].iter_mut().zip(acc) {
        v.normal = n.normalize_or(Vec3::Z);
    }
}

/// Moves the trunk base to the origin: z from the lowest vertex, x/y from the
/// centre of the lowest 2 % of the height (the trunk foot).
fn recenter(model: &mut ImportedModel) {
    let (lo, hi) = model.bounds();
    let slice = lo.z + (hi.z - lo.z) * 0.02;
    let (mut sum, mut count) = (Vec2::ZERO, 0.0f32);
    for v in &model.vertices {
        if v.position.z <= slice {
            sum += v.position.truncate();
            count += 1.0;
        }
    }
    let foot = if count > 0.0 { sum / count } else { Vec2::ZERO };
    let shift = Vec3::new(foot.x, foot.y, lo.z);
    for v in &mut model.vertices {
        v.position -= shift;
        if v.normal == Vec3::ZERO {
            v.normal = Vec3::Z;
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use serde_json::json;

    /// A tiny RGBA PNG: opaque green disc on transparent black.
    pub(crate) fn leaf_png() -> Vec<u8> {
        let img = image::RgbaImage::from_fn(8, 8, |x, y| {
            let (dx, dy) = (x as f32 - 3.5, y as f32 - 3.5);
            if dx * dx + dy * dy < 12.0 {
                image::Rgba([30, 150, 40, 255])
            } else {
                image::Rgba([0, 0, 0, 0])
            }
        });
        let mut out = std::io::Cursor::new(Vec::new());
        img.write_to(&mut out, image::ImageFormat::Png).unwrap();
        out.into_inner()
    }

    /// Packs JSON and a binary chunk into a GLB.
    pub(crate) fn glb(json: &serde_json::Value, bin: &[u8]) -> Vec<u8> {
        let mut j = serde_json::to_vec(json).unwrap();
        while !j.len().is_multiple_of(4) {
            j.push(b' ');
        }
        let mut b = bin.to_vec();
        while !b.len().is_multiple_of(4) {
            b.push(0);
        }
        let total = 12 + 8 + j.len() + 8 + b.len();
        let mut out = Vec::new();
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(j.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&j);
        out.extend_from_slice(&(b.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&b);
        out
    }

    /// Interleaved POSITION/NORMAL/TEXCOORD_0 (stride 32) for two quads (y-up: a
    /// 1×2 trunk quad and a 2×2 leaf quad above it), u16 indices, u8 vertex colours.
    fn interleaved_buffers() -> (Vec<u8>, usize, usize, usize) {
        let mut bin = Vec::new();
        let quads = [
            [[-0.5f32, 0.0, 0.0], [0.5, 0.0, 0.0], [0.5, 2.0, 0.0], [-0.5, 2.0, 0.0]],
            [[-1.0, 2.0, 0.0], [1.0, 2.0, 0.0], [1.0, 4.0, 0.0], [-1.0, 4.0, 0.0]],
        ];
        let uvs = [[0.0f32, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]];
        for q in &quads {
            for (p, uv) in q.iter().zip(&uvs) {
                for v in p.iter().chain(&[0.0, 0.0, 1.0]).chain(uv) {
                    bin.extend_from_slice(&v.to_le_bytes());
                }
            }
        }
        let vertex_bytes = bin.len();
        let colors_at = bin.len();
        for i in 0..8u8 {
            bin.extend_from_slice(&[255, 128, i * 30, 255]);
        }
        let indices_at = bin.len();
        for i in [0u16, 1, 2, 0, 2, 3] {
            bin.extend_from_slice(&i.to_le_bytes());
        }
        (bin, vertex_bytes, colors_at, indices_at)
    }

    fn accessors(vertex_view: usize, color_view: usize, index_view: usize, first_vertex: usize) -> serde_json::Value {
        json!([
            {"bufferView": vertex_view, "byteOffset": first_vertex * 32, "componentType": 5126, "count": 4, "type": "VEC3",
             "min": [-1.0, 0.0, 0.0], "max": [1.0, 4.0, 0.0]},
            {"bufferView": vertex_view, "byteOffset": first_vertex * 32 + 12, "componentType": 5126, "count": 4, "type": "VEC3"},
            {"bufferView": vertex_view, "byteOffset": first_vertex * 32 + 24, "componentType": 5126, "count": 4, "type": "VEC2"},
            {"bufferView": color_view, "byteOffset": first_vertex * 4, "componentType": 5121, "normalized": true, "count": 4, "type": "VEC4"},
            {"bufferView": index_view, "componentType": 5123, "count": 6, "type": "SCALAR"}
        ])
    }

    /// GLB: one mesh with two primitives (bark, leaves), node hierarchy with
    /// transforms, interleaved buffer, u16 indices, vertex colours, embedded PNG.
    pub(crate) fn multi_primitive_glb() -> Vec<u8> {
        let (mut bin, vbytes, colors_at, indices_at) = interleaved_buffers();
        let image_at = bin.len();
        let png = leaf_png();
        bin.extend_from_slice(&png);
        let mut acc = accessors(0, 1, 2, 0).as_array().unwrap().clone();
        let acc2 = accessors(0, 1, 2, 4);
        acc.extend(acc2.as_array().unwrap().iter().cloned());
        let gltf = json!({
            "asset": {"version": "2.0", "generator": "sylva test"},
            "scene": 0,
            "scenes": [{"nodes": [0]}],
            "nodes": [
                {"name": "Tree", "children": [1], "translation": [10.0, 0.0, 0.0], "scale": [2.0, 2.0, 2.0]},
                {"name": "TreeMesh", "mesh": 0, "rotation": [0.0, std::f32::consts::FRAC_1_SQRT_2, 0.0, std::f32::consts::FRAC_1_SQRT_2]}
            ],
            "meshes": [{"name": "tree", "primitives": [
                {"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2, "COLOR_0": 3}, "indices": 4, "material": 0},
                {"attributes": {"POSITION": 5, "NORMAL": 6, "TEXCOORD_0": 7, "COLOR_0": 8}, "indices": 9, "material": 1}
            ]}],
            "materials": [
                {"name": "Material.001", "pbrMetallicRoughness": {"baseColorFactor": [0.4, 0.3, 0.2, 1.0]}},
                {"name": "Material.002", "alphaMode": "MASK", "alphaCutoff": 0.4, "doubleSided": true,
                 "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}
            ],
            "textures": [{"source": 0}],
            "images": [{"bufferView": 3, "mimeType": "image/png"}],
            "buffers": [{"byteLength": bin.len()}],
            "bufferViews": [
                {"buffer": 0, "byteOffset": 0, "byteLength": vbytes, "byteStride": 32},
                {"buffer": 0, "byteOffset": colors_at, "byteLength": 32},
                {"buffer": 0, "byteOffset": indices_at, "byteLength": 12},
                {"buffer": 0, "byteOffset": image_at, "byteLength": png.len()}
            ],
            "accessors": acc
        });
        glb(&gltf, &bin)
    }

    #[test]
    fn imports_interleaved_multi_primitive_glb_with_transforms() {
        let m = import_slice(&multi_primitive_glb(), None, &Classifier::default()).unwrap();
        assert_eq!(m.materials.len(), 2);
        assert_eq!(m.materials[0].kind, MaterialKind::Branch, "OPAQUE → branch");
        assert_eq!(m.materials[1].kind, MaterialKind::Leaf, "MASK → leaf");
        assert_eq!(m.materials[1].alpha_cutoff, 0.4);
        assert!(m.materials[1].double_sided);
        assert_eq!(m.materials[1].texture.as_ref().map(|t| t.dimensions()), Some((8, 8)));
        assert_eq!(m.materials[0].base_color, [0.4, 0.3, 0.2, 1.0]);
        assert_eq!(m.vertices.len(), 8);
        assert_eq!(m.triangles.len(), 4);
        // Node scale 2 and Y-up → Z-up: 4 units of glTF height become 8 along z.
        assert!((m.height() - 8.0).abs() < 1e-4, "height {}", m.height());
        let (lo, _) = m.bounds();
        assert!(lo.z.abs() < 1e-6, "trunk base moved to z = 0");
        // Vertex colours came through (normalised u8).
        assert!((m.vertices[0].color[1] - 128.0 / 255.0).abs() < 1e-3);
        // The 90° rotation about y turned the quad's +z normal into +x (glTF) = +x (Sylva).
        assert!((m.vertices[0].normal - Vec3::X).length() < 1e-4, "{}", m.vertices[0].normal);
    }

    #[test]
    fn imports_gltf_with_external_bin_and_image_and_u32_indices() {
        let dir = std::env::temp_dir().join(format!("sylva-gltf-ext-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (bin16, vbytes, colors_at, _) = interleaved_buffers();
        let mut bin = bin16[..colors_at + 32].to_vec();
        let indices_at = bin.len();
        for i in [0u32, 1, 2, 0, 2, 3] {
            bin.extend_from_slice(&i.to_le_bytes());
        }
        std::fs::write(dir.join("tree.bin"), &bin).unwrap();
        std::fs::write(dir.join("leaf image.png"), leaf_png()).unwrap();
        let mut acc = accessors(0, 1, 2, 4);
        acc[4]["componentType"] = json!(5125);
        let gltf = json!({
            "asset": {"version": "2.0"},
            "nodes": [{"name": "leaves", "mesh": 0}],
            "scenes": [{"nodes": [0]}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 2}, "indices": 4, "material": 0}]}],
            "materials": [{"name": "Foliage", "alphaMode": "BLEND", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
            "textures": [{"source": 0}],
            "images": [{"uri": "leaf%20image.png"}],
            "buffers": [{"uri": "tree.bin", "byteLength": bin.len()}],
            "bufferViews": [
                {"buffer": 0, "byteOffset": 0, "byteLength": vbytes, "byteStride": 32},
                {"buffer": 0, "byteOffset": colors_at, "byteLength": 32},
                {"buffer": 0, "byteOffset": indices_at, "byteLength": 24}
            ],
            "accessors": acc
        });
        let path = dir.join("tree.gltf");
        std::fs::write(&path, serde_json::to_vec(&gltf).unwrap()).unwrap();
        let m = import(&path, &Classifier::default()).unwrap();
        assert_eq!(m.triangles.len(), 2);
        assert_eq!(m.materials[0].kind, MaterialKind::Leaf);
        assert_eq!(m.materials[0].alpha_cutoff, 0.5, "BLEND is drawn alpha-tested at 0.5");
        assert!(m.materials[0].texture.is_some());
        // No NORMAL attribute: normals are computed (the quad faces +z in glTF = −y in Sylva).
        assert!((m.vertices[0].normal - Vec3::NEG_Y).length() < 1e-4, "{}", m.vertices[0].normal);
        // A missing external image is an error naming the file.
        std::fs::remove_file(dir.join("leaf image.png")).unwrap();
        let e = format!("{:#}", import(&path, &Classifier::default()).unwrap_err());
        assert!(e.contains("leaf image.png") && e.contains("tree.gltf"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn data_uri_images_and_name_overrides() {
        use base64::Engine as _;
        let (bin, vbytes, colors_at, indices_at) = interleaved_buffers();
        let b64 = base64::engine::general_purpose::STANDARD.encode(leaf_png());
        let all_accessors: Vec<serde_json::Value> =
            [accessors(0, 1, 2, 0).as_array().unwrap().clone(), accessors(0, 1, 2, 4).as_array().unwrap().clone()]
                .concat();
        let gltf = json!({
            "asset": {"version": "2.0"},
            "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [
                {"attributes": {"POSITION": 0}, "indices": 4, "material": 0},
                {"attributes": {"POSITION": 5, "TEXCOORD_0": 7}, "indices": 9, "material": 1}
            ]}],
            "materials": [
                {"name": "trunk_opaque"},
                {"name": "cards", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}
            ],
            "textures": [{"source": 0}],
            "images": [{"uri": format!("data:image/png;base64,{b64}")}],
            "buffers": [{"byteLength": bin.len()}],
            "bufferViews": [
                {"buffer": 0, "byteOffset": 0, "byteLength": vbytes, "byteStride": 32},
                {"buffer": 0, "byteOffset": colors_at, "byteLength": 32},
                {"buffer": 0, "byteOffset": indices_at, "byteLength": 12}
            ],
            "accessors": all_accessors
        });
        let bytes = glb(&gltf, &bin);
        // Both materials are OPAQUE and "cards" is no leaf word: no leaves → a clear error.
        let e = import_slice(&bytes, None, &Classifier::default()).unwrap_err().to_string();
        assert!(e.contains("no leaves") && e.contains("--leaf-material"), "{e}");
        // With an explicit pattern the cards are leaves and the data-URI image loads.
        let c = Classifier { leaf_patterns: vec!["CARDS".into()], branch_patterns: vec![] };
        let m = import_slice(&bytes, None, &c).unwrap();
        assert_eq!(m.materials[1].kind, MaterialKind::Leaf);
        assert_eq!(m.materials[0].kind, MaterialKind::Branch);
        assert_eq!(m.materials[1].texture.as_ref().map(|t| t.dimensions()), Some((8, 8)));
    }

    #[test]
    fn imports_embedded_webp_images() {
        // The same GLB with its leaf image re-encoded as lossless WebP (mimeType image/webp).
        let png = image::load_from_memory(&leaf_png()).unwrap().to_rgba8();
        let mut webp = Vec::new();
        image::codecs::webp::WebPEncoder::new_lossless(&mut webp)
            .encode(png.as_raw(), 8, 8, image::ExtendedColorType::Rgba8)
            .unwrap();
        let (mut bin, vbytes, colors_at, indices_at) = interleaved_buffers();
        let image_at = bin.len();
        bin.extend_from_slice(&webp);
        let gltf = json!({
            "asset": {"version": "2.0"},
            "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 2}, "indices": 4, "material": 0}]}],
            "materials": [{"name": "leaf", "alphaMode": "MASK", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
            "textures": [{"source": 0}],
            "images": [{"bufferView": 3, "mimeType": "image/webp"}],
            "buffers": [{"byteLength": bin.len()}],
            "bufferViews": [
                {"buffer": 0, "byteOffset": 0, "byteLength": vbytes, "byteStride": 32},
                {"buffer": 0, "byteOffset": colors_at, "byteLength": 32},
                {"buffer": 0, "byteOffset": indices_at, "byteLength": 12},
                {"buffer": 0, "byteOffset": image_at, "byteLength": webp.len()}
            ],
            "accessors": accessors(0, 1, 2, 0)
        });
        let m = import_slice(&glb(&gltf, &bin), None, &Classifier::default()).unwrap();
        let tex = m.materials[0].texture.as_ref().expect("WebP decoded");
        assert_eq!(tex.as_raw(), png.as_raw(), "lossless WebP gives the same texels");
    }

    #[test]
    fn broken_inputs_give_errors_not_panics() {
        let c = Classifier::default();
        assert!(import_slice(b"definitely not gltf", None, &c).is_err());
        let mut truncated = multi_primitive_glb();
        truncated.truncate(truncated.len() / 2);
        assert!(import_slice(&truncated, None, &c).is_err());
        let empty = glb(&json!({"asset": {"version": "2.0"}, "nodes": [{"name": "x"}]}), &[]);
        let e = import_slice(&empty, None, &c).unwrap_err().to_string();
        assert!(e.contains("no triangle meshes"), "{e}");
        let e = format!("{:#}", import(Path::new("/nonexistent/tree.glb"), &c).unwrap_err());
        assert!(e.contains("/nonexistent/tree.glb"), "{e}");
    }

    #[test]
    fn imports_the_shared_ez_tree_models() {
        // Real exporter output (three.js GLTFExporter); skipped where shared/ is absent.
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/models");
        for (file, leaves) in [("eztree_oak_medium.glb", 10_640 / 2), ("eztree_pine_medium.glb", 9_840 / 2)] {
            let path = dir.join(file);
            if !path.exists() {
                eprintln!("skipping {}: not present", path.display());
                continue;
            }
            let m = import(&path, &Classifier::default()).unwrap();
            let (leaf, wood) = m.triangle_counts();
            assert_eq!(leaf, leaves * 2, "{file}");
            assert!(wood > 3000, "{file}");
            assert!(m.height() > 40.0, "{file}: {}", m.height());
        }
    }
}
