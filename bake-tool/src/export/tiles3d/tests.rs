//! The 3D Tiles export's tests: placement round trips through WGS84, the
//! tileset's structure and every GLB's content.

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

const OFFSET_30: ExportOptions = ExportOptions { ground: true, height_offset_m: 30.0, season: Season::LeafOn };

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
            assert_eq!(sampler["minFilter"], 9729, "LINEAR (the spec's number)");
            let img = far["images"][far["textures"][tex]["source"].as_u64().unwrap() as usize]["uri"].as_str().unwrap();
            let png = image::open(out.join("tiles").join(img)).unwrap().to_rgba8();
            let covered = png.pixels().filter(|p| p[3] >= 128).count() as f64 / f64::from(png.width() * png.height());
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
        let tile =
            sylva::format::terrain::TerrainTile::decode("t", &std::fs::read(dir.join(e.tile_url(l, x, y))).unwrap())
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
            assert_eq!(acc["componentType"], 5123, "UNSIGNED_SHORT (the spec's number)");
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
            assert_eq!(
                (sampler["wrapS"].as_u64(), sampler["wrapT"].as_u64()),
                (Some(33071), Some(33071)),
                "CLAMP_TO_EDGE (the spec's number)"
            );
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
    let e =
        export(&dir.join("scene"), &dir.join("out"), ExportOptions::default(), &mut |_| {}).unwrap_err().to_string();
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

#[test]
fn each_season_exports_its_own_look_of_the_deciduous_species() {
    // The fixture's beech and birch are deciduous, the spruce evergreen.
    let export_in = |season: Season| {
        let out = std::env::temp_dir().join(format!("sylva-3dtiles-season-{}-{}", season.name(), std::process::id()));
        let _ = std::fs::remove_dir_all(&out);
        let options = ExportOptions { ground: false, height_offset_m: 0.0, season };
        export(&fixture(), &out, options, &mut |_| {}).unwrap();
        out
    };
    let dirs: Vec<std::path::PathBuf> = Season::ALL.iter().map(|s| export_in(*s)).collect();
    let file = |d: &Path, name: &str| std::fs::read(d.join("meshes").join(name)).unwrap();
    let names: Vec<String> = std::fs::read_dir(dirs[0].join("meshes"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    let png = |species: &str, what: &str| {
        names.iter().find(|n| n.contains(species) && n.contains(what) && n.ends_with(".png")).unwrap().clone()
    };
    for n in &names {
        // Geometry is shared by every season; the evergreen's textures too.
        if n.ends_with(".bin") || n.contains("spruce") {
            for d in &dirs[1..] {
                assert!(file(&dirs[0], n) == file(d, n), "{n} differs in {}", d.display());
            }
        }
    }
    for species in ["beech", "birch"] {
        let bb = png(species, "billboard");
        let layer = png(species, "layer");
        let (on, autumn, off) = (file(&dirs[0], &bb), file(&dirs[1], &bb), file(&dirs[2], &bb));
        assert!(autumn != on && off != on && off != autumn, "{species}'s far quads show each season");
        // Autumn recolours a leaf texture layer (the bark's stays).
        let layers: Vec<&String> = names.iter().filter(|n| n.contains(species) && n.contains("layer")).collect();
        assert!(layers.iter().any(|l| file(&dirs[1], l) != file(&dirs[0], l)), "{species}: no layer recoloured");
        assert!(file(&dirs[2], &layer) == file(&dirs[0], &layer), "leaf-off keeps the textures");
    }
    // Leaf-off: the full meshes of the deciduous species lose their leaf
    // primitives; the spruce keeps all of its.
    // (Summed over every tile's full GLB: name → primitives.)
    let primitives = |d: &Path| {
        let mut by_species: BTreeMap<String, usize> = BTreeMap::new();
        for e in std::fs::read_dir(d.join("tiles")).unwrap() {
            let p = e.unwrap().path();
            let n = p.file_name().unwrap().to_string_lossy().into_owned();
            if !n.ends_with(".glb") || n.ends_with("_far.glb") || n.ends_with("_coarse.glb") {
                continue;
            }
            let (doc, _) = glb_parts(&std::fs::read(&p).unwrap());
            for node in doc["nodes"].as_array().unwrap() {
                let mesh = &doc["meshes"][node["mesh"].as_u64().unwrap() as usize];
                *by_species.entry(node["name"].as_str().unwrap().to_string()).or_default() +=
                    mesh["primitives"].as_array().unwrap().len();
            }
        }
        by_species
    };
    let (on, off) = (primitives(&dirs[0]), primitives(&dirs[2]));
    assert_eq!(on.keys().collect::<Vec<_>>(), ["beech", "birch", "spruce"]);
    for (species, n) in &on {
        let bare = off[species];
        if species == "spruce" {
            assert_eq!(bare, *n, "the spruce keeps its leaves");
        } else {
            assert!(bare < *n && bare > 0, "{species}: {n} primitives leaf-on, {bare} leaf-off");
        }
    }
    for d in dirs {
        let _ = std::fs::remove_dir_all(d);
    }
}
