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
use glam::{Mat4, Vec2, Vec3};
use sylva::format::pack::MaterialKind;

mod accessors;
mod extensions;
mod graph;
mod skin;
mod sources;

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
    /// The glTF material was alpha-blended (drawn alpha-tested at `alpha_cutoff`).
    pub blended: bool,
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
    /// What the import changed or left out, for the bake's log (line and point
    /// primitives skipped, blended materials cut out, instances expanded).
    pub notes: Vec<String>,
    /// Other shapes of the same tree (the library's variants): for each, a
    /// position and normal per vertex of `vertices`; the triangles, uvs,
    /// colours and materials are the model's. Empty for a glTF model.
    pub variants: Vec<Vec<[Vec3; 2]>>,
    /// A deciduous tree's leaves' autumn colour (sRGB): the pack then holds
    /// its seasons (leaf-on, autumn, leaf-off). `None`: evergreen, one state.
    pub autumn: Option<[u8; 3]>,
    /// The genus whose leaf calendar a deciduous tree keeps (Latin, e.g.
    /// `Fagus`; the viewer's phenology at a date): the library's, or the one
    /// its model's name places. `None`: the default deciduous calendar.
    pub genus: Option<String>,
}

impl ImportedModel {
    /// Bounds (min, max) of all vertices, of every variant.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.variants.iter().flatten().fold(self.own_bounds(), |(lo, hi), [p, _]| (lo.min(*p), hi.max(*p)))
    }

    /// Bounds (min, max) of the model's own vertices (variant 0).
    pub fn own_bounds(&self) -> (Vec3, Vec3) {
        self.vertices.iter().fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(lo, hi), v| {
            (lo.min(v.position), hi.max(v.position))
        })
    }

    /// Height (z extent; variant 0's, which the other variants are stretched to).
    pub fn height(&self) -> f32 {
        let (lo, hi) = self.own_bounds();
        hi.z - lo.z
    }

    /// Crown width: the mean of the x and y extents (as foresters average two
    /// perpendicular crown widths).
    pub fn crown_width(&self) -> f32 {
        let (lo, hi) = self.own_bounds();
        ((hi.x - lo.x) + (hi.y - lo.y)) * 0.5
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
    /// Patterns of material/mesh/node names forcing "leaf" (case-insensitive;
    /// `*` a wildcard, else a substring: [`crate::patterns::pattern_matches`]).
    pub leaf_patterns: Vec<String>,
    /// Patterns forcing "branch".
    pub branch_patterns: Vec<String>,
}

const LEAF_WORDS: &[&str] = &["leaf", "leaves", "needle", "foliage", "frond", "blatt", "laub", "canopy", "crown"];
const BRANCH_WORDS: &[&str] = &["bark", "trunk", "branch", "wood", "stem", "twig", "stamm", "rinde"];

impl Classifier {
    /// Explicit patterns first, then well-known words in the names, then the alpha mode
    /// (MASK and BLEND are leaf cards; OPAQUE is wood).
    pub fn classify(&self, names: &[&str], alpha_mode: gltf::material::AlphaMode) -> MaterialKind {
        let lower: Vec<String> = names.iter().map(|n| n.to_lowercase()).collect();
        let any = |pats: &[String]| pats.iter().any(|p| names.iter().any(|n| crate::patterns::pattern_matches(p, n)));
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

/// Most vertices (and a quarter of the most triangles) one model may expand to.
pub const MAX_VERTICES: usize = 8 << 20;
/// Most triangles one model may expand to.
pub const MAX_TRIANGLES: usize = 16 << 20;
/// Largest model extent, in model units (a 100 m tree in millimetres is 10^5).
pub const MAX_MODEL_EXTENT: f32 = 1.0e6;
/// Smallest model height, in model units.
pub const MIN_MODEL_HEIGHT: f32 = 1.0e-4;
/// Most decoded texture bytes (RGBA8) one model may hold.
pub const MAX_TEXTURE_BYTES: u64 = 1 << 30;
/// Node names kept per path for leaf/wood classification (the nearest ones).
const MAX_NAMES: usize = 16;

/// Imports a `.glb` or `.gltf` file. External buffers and images are read
/// only from regular files inside the model's folder ([`sources`]).
///
/// # Errors
/// An unreadable or malformed file, a broken node graph or accessor, a URI
/// outside the model's folder, or a model without leaves or height; the
/// message names the file and the part.
pub fn import(path: &Path, classifier: &Classifier) -> Result<ImportedModel> {
    let meta = std::fs::metadata(path).with_context(|| format!("cannot read model {}", path.display()))?;
    if !meta.is_file() {
        bail!("model {} is not a regular file", path.display());
    }
    let bytes = std::fs::read(path).with_context(|| format!("cannot read model {}", path.display()))?;
    let base = path.parent().map(|p| if p.as_os_str().is_empty() { Path::new(".") } else { p });
    // A panic inside the gltf crate's reader is turned into an error for this
    // file (the checks below are meant to make it unreachable).
    let result = std::panic::catch_unwind(|| import_slice(&bytes, base, classifier));
    match result {
        Ok(r) => r.with_context(|| format!("model {}", path.display())),
        Err(_) => bail!("model {}: malformed glTF data (the importer could not read an accessor)", path.display()),
    }
}

/// Imports glTF/GLB bytes; external files are resolved inside `base`.
///
/// # Errors
/// As [`import`].
pub fn import_slice(bytes: &[u8], base: Option<&Path>, classifier: &Classifier) -> Result<ImportedModel> {
    // The gltf crate subtracts the 12-byte header from the GLB's declared
    // length unchecked (found by the import_gltf fuzz target).
    if let Some(declared) = bytes.strip_prefix(b"glTF").and_then(|b| b.get(4..8)) {
        let declared = u32::from_le_bytes(declared.try_into().expect("4 bytes"));
        if declared < 12 {
            bail!("not a valid GLB file: its header declares {declared} bytes, less than the header itself");
        }
    }
    let raw = raw_json(bytes)?;
    check_position_indices(&raw)?;
    extensions::check(&raw)?;
    // The extensions handled here are taken out of `extensionsRequired`, which the
    // gltf crate refuses otherwise; then it validates the rest as always.
    let parsed =
        gltf::Gltf::from_slice_without_validation(bytes).map_err(|e| anyhow!("not a valid glTF/GLB file: {e}"))?;
    let mut json = parsed.document.into_json();
    json.extensions_required.retain(|e| !extensions::HANDLED.contains(&e.as_str()));
    let document = gltf::Document::from_json(json).map_err(|e| anyhow!("not a valid glTF/GLB file: {e}"))?;
    let gltf = gltf::Gltf { document, blob: parsed.blob };
    let mut buffers =
        sources::load_buffers(&gltf.document, gltf.blob.as_deref(), base, &extensions::meshopt_fallbacks(&raw))?;
    let meshopt_views = extensions::decode_meshopt(&raw, &mut buffers)?;
    let doc = &gltf.document;
    let roots = graph::roots(doc);
    graph::check(doc, &roots)?;
    let globals = skin::node_globals(doc, &roots);
    let mut skinned = 0usize;
    let mut images: Vec<Option<image::RgbaImage>> = vec![None; doc.images().len()];
    let mut model = ImportedModel::default();
    let mut texture_bytes = 0u64;
    // Materials are created on first use, with index `materials.len()` for the default one.
    let mut material_slot: Vec<Option<u16>> = vec![None; doc.materials().len() + 1];
    let uv_sets: Vec<extensions::UvSet> = (0..=doc.materials().len())
        .map(|i| extensions::uv_set(&raw, (i < doc.materials().len()).then_some(i)))
        .collect();
    let mut skipped_modes = std::collections::BTreeMap::<String, usize>::new();
    let mut instanced = 0usize;
    let nodes: Vec<gltf::Node<'_>> = doc.nodes().collect();
    let mut stack: Vec<(usize, Mat4, Vec<String>)> =
        roots.into_iter().map(|n| (n, Mat4::IDENTITY, Vec::new())).collect();
    while let Some((index, parent, mut names)) = stack.pop() {
        let node = &nodes[index];
        let local = Mat4::from_cols_array_2d(&node.transform().matrix());
        let world = parent * local;
        if let Some(n) = node.name() {
            // The nearest names decide leaf or wood; a bounded list keeps a deep
            // chain of named nodes linear.
            if names.len() == MAX_NAMES {
                names.remove(0);
            }
            names.push(n.to_string());
        }
        if let Some(mesh) = node.mesh() {
            let mut mesh_names = names.clone();
            if let Some(n) = mesh.name() {
                mesh_names.push(n.to_string());
            }
            // EXT_mesh_gpu_instancing: the mesh once per instance row.
            // A skinned mesh is placed by its joints, not by its node (§3.7.3.3).
            let joints = match node.skin() {
                Some(s) => {
                    skinned += 1;
                    Some(skin::joint_matrices(&s, &buffers, &globals)?)
                }
                None => None,
            };
            let instances = match extensions::instancing(&raw, index) {
                Some(attrs) => {
                    let list = instance_transforms(doc, &buffers, attrs, index)?;
                    instanced += list.len();
                    list
                }
                None => vec![Mat4::IDENTITY],
            };
            for prim in mesh.primitives() {
                use gltf::mesh::Mode;
                if !matches!(prim.mode(), Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan) {
                    *skipped_modes.entry(format!("{:?}", prim.mode())).or_default() += 1;
                    continue;
                }
                let mat = prim.material();
                let slot_index = mat.index().unwrap_or(doc.materials().len());
                let material = match material_slot[slot_index] {
                    Some(m) => m,
                    None => {
                        let m = import_material(&mat, &mesh_names, classifier, doc, &buffers, base, &mut images)?;
                        texture_bytes += m.texture.as_ref().map_or(0, |t| t.as_raw().len() as u64);
                        if texture_bytes > MAX_TEXTURE_BYTES {
                            bail!(
                                "the model's textures decode to more than {} MiB (material {:?}): downscale them",
                                MAX_TEXTURE_BYTES >> 20,
                                m.name
                            );
                        }
                        model.materials.push(m);
                        let idx = u16::try_from(model.materials.len() - 1)
                            .map_err(|_| anyhow!("more than 65535 materials"))?;
                        material_slot[slot_index] = Some(idx);
                        idx
                    }
                };
                let what = format!("mesh {:?} primitive {}", mesh.name().unwrap_or("?"), prim.index());
                let uv = uv_sets[slot_index];
                let per_vertex = match &joints {
                    Some(j) => Some(skin::vertex_matrices(&prim, &buffers, j, &what)?),
                    None => None,
                };
                for instance in &instances {
                    let placed = Placement { world: world * *instance, per_vertex: per_vertex.as_deref() };
                    append_primitive(&mut model, &prim, &buffers, placed, material, uv, &what)
                        .with_context(|| format!("{what} of {}", graph::describe(doc, index)))?;
                }
            }
        }
        for child in node.children() {
            stack.push((child.index(), world, names.clone()));
        }
    }
    for (mode, n) in &skipped_modes {
        model.notes.push(format!("{n} primitives drawn as {mode} (not triangles) were left out"));
    }
    if skinned > 0 {
        model.notes.push(format!("{skinned} skinned meshes placed in their rest pose"));
    }
    if meshopt_views > 0 {
        model.notes.push(format!("{meshopt_views} meshopt-compressed buffer views decoded"));
    }
    if instanced > 0 {
        model.notes.push(format!("{instanced} mesh instances (EXT_mesh_gpu_instancing) expanded"));
    }
    for m in model.materials.iter().filter(|m| m.blended) {
        model.notes.push(format!(
            "material {:?} is alpha-blended: drawn as a cut-out at alpha {} (no sorting in a forest)",
            m.name, m.alpha_cutoff
        ));
    }
    if model.triangles.is_empty() {
        bail!("the model has no triangle meshes");
    }
    if !model.materials.iter().any(|m| m.kind == MaterialKind::Leaf) {
        bail!("the model has no leaves: no material is alpha-masked/blended or named like leaves; name them with --leaf-material PATTERN");
    }
    check_extent(&model)?;
    recenter(&mut model);
    Ok(model)
}

/// Where a primitive's vertices go: the node's world transform, or per vertex
/// (skinned meshes) the weighted joint matrices.
#[derive(Clone, Copy)]
struct Placement<'a> {
    world: Mat4,
    per_vertex: Option<&'a [Mat4]>,
}

/// The instance transforms of node `node`'s `EXT_mesh_gpu_instancing`
/// (TRANSLATION, ROTATION, SCALE accessors; quantised rows allowed), checked
/// like every accessor and bounded like node reuse.
fn instance_transforms(
    doc: &gltf::Document,
    buffers: &[Vec<u8>],
    [t, r, sc]: [Option<usize>; 3],
    node: usize,
) -> Result<Vec<Mat4>> {
    let what = |k: &str| format!("{k} of EXT_mesh_gpu_instancing of node {node}");
    let accessor = |i: Option<usize>, k: &str| -> Result<Option<gltf::Accessor<'_>>> {
        let Some(i) = i else { return Ok(None) };
        let a = doc.accessors().nth(i).ok_or_else(|| anyhow!("{}: accessor {i} does not exist", what(k)))?;
        accessors::check(&a, buffers, &what(k))?;
        Ok(Some(a))
    };
    let (ta, ra, sa) = (accessor(t, "TRANSLATION")?, accessor(r, "ROTATION")?, accessor(sc, "SCALE")?);
    let count = [&ta, &ra, &sa].iter().filter_map(|a| a.as_ref().map(gltf::Accessor::count)).max().unwrap_or(0);
    if count == 0 {
        bail!("{}: no TRANSLATION, ROTATION or SCALE accessor", what("attributes"));
    }
    if count as u64 > graph::MAX_NODE_INSTANCES {
        bail!(
            "node {node} instances its mesh {count} times, more than {} (a tree has far fewer)",
            graph::MAX_NODE_INSTANCES
        );
    }
    let read3 = |a: &Option<gltf::Accessor<'_>>, k: &str| -> Result<Vec<[f32; 3]>> {
        a.as_ref().map_or(Ok(Vec::new()), |a| {
            accessors::read_floats::<3>(a, buffers).ok_or_else(|| {
                anyhow!("{}: accessor {} is {:?} of {:?}, not VEC3", what(k), a.index(), a.dimensions(), a.data_type())
            })
        })
    };
    let rotations = match &ra {
        Some(a) => accessors::read_floats::<4>(a, buffers).ok_or_else(|| {
            let (d, t) = (a.dimensions(), a.data_type());
            anyhow!("{}: accessor {} is {d:?} of {t:?}, not VEC4", what("ROTATION"), a.index())
        })?,
        None => Vec::new(),
    };
    let (translations, scales) = (read3(&ta, "TRANSLATION")?, read3(&sa, "SCALE")?);
    Ok(extensions::instance_matrices(&translations, &rotations, &scales, count))
}

/// gltf-json 1.4 reads a primitive's POSITION accessor by its index before it
/// has checked the index (a panic on hostile input, found by the import_gltf
/// fuzz target): the indices are checked here first.
/// The file's JSON as a value (GLB: its JSON chunk), for what the gltf crate
/// does not expose; `Null` when it does not parse (the gltf crate then says why).
fn raw_json(bytes: &[u8]) -> Result<serde_json::Value> {
    let json = if bytes.starts_with(b"glTF") {
        gltf::Glb::from_slice(bytes).map_err(|e| anyhow!("not a valid GLB file: {e}"))?.json
    } else {
        std::borrow::Cow::Borrowed(bytes)
    };
    // Lossy: the gltf crate skips unknown keys without checking their UTF-8.
    Ok(serde_json::from_str(&String::from_utf8_lossy(&json)).unwrap_or(serde_json::Value::Null))
}

fn check_position_indices(root: &serde_json::Value) -> Result<()> {
    let accessors = root.get("accessors").and_then(|a| a.as_array()).map_or(0, Vec::len) as u64;
    let meshes = root.get("meshes").and_then(|m| m.as_array()).map(Vec::as_slice).unwrap_or_default();
    for (m, mesh) in meshes.iter().enumerate() {
        let primitives = mesh.get("primitives").and_then(|p| p.as_array()).map(Vec::as_slice).unwrap_or_default();
        for (p, primitive) in primitives.iter().enumerate() {
            if let Some(index) = primitive.pointer("/attributes/POSITION").and_then(serde_json::Value::as_u64) {
                if index >= accessors {
                    bail!("mesh {m} primitive {p}: POSITION names accessor {index}, but there are {accessors}");
                }
            }
        }
    }
    Ok(())
}

/// A tree has a height, and a size a float can scale: a flat model (height 0,
/// or a node scale of 0 or 1e-30) would be scaled thousands of times to its
/// placement height; a node scale of 1e30 would overflow later.
fn check_extent(model: &ImportedModel) -> Result<()> {
    let (lo, hi) = model.bounds();
    let size = hi - lo;
    let widest = size.max_element();
    // (Written so that NaN fails too.)
    if widest.is_nan() || widest > MAX_MODEL_EXTENT {
        bail!(
            "the model is {:.3e} × {:.3e} × {:.3e} units, larger than {MAX_MODEL_EXTENT:e}: check the node scales",
            size.x,
            size.y,
            size.z
        );
    }
    if size.z.is_nan() || size.z < MIN_MODEL_HEIGHT || size.z < widest * 1e-3 {
        bail!(
            "the model has no height ({:.3e} units tall, {:.3e} wide): a tree must extend along glTF's +Y (up); \
             check the node scales and the up axis",
            size.z,
            widest
        );
    }
    Ok(())
}

fn import_material(
    mat: &gltf::Material<'_>,
    names: &[String],
    classifier: &Classifier,
    doc: &gltf::Document,
    buffers: &[Vec<u8>],
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
                    load_image(doc, idx, buffers, base).with_context(|| format!("image {idx} of material {name:?}"))?,
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
        blended: mat.alpha_mode() == gltf::material::AlphaMode::Blend,
    })
}

/// The encoded bytes of image `index`, read from the JSON directly: the gltf
/// crate's `Image::source` unwraps a missing `mimeType` or `uri` (a panic on
/// hostile input, found by the import_gltf fuzz target).
fn load_image(
    doc: &gltf::Document,
    index: usize,
    buffers: &[Vec<u8>],
    base: Option<&Path>,
) -> Result<image::RgbaImage> {
    let json = doc.as_json().images.get(index).ok_or_else(|| anyhow!("missing image"))?;
    let mime = json.mime_type.as_ref().map(|m| m.0.as_str());
    if let Some(message) = extensions::ktx2_image(index, mime, json.uri.as_deref()) {
        bail!("{message}");
    }
    let encoded: Vec<u8> = match (&json.buffer_view, &json.uri) {
        (Some(view), _) => {
            let view = doc.views().nth(view.value()).ok_or_else(|| anyhow!("missing buffer view"))?;
            let data = buffers.get(view.buffer().index()).ok_or_else(|| anyhow!("missing buffer"))?;
            let end = view.offset().checked_add(view.length()).ok_or_else(|| anyhow!("bad buffer view"))?;
            data.get(view.offset()..end)
                .ok_or_else(|| anyhow!("buffer view {}..{end} is outside its buffer", view.offset()))?
                .to_vec()
        }
        (None, Some(uri)) => {
            sources::read_uri(uri, base, sources::MAX_IMAGE_BYTES).with_context(|| format!("external image {uri:?}"))?
        }
        (None, None) => bail!("the image has neither a bufferView nor a uri"),
    };
    let img = image::load_from_memory(&encoded).map_err(|e| anyhow!("cannot decode image (PNG/JPEG/WebP): {e}"))?;
    Ok(img.to_rgba8())
}

/// glTF Y-up to Sylva Z-up.
fn y_up_to_z_up(v: Vec3) -> Vec3 {
    Vec3::new(v.x, -v.z, v.y)
}

fn append_primitive(
    model: &mut ImportedModel,
    prim: &gltf::Primitive<'_>,
    buffers: &[Vec<u8>],
    placed: Placement<'_>,
    material: u16,
    uv_set: extensions::UvSet,
    what: &str,
) -> Result<()> {
    let world = placed.world;
    // Every accessor this primitive reads, checked before the reader sees it.
    for (semantic, accessor) in prim.attributes() {
        let role = format!("{semantic:?} of {what}");
        accessors::check_type(&accessor, Some(&semantic), &role)?;
        accessors::check(&accessor, buffers, &role)?;
    }
    if let Some(accessor) = prim.indices() {
        let role = format!("indices of {what}");
        accessors::check_type(&accessor, None, &role)?;
        accessors::check(&accessor, buffers, &role)?;
    }
    let position_accessor = prim.get(&gltf::Semantic::Positions).ok_or_else(|| anyhow!("no POSITION attribute"))?;
    let n = position_accessor.count();
    // glTF: every attribute of a primitive has the same count.
    for (semantic, accessor) in prim.attributes() {
        if accessor.count() != n {
            bail!(
                "accessor {} ({semantic:?} of {what}) has {} elements for {n} vertices",
                accessor.index(),
                accessor.count()
            );
        }
    }
    let index_count = prim.indices().map_or(n, |a| a.count());
    let mode = prim.mode();
    if mode == gltf::mesh::Mode::Triangles && !index_count.is_multiple_of(3) {
        bail!("{index_count} indices are no whole number of triangles");
    }
    let triangles = match mode {
        gltf::mesh::Mode::TriangleStrip | gltf::mesh::Mode::TriangleFan => index_count.saturating_sub(2),
        _ => index_count / 3,
    };
    if model.vertices.len().saturating_add(n) > MAX_VERTICES || model.triangles.len() + triangles > MAX_TRIANGLES {
        bail!(
            "the model expands to more than {MAX_VERTICES} vertices or {MAX_TRIANGLES} triangles (a tree model has \
             far fewer: check for nodes that reuse a big mesh many times)"
        );
    }
    let reader = prim.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
    // Positions, normals and texture coordinates may be quantised (KHR_mesh_quantization).
    let positions: Vec<[f32; 3]> =
        accessors::read_floats(&position_accessor, buffers).ok_or_else(|| anyhow!("no POSITION attribute"))?;
    let normals: Option<Vec<[f32; 3]>> =
        prim.get(&gltf::Semantic::Normals).and_then(|a| accessors::read_floats(&a, buffers));
    // The set the base colour texture reads (texCoord / KHR_texture_transform), transformed.
    let uvs: Option<Vec<[f32; 2]>> = prim
        .get(&gltf::Semantic::TexCoords(uv_set.set))
        .and_then(|a| accessors::read_floats::<2>(&a, buffers))
        .map(|uvs| uvs.into_iter().map(|uv| uv_set.apply(uv)).collect());
    let colors: Option<Vec<[f32; 4]>> = reader.read_colors(0).map(|c| c.into_rgba_f32().collect());
    let strip: Vec<u32> = match reader.read_indices() {
        Some(i) => i.into_u32().collect(),
        None => (0..n as u32).collect(),
    };
    let strip_len = strip.len();
    // Strips and fans as triangle lists (glTF 2.0 §3.7.2.1), windings kept.
    let indices: Vec<u32> = match mode {
        gltf::mesh::Mode::TriangleStrip => (0..strip.len().saturating_sub(2))
            .flat_map(|i| {
                if i % 2 == 0 {
                    [strip[i], strip[i + 1], strip[i + 2]]
                } else {
                    [strip[i + 1], strip[i], strip[i + 2]]
                }
            })
            .collect(),
        gltf::mesh::Mode::TriangleFan => {
            (1..strip.len().saturating_sub(1)).flat_map(|i| [strip[0], strip[i], strip[i + 1]]).collect()
        }
        _ => strip,
    };
    // The checks above make short reads impossible; a reader that still stops
    // early must not bake part of a model silently.
    let short = |got: usize, want: usize, name: &str| {
        if got == want {
            Ok(())
        } else {
            Err(anyhow!("read {got} of the {want} {name}: the accessor is truncated"))
        }
    };
    short(positions.len(), n, "positions")?;
    short(strip_len, index_count, "indices")?;
    for (got, name) in [
        (normals.as_ref().map(Vec::len), "normals"),
        (uvs.as_ref().map(Vec::len), "texture coordinates"),
        (colors.as_ref().map(Vec::len), "colours"),
    ] {
        if let Some(got) = got {
            if got < n {
                bail!("read {got} {name} for {n} vertices: the accessor is too short");
            }
        }
    }
    if indices.iter().any(|&i| i as usize >= n) {
        bail!("an index is out of range of the {n} vertices");
    }
    let normal_matrix = world.inverse().transpose();
    let first = u32::try_from(model.vertices.len()).map_err(|_| anyhow!("too many vertices"))?;
    // A skinned mesh: each vertex by its own weighted joint matrix (the node's is ignored).
    let matrix_of = |i: usize| placed.per_vertex.and_then(|m| m.get(i)).copied();
    let flip = matrix_of(0).unwrap_or(world).determinant() < 0.0;
    for (i, &position) in positions.iter().enumerate() {
        let (m, nm) = match matrix_of(i) {
            Some(m) => (m, m.inverse().transpose()),
            None => (world, normal_matrix),
        };
        let p = m.transform_point3(Vec3::from(position));
        let nrm = normals
            .as_ref()
            .and_then(|ns| ns.get(i))
            .map(|&v| nm.transform_vector3(Vec3::from(v)).normalize_or_zero())
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
mod tests;
