//! The GLBs of the export: a glTF document built up (buffers, views,
//! accessors named by `gltf::json`'s constants), a species' mesh levels and far
//! tier as meshes, and a tile's trees as EXT_mesh_gpu_instancing instances
//! with EXT_structural_metadata features.

use gltf::json::accessor::{FLOAT, UNSIGNED_BYTE, UNSIGNED_INT};
use gltf::json::buffer::{ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER};
use gltf::json::texture::{CLAMP_TO_EDGE, LINEAR, LINEAR_MIPMAP_LINEAR, REPEAT};
use serde_json::{json, Value};
use std::collections::BTreeMap;

use super::*;

/// A glTF document being built: arrays by name, and the GLB's own binary chunk.
#[derive(Default)]
pub(super) struct Gltf {
    pub(super) arrays: BTreeMap<&'static str, Vec<Value>>,
    pub(super) bin: Vec<u8>,
    /// Top-level extensions (`EXT_structural_metadata`).
    pub(super) extensions: serde_json::Map<String, Value>,
}

impl Gltf {
    pub(super) fn push(&mut self, array: &'static str, v: Value) -> usize {
        let a = self.arrays.entry(array).or_default();
        a.push(v);
        a.len() - 1
    }

    /// A texture of the shared image `uri` (relative to the tileset): sampled
    /// linearly with trilinear mips, or (`mips` false) without mips — an
    /// alpha-tested billboard's mips average its sparse leaves' coverage below
    /// the cutoff, and a far tree would vanish; repeated, or (`clamp`) clamped
    /// to its edges (a ground image: its edge must not blend with the opposite one).
    pub(super) fn texture(&mut self, uri: &str, mips: bool, clamp: bool) -> usize {
        let image = self.push("images", json!({"uri": format!("../{uri}")}));
        let min_filter = if mips { LINEAR_MIPMAP_LINEAR } else { LINEAR };
        let wrap = if clamp { CLAMP_TO_EDGE } else { REPEAT };
        let samplers = self.arrays.get("samplers").map_or(&[][..], |v| &v[..]);
        let sampler = match samplers.iter().position(|v| v["minFilter"] == min_filter && v["wrapS"] == wrap) {
            Some(i) => i,
            None => self
                .push("samplers", json!({"magFilter": LINEAR, "minFilter": min_filter, "wrapS": wrap, "wrapT": wrap})),
        };
        self.push("textures", json!({"source": image, "sampler": sampler}))
    }

    /// Appends `data` to the GLB's chunk as a buffer view (8-byte aligned, as
    /// 64-bit metadata values need).
    pub(super) fn own_view(&mut self, data: &[u8]) -> usize {
        while !self.bin.len().is_multiple_of(8) {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(data);
        self.push("bufferViews", json!({"buffer": 0, "byteOffset": offset, "byteLength": data.len()}))
    }

    /// The GLB: header, JSON chunk (space-padded), binary chunk (zero-padded).
    pub(super) fn glb(mut self, used: &[&str], required: &[&str]) -> Vec<u8> {
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
pub(super) fn add_mesh(g: &mut Gltf, sp: &SpeciesOut, level: u32) -> usize {
    let mb = &sp.levels[&level];
    let buffer = g.push("buffers", json!({"uri": format!("../{}", mb.uri), "byteLength": mb.bytes})) + 1;
    let view = |g: &mut Gltf, k: usize, target: u32| {
        let (o, l) = mb.views[k];
        g.push("bufferViews", json!({"buffer": buffer, "byteOffset": o, "byteLength": l, "target": target}))
    };
    let (vp, vn, vu, vc, vi) = (
        view(g, 0, ARRAY_BUFFER),
        view(g, 1, ARRAY_BUFFER),
        view(g, 2, ARRAY_BUFFER),
        view(g, 3, ARRAY_BUFFER),
        view(g, 4, ELEMENT_ARRAY_BUFFER),
    );
    let n = mb.vertices;
    let pos = g.push(
        "accessors",
        json!({"bufferView": vp, "componentType": FLOAT, "count": n, "type": "VEC3", "min": mb.pos_min, "max": mb.pos_max}),
    );
    let nrm = g.push("accessors", json!({"bufferView": vn, "componentType": FLOAT, "count": n, "type": "VEC3"}));
    let uv = g.push("accessors", json!({"bufferView": vu, "componentType": FLOAT, "count": n, "type": "VEC2"}));
    let col = g.push(
        "accessors",
        json!({"bufferView": vc, "componentType": UNSIGNED_BYTE, "normalized": true, "count": n, "type": "VEC4"}),
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
            json!({"bufferView": vi, "byteOffset": u64::from(first) * 4, "componentType": UNSIGNED_INT, "count": count, "type": "SCALAR"}),
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
pub(super) fn far_material(g: &mut Gltf, sp: &SpeciesOut) -> usize {
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
        let at = g.push("accessors", json!({"bufferView": vt, "componentType": FLOAT, "count": n, "type": "VEC3"}));
        let ar = g.push("accessors", json!({"bufferView": vr, "componentType": FLOAT, "count": n, "type": "VEC4"}));
        let asc = g.push("accessors", json!({"bufferView": vs, "componentType": FLOAT, "count": n, "type": "VEC3"}));
        let af = g.push("accessors", json!({"bufferView": vf, "componentType": FLOAT, "count": n, "type": "SCALAR"}));
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
