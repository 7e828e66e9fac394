//! The GLBs of the export: a typed `gltf::json` document built up (buffers,
//! views, accessors, materials), a species' mesh levels and far tier as
//! meshes, and a tile's trees as EXT_mesh_gpu_instancing instances with
//! EXT_structural_metadata features (extensions `gltf::json` does not model:
//! their JSON goes into its `others` maps).

use gltf::json::accessor::{ComponentType, GenericComponentType, Type};
use gltf::json::buffer::Target;
use gltf::json::material::{AlphaCutoff, AlphaMode, PbrBaseColorFactor, PbrMetallicRoughness, StrengthFactor};
use gltf::json::mesh::{Primitive, Semantic};
use gltf::json::texture::{MagFilter, MinFilter, WrappingMode};
use gltf::json::validation::{Checked::Valid, USize64};
use gltf::json::{self, Index};
use serde_json::{json, Value};
use std::collections::BTreeMap;

use super::*;

/// A glTF document being built and the GLB's own binary chunk (buffer 0).
pub(super) struct Gltf {
    pub(super) root: json::Root,
    pub(super) bin: Vec<u8>,
}

impl Default for Gltf {
    fn default() -> Self {
        let mut root = json::Root::default();
        root.asset.generator = Some("sylva-bake export-3dtiles".into());
        // Buffer 0: the GLB's binary chunk (its length is set by `glb`).
        root.push(json::Buffer {
            byte_length: USize64(0),
            name: None,
            uri: None,
            extensions: None,
            extras: Default::default(),
        });
        Self { root, bin: Vec::new() }
    }
}

/// An attribute or index accessor: `count` elements of `type_` made of
/// `component`s, from `offset` bytes into `view`.
pub(super) struct Elements {
    pub(super) view: Index<json::buffer::View>,
    pub(super) offset: u64,
    pub(super) component: ComponentType,
    pub(super) normalized: bool,
    pub(super) count: usize,
    pub(super) type_: Type,
}

impl Elements {
    /// `count` elements of `type_` from the start of `view`, f32 components
    /// (change `component` and `normalized` for others).
    pub(super) fn of(view: Index<json::buffer::View>, count: usize, type_: Type) -> Self {
        Self { view, offset: 0, component: ComponentType::F32, normalized: false, count, type_ }
    }
}

/// A triangle list: (attributes, indices, material).
pub(super) type Part = (Vec<(Semantic, Index<json::Accessor>)>, Index<json::Accessor>, Index<json::Material>);

/// A material as the export draws it: a base colour (and texture), metallic 0,
/// roughness 1.
pub(super) struct Look {
    pub(super) name: String,
    pub(super) base_color: [f32; 4],
    pub(super) texture: Option<Index<json::Texture>>,
    pub(super) double_sided: bool,
    /// Alpha-tested at this cutoff (`None`: opaque).
    pub(super) alpha_cutoff: Option<f32>,
    /// Unlit (`KHR_materials_unlit`).
    pub(super) unlit: bool,
}

impl Gltf {
    /// A buffer beside the GLB (a species' shared mesh buffer, by `uri`).
    pub(super) fn buffer(&mut self, uri: String, bytes: u64) -> Index<json::Buffer> {
        self.root.push(json::Buffer {
            byte_length: USize64(bytes),
            name: None,
            uri: Some(uri),
            extensions: None,
            extras: Default::default(),
        })
    }

    /// A view of `length` bytes at `offset` in `buffer`, bound as `target`.
    pub(super) fn view(
        &mut self,
        buffer: Index<json::Buffer>,
        offset: u64,
        length: u64,
        target: Option<Target>,
    ) -> Index<json::buffer::View> {
        self.root.push(json::buffer::View {
            buffer,
            byte_length: USize64(length),
            byte_offset: Some(USize64(offset)),
            byte_stride: None,
            name: None,
            target: target.map(Valid),
            extensions: None,
            extras: Default::default(),
        })
    }

    /// An accessor of `e`, with the bounds `min..max` where given (positions
    /// must have them).
    pub(super) fn accessor(&mut self, e: Elements, bounds: Option<([f32; 3], [f32; 3])>) -> Index<json::Accessor> {
        self.root.push(json::Accessor {
            buffer_view: Some(e.view),
            byte_offset: (e.offset > 0).then_some(USize64(e.offset)),
            count: USize64(e.count as u64),
            component_type: Valid(GenericComponentType(e.component)),
            extensions: None,
            extras: Default::default(),
            type_: Valid(e.type_),
            min: bounds.map(|(lo, _)| json!(lo)),
            max: bounds.map(|(_, hi)| json!(hi)),
            name: None,
            normalized: e.normalized,
            sparse: None,
        })
    }

    /// A texture of the shared image `uri` (relative to the tileset): sampled
    /// linearly with trilinear mips, or (`mips` false) without mips — an
    /// alpha-tested billboard's mips average its sparse leaves' coverage below
    /// the cutoff, and a far tree would vanish; repeated, or (`clamp`) clamped
    /// to its edges (a ground image: its edge must not blend with the opposite one).
    pub(super) fn texture(&mut self, uri: &str, mips: bool, clamp: bool) -> Index<json::Texture> {
        let source = self.root.push(json::Image {
            buffer_view: None,
            mime_type: None,
            name: None,
            uri: Some(format!("../{uri}")),
            extensions: None,
            extras: Default::default(),
        });
        let min_filter = Valid(if mips { MinFilter::LinearMipmapLinear } else { MinFilter::Linear });
        let wrap = Valid(if clamp { WrappingMode::ClampToEdge } else { WrappingMode::Repeat });
        let sampler = match self.root.samplers.iter().position(|s| s.min_filter == Some(min_filter) && s.wrap_s == wrap)
        {
            Some(i) => Index::new(i as u32),
            None => self.root.push(json::texture::Sampler {
                mag_filter: Some(Valid(MagFilter::Linear)),
                min_filter: Some(min_filter),
                wrap_s: wrap,
                wrap_t: wrap,
                ..Default::default()
            }),
        };
        self.root.push(json::Texture {
            name: None,
            sampler: Some(sampler),
            source,
            extensions: None,
            extras: Default::default(),
        })
    }

    /// The material `look`.
    pub(super) fn material(&mut self, look: Look) -> Index<json::Material> {
        let base_color_texture = look.texture.map(|index| json::texture::Info {
            index,
            tex_coord: 0,
            extensions: None,
            extras: Default::default(),
        });
        // (`..Default::default()`: gltf features that name extensions add fields.)
        #[allow(clippy::needless_update)]
        let extensions = look.unlit.then(|| json::extensions::material::Material {
            others: [("KHR_materials_unlit".to_string(), json!({}))].into_iter().collect(),
            ..Default::default()
        });
        self.root.push(json::Material {
            name: Some(look.name),
            pbr_metallic_roughness: PbrMetallicRoughness {
                base_color_factor: PbrBaseColorFactor(look.base_color),
                base_color_texture,
                metallic_factor: StrengthFactor(0.0),
                roughness_factor: StrengthFactor(1.0),
                ..Default::default()
            },
            double_sided: look.double_sided,
            alpha_mode: Valid(if look.alpha_cutoff.is_some() { AlphaMode::Mask } else { AlphaMode::Opaque }),
            alpha_cutoff: look.alpha_cutoff.map(AlphaCutoff),
            extensions,
            ..Default::default()
        })
    }

    /// A mesh of `primitives`.
    pub(super) fn mesh(&mut self, name: &str, primitives: Vec<Part>) -> Index<json::Mesh> {
        let primitives = primitives
            .into_iter()
            .map(|(attributes, indices, material)| Primitive {
                attributes: attributes.into_iter().map(|(k, v)| (Valid(k), v)).collect(),
                extensions: None,
                extras: Default::default(),
                indices: Some(indices),
                material: Some(material),
                mode: Valid(json::mesh::Mode::Triangles),
                targets: None,
            })
            .collect();
        self.root.push(json::Mesh {
            extensions: None,
            extras: Default::default(),
            name: Some(name.to_string()),
            primitives,
            weights: None,
        })
    }

    /// The scene: `nodes`, each a named mesh with the extensions `others`.
    pub(super) fn scene(&mut self, nodes: Vec<(String, Index<json::Mesh>, serde_json::Map<String, Value>)>) {
        let nodes = nodes
            .into_iter()
            .map(|(name, mesh, others)| {
                self.root.push(json::Node {
                    name: Some(name),
                    mesh: Some(mesh),
                    #[allow(clippy::needless_update)] // (gltf features that name extensions add fields)
                    extensions: (!others.is_empty())
                        .then_some(json::extensions::scene::Node { others, ..Default::default() }),
                    ..Default::default()
                })
            })
            .collect();
        let scene = self.root.push(json::Scene { extensions: None, extras: Default::default(), name: None, nodes });
        self.root.scene = Some(scene);
    }

    /// Appends `data` to the GLB's chunk as a buffer view (8-byte aligned, as
    /// 64-bit metadata values need).
    pub(super) fn own_view(&mut self, data: &[u8]) -> Index<json::buffer::View> {
        self.own_view_for(data, None)
    }

    /// As [`Self::own_view`], bound as `target` (vertex or index data).
    pub(super) fn own_view_for(&mut self, data: &[u8], target: Option<Target>) -> Index<json::buffer::View> {
        while !self.bin.len().is_multiple_of(8) {
            self.bin.push(0);
        }
        let offset = self.bin.len() as u64;
        self.bin.extend_from_slice(data);
        self.view(Index::new(0), offset, data.len() as u64, target)
    }

    /// Sets a top-level extension (`EXT_structural_metadata`).
    pub(super) fn extension(&mut self, name: &str, value: Value) {
        self.root.extensions.get_or_insert_with(Default::default).others.insert(name.to_string(), value);
    }

    /// The GLB: header, JSON chunk (space-padded), binary chunk (zero-padded).
    pub(super) fn glb(mut self, used: &[&str], required: &[&str]) -> Vec<u8> {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        self.root.buffers[0].byte_length = USize64(self.bin.len() as u64);
        self.root.extensions_used = used.iter().map(|s| s.to_string()).collect();
        self.root.extensions_required = required.iter().map(|s| s.to_string()).collect();
        let mut js = self.root.to_vec().expect("JSON");
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
pub(super) fn add_mesh(g: &mut Gltf, sp: &SpeciesOut, level: u32) -> Index<json::Mesh> {
    let mb = &sp.levels[&level];
    let buffer = g.buffer(format!("../{}", mb.uri), mb.bytes);
    let mut view = |k: usize, target: Target| {
        let (o, l) = mb.views[k];
        g.view(buffer, o, l, Some(target))
    };
    let (vp, vn, vu, vc, vi) = (
        view(0, Target::ArrayBuffer),
        view(1, Target::ArrayBuffer),
        view(2, Target::ArrayBuffer),
        view(3, Target::ArrayBuffer),
        view(4, Target::ElementArrayBuffer),
    );
    let n = mb.vertices as usize;
    let pos = g.accessor(Elements::of(vp, n, Type::Vec3), Some((mb.pos_min, mb.pos_max)));
    let nrm = g.accessor(Elements::of(vn, n, Type::Vec3), None);
    let uv = g.accessor(Elements::of(vu, n, Type::Vec2), None);
    let colors = Elements { component: ComponentType::U8, normalized: true, ..Elements::of(vc, n, Type::Vec4) };
    let col = g.accessor(colors, None);
    let mut materials: BTreeMap<usize, Index<json::Material>> = BTreeMap::new();
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
            let texture = m.texture_layer.and_then(|l| sp.layers.get(&l)).map(|uri| g.texture(uri, true, false));
            g.material(Look {
                name: m.name.clone(),
                base_color: m.base_color,
                texture,
                double_sided: m.double_sided,
                alpha_cutoff: (m.alpha_cutoff > 0.0).then_some(m.alpha_cutoff),
                unlit: false,
            })
        });
        let indices = Elements {
            offset: u64::from(first) * 4,
            component: ComponentType::U32,
            ..Elements::of(vi, count as usize, Type::Scalar)
        };
        let idx = g.accessor(indices, None);
        let attributes = vec![
            (Semantic::Positions, pos),
            (Semantic::Normals, nrm),
            (Semantic::TexCoords(0), uv),
            (Semantic::Colors(0), col),
        ];
        primitives.push((attributes, idx, material));
    }
    g.mesh(&sp.meta.name, primitives)
}

/// The far quads' material: the species' billboard, alpha-tested at ½ as
/// Sylva's viewer tests it, both faces, unlit colour × the sun's light.
pub(super) fn far_material(g: &mut Gltf, sp: &SpeciesOut) -> Index<json::Material> {
    let texture = sp.billboard.as_ref().map(|uri| g.texture(uri, false, false));
    g.material(Look {
        name: format!("{} far", sp.meta.name),
        base_color: [1.0; 4],
        texture,
        double_sided: true,
        alpha_cutoff: Some(0.5),
        unlit: false,
    })
}

/// A tile's trees by species, placed in the tile's frame.
pub(super) type Placed = BTreeMap<u32, Vec<ExportedTree>>;

/// What the property table says of a tile's trees: ids, and the inventory's
/// attributes where the scene has them.
pub(super) struct TreeData<'a> {
    pub(super) ids: Vec<u64>,
    /// Text ids of the trees that have one (`.ids` version 2), by tile index.
    pub(super) texts: Vec<(u32, String)>,
    pub(super) codes:
        Option<(&'a sylva::format::attributes::AttributeSchema, sylva::format::attributes::AttributeCodes)>,
    /// Species model names (the `model` property).
    pub(super) models: Vec<&'a str>,
    /// Property names of the attribute columns (identifiers, unique).
    pub(super) names: &'a [String],
}

/// Property identifiers for the attribute columns: `[A-Za-z_][A-Za-z0-9_]*`,
/// unique, none of them `id`, `id_text` or `model`.
pub(super) fn property_names(schema: Option<&sylva::format::attributes::AttributeSchema>) -> Vec<String> {
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
pub(super) fn metadata_schema(schema: Option<&sylva::format::attributes::AttributeSchema>, names: &[String]) -> Value {
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
pub(super) const NO_NUMBER: f64 = -1.0e300;

/// A property table of `rows` (tile indices, GLB order) in `g`.
pub(super) fn property_table(g: &mut Gltf, data: &TreeData<'_>, placed: &Placed, rows: &[u32]) -> Value {
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
pub(super) fn tile_glb(
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
        let at = g.accessor(Elements::of(vt, n, Type::Vec3), None);
        let ar = g.accessor(Elements::of(vr, n, Type::Vec4), None);
        let asc = g.accessor(Elements::of(vs, n, Type::Vec3), None);
        let af = g.accessor(Elements::of(vf, n, Type::Scalar), None);
        let extensions = json!({
            "EXT_mesh_gpu_instancing": {
                "attributes": {"TRANSLATION": at, "ROTATION": ar, "SCALE": asc, "_FEATURE_ID_0": af},
            },
            "EXT_instance_features": {
                "featureIds": [{"featureCount": n, "attribute": 0, "propertyTable": 0, "label": "tree"}],
            },
        });
        let Value::Object(others) = extensions else { unreachable!("an object") };
        nodes.push((sp.meta.name.clone(), mesh, others));
    }
    let table = property_table(&mut g, data, placed, &rows);
    g.extension("EXT_structural_metadata", json!({"schema": meta_schema, "propertyTables": [table]}));
    g.scene(nodes);
    g.glb(
        &["EXT_mesh_gpu_instancing", "EXT_instance_features", "EXT_structural_metadata"],
        &["EXT_mesh_gpu_instancing"],
    )
}
