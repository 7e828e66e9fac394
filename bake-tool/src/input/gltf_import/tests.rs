//! Import tests: real exporter layouts, and broken or hostile files.
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
    let (gltf, bin) = multi_primitive_parts();
    glb(&gltf, &bin)
}

/// The JSON and binary chunk of [`multi_primitive_glb`], to be broken by tests.
fn multi_primitive_parts() -> (serde_json::Value, Vec<u8>) {
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
    (gltf, bin)
}

#[test]
fn imports_interleaved_multi_primitive_glb_with_transforms() {
    // `SYLVA_WRITE_FUZZ_SEED=DIR` writes this GLB as a seed of the import_gltf fuzz target.
    if let Some(dir) = std::env::var_os("SYLVA_WRITE_FUZZ_SEED") {
        std::fs::write(Path::new(&dir).join("multi_primitive.glb"), multi_primitive_glb()).unwrap();
    }
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
        [accessors(0, 1, 2, 0).as_array().unwrap().clone(), accessors(0, 1, 2, 4).as_array().unwrap().clone()].concat();
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
    // A GLB header declaring fewer bytes than itself (found by the fuzz target).
    let mut short = multi_primitive_glb();
    short[8..12].copy_from_slice(&5u32.to_le_bytes());
    assert!(import_slice(&short, None, &c).unwrap_err().to_string().contains("header declares 5 bytes"));
    // An image without mimeType (read: the format is in its bytes) or without
    // any source (an error): the gltf crate unwrapped both.
    let (mut g, bin) = multi_primitive_parts();
    g["images"][0] = json!({"bufferView": 3});
    assert!(import_slice(&glb(&g, &bin), None, &c).unwrap().materials[1].texture.is_some());
    g["images"][0] = json!({"name": "nothing"});
    let e = format!("{:#}", import_slice(&glb(&g, &bin), None, &c).unwrap_err());
    assert!(e.contains("neither a bufferView nor a uri"), "{e}");
    // A POSITION accessor index past the accessors (gltf-json's check panicked).
    let (mut g, bin) = multi_primitive_parts();
    g["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = json!(99);
    let e = import_slice(&glb(&g, &bin), None, &c).unwrap_err().to_string();
    assert!(e.contains("POSITION names accessor 99"), "{e}");
    // ... also with bytes that are no UTF-8 in a key the gltf crate ignores.
    g["accessors"][0]["unknownKEY"] = json!(1);
    let mut bytes = glb(&g, &bin);
    let at = bytes.windows(10).position(|w| w == b"unknownKEY").unwrap();
    bytes[at + 7] = 0xf9;
    let e = import_slice(&bytes, None, &c).unwrap_err().to_string();
    assert!(e.contains("POSITION names accessor 99"), "{e}");
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

/// Imports `gltf` + `bin` as a GLB and returns the error text.
fn import_error(gltf: &serde_json::Value, bin: &[u8]) -> String {
    match import_slice(&glb(gltf, bin), None, &Classifier::default()) {
        Ok(m) => panic!("imported {} triangles from a broken file", m.triangles.len()),
        Err(e) => format!("{e:#}"),
    }
}

#[test]
fn node_cycles_and_reuse_are_refused_naming_the_node() {
    let (base, bin) = multi_primitive_parts();
    // A node that lists itself (this hung the bake at 100 % CPU).
    let mut g = base.clone();
    g["nodes"][1]["children"] = json!([1]);
    let e = import_error(&g, &bin);
    assert!(e.contains("node 1 (\"TreeMesh\") lists itself"), "{e}");
    // A two-node loop 0 → 1 → 0 (this grew memory to GBs).
    let mut g = base.clone();
    g["nodes"][1]["children"] = json!([0]);
    let e = import_error(&g, &bin);
    assert!(e.contains("is its own descendant") && e.contains("node 0 (\"Tree\")"), "{e}");
    // A DAG 24 levels deep, each node listing the next one twice: 2^24 copies.
    let mut g = base.clone();
    let mut nodes = vec![json!({"name": "Tree", "children": [1]}), json!({"name": "TreeMesh", "mesh": 0})];
    for level in 0..24 {
        let next = nodes.len() + 1;
        nodes.push(json!({"name": format!("level{level}"), "mesh": 0, "children": [next, next]}));
    }
    nodes.push(json!({"name": "last", "mesh": 0}));
    nodes[0]["children"] = json!([1, 2]);
    g["nodes"] = json!(nodes);
    let e = import_error(&g, &bin);
    assert!(e.contains("node instances") && e.contains("level"), "{e}");
    // Reuse within the budget is instancing, as in glTF viewers: a node listed
    // by two parents is imported twice.
    let mut g = base.clone();
    g["nodes"] = json!([
        {"name": "Tree", "children": [1, 2]},
        {"name": "a", "children": [3]},
        {"name": "b", "children": [3], "translation": [5.0, 0.0, 0.0]},
        {"name": "TreeMesh", "mesh": 0}
    ]);
    let m = import_slice(&glb(&g, &bin), None, &Classifier::default()).unwrap();
    assert_eq!(m.triangles.len(), 8, "two instances of two quads");
}

#[test]
fn accessors_past_their_buffer_are_errors_naming_the_accessor() {
    let (base, bin) = multi_primitive_parts();
    // An index accessor whose count runs past its view (baked 7,093 of 10,640
    // leaf triangles silently before).
    let mut g = base.clone();
    g["accessors"][9]["count"] = json!(600);
    let e = import_error(&g, &bin);
    assert!(e.contains("accessor 9 (indices of mesh \"tree\" primitive 1)") && e.contains("buffer view 2"), "{e}");
    // A POSITION accessor past its view (reported as "no POSITION attribute" before).
    let mut g = base.clone();
    g["accessors"][0]["count"] = json!(400);
    let e = import_error(&g, &bin);
    assert!(e.contains("accessor 0 (Positions of mesh \"tree\" primitive 0)") && e.contains("400 elements"), "{e}");
    // A view past its buffer.
    let mut g = base.clone();
    g["bufferViews"][1]["byteOffset"] = json!(100_000);
    let e = import_error(&g, &bin);
    assert!(e.contains("buffer view 1 spans bytes 100000..100032 of buffer 0"), "{e}");
    // A stride smaller than the element.
    let mut g = base.clone();
    g["bufferViews"][0]["byteStride"] = json!(8);
    let e = import_error(&g, &bin);
    assert!(e.contains("byteStride 8"), "{e}");
    // A buffer that declares more than the GLB holds.
    let mut g = base.clone();
    g["buffers"][0]["byteLength"] = json!(bin.len() + 4096);
    let e = import_error(&g, &bin);
    assert!(e.contains("buffer 0 declares"), "{e}");
}

#[test]
fn flat_tiny_and_huge_models_are_refused_up_front() {
    let (base, bin) = multi_primitive_parts();
    for (scale, what) in
        [([1.0, 0.0, 1.0], "no height"), ([1e-30, 1e-30, 1e-30], "no height"), ([1e30, 1e30, 1e30], "larger than")]
    {
        let mut g = base.clone();
        g["nodes"][0]["scale"] = json!(scale);
        // The mesh node's rotation turns glTF y into y: the scale's y is the height.
        g["nodes"][1].as_object_mut().unwrap().remove("rotation");
        let e = import_error(&g, &bin);
        assert!(e.contains(what) && e.contains("node scales"), "{scale:?}: {e}");
    }
}

#[test]
fn buffer_uris_are_confined_to_the_model_folder() {
    let dir = std::env::temp_dir().join(format!("sylva-gltf-confined-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("model")).unwrap();
    let (mut g, bin) = multi_primitive_parts();
    std::fs::write(dir.join("model/tree.bin"), &bin).unwrap();
    std::fs::write(dir.join("outside.bin"), &bin).unwrap();
    let path = dir.join("model/tree.gltf");
    let import_with = |g: &serde_json::Value| {
        std::fs::write(&path, serde_json::to_vec(g).unwrap()).unwrap();
        import(&path, &Classifier::default())
    };
    g["buffers"][0]["uri"] = json!("tree.bin");
    assert_eq!(import_with(&g).unwrap().triangles.len(), 4, "a buffer beside the model loads");
    for uri in
        ["../outside.bin", "/etc/shadow", "/proc/self/environ", "/dev/zero", "file:///etc/passwd", "%2E%2E/outside.bin"]
    {
        g["buffers"][0]["uri"] = json!(uri);
        let e = format!("{:#}", import_with(&g).unwrap_err());
        assert!(e.contains("outside the model's folder") && e.contains("buffer 0"), "{uri}: {e}");
    }
    // A link inside the folder that leads out of it is refused too.
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink(dir.join("outside.bin"), dir.join("model/link.bin")).unwrap();
        g["buffers"][0]["uri"] = json!("link.bin");
        let e = format!("{:#}", import_with(&g).unwrap_err());
        assert!(e.contains("outside the model's folder"), "{e}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A small deterministic generator for the property test (xorshift64*).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n.max(1)
    }
}

/// Property test over node graphs and accessors: random graphs (self loops,
/// cycles, shared children, deep chains) and random accessor, view and buffer
/// numbers. Every import ends, without a panic, and either fails with an error
/// or imports exactly the triangles its expanded graph and accessors say —
/// never part of them.
#[test]
fn random_graphs_and_accessors_import_whole_or_fail_clearly() {
    let (base, bin) = multi_primitive_parts();
    let mut rng = Rng(0x5EED_0F61_F7A1);
    let (mut ok, mut failed) = (0, 0);
    for case in 0..400 {
        let mut g = base.clone();
        let n = 1 + rng.below(30) as usize;
        let mut nodes = Vec::new();
        for i in 0..n {
            let mut node = json!({"name": format!("n{i}")});
            if rng.below(2) == 0 {
                node["mesh"] = json!(0);
            }
            // Mostly trees and DAGs (children after their parent), sometimes any
            // node (loops, self loops).
            let kids: Vec<u64> = (0..rng.below(4))
                .filter_map(|_| match rng.below(16) {
                    0 => Some(rng.below(n as u64)),
                    _ if i + 1 < n => Some(i as u64 + 1 + rng.below((n - i - 1) as u64)),
                    _ => None,
                })
                .collect();
            if !kids.is_empty() {
                node["children"] = json!(kids);
            }
            nodes.push(node);
        }
        g["nodes"] = json!(nodes);
        g["scenes"] =
            json!([{"nodes": (0..1 + rng.below(2)).map(|_| rng.below(1 + n as u64 / 4)).collect::<Vec<_>>()}]);
        // Break one number in a third of the cases.
        match rng.below(9) {
            0 => g["accessors"][rng.below(10) as usize]["count"] = json!(rng.below(64)),
            1 => g["accessors"][rng.below(10) as usize]["byteOffset"] = json!(rng.below(300)),
            2 => g["bufferViews"][rng.below(4) as usize]["byteOffset"] = json!(rng.below(1200)),
            3 => g["bufferViews"][rng.below(4) as usize]["byteLength"] = json!(1 + rng.below(1200)),
            4 => g["buffers"][0]["byteLength"] = json!(rng.below(2 * bin.len() as u64)),
            5 => g["bufferViews"][0]["byteStride"] = json!(4 * (1 + rng.below(20))),
            _ => {}
        }
        match import_slice(&glb(&g, &bin), None, &Classifier::default()) {
            Err(_) => failed += 1,
            Ok(m) => {
                ok += 1;
                // Expand the graph here too (the import succeeded, so it is small).
                let mut expected = 0usize;
                let per_mesh: usize =
                    [4usize, 9].iter().map(|&a| g["accessors"][a]["count"].as_u64().unwrap() as usize / 3).sum();
                let mut stack: Vec<u64> =
                    g["scenes"][0]["nodes"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap()).collect();
                while let Some(i) = stack.pop() {
                    let node = &g["nodes"][i as usize];
                    if node.get("mesh").is_some() {
                        expected += per_mesh;
                    }
                    if let Some(kids) = node.get("children") {
                        stack.extend(kids.as_array().unwrap().iter().map(|v| v.as_u64().unwrap()));
                    }
                }
                assert_eq!(m.triangles.len(), expected, "case {case}: part of the model was imported");
                assert!(m.triangles.iter().flatten().all(|&i| (i as usize) < m.vertices.len()), "case {case}");
            }
        }
    }
    // Both outcomes occur, or the generator tests nothing.
    assert!(ok > 20 && failed > 20, "{ok} imported, {failed} refused");
}

#[test]
fn leaf_and_branch_patterns_are_globs_like_map() {
    use gltf::material::AlphaMode;
    let c = Classifier { leaf_patterns: vec!["*".into()], branch_patterns: Vec::new() };
    assert_eq!(c.classify(&["Bark_Mat", "trunk"], AlphaMode::Opaque), MaterialKind::Leaf, "'*' matches every name");
    let c = Classifier { leaf_patterns: vec!["mat_0*".into()], branch_patterns: vec!["*_1".into()] };
    assert_eq!(c.classify(&["Mat_03"], AlphaMode::Opaque), MaterialKind::Leaf);
    assert_eq!(c.classify(&["mesh_1"], AlphaMode::Mask), MaterialKind::Branch);
    // Without '*' a substring, as before.
    let c = Classifier { leaf_patterns: vec!["nadel".into()], branch_patterns: Vec::new() };
    assert_eq!(c.classify(&["Fichte_Nadeln"], AlphaMode::Opaque), MaterialKind::Leaf);
}

/// A one-material model as optimisers write it: `positions` (f32 unless
/// `quantized`), `uvs` in TEXCOORD_0 and `uvs1` in TEXCOORD_1, `indices` drawn
/// with `mode`; `extra` is merged into the root JSON (extensions, instancing).
fn optimised_model(
    positions: &[[f32; 3]],
    uvs: &[[f32; 2]],
    indices: &[u16],
    mode: u32,
    quantized: bool,
    extra: serde_json::Value,
) -> (serde_json::Value, Vec<u8>) {
    let mut bin = Vec::new();
    let pos_at = bin.len();
    for p in positions {
        for v in p {
            if quantized {
                bin.extend_from_slice(&(*v as i16).to_le_bytes());
            } else {
                bin.extend_from_slice(&v.to_le_bytes());
            }
        }
        if quantized {
            bin.extend_from_slice(&[0, 0]); // 4-byte aligned rows
        }
    }
    let uv_at = bin.len();
    for uv in uvs {
        for v in uv {
            bin.extend_from_slice(&((v * 65535.0) as u16).to_le_bytes());
        }
    }
    let uv1_at = bin.len();
    for uv in uvs {
        for v in uv {
            bin.extend_from_slice(&(v * 0.5).to_le_bytes());
        }
    }
    let idx_at = bin.len();
    for i in indices {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let tail = bin.len();
    let n = positions.len();
    let mut root = json!({
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": tail}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": pos_at, "byteLength": uv_at - pos_at, "byteStride": if quantized { 8 } else { 12 }},
            {"buffer": 0, "byteOffset": uv_at, "byteLength": uv1_at - uv_at},
            {"buffer": 0, "byteOffset": uv1_at, "byteLength": idx_at - uv1_at},
            {"buffer": 0, "byteOffset": idx_at, "byteLength": indices.len() * 2}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": if quantized { 5122 } else { 5126 }, "count": n, "type": "VEC3",
             "min": [-1.0, 0.0, 0.0], "max": [1.0, 4.0, 0.0]},
            {"bufferView": 1, "componentType": 5123, "normalized": true, "count": n, "type": "VEC2"},
            {"bufferView": 2, "componentType": 5126, "count": n, "type": "VEC2"},
            {"bufferView": 3, "componentType": 5123, "count": indices.len(), "type": "SCALAR"}
        ],
        "materials": [{"name": "leaves", "alphaMode": "MASK",
                        "pbrMetallicRoughness": {"baseColorFactor": [0.2, 0.6, 0.2, 1.0]}}],
        "meshes": [{"name": "tree", "primitives": [
            {"attributes": {"POSITION": 0, "TEXCOORD_0": 1, "TEXCOORD_1": 2}, "indices": 3, "material": 0, "mode": mode}]}],
        "nodes": [{"mesh": 0}],
        "scenes": [{"nodes": [0]}],
        "scene": 0
    });
    merge(&mut root, extra);
    (root, bin)
}

fn merge(a: &mut serde_json::Value, b: serde_json::Value) {
    match (a, b) {
        (serde_json::Value::Object(a), serde_json::Value::Object(b)) => {
            for (k, v) in b {
                merge(a.entry(k).or_insert(serde_json::Value::Null), v);
            }
        }
        (a, b) => *a = b,
    }
}

fn import_glb(root: &serde_json::Value, bin: &[u8]) -> Result<ImportedModel> {
    let bytes = glb(root, bin);
    // `SYLVA_FUZZ_SEEDS=fuzz/seeds/import_gltf cargo test -p sylva-bake --lib gltf_import`
    // writes every model these tests build as a seed of the import_gltf fuzz target.
    if let Some(dir) = std::env::var_os("SYLVA_FUZZ_SEEDS") {
        use std::hash::{Hash, Hasher};
        let mut h = std::collections::hash_map::DefaultHasher::new();
        bytes.hash(&mut h);
        std::fs::write(std::path::Path::new(&dir).join(format!("ext-{:016x}.glb", h.finish())), &bytes).unwrap();
    }
    import_slice(&bytes, None, &Classifier::default())
}

const QUAD: [[f32; 3]; 4] = [[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [-1.0, 4.0, 0.0], [1.0, 4.0, 0.0]];
const QUAD_UV: [[f32; 2]; 4] = [[0.0, 1.0], [1.0, 1.0], [0.0, 0.0], [1.0, 0.0]];

#[test]
fn strips_and_fans_become_triangles_and_lines_are_reported() {
    // A strip of 4 vertices: 2 triangles, the second with its winding restored.
    let (root, bin) = optimised_model(&QUAD, &QUAD_UV, &[0, 1, 2, 3], 5, false, json!({}));
    let m = import_glb(&root, &bin).unwrap();
    assert_eq!(m.triangles.len(), 2);
    let normal = |t: [u32; 3]| {
        let p = t.map(|i| m.vertices[i as usize].position);
        (p[1] - p[0]).cross(p[2] - p[0]).normalize()
    };
    assert!(normal(m.triangles[0]).dot(normal(m.triangles[1])) > 0.99, "both triangles face the same way");
    // A fan of 5 vertices: 3 triangles around vertex 0.
    let fan = [[0.0, 2.0, 0.0], [1.0, 0.0, 0.0], [1.0, 4.0, 0.0], [-1.0, 4.0, 0.0], [-1.0, 0.0, 0.0]];
    let (root, bin) = optimised_model(&fan, &[[0.5, 0.5]; 5], &[0, 1, 2, 3, 4], 6, false, json!({}));
    let m = import_glb(&root, &bin).unwrap();
    assert_eq!(m.triangles.len(), 3);
    assert!(m.triangles.iter().all(|t| t[0] == 0));
    // Lines next to triangles: left out, and said.
    let (mut root, bin) = optimised_model(&QUAD, &QUAD_UV, &[0, 1, 2, 1, 3, 2], 4, false, json!({}));
    let prim = root["meshes"][0]["primitives"][0].clone();
    let mut line = prim.clone();
    line["mode"] = 1.into();
    root["meshes"][0]["primitives"] = json!([prim, line]);
    let m = import_glb(&root, &bin).unwrap();
    assert_eq!(m.triangles.len(), 2);
    assert!(m.notes.iter().any(|n| n.contains("1 primitives drawn as Lines")), "{:?}", m.notes);
}

#[test]
fn quantized_texture_transformed_and_instanced_models_as_optimisers_write_them() {
    // KHR_mesh_quantization: i16 positions (not normalized) and u16 normalized UVs.
    let ext = json!({"extensionsUsed": ["KHR_mesh_quantization"], "extensionsRequired": ["KHR_mesh_quantization"]});
    let (root, bin) = optimised_model(&QUAD, &QUAD_UV, &[0, 1, 2, 1, 3, 2], 4, true, ext);
    let m = import_glb(&root, &bin).unwrap();
    assert_eq!(m.triangles.len(), 2);
    let (lo, hi) = m.bounds();
    assert!((hi.z - lo.z - 4.0).abs() < 1e-4 && (hi.x - lo.x - 2.0).abs() < 1e-4, "{lo} {hi}");
    let mut uvs: Vec<[f32; 2]> = m.vertices.iter().map(|v| v.uv.to_array()).collect();
    uvs.sort_by(|a, b| a.partial_cmp(b).unwrap());
    assert_eq!(uvs, vec![[0.0, 0.0], [0.0, 1.0], [1.0, 0.0], [1.0, 1.0]]);
    // KHR_texture_transform (scale 2, offset 0.5) on texCoord 1 (which holds uv / 2).
    let ext = json!({
        "extensionsUsed": ["KHR_texture_transform"], "extensionsRequired": ["KHR_texture_transform"],
        "materials": [{"name": "leaves", "alphaMode": "MASK", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0, "texCoord": 1,
            "extensions": {"KHR_texture_transform": {"offset": [0.5, 0.25], "scale": [2.0, 2.0]}}}}}],
        "textures": [{"source": 0}],
        "images": [{"bufferView": 4, "mimeType": "image/png"}]
    });
    let (mut root, mut bin) = optimised_model(&QUAD, &QUAD_UV, &[0, 1, 2, 1, 3, 2], 4, false, ext);
    let png = leaf_png();
    let at = bin.len();
    bin.extend_from_slice(&png);
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    root["buffers"][0]["byteLength"] = bin.len().into();
    root["bufferViews"].as_array_mut().unwrap().push(json!({"buffer": 0, "byteOffset": at, "byteLength": png.len()}));
    let m = import_glb(&root, &bin).unwrap();
    let got: Vec<[f32; 2]> = m.vertices.iter().map(|v| v.uv.to_array()).collect();
    for (g, src) in got.iter().zip(QUAD_UV) {
        // texCoord 1 is uv / 2; × 2 + offset.
        assert!((g[0] - (src[0] + 0.5)).abs() < 1e-5 && (g[1] - (src[1] + 0.25)).abs() < 1e-5, "{g:?} from {src:?}");
    }
    assert!(m.materials[0].texture.is_some());
    // EXT_mesh_gpu_instancing: 125 leaf cards from one mesh (what gltfpack -mi writes).
    let mut bin2 = Vec::new();
    for i in 0..125 {
        for v in [(i % 5) as f32 * 3.0, (i / 25) as f32 * 5.0, ((i / 5) % 5) as f32 * 3.0] {
            bin2.extend_from_slice(&v.to_le_bytes());
        }
    }
    let (mut root, mut bin) = optimised_model(
        &QUAD,
        &QUAD_UV,
        &[0, 1, 2, 1, 3, 2],
        4,
        false,
        json!({
            "extensionsUsed": ["EXT_mesh_gpu_instancing"], "extensionsRequired": ["EXT_mesh_gpu_instancing"]
        }),
    );
    let at = bin.len();
    bin.extend_from_slice(&bin2);
    root["buffers"][0]["byteLength"] = bin.len().into();
    root["bufferViews"].as_array_mut().unwrap().push(json!({"buffer": 0, "byteOffset": at, "byteLength": bin2.len()}));
    root["accessors"]
        .as_array_mut()
        .unwrap()
        .push(json!({"bufferView": 4, "componentType": 5126, "count": 125, "type": "VEC3"}));
    root["nodes"][0]["extensions"] = json!({"EXT_mesh_gpu_instancing": {"attributes": {"TRANSLATION": 4}}});
    let m = import_glb(&root, &bin).unwrap();
    assert_eq!(m.triangles.len(), 2 * 125, "every instance kept");
    let (lo, hi) = m.bounds();
    assert!((hi.z - lo.z - (4.0 * 5.0 + 4.0)).abs() < 1e-3, "instances stacked 5 high: {lo} {hi}");
    assert!(m.notes.iter().any(|n| n.contains("125 mesh instances")), "{:?}", m.notes);
    // A blended material is said to be cut out.
    let (mut root, bin) = optimised_model(&QUAD, &QUAD_UV, &[0, 1, 2, 1, 3, 2], 4, false, json!({}));
    root["materials"][0]["alphaMode"] = "BLEND".into();
    let m = import_glb(&root, &bin).unwrap();
    assert!(m.notes.iter().any(|n| n.contains("alpha-blended") && n.contains("0.5")), "{:?}", m.notes);
}

#[test]
fn compressed_models_are_refused_by_name() {
    for (ext, want) in [
        ("KHR_draco_mesh_compression", "Draco"),
        ("KHR_texture_basisu", "KTX2"),
        ("KHR_materials_volume_scatter_future", "KHR_materials_volume_scatter_future"),
    ] {
        let extra = json!({"extensionsUsed": [ext], "extensionsRequired": [ext]});
        let (root, bin) = optimised_model(&QUAD, &QUAD_UV, &[0, 1, 2, 1, 3, 2], 4, false, extra);
        let e = format!("{:#}", import_glb(&root, &bin).unwrap_err());
        assert!(e.contains(ext) && e.contains(want), "{ext}: {e}");
    }
    // A KTX2 image a material uses, without the extension declared.
    let extra = json!({
        "images": [{"uri": "bark.ktx2"}],
        "textures": [{"source": 0}],
        "materials": [{"name": "leaves", "alphaMode": "MASK", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
    });
    let (root, bin) = optimised_model(&QUAD, &QUAD_UV, &[0, 1, 2, 1, 3, 2], 4, false, extra);
    let e = format!("{:#}", import_glb(&root, &bin).unwrap_err());
    assert!(e.contains("image 0 is KTX2"), "{e}");
    // Draco only used (with plain accessors as fallback): imported from the fallback.
    let extra = json!({"extensionsUsed": ["KHR_draco_mesh_compression"]});
    let (root, bin) = optimised_model(&QUAD, &QUAD_UV, &[0, 1, 2, 1, 3, 2], 4, false, extra);
    assert_eq!(import_glb(&root, &bin).unwrap().triangles.len(), 2);
}

#[test]
fn meshopt_compressed_models_decode_to_the_same_model() {
    // The plain model, then the same with its three views meshopt-compressed (as gltfpack -c writes).
    let indices = [0u16, 1, 2, 1, 3, 2];
    let (plain_root, plain_bin) = optimised_model(&QUAD, &QUAD_UV, &indices, 4, false, json!({}));
    let plain = import_glb(&plain_root, &plain_bin).unwrap();
    let positions: Vec<[f32; 3]> = QUAD.to_vec();
    let uv0: Vec<[u16; 2]> = QUAD_UV.iter().map(|uv| uv.map(|v| (v * 65535.0) as u16)).collect();
    let uv1: Vec<[f32; 2]> = QUAD_UV.iter().map(|uv| uv.map(|v| v * 0.5)).collect();
    let idx32: Vec<u32> = indices.iter().map(|&i| u32::from(i)).collect();
    let streams = [
        (meshopt::encode_vertex_buffer(&positions).unwrap(), 12, 4, "ATTRIBUTES"),
        (meshopt::encode_vertex_buffer(&uv0).unwrap(), 4, 4, "ATTRIBUTES"),
        (meshopt::encode_vertex_buffer(&uv1).unwrap(), 8, 4, "ATTRIBUTES"),
        (meshopt::encode_index_buffer(&idx32, 4).unwrap(), 2, 6, "TRIANGLES"),
    ];
    let mut bin = Vec::new();
    let mut compressed = Vec::new();
    for (bytes, stride, count, mode) in &streams {
        compressed.push((bin.len(), bytes.len(), *stride, *count, *mode));
        bin.extend_from_slice(bytes);
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
    }
    let mut root = plain_root.clone();
    let views = root["bufferViews"].as_array_mut().unwrap();
    for (view, (offset, len, stride, count, mode)) in views.iter_mut().zip(&compressed) {
        view["buffer"] = 1.into();
        view["extensions"] = json!({"EXT_meshopt_compression": {
            "buffer": 0, "byteOffset": offset, "byteLength": len, "byteStride": stride, "count": count, "mode": mode}});
    }
    root["buffers"] = json!([
        {"byteLength": bin.len()},
        {"byteLength": plain_bin.len(), "extensions": {"EXT_meshopt_compression": {"fallback": true}}}
    ]);
    root["extensionsUsed"] = json!(["EXT_meshopt_compression"]);
    root["extensionsRequired"] = json!(["EXT_meshopt_compression"]);
    let m = import_glb(&root, &bin).unwrap();
    // The index codec may rotate a triangle's corners (the winding stays).
    let canonical = |t: &[u32; 3]| {
        let k = (0..3).min_by_key(|&k| t[k]).unwrap();
        [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
    };
    let tris = |m: &ImportedModel| m.triangles.iter().map(canonical).collect::<Vec<_>>();
    assert_eq!(tris(&m), tris(&plain));
    assert_eq!(m.vertices, plain.vertices, "decoded exactly");
    assert!(m.notes.iter().any(|n| n.contains("4 meshopt-compressed buffer views decoded")), "{:?}", m.notes);
    // Garbage instead of the compressed bytes: an error naming the view, no panic.
    let mut broken = bin.clone();
    for b in &mut broken[..8] {
        *b = 0xff;
    }
    let e = format!("{:#}", import_glb(&root, &broken).unwrap_err());
    assert!(e.contains("buffer view 0 (meshopt)"), "{e}");
}

#[test]
fn skinned_meshes_are_placed_in_their_rest_pose() {
    let (mut root, mut bin) = optimised_model(&QUAD, &QUAD_UV, &[0, 1, 2, 1, 3, 2], 4, false, json!({}));
    // Vertices 0, 1 follow joint 0 (at the origin), vertices 2, 3 joint 1 (10 up).
    let at = bin.len();
    for j in [0u8, 0, 1, 1] {
        bin.extend_from_slice(&[j, 0, 0, 0]);
    }
    let weights_at = bin.len();
    for _ in 0..4 {
        for w in [1.0f32, 0.0, 0.0, 0.0] {
            bin.extend_from_slice(&w.to_le_bytes());
        }
    }
    root["buffers"][0]["byteLength"] = bin.len().into();
    let views = root["bufferViews"].as_array_mut().unwrap();
    views.push(json!({"buffer": 0, "byteOffset": at, "byteLength": 16}));
    views.push(json!({"buffer": 0, "byteOffset": weights_at, "byteLength": 64}));
    let accessors = root["accessors"].as_array_mut().unwrap();
    accessors.push(json!({"bufferView": 4, "componentType": 5121, "count": 4, "type": "VEC4"}));
    accessors.push(json!({"bufferView": 5, "componentType": 5126, "count": 4, "type": "VEC4"}));
    let prim = &mut root["meshes"][0]["primitives"][0]["attributes"];
    prim["JOINTS_0"] = 4.into();
    prim["WEIGHTS_0"] = 5.into();
    // The skinned node's own transform (100 m aside) must not apply.
    root["nodes"] = json!([
        {"mesh": 0, "skin": 0, "translation": [100.0, 0.0, 0.0]},
        {"name": "root", "children": [2]},
        {"name": "top", "translation": [0.0, 10.0, 0.0]}
    ]);
    root["skins"] = json!([{"joints": [1, 2]}]);
    root["scenes"] = json!([{"nodes": [0, 1]}]);
    let m = import_glb(&root, &bin).unwrap();
    let (lo, hi) = m.bounds();
    // Recentred on the trunk base: x spans the quad's 2 m, z from 0 to 14 (4 m + 10 m up).
    assert!((hi.x - lo.x - 2.0).abs() < 1e-4 && (hi.z - lo.z - 14.0).abs() < 1e-4, "{lo} {hi}");
    assert!(m.notes.iter().any(|n| n.contains("1 skinned meshes")), "{:?}", m.notes);
    // A joint index beyond the skin is an error naming it.
    let mut bad = bin.clone();
    bad[at + 8] = 7;
    let e = format!("{:#}", import_glb(&root, &bad).unwrap_err());
    assert!(e.contains("names joint 7") && e.contains("2"), "{e}");
}

#[test]
fn every_fuzz_seed_imports_or_fails_without_panicking() {
    // The seeds include every crash the import_gltf fuzz target found (regression-*).
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/seeds/import_gltf");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        let bytes = std::fs::read(&path).unwrap();
        let result = std::panic::catch_unwind(|| import_slice(&bytes, None, &Classifier::default()).map(|_| ()));
        assert!(result.is_ok(), "{} panicked", path.display());
        n += 1;
    }
    assert!(n >= 20, "{n} seeds");
}

#[test]
fn hostile_meshopt_and_skin_declarations_are_refused_before_allocating() {
    // A no-uri buffer claiming to be a meshopt fallback without the extension declared: refused as before.
    let (mut root, bin) = optimised_model(&QUAD, &QUAD_UV, &[0, 1, 2, 1, 3, 2], 4, false, json!({}));
    root["buffers"] = json!([{"byteLength": bin.len()},
        {"byteLength": 1 << 29, "extensions": {"EXT_meshopt_compression": {"fallback": true}}}]);
    let e = format!("{:#}", import_glb(&root, &bin).unwrap_err());
    assert!(e.contains("buffer 1"), "{e}");
    // Triangle indices that are no whole number of triangles: refused before decoding.
    root["extensionsUsed"] = json!(["EXT_meshopt_compression"]);
    root["buffers"][1]["byteLength"] = 64.into();
    root["bufferViews"][3]["buffer"] = 1.into();
    root["bufferViews"][3]["byteOffset"] = 0.into();
    root["bufferViews"][3]["extensions"] = json!({"EXT_meshopt_compression": {
        "buffer": 0, "byteOffset": 0, "byteLength": 16, "byteStride": 2, "count": 4, "mode": "TRIANGLES"}});
    let e = format!("{:#}", import_glb(&root, &bin).unwrap_err());
    assert!(e.contains("no whole number of triangles"), "{e}");
    // A decoded size beyond its view: refused before decoding.
    root["bufferViews"][3]["extensions"]["EXT_meshopt_compression"]["count"] = 3_000_000.into();
    let e = format!("{:#}", import_glb(&root, &bin).unwrap_err());
    assert!(e.contains("do not fit the view"), "{e}");
}
