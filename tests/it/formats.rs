//! Format round trips, golden files and every decoder error path.
//!
//! Golden files in `tests/golden/` pin the bytes of format version 1: the
//! encoders must reproduce them and the decoders must read them. After an
//! intended format change, bump the version and re-bless with
//! `SYLVA_BLESS=1 cargo test --test it formats::`.

use std::path::PathBuf;

use sylva::format::ids::{decode_ids, encode_ids};
use sylva::format::manifest::{Bounds, Counts, Crs, Manifest, SpeciesEntry, TileEntry, SCENE_VERSION};
use sylva::format::pack::{
    kind, BillboardMeta, DrawRange, MaterialKind, MaterialMeta, MeshLevelMeta, MeshVertex, PackHead, PackMeta,
    PackPart, SeasonMeta, Section, TextureArrayMeta,
};
use sylva::format::terrain::{dequantise, quantise, TerrainChild, TerrainTile, TERRAIN_HOLE};
use sylva::format::tile::{
    variation_of, whole_index, CrownRange, GpuBatch, Levels, PackedInstance, Tile, BATCH_CROWN_ASPECT,
    BATCH_DENSITY_ORDERED, BATCH_PARTIAL, TILE_LEVELS, TILE_LEVELS_V3,
};
use sylva::format::{decode_pack, encode_pack, Problem};

fn golden(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/golden").join(name)
}

/// Compares `bytes` with the golden file, or writes it when blessing.
fn check_golden(name: &str, bytes: &[u8]) {
    let path = golden(name);
    if std::env::var_os("SYLVA_BLESS").is_some() {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(&path, bytes).unwrap();
    }
    let expected =
        std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e} (bless with SYLVA_BLESS=1)", path.display()));
    assert!(expected == bytes, "{name} differs from its golden file; a format change needs a version bump");
}

fn sample_batch(species: u32, offset: u32, count: u32) -> GpuBatch {
    GpuBatch {
        origin_m: [-128.0, 256.0, 12.5],
        instance_offset: offset,
        center_m: [-96.0, 288.0, 25.0],
        radius_m: 60.0,
        half_extent_m: [40.0, 40.0, 20.0],
        instance_count: count,
        species,
        xy_step_m: 64.0 / 65535.0,
        z_step_m: 0.016,
        scale_min: 0.5,
        scale_log2_step: 0.01,
        max_height_m: 30.0,
        flags: 0,
        crown: 0,
    }
}

fn sample_tile() -> Tile {
    Tile {
        tile_x: -1,
        tile_y: 2,
        batches: vec![sample_batch(0, 0, 3), sample_batch(1, 3, 2)],
        instances: vec![
            PackedInstance::new(0, 0, 0, 0, 0, 0),
            PackedInstance::new(65535, 65535, 2047, 255, 255, 31),
            PackedInstance::new(1234, 40000, 100, 64, 128, 7),
            PackedInstance::new(1, 2, 3, 4, 5, 6),
            PackedInstance::new(30000, 20000, 1000, 200, 10, 20),
        ],
    }
}

fn sample_pack() -> (PackMeta, Vec<Section>) {
    let vertices = [
        MeshVertex { position: [0, 0, 0], material: 0, normal_oct: [0, 0, 0, 0], uv: [0, 0], color: [255; 4] },
        MeshVertex {
            position: [65535, 0, 0],
            material: 0,
            normal_oct: [127, 0, 0, 0],
            uv: [65535, 0],
            color: [255; 4],
        },
        MeshVertex {
            position: [0, 65535, 65535],
            material: 1,
            normal_oct: [0, -127, 0, 0],
            uv: [0, 65535],
            color: [200, 180, 160, 255],
        },
    ];
    let indices: [u32; 6] = [0, 1, 2, 2, 1, 0];
    let tex = TextureArrayMeta::plain(4, 1, 3);
    let bb_tex = TextureArrayMeta::plain(2, 2, 2);
    let meta = PackMeta {
        name: "sample".into(),
        height_m: 10.0,
        bounds_min: [-2.0, -2.0, 0.0],
        bounds_max: [2.0, 2.0, 10.0],
        materials: vec![
            MaterialMeta {
                name: "bark".into(),
                kind: MaterialKind::Branch,
                base_color: [1.0; 4],
                alpha_cutoff: 0.0,
                double_sided: false,
                texture_layer: None,
                coverage: None,
            },
            MaterialMeta {
                name: "leaves".into(),
                kind: MaterialKind::Leaf,
                base_color: [1.0; 4],
                alpha_cutoff: 0.5,
                double_sided: true,
                texture_layer: Some(0),
                coverage: None,
            },
        ],
        material_texture: Some(tex),
        mesh_levels: vec![MeshLevelMeta {
            vertex_count: 3,
            index_count: 6,
            pos_min: [-2.0, -2.0, 0.0],
            pos_max: [2.0, 2.0, 10.0],
            uv_min: [0.0, 0.0],
            uv_max: [1.0, 1.0],
            draws: vec![
                DrawRange { material: 0, first_index: 0, index_count: 3 },
                DrawRange { material: 1, first_index: 3, index_count: 3 },
            ],
            select_px: 360.0,
            policy_px: None,
            variants: 0,
        }],
        billboards: Some(BillboardMeta {
            angles: 2,
            azimuths: 1,
            texture: bb_tex,
            center: [0.0, 0.0, 5.0],
            half_width: 2.0,
            half_height: 5.5,
            select_px: 0.0,
            variants: None,
        }),
        clusters: None,
        impostors: None,
        cloud: None,
        season: None,
    };
    let fill = |n: u64, v: u8| vec![v; n as usize];
    let sections = vec![
        Section {
            kind: kind::MESH_VERTICES,
            index: 0,
            count: 3,
            stride: 20,
            data: bytemuck::cast_slice(&vertices).to_vec(),
        },
        Section {
            kind: kind::MESH_INDICES,
            index: 0,
            count: 6,
            stride: 4,
            data: bytemuck::cast_slice(&indices).to_vec(),
        },
        Section { kind: kind::MATERIAL_TEXTURES, index: 0, count: 0, stride: 0, data: fill(tex.byte_len(), 0x80) },
        Section { kind: kind::BILLBOARD_COLOR, index: 0, count: 0, stride: 0, data: fill(bb_tex.byte_len(), 0x40) },
        Section { kind: kind::BILLBOARD_NORMAL, index: 0, count: 0, stride: 0, data: fill(bb_tex.byte_len(), 0xC0) },
    ];
    (meta, sections)
}

fn sample_manifest() -> Manifest {
    let b = Bounds { min: [-200.0, 200.0, 0.0], max: [0.0, 400.0, 40.0] };
    Manifest {
        format: "sylva-scene".into(),
        version: 1,
        crs: Crs { epsg: 32633, proj4: "+proj=utm +zone=33 +datum=WGS84 +units=m +no_defs".into(), fit: None },
        origin_m: [540_000.0, 5_360_000.0, 0.0],
        bounds: b,
        cell_size_m: 64.0,
        tile_cells: 8,
        counts: Counts { trees: 5, batches: 2, tiles: 1 },
        species: vec![
            SpeciesEntry {
                name: "a".into(),
                pack: "species/a.pack".into(),
                bytes: 100,
                height_m: 10.0,
                bounds: b,
                trees: 3,
                head_bytes: None,
                variants: Vec::new(),
            },
            SpeciesEntry {
                name: "b".into(),
                pack: "species/b.pack".into(),
                bytes: 100,
                height_m: 10.0,
                bounds: b,
                trees: 2,
                head_bytes: None,
                variants: Vec::new(),
            },
        ],
        tiles: vec![TileEntry {
            x: -1,
            y: 2,
            url: "tiles/-1_2.tile".into(),
            ids_url: "tiles/-1_2.ids".into(),
            bytes: 432,
            trees: 5,
            batches: 2,
            bounds: b,
            attribute_codes: None,
            levels: None,
        }],
        index: None,
        home: None,
        shard: None,
        terrain: None,
        attributes: None,
        canopy: None,
        timeline: None,
    }
}

#[test]
fn tile_golden_and_round_trip() {
    let tile = sample_tile();
    let bytes = tile.encode_whole();
    assert_eq!(bytes.len(), 32 + 2 * 80 + 5 * 8);
    check_golden("v1.tile", &bytes);
    let decoded = Tile::decode("v1.tile", &std::fs::read(golden("v1.tile")).unwrap(), 2).unwrap();
    assert_eq!(decoded, tile);
    // Field packing: the second instance has every field at its maximum.
    let d = decoded.instances[1].decode(&decoded.batches[0]);
    assert!((d.position_m[0] - (-128.0 + 64.0)).abs() < 1e-3);
    assert!((d.position_m[2] - (12.5 + 2047.0 * 0.016)).abs() < 1e-3);
    assert_eq!(d.variation, 31);
    assert!((d.scale - 0.5 * (255.0f32 * 0.01).exp2()).abs() < 1e-5);
}

/// A tile of a density-ordered batch of 100 trees and a plain batch of 3.
fn sample_level_tile() -> Tile {
    let mut ordered = sample_batch(0, 0, 100);
    ordered.flags = BATCH_DENSITY_ORDERED;
    let instances = (0..103u32).map(|i| PackedInstance::new(i as u16 * 600, i as u16, i, i, i, i)).collect();
    Tile { tile_x: 3, tile_y: -4, batches: vec![ordered, sample_batch(1, 100, 3)], instances }
}

#[test]
fn level_tile_golden_prefixes_and_errors() {
    // Version 3 (what scenes baked before version 4 hold): still read by range.
    let tile = sample_level_tile();
    let bytes = tile.encode_v3();
    assert_eq!(u16::from_le_bytes([bytes[4], bytes[5]]), 3);
    assert_eq!(bytes.len(), 32 + 2 * 80 + 4 + 4 * TILE_LEVELS_V3 as usize + 103 * 8, "levels cost 32 bytes a tile");
    check_golden("v3.tile", &bytes);
    assert_eq!(Tile::decode("v3.tile", &std::fs::read(golden("v3.tile")).unwrap(), 2).unwrap(), tile);
    // Level ends: 1/64 of the ordered batch (2 trees) and the plain batch whole, then 1/32 … all.
    let scheme = Levels::new(3, TILE_LEVELS_V3, &tile.batches);
    let head = 32 + 160 + 32;
    let counts = tile.level_counts(&scheme);
    assert_eq!(counts, [2 + 3, 4 + 3, 7 + 3, 13 + 3, 25 + 3, 50 + 3, 100 + 3]);
    let ends: Vec<u64> = counts.iter().map(|&c| head + 8 * u64::from(c)).collect();
    assert_eq!(*ends.last().unwrap(), bytes.len() as u64);
    for (l, &end) in ends.iter().enumerate() {
        let p = Tile::decode_prefix("t", &bytes[..end as usize], 2).unwrap();
        assert_eq!((p.levels, p.of, p.scheme), (l as u32 + 1, TILE_LEVELS_V3, scheme));
        let k = scheme.prefix(&tile.batches[0], l as u32);
        let b = &p.tile.batches[0];
        assert_eq!(b.instance_count, k);
        assert_eq!(b.whole_count(), 100);
        assert_eq!(b.flags & BATCH_PARTIAL != 0, k < 100, "level {l}");
        assert_eq!(&p.tile.instances[..k as usize], &tile.instances[..k as usize], "each batch's first trees");
        assert_eq!((p.tile.batches[1].instance_offset, p.tile.batches[1].instance_count), (k, 3));
        assert_eq!(p.tile.instances[k as usize..], tile.instances[100..]);
        // Resident instances map back to their index in the whole tile (ids, attributes).
        let runs = p.runs();
        assert_eq!(runs.is_empty(), k == 100);
        for i in 0..k + 3 {
            let w = whole_index(&runs, i) as usize;
            assert_eq!(tile.instances[w], p.tile.instances[i as usize], "resident {i} is tile instance {w}");
        }
    }
    // Not a level's end, or the whole decoder on a prefix: truncated.
    let msg = Tile::decode_prefix("t", &bytes[..ends[0] as usize + 8], 2).unwrap_err().to_string();
    assert!(msg.contains("truncated"), "{msg}");
    let msg = Tile::decode("t", &bytes[..ends[3] as usize], 2).unwrap_err().to_string();
    assert!(msg.contains("truncated"), "{msg}");
    // The level table must say what the batches give.
    let table = 32 + 160;
    for (at, v, needle) in [
        (table, 0, "levels.count"),
        (table, 17, "levels.count"),
        (table, 6, "trailing bytes"),
        (table + 4, 6, "levels.counts[0] is 6"),
        (table + 4 + 4 * 6, 102, "levels.counts[6] is 102"),
    ] {
        let mut b = bytes.clone();
        put_u32(&mut b, at, v);
        let msg = Tile::decode_prefix("t", &b, 2).unwrap_err().to_string();
        assert!(msg.contains(needle), "expected {needle:?} in {msg:?}");
    }
    // The in-memory flag is refused in files.
    let mut b = bytes.clone();
    put_u32(&mut b, 32 + 72, BATCH_DENSITY_ORDERED | BATCH_PARTIAL);
    assert!(Tile::decode("t", &b, 2).unwrap_err().to_string().contains("unknown flags"));
}

/// Version 4: levels of √2 steps, a batch half as tall as the tallest holding
/// a quarter of its share (but never less than 1/64 where the tallest holds that).
#[test]
fn level_tile_v4_golden_steps_and_heights() {
    let mut tile = sample_level_tile();
    let mut short = sample_batch(1, 100, 60);
    short.flags = BATCH_DENSITY_ORDERED;
    short.max_height_m = tile.batches[0].max_height_m / 2.0;
    let mut plain = tile.batches[1];
    plain.instance_offset = 160;
    tile.batches = vec![tile.batches[0], short, plain];
    tile.instances = (0..163u32).map(|i| PackedInstance::new(i as u16 * 400, i as u16, i, i, i, i)).collect();
    let bytes = tile.encode();
    assert_eq!(u16::from_le_bytes([bytes[4], bytes[5]]), 4);
    assert_eq!(TILE_LEVELS, 15);
    assert_eq!(bytes.len(), 32 + 3 * 80 + 4 + 4 * 15 + 163 * 8);
    check_golden("v4.tile", &bytes);
    assert_eq!(Tile::decode("v4.tile", &std::fs::read(golden("v4.tile")).unwrap(), 2).unwrap(), tile);
    let scheme = tile.levels();
    assert_eq!((scheme.version, scheme.count, scheme.tallest_m), (4, 15, 30.0));
    // The tallest: 1/128, 1/91, 1/64, … 1/√2, all of 100; the short one r² = ¼ of
    // that from 1/64 up; the plain batch whole from level 0.
    let per_batch = |b: usize| (0..15).map(|l| scheme.prefix(&tile.batches[b], l)).collect::<Vec<_>>();
    assert_eq!(per_batch(0), [1, 2, 2, 3, 4, 5, 7, 9, 13, 18, 25, 36, 50, 71, 100]);
    assert_eq!(per_batch(1), [1, 1, 1, 1, 1, 1, 1, 2, 2, 3, 4, 6, 8, 11, 60]);
    assert_eq!(per_batch(2), [3; 15]);
    let counts = tile.level_counts(&scheme);
    assert_eq!(counts, [5, 6, 6, 7, 8, 9, 11, 14, 18, 24, 32, 45, 61, 85, 163]);
    // Levels adding no trees end where the one before does: a prefix ending
    // there holds the later of them.
    let head = (32 + 3 * 80 + 4 + 60) as u64;
    assert_eq!(tile.level_bytes(), counts.iter().map(|&c| head + 8 * u64::from(c)).collect::<Vec<_>>());
    for (l, &end) in tile.level_bytes().iter().enumerate() {
        let p = Tile::decode_prefix("t", &bytes[..end as usize], 2).unwrap();
        let l = if l == 1 { 2 } else { l };
        assert_eq!((p.levels, p.of, p.scheme), (l as u32 + 1, 15, scheme));
        for (b, held) in p.tile.batches.iter().enumerate() {
            let k = scheme.prefix(&tile.batches[b], l as u32);
            assert_eq!((held.instance_count, held.whole_count()), (k, tile.batches[b].instance_count));
            let whole = tile.batches[b].instance_offset as usize;
            let at = held.instance_offset as usize;
            assert_eq!(p.tile.instances[at..at + k as usize], tile.instances[whole..whole + k as usize]);
        }
    }
    // The same tile as version 3 holds more of the short batch at every level.
    let v3 = Levels::new(3, TILE_LEVELS_V3, &tile.batches);
    assert_eq!(v3.prefix(&tile.batches[1], 0), 1);
    assert_eq!(v3.prefix(&tile.batches[1], 5), 30);
    assert_eq!(scheme.covering(1.0 / 64.0), 3);
    assert_eq!(scheme.covering(0.2), 11);
    assert_eq!(scheme.covering(f32::NAN), 15);
    // The level table must say what the batches give (a version 3 table is not).
    let mut b = bytes.clone();
    b[4] = 3;
    let msg = Tile::decode("t", &b, 2).unwrap_err().to_string();
    assert!(msg.contains("levels.counts"), "{msg}");
}

/// The sample tile with crown aspects in its second batch (version 2).
fn sample_crown_tile() -> Tile {
    let mut tile = sample_tile();
    let range = CrownRange::covering(0.5, 2.0);
    tile.batches[1].flags = BATCH_DENSITY_ORDERED | BATCH_CROWN_ASPECT;
    tile.batches[1].crown = range.pack();
    tile.instances[3] = PackedInstance::new(1, 2, 3, 4, 5, range.quantise(0.5));
    tile.instances[4] = PackedInstance::new(30000, 20000, 1000, 200, 10, range.quantise(1.3));
    tile
}

#[test]
fn crown_tile_golden_and_round_trip() {
    let tile = sample_crown_tile();
    assert_eq!(tile.whole_version(), 2);
    let bytes = tile.encode_whole();
    assert_eq!(u16::from_le_bytes([bytes[4], bytes[5]]), 2, "a tile with crown aspects is version 2");
    assert_eq!(bytes.len(), 32 + 2 * 80 + 5 * 8, "crown widths cost no bytes per tree");
    check_golden("v2.tile", &bytes);
    let decoded = Tile::decode("v2.tile", &std::fs::read(golden("v2.tile")).unwrap(), 2).unwrap();
    assert_eq!(decoded, tile);
    // The first batch has no crowns: aspect 1 and the variation bits as before.
    let plain = decoded.instances[1].decode(&decoded.batches[0]);
    assert_eq!((plain.aspect, plain.variation), (1.0, 31));
    // The second batch: aspects to half a step of a 4× range (2/62 octave, 2.3 %),
    // the variation hashed from the position.
    let b = &decoded.batches[1];
    for (i, want) in [(3, 0.5f32), (4, 1.3)] {
        let d = decoded.instances[i].decode(b);
        assert!((d.aspect / want).log2().abs() <= 2.0 / 62.0 + 1e-4, "aspect {} for {want}", d.aspect);
        assert_eq!(u32::from(d.variation), variation_of(decoded.instances[i].xy));
        assert!((d.scale - 0.5 * (10.0f32 * 0.01).exp2()).abs() < 1e-5 || i == 3, "the scale is unchanged");
    }
    // Every quantised aspect of a range decodes inside it, in order.
    let r = CrownRange::covering(0.3, 3.0);
    let all: Vec<f32> = (0..32).map(|q| r.aspect(q)).collect();
    assert!(all[0] <= 0.3 && all[0] > 0.299 && all[31] >= 3.0 && all[31] < 3.01, "{all:?}");
    assert!(all.windows(2).all(|w| w[1] > w[0]));
    assert!((0..32).all(|q| r.quantise(r.aspect(q)) == q));
    // Nonsense in: a range the decoder accepts (a positive smallest aspect).
    for (lo, hi) in [(f32::NAN, f32::NAN), (0.0, 0.0), (-1.0, f32::INFINITY), (f32::MAX, f32::MIN)] {
        let c = CrownRange::covering(lo, hi);
        assert!(c.min_q > 0 && (0..32).all(|q| c.aspect(q).is_finite() && c.aspect(q) > 0.0), "{lo} {hi}: {c:?}");
    }
}

fn sample_terrain() -> TerrainTile {
    let child = TerrainChild { exists: true, min_m: 10.0, max_m: 12.0, error_m: 0.0 };
    TerrainTile {
        level: 2,
        x: 3,
        y: 1,
        grid: 2,
        min_m: 10.0,
        max_m: 14.0,
        error_m: 0.75,
        children: [child, TerrainChild::default(), child, TerrainChild { max_m: 14.0, ..child }],
        heights: vec![0, 100, 200, 300, TERRAIN_HOLE, 65534, 7, 8, 9],
    }
}

#[test]
fn terrain_golden_and_round_trip() {
    let tile = sample_terrain();
    let bytes = tile.encode();
    assert_eq!(bytes.len(), 96 + 9 * 2);
    check_golden("v1.terr", &bytes);
    let decoded = TerrainTile::decode("v1.terr", &std::fs::read(golden("v1.terr")).unwrap()).unwrap();
    assert_eq!(decoded, tile);
    assert_eq!(decoded.height(1, 1), None, "a hole");
    assert_eq!(decoded.height(2, 1), Some(14.0));
    assert_eq!(decoded.height(0, 0), Some(10.0));
    // Quantisation: 1/65534 of the range.
    assert_eq!(quantise(12.0, 10.0, 14.0), 32767);
    assert!((dequantise(32767, 10.0, 14.0) - 12.0).abs() < 1e-4);
}

#[test]
fn terrain_decoder_error_paths() {
    let err = |mutate: &dyn Fn(&mut Vec<u8>), needle: &str| {
        let mut bytes = sample_terrain().encode();
        mutate(&mut bytes);
        let e = TerrainTile::decode("terrain/2/3_1.terr", &bytes).expect_err(needle).to_string();
        assert!(e.starts_with("terrain/2/3_1.terr: ") && e.contains(needle), "expected {needle:?} in {e:?}");
    };
    err(&|b| b[0] = b'X', "not a Sylva terrain tile");
    err(&|b| b[4] = 2, "version 2");
    err(&|b| b[6] = 90, "header_bytes");
    err(&|b| b[8] = 25, "header.level");
    err(&|b| b[9] = 0x1f, "child_mask");
    err(&|b| b[10] = 0, "header.grid");
    err(&|b| b[10] = 3, "an even");
    err(&|b| put_f32(b, 20, -2.0e6), "beyond");
    err(&|b| put_f32(b, 32 + 4, 3.0e6), "child 0: range or error beyond");
    err(&|b| b[12] = 4, "outside level 2's 4×4 tiles");
    err(&|b| put_f32(b, 20, f32::NAN), "not a finite number");
    err(&|b| put_f32(b, 20, 20.0), "inverted");
    err(&|b| put_f32(b, 28, -1.0), "negative");
    err(&|b| put_f32(b, 32 + 12, 1.0), "child 1 has a summary but no flag");
    err(&|b| b[90] = 1, "reserved");
    err(&|b| b.truncate(100), "truncated");
    err(&|b| b.push(0), "trailing bytes");
    // Manifest version 4 carries the terrain; version 3 may not.
    let mut m = sample_manifest();
    m.version = 4;
    m.terrain = Some(sylva::format::TerrainEntry {
        path: "terrain".into(),
        origin_m: [-512.0, -512.0],
        root_size_m: 1024.0,
        grid: 64,
        levels: 3,
        resolution_m: 4.0,
        height_range_m: [10.0, 80.0],
        tiles: 21,
        bytes: 180_000,
        source: "dem.tif".into(),
        imagery: None,
    });
    let back = Manifest::decode("scene.json", &m.encode()).unwrap();
    assert_eq!(back.terrain.as_ref().unwrap().tile_url(2, 3, 1), "terrain/2/3_1.terr");
    assert_eq!(back.terrain.as_ref().unwrap().tile_origin_m(2, 3, 1), [-512.0 + 768.0, -512.0 + 256.0]);
    m.version = 3;
    let e = Manifest::decode("scene.json", &m.encode()).unwrap_err().to_string();
    assert!(e.contains("\"terrain\" needs manifest version 4"), "{e}");
    m.version = 4;
    m.terrain.as_mut().unwrap().path = "../outside".into();
    assert!(Manifest::decode("scene.json", &m.encode()).is_err(), "a terrain path leaving the scene is refused");
    // Version 5 adds ground imagery.
    m.terrain.as_mut().unwrap().path = "terrain".into();
    m.terrain.as_mut().unwrap().imagery = Some(sylva::format::terrain::ImageryEntry {
        path: "terrain/img".into(),
        tile_px: 256,
        levels: 2,
        extent_m: [-300.0, -300.0, 300.0, 250.0],
        resolution_m: 0.5,
        tiles: 5,
        bytes: 90_000,
        source: "ortho.tif".into(),
    });
    let e = Manifest::decode("scene.json", &m.encode()).unwrap_err().to_string();
    assert!(e.contains("\"terrain.imagery\" needs manifest version 5"), "{e}");
    m.version = 5;
    let back = Manifest::decode("scene.json", &m.encode()).unwrap();
    assert_eq!(back.terrain.as_ref().unwrap().imagery.as_ref().unwrap().tile_url(1, 0, 1), "terrain/img/1/0_1.jpg");
    type Edit = fn(&mut sylva::format::terrain::ImageryEntry);
    let edits: [(Edit, &str); 4] = [
        (|i: &mut sylva::format::terrain::ImageryEntry| i.levels = 4, "levels"),
        (|i: &mut sylva::format::terrain::ImageryEntry| i.tile_px = 300, "tile_px"),
        (|i: &mut sylva::format::terrain::ImageryEntry| i.extent_m[0] = 400.0, "extent_m"),
        (|i: &mut sylva::format::terrain::ImageryEntry| i.path = "/etc".into(), "path"),
    ];
    for (bad, why) in edits {
        let mut m = m.clone();
        bad(m.terrain.as_mut().unwrap().imagery.as_mut().unwrap());
        let e = Manifest::decode("scene.json", &m.encode()).expect_err(why).to_string();
        assert!(e.contains(why), "{why}: {e}");
    }
}

#[test]
fn pack_golden_and_round_trip() {
    let (meta, sections) = sample_pack();
    let bytes = encode_pack(&meta, &sections);
    check_golden("v1.pack", &bytes);
    let file = std::fs::read(golden("v1.pack")).unwrap();
    let pack = decode_pack("v1.pack", &file).unwrap();
    assert_eq!(pack.meta, meta);
    assert_eq!(pack.mesh_indices(0), vec![0, 1, 2, 2, 1, 0]);
    assert_eq!(pack.mesh_vertices(0)[1].position, [65535, 0, 0]);
    for (entry, _) in &pack.sections {
        assert_eq!(entry.offset % 256, 0, "sections are 256-byte aligned for direct upload");
    }
}

#[test]
fn manifest_golden_and_round_trip() {
    let m = sample_manifest();
    let bytes = m.encode();
    check_golden("v1-scene.json", &bytes);
    assert_eq!(Manifest::decode("scene.json", &std::fs::read(golden("v1-scene.json")).unwrap()).unwrap(), m);
}

#[test]
fn ids_round_trip_and_errors() {
    let ids = [1u64, 42, u64::MAX];
    let bytes = encode_ids(&ids);
    assert_eq!(decode_ids("x.ids", &bytes).unwrap(), ids);
    assert!(decode_ids("x.ids", &bytes[..bytes.len() - 1]).is_err());
    assert!(decode_ids("x.ids", b"SYID").is_err());
    let mut hostile = encode_ids(&[]);
    hostile[8..16].copy_from_slice(&u64::MAX.to_le_bytes());
    let e = decode_ids("x.ids", &hostile).unwrap_err();
    assert!(matches!(e.problem, Problem::OutOfRange { .. }), "{e}");
    // Version 2: text ids of some instances (an inventory's own keys).
    let with_text = sylva::format::TreeIds {
        numbers: vec![7, (1 << 63) + 2, 9, (1 << 63) + 4],
        texts: vec![(1, "EY17080".into()), (3, "Baum Nr. 7 — Süd".into())],
    };
    let bytes = sylva::format::encode_tree_ids(&with_text).unwrap();
    assert_eq!(u32::from_le_bytes(bytes[4..8].try_into().unwrap()), 2);
    let back = sylva::format::decode_tree_ids("x.ids", &bytes).unwrap();
    assert_eq!(back, with_text);
    assert_eq!((back.text(1), back.text(2), back.text(3)), (Some("EY17080"), None, Some("Baum Nr. 7 — Süd")));
    assert_eq!(decode_ids("x.ids", &bytes).unwrap(), with_text.numbers, "numbers as before");
    // Without text ids: version 1, as before.
    let plain = sylva::format::TreeIds { numbers: ids.to_vec(), texts: Vec::new() };
    assert_eq!(sylva::format::encode_tree_ids(&plain).unwrap(), encode_ids(&ids));
    // What the decoder refuses is never written: a text on a numbered tree, out of order.
    let mut numbered = with_text.clone();
    numbered.texts[0].0 = 0;
    assert!(sylva::format::encode_tree_ids(&numbered).is_err());
    let mut unordered = with_text.clone();
    unordered.texts.reverse();
    assert!(sylva::format::encode_tree_ids(&unordered).is_err());
    // Hostile text sections: each refused, named.
    let at = 16 + 4 * 8; // the text count
    let text_error = |mutate: &dyn Fn(&mut Vec<u8>), needle: &str| {
        let mut b = bytes.clone();
        mutate(&mut b);
        let e = sylva::format::decode_tree_ids("t.ids", &b).unwrap_err().to_string();
        assert!(e.starts_with("t.ids: ") && e.contains(needle), "{needle}: {e}");
    };
    text_error(&|b| b.truncate(b.len() - 1), "end at byte");
    text_error(&|b| b.push(b'x'), "end at byte");
    text_error(&|b| b[at..at + 4].copy_from_slice(&99u32.to_le_bytes()), "at most 4");
    text_error(&|b| b[at..at + 4].copy_from_slice(&0u32.to_le_bytes()), "without text ids");
    text_error(&|b| b[at + 4..at + 8].copy_from_slice(&3u32.to_le_bytes()), "instances rise");
    text_error(&|b| b[at + 8..at + 12].copy_from_slice(&4u32.to_le_bytes()), "below 4");
    text_error(&|b| b[at + 12..at + 16].copy_from_slice(&0u32.to_le_bytes()), "bytes 0–0");
    text_error(&|b| b[at + 20] = 0xff, "not UTF-8");
    text_error(&|b| b[16 + 8..16 + 16].copy_from_slice(&5u64.to_le_bytes()), "has the number 5");
}

/// Decodes a tile after `mutate`, expecting an error whose message contains `needle`.
fn tile_error(mutate: impl FnOnce(&mut Vec<u8>), needle: &str) {
    let mut bytes = sample_tile().encode_whole();
    mutate(&mut bytes);
    let e = Tile::decode("tiles/-1_2.tile", &bytes, 2).expect_err(needle);
    let msg = e.to_string();
    assert!(msg.starts_with("tiles/-1_2.tile: "), "the error names the file: {msg}");
    assert!(msg.contains(needle), "expected {needle:?} in {msg:?}");
}

fn put_f32(bytes: &mut [u8], at: usize, v: f32) {
    bytes[at..at + 4].copy_from_slice(&v.to_le_bytes());
}

fn put_u32(bytes: &mut [u8], at: usize, v: u32) {
    bytes[at..at + 4].copy_from_slice(&v.to_le_bytes());
}

#[test]
fn tile_decoder_error_paths() {
    tile_error(|b| b[0] = b'X', "not a Sylva tile");
    tile_error(|b| b.truncate(2), "not a Sylva tile");
    tile_error(|b| b[4] = 9, "version 9");
    tile_error(|b| b[6] = 33, "header_bytes");
    tile_error(|b| b.truncate(20), "truncated");
    tile_error(|b| b.truncate(b.len() - 1), "truncated");
    tile_error(|b| b.push(0), "trailing bytes");
    tile_error(|b| put_u32(b, 8, u32::MAX), "batch_count");
    tile_error(|b| put_u32(b, 12, u32::MAX), "instance_count");
    tile_error(|b| b[24] = 81, "record sizes");
    // Found by the fuzzer: reserved flags must be zero, or the tile would not round-trip.
    tile_error(|b| b[28] = 32, "header.flags");
    // Batch 0 starts at byte 32.
    tile_error(|b| put_f32(b, 32, f32::NAN), "batch[0].origin_m[0] is not a finite number");
    tile_error(|b| put_f32(b, 32 + 28, f32::INFINITY), "batch[0]");
    tile_error(|b| put_u32(b, 32 + 48, 7), "batch[0].species = 7 is out of range");
    tile_error(|b| put_f32(b, 32 + 52, 0.0), "xy_step_m");
    tile_error(|b| put_f32(b, 32 + 52, 0.5), "1 cm position error");
    tile_error(|b| put_f32(b, 32 + 28, -1.0), "radius_m");
    tile_error(|b| put_u32(b, 32 + 80 + 12, 4), "instance_offset is 4, expected 3");
    tile_error(|b| put_u32(b, 32 + 44, 2), "instance_offset");
    // Batch flags (byte 72 of a batch) and the crown word (76).
    tile_error(|b| put_u32(b, 32 + 72, 4), "unknown flags 0x4");
    tile_error(|b| put_u32(b, 32 + 76, 9), "crown is 0x9 without the crown flag");
    tile_error(|b| put_u32(b, 32 + 72, BATCH_CROWN_ASPECT), "need tile version 2; this tile is version 1");
    let crown_error = |mutate: &dyn Fn(&mut Vec<u8>), needle: &str| {
        let mut bytes = sample_crown_tile().encode_whole();
        mutate(&mut bytes);
        let e = Tile::decode("t", &bytes, 2).expect_err(needle).to_string();
        assert!(e.contains(needle), "expected {needle:?} in {e:?}");
    };
    crown_error(&|b| put_u32(b, 32 + 80 + 76, 0), "smallest aspect of 0");
    crown_error(&|b| b[4] = 5, "version 5 is not supported");
    // A version 2 tile without crowns reads (it re-encodes as version 1).
    let mut bytes = sample_tile().encode_whole();
    bytes[4] = 2;
    assert_eq!(Tile::decode("t", &bytes, 2).unwrap(), sample_tile());
}

#[test]
fn hostile_counts_do_not_allocate() {
    // A 32-byte header claiming the maximum counts: rejected from the size check
    // before any allocation sized by the counts.
    let mut bytes = sample_tile().encode();
    bytes.truncate(32);
    put_u32(&mut bytes, 8, 1 << 20);
    put_u32(&mut bytes, 12, 1 << 26);
    let e = Tile::decode("t", &bytes, 2).unwrap_err();
    assert!(matches!(e.problem, Problem::Truncated { .. }), "{e}");
}

fn pack_error(mutate: impl FnOnce(&mut PackMeta, &mut Vec<Section>), needle: &str) {
    let (mut meta, mut sections) = sample_pack();
    mutate(&mut meta, &mut sections);
    let bytes = encode_pack(&meta, &sections);
    let msg = decode_pack("species/x.pack", &bytes).expect_err(needle).to_string();
    assert!(msg.starts_with("species/x.pack: "), "{msg}");
    assert!(msg.contains(needle), "expected {needle:?} in {msg:?}");
}

fn pack_bytes_error(mutate: impl FnOnce(&mut Vec<u8>), needle: &str) {
    let (meta, sections) = sample_pack();
    let mut bytes = encode_pack(&meta, &sections);
    mutate(&mut bytes);
    let msg = decode_pack("species/x.pack", &bytes).expect_err(needle).to_string();
    assert!(msg.contains(needle), "expected {needle:?} in {msg:?}");
}

#[test]
fn pack_decoder_error_paths() {
    pack_bytes_error(|b| b[1] = 0, "not a Sylva LoD pack");
    pack_bytes_error(|b| b[4] = 2, "version 2");
    pack_bytes_error(|b| b[6] = 0, "header_bytes");
    pack_bytes_error(|b| put_u32(b, 8, 1_000_000), "section_count");
    pack_bytes_error(|b| put_u32(b, 12, 16), "section_align");
    pack_bytes_error(|b| b.truncate(b.len() - 1), "truncated");
    pack_bytes_error(|b| b.extend_from_slice(&[0; 8]), "file_bytes");
    // Section 1 (MVTX) offset → misaligned; then overlapping; then beyond the file.
    let entry = |i: usize| 32 + 32 * i;
    pack_bytes_error(|b| b[entry(1) + 8] = 1, "not a multiple of 256");
    pack_bytes_error(|b| b[entry(2) + 8..entry(2) + 16].copy_from_slice(&256u64.to_le_bytes()), "overlaps");
    pack_bytes_error(
        |b| {
            let last = entry(5);
            let huge = (1u64 << 40).to_le_bytes();
            b[last + 16..last + 24].copy_from_slice(&huge);
        },
        "truncated",
    );
    pack_bytes_error(|b| put_u32(b, entry(1) + 24, 4), "declares 4 elements");
    pack_bytes_error(|b| b[entry(0)..entry(0) + 4].copy_from_slice(b"MVTX"), "first section is not META");
    // serde_json writes NaN as null, which the schema refuses; overflowing numbers
    // become infinities, which validation refuses (see pack_meta_json_errors).
    pack_error(|m, _| m.height_m = f32::NAN, "expected f32");
    pack_error(|m, _| m.height_m = -1.0, "height_m is -1");
    pack_error(|m, _| m.materials[1].texture_layer = Some(3), "texture_layer = 3");
    pack_error(|m, _| m.mesh_levels[0].vertex_count = 4, "declares 4 vertices");
    pack_error(|m, _| m.mesh_levels[0].draws[1].index_count = 6, "draws[1]");
    pack_error(|m, _| m.mesh_levels[0].draws[0].material = 9, "draws[0].material = 9");
    pack_error(|m, _| m.mesh_levels.push(m.mesh_levels[0].clone()), "no MVTX/MIDX section with index 1");
    pack_error(|_, s| s[1].data[8..12].copy_from_slice(&3u32.to_le_bytes()), "index[2] = 3 is out of range");
    pack_error(|_, s| s[0].data[6] = 5, "vertex[0].material = 5");
    pack_error(|m, _| m.material_texture = Some(TextureArrayMeta::plain(8, 1, 3)), "needs 336 bytes");
    pack_error(|m, _| m.material_texture = Some(TextureArrayMeta::plain(4, 1, 9)), "mips = 9");
    // Block-encoded (BC7) arrays: 16 bytes a 4 × 4 block, a whole block for
    // mips under it; RGBA arrays of sides that are multiples of 4 only.
    let bc7 = |t: TextureArrayMeta| TextureArrayMeta { encoding: Some(sylva::format::pack::TexelEncoding::Bc7), ..t };
    assert_eq!(bc7(TextureArrayMeta::plain(8, 2, 4)).byte_len(), (4 + 1 + 1 + 1) * 16 * 2);
    pack_error(|m, _| m.material_texture = Some(bc7(TextureArrayMeta::plain(4, 1, 3))), "needs 48 bytes");
    pack_error(
        |m, _| m.billboards.as_mut().unwrap().texture.encoding = bc7(m.billboards.as_ref().unwrap().texture).encoding,
        "bc7 encoded but its size is no multiple of 4",
    );
    {
        let (mut meta, mut sections) = sample_pack();
        meta.material_texture = Some(bc7(TextureArrayMeta::plain(4, 1, 3)));
        let mtex = sections.iter_mut().find(|s| s.kind == sylva::format::pack::kind::MATERIAL_TEXTURES).unwrap();
        mtex.data = vec![0; 48];
        decode_pack("species/x.pack", &encode_pack(&meta, &sections)).expect("three BC7 blocks");
    }
    pack_error(|m, _| m.material_texture = Some(TextureArrayMeta::plain(1 << 20, 1, 1)), "size = 1048576");
    pack_error(|_, s| drop(s.remove(2)), "has no texture section");
    pack_error(|m, _| m.billboards.as_mut().unwrap().angles = 3, "3 angles");
    // The optional occlusion: a billboard array of one byte per texel, a field
    // whose header matches its bytes.
    pack_error(|_, s| s.push(Section { kind: *b"BBAO", index: 0, count: 0, stride: 0, data: vec![0; 3] }), "BBAO");
    let field = sylva::format::pack::AoFieldRef::encode([2, 2, 3], [0.0; 3], 0.5, &[200; 12]);
    let with_field = |data: Vec<u8>| {
        move |_: &mut PackMeta, s: &mut Vec<Section>| {
            s.push(Section { kind: *b"AOFD", index: 0, count: 0, stride: 0, data });
        }
    };
    pack_error(with_field(field[..field.len() - 1].to_vec()), "needs 44");
    let mut zero = field.clone();
    zero[0..4].copy_from_slice(&0u32.to_le_bytes());
    pack_error(with_field(zero), "AOFD.dims = 0");
    let mut flat = field.clone();
    flat[24..28].copy_from_slice(&0f32.to_le_bytes());
    pack_error(with_field(flat), "AOFD.cell is 0");
    let mut reserved = field.clone();
    reserved[28] = 1;
    pack_error(with_field(reserved), "AOFD.reserved is 1");
    let (meta, mut sections) = sample_pack();
    sections.push(Section { kind: *b"AOFD", index: 0, count: 0, stride: 0, data: field });
    let bytes = encode_pack(&meta, &sections);
    let pack = decode_pack("x", &bytes).unwrap();
    assert_eq!(pack.ao_field().map(|f| (f.dims, f.cell, f.cells.len())), Some(([2, 2, 3], 0.5, 12)));
    // Impostors: grid² layers, both arrays, the right byte counts, a positive radius.
    let imp_tex = TextureArrayMeta::plain(2, 4, 2);
    let with_impostors = |grid: u32, radius: f32, surface: bool| {
        move |m: &mut PackMeta, s: &mut Vec<Section>| {
            m.impostors = Some(sylva::format::pack::ImpostorMeta {
                grid,
                texture: imp_tex,
                center: [0.0; 3],
                radius,
                normal_length: Vec::new(),
                half_extent: None,
                variants: None,
            });
            s.push(Section { kind: kind::IMPOSTOR_COLOR, index: 0, count: 0, stride: 0, data: vec![0; 80] });
            if surface {
                s.push(Section { kind: kind::IMPOSTOR_SURFACE, index: 0, count: 0, stride: 0, data: vec![0; 80] });
            }
        }
    };
    pack_error(with_impostors(3, 1.0, true), "a 3×3 grid");
    pack_error(with_impostors(2, 0.0, true), "radius 0");
    pack_error(with_impostors(2, f32::INFINITY, true), "expected f32");
    pack_error(with_impostors(2, 1.0, false), "META.impostors.texture (state 0) has no texture section");
    let (mut meta, mut sections) = sample_pack();
    with_impostors(2, 1.0, true)(&mut meta, &mut sections);
    let bytes = encode_pack(&meta, &sections);
    let pack = decode_pack("x", &bytes).expect("a valid impostor pack");
    assert_eq!(pack.meta.impostors.as_ref().map(|i| i.grid), Some(2));
    // Seasons: the bare wood's far tiers (index 1) only with META.season.bare_far,
    // of the same layout as index 0's, in their own fetch part; bare_cover 0–1.
    let bare = |season: Option<SeasonMeta>, bytes: usize| {
        move |m: &mut PackMeta, s: &mut Vec<Section>| {
            with_impostors(2, 1.0, true)(m, s);
            m.season = season;
            for k in [kind::IMPOSTOR_COLOR, kind::IMPOSTOR_SURFACE] {
                s.push(Section { kind: k, index: 1, count: 0, stride: 0, data: vec![0; bytes] });
            }
            // The billboards' bare state: as their leafy one.
            let billboards: Vec<Section> = s
                .iter()
                .filter(|x| [kind::BILLBOARD_COLOR, kind::BILLBOARD_NORMAL, kind::BILLBOARD_AO].contains(&x.kind))
                .map(|x| Section { index: 1, ..x.clone() })
                .collect();
            s.extend(billboards);
        }
    };
    let season = |bare_far, bare_cover| Some(SeasonMeta { autumn: [200, 80, 30], bare_far, bare_cover, genus: None });
    pack_error(bare(None, 80), "section IMCO with index 1: the far tiers have 1 state here");
    pack_error(bare(season(false, 0.2), 80), "index 1");
    pack_error(bare(season(true, 0.2), 79), "META.impostors.texture (state 1) needs 80 bytes");
    pack_error(bare(season(true, 1.5), 80), "META.season.bare_cover is 1.5");
    let named =
        |g: &str| Some(SeasonMeta { autumn: [200, 80, 30], bare_far: true, bare_cover: 0.2, genus: Some(g.into()) });
    pack_error(bare(named("Fa gus\u{0}"), 80), "META.season.genus");
    pack_error(bare(named(""), 80), "META.season.genus");
    let (mut meta, mut sections) = sample_pack();
    bare(season(true, 0.2), 80)(&mut meta, &mut sections);
    let bytes = encode_pack(&meta, &sections);
    let head = PackHead::decode("x", &bytes).unwrap();
    let (leafy, bare_part) =
        (head.part_range(PackPart::Impostors).unwrap(), head.part_range(PackPart::BareImpostors).unwrap());
    assert!(leafy.1 <= bare_part.0 || bare_part.1 <= leafy.0, "the parts overlap: {leafy:?} {bare_part:?}");
    // A leaf-off viewer holding the head and the bare part alone assembles a valid pack.
    let held = vec![(bare_part.0, bytes[bare_part.0 as usize..bare_part.1 as usize].to_vec())];
    let pack = head.assemble("x", &held).expect("the bare part alone");
    assert!(pack.section(kind::IMPOSTOR_COLOR, 1).is_some() && pack.section(kind::IMPOSTOR_COLOR, 0).is_none());
    // Far tiers of every mesh variant: variants must be 1 or the mesh's, and
    // the layers grid² (or angles × azimuths) × variants.
    pack_error(
        |m: &mut PackMeta, s: &mut Vec<Section>| {
            with_impostors(2, 1.0, true)(m, s);
            m.impostors.as_mut().unwrap().variants = Some(2);
        },
        "META.impostors.variants",
    );
    pack_error(
        |m: &mut PackMeta, s: &mut Vec<Section>| {
            // A second mesh variant (all at the box's corner), and billboards
            // that say they hold both but have one's layers.
            m.mesh_levels[0].variants = 1;
            let n = m.mesh_levels[0].vertex_count;
            s.push(Section { kind: kind::MESH_VARIANTS, index: 0, count: n, stride: 8, data: vec![0; n as usize * 8] });
            m.billboards.as_mut().unwrap().variants = Some(2);
        },
        "2 variants but",
    );
    // Unknown section kinds are skipped (forward compatibility).
    let (meta, mut sections) = sample_pack();
    sections.push(Section { kind: *b"ELPS", index: 0, count: 2, stride: 32, data: vec![0; 64] });
    assert!(decode_pack("x", &encode_pack(&meta, &sections)).is_ok());
}

#[test]
fn pack_meta_json_errors() {
    let (meta, sections) = sample_pack();
    let mut bytes = encode_pack(&meta, &sections);
    // The META section starts at the first 256-byte boundary after the table.
    let meta_at = u64::from_le_bytes(bytes[40..48].try_into().unwrap()) as usize;
    let meta_len = u64::from_le_bytes(bytes[48..56].try_into().unwrap()) as usize;
    let original = bytes.clone();
    bytes[meta_at] = b'[';
    let msg = decode_pack("p", &bytes).unwrap_err().to_string();
    assert!(msg.contains("invalid JSON: META"), "{msg}");
    // Same-length edits of the JSON text: numbers that overflow f32 become infinite.
    for (from, to, needle) in [
        ("\"height_m\":10.0", "\"height_m\":1e39", "META.height_m is not a finite number"),
        ("\"bounds_max\":[2.0,2.0,10.0", "\"bounds_max\":[2.0,2.0,1e39", "META.bounds_max[2]"),
        ("\"center\":[0.0,0.0,5.0]", "\"center\":[1e39,0.0,5 ]", "META.billboards.center[0]"),
        ("\"base_color\":[1.0,1.0", "\"base_color\":[1e50,1 ", "base_color[0]"),
    ] {
        let mut b = original.clone();
        let text = String::from_utf8(b[meta_at..meta_at + meta_len].to_vec()).unwrap();
        assert!(text.contains(from), "{from} not in {text}");
        let edited = text.replacen(from, to, 1);
        assert_eq!(edited.len(), text.len());
        b[meta_at..meta_at + meta_len].copy_from_slice(edited.as_bytes());
        let msg = decode_pack("p", &b).unwrap_err().to_string();
        assert!(msg.contains(needle), "expected {needle:?} in {msg:?}");
    }
}

fn manifest_error(mutate: impl FnOnce(&mut serde_json::Value), needle: &str) {
    let mut v: serde_json::Value = serde_json::from_slice(&sample_manifest().encode()).unwrap();
    mutate(&mut v);
    let msg = Manifest::decode("https://example.org/scene.json", &serde_json::to_vec(&v).unwrap())
        .expect_err(needle)
        .to_string();
    assert!(msg.starts_with("https://example.org/scene.json: "), "{msg}");
    assert!(msg.contains(needle), "expected {needle:?} in {msg:?}");
}

#[test]
fn manifest_decoder_error_paths() {
    assert!(Manifest::decode("s", b"{not json").unwrap_err().to_string().contains("invalid JSON"));
    assert!(Manifest::decode("s", b"<html>404</html>").unwrap_err().to_string().contains("invalid JSON"));
    manifest_error(|v| v["format"] = "other".into(), "not a Sylva scene manifest");
    manifest_error(|v| v["version"] = (SCENE_VERSION + 1).into(), &format!("version {}", SCENE_VERSION + 1));
    // A species' block-compressed pack variants: version 12, URLs inside the
    // scene, a handful, named.
    let variant = serde_json::json!({"textures": "bc7", "pack": "species/a.bc7.pack", "bytes": 50});
    manifest_error(
        |v| {
            v["version"] = 11.into();
            v["species"][0]["variants"] = serde_json::json!([variant.clone()]);
        },
        "species[0].variants needs manifest version 12",
    );
    manifest_error(
        |v| {
            v["version"] = 12.into();
            v["species"][0]["variants"] = serde_json::json!([{"textures": "bc7", "pack": "../x.pack", "bytes": 1}]);
        },
        "species[0].variants[0].pack",
    );
    manifest_error(
        |v| {
            v["version"] = 12.into();
            v["species"][0]["variants"] = serde_json::json!(vec![variant.clone(); 9]);
        },
        "9 variants exceed 8",
    );
    manifest_error(
        |v| {
            v["version"] = 12.into();
            v["species"][0]["variants"] =
                serde_json::json!([{"textures": "", "pack": "species/a.bc7.pack", "bytes": 1}]);
        },
        "is no encoding name",
    );
    {
        let mut v: serde_json::Value = serde_json::from_slice(&sample_manifest().encode()).unwrap();
        v["version"] = 12.into();
        v["species"][0]["variants"] =
            serde_json::json!([{"textures": "astc4x4", "pack": "species/a.astc.pack", "bytes": 40}, variant]);
        let m = Manifest::decode("scene.json", &serde_json::to_vec(&v).unwrap()).unwrap();
        use sylva::format::pack::TexelEncoding::Bc7;
        // The first encoding the device samples that the species has; names it does not know are skipped.
        let c = m.species[0].pack_for(&[Bc7]);
        assert_eq!((c.pack, c.bytes, c.encoding), ("species/a.bc7.pack", 50, Some(Bc7)));
        let c = m.species[0].pack_for(&[]);
        assert_eq!((c.pack, c.encoding), (m.species[0].pack.as_str(), None));
        assert_eq!(m.species[1].pack_for(&[Bc7]).encoding, None, "no variant: the plain pack");
    }
    // Version 8 adds the canopy quadtree; its folder stays inside the scene, its sizes are bounded.
    let canopy = serde_json::json!({"path": "canopy", "origin_m": [-512.0, 0.0], "root_size_m": 2048.0,
        "levels": 3, "cells": 64, "rasters": 5, "bytes": 164_080});
    manifest_error(|v| v["canopy"] = canopy.clone(), "\"canopy\" needs manifest version 8");
    let with = |key: &'static str, value: serde_json::Value| {
        let mut c = canopy.clone();
        c[key] = value;
        move |v: &mut serde_json::Value| {
            v["version"] = 8.into();
            v["canopy"] = c.clone();
        }
    };
    manifest_error(with("path", "../secret".into()), "canopy.path");
    manifest_error(with("root_size_m", 0.0.into()), "root_size_m");
    manifest_error(with("levels", 0.into()), "canopy.levels");
    manifest_error(with("levels", 40.into()), "canopy.levels");
    manifest_error(with("cells", 5000.into()), "canopy.cells");
    manifest_error(with("extra", 1.into()), "unknown field");
    let mut m = sample_manifest();
    m.version = 8;
    m.canopy = Some(serde_json::from_value(canopy).unwrap());
    assert_eq!(Manifest::decode("s", &m.encode()).unwrap().canopy, m.canopy);
    manifest_error(
        |v| v["index"] = serde_json::json!({"root": "index/r.json", "nodes": 1, "depth": 1, "node_tiles": 64}),
        "needs manifest version 2",
    );
    manifest_error(
        |v| {
            v["version"] = 2.into();
            v["index"] = serde_json::json!({"root": "index/r.json", "nodes": 1, "depth": 1, "node_tiles": 64});
        },
        "empty \"tiles\" list",
    );
    manifest_error(
        |v| {
            v["version"] = 2.into();
            v["shard"] = serde_json::json!({"index": 2, "count": 2});
        },
        "shard 2 of 2",
    );
    manifest_error(|v| v["cell_size_m"] = (-1.0).into(), "must be positive");
    manifest_error(|v| v["origin_m"][1] = serde_json::Value::Null, "invalid JSON");
    manifest_error(|v| v["bounds"]["min"][0] = 1000.0.into(), "exceeds max");
    manifest_error(|v| v["tiles"][0]["url"] = "../../etc/passwd".into(), "relative path inside the scene");
    manifest_error(|v| v["tiles"][0]["url"] = "https://evil.example/x.tile".into(), "relative path inside the scene");
    manifest_error(|v| v["species"][0]["pack"] = "/abs.pack".into(), "species[0].pack");
    manifest_error(|v| v["counts"]["trees"] = 6.into(), "do not match");
    manifest_error(|v| v["species"][1]["trees"] = 3.into(), "do not match");
    manifest_error(|v| v["unexpected"] = 1.into(), "unknown field");
    manifest_error(|v| v["species"][0]["height_m"] = 1e39.into(), "species[0].height_m");
}

#[test]
fn the_home_of_a_scene_is_its_largest_group_of_touching_tiles() {
    use sylva::format::manifest::densest_group;
    let tile = |x: i32, y: i32, trees: u64| TileEntry {
        x,
        y,
        url: format!("tiles/{x}_{y}.tile"),
        ids_url: format!("tiles/{x}_{y}.ids"),
        bytes: 1,
        trees,
        batches: 1,
        bounds: Bounds {
            min: [x as f32 * 100.0, y as f32 * 100.0, 0.0],
            max: [x as f32 * 100.0 + 90.0, y as f32 * 100.0 + 90.0, 20.0],
        },
        attribute_codes: None,
        levels: None,
    };
    // West: three tiles touching (one only by a corner), 60 trees; east: one tile of 50.
    let mut tiles = vec![tile(0, 0, 20), tile(1, 1, 20), tile(0, 1, 20), tile(40, 0, 50)];
    let home = densest_group(&tiles).unwrap();
    assert_eq!(home.trees, 60);
    assert_eq!((home.bounds.min[0], home.bounds.max[0], home.bounds.max[1]), (0.0, 190.0, 190.0));
    // Whatever the order.
    tiles.reverse();
    assert_eq!(densest_group(&tiles), Some(home));
    // A bigger east group wins; an empty scene has none.
    tiles.push(tile(41, 0, 20));
    assert_eq!(densest_group(&tiles).unwrap().trees, 70);
    assert_eq!(densest_group(&[]), None);
    // A manifest's focus: its home, else the group of its flat list, else its bounds.
    let mut m = sample_manifest();
    assert_eq!(m.focus(), m.tiles[0].bounds);
    m.tiles.clear();
    assert_eq!(m.focus(), m.bounds);
}

#[test]
fn pack_mesh_variants_are_checked() {
    use sylva::format::pack::{variant_of, VariantVertex, MAX_VARIANTS};
    // Two other shapes of the sample's 3 vertices: read back as written.
    let (mut meta, mut sections) = sample_pack();
    meta.mesh_levels[0].variants = 2;
    let shapes: Vec<VariantVertex> =
        (0..6u16).map(|i| VariantVertex { position: [i, 2 * i, 3 * i], normal_oct: [0, 127] }).collect();
    sections.push(Section {
        kind: kind::MESH_VARIANTS,
        index: 0,
        count: 6,
        stride: 8,
        data: bytemuck::cast_slice(&shapes).to_vec(),
    });
    let bytes = encode_pack(&meta, &sections);
    let pack = decode_pack("p", &bytes).unwrap();
    assert_eq!(pack.meta.mesh_levels[0].variants, 2);
    assert_eq!(pack.section(kind::MESH_VARIANTS, 0).unwrap(), bytemuck::cast_slice::<_, u8>(&shapes));
    // A section of the wrong length, none, or too many variants: refused, saying what.
    let mut short = sections.clone();
    let last = short.last_mut().unwrap();
    last.data.truncate(40);
    last.count = 5;
    let e = decode_pack("p", &encode_pack(&meta, &short)).unwrap_err().to_string();
    assert!(e.contains("2 variants of 3 vertices (48 bytes)") && e.contains("40 bytes"), "{e}");
    let none: Vec<Section> = sections.iter().filter(|s| s.kind != kind::MESH_VARIANTS).cloned().collect();
    let e = decode_pack("p", &encode_pack(&meta, &none)).unwrap_err().to_string();
    assert!(e.contains("no MVAR section"), "{e}");
    meta.mesh_levels[0].variants = MAX_VARIANTS + 1;
    let e = decode_pack("p", &encode_pack(&meta, &sections)).unwrap_err().to_string();
    assert!(e.contains("variants"), "{e}");
    // A single tree is captured with variation 15: variant 0 whatever the count.
    for extra in 0..=MAX_VARIANTS {
        assert_eq!(variant_of(15, extra), 0);
        let used: std::collections::BTreeSet<u32> = (0..32).map(|v| variant_of(v, extra)).collect();
        assert_eq!(used.len() as u32, extra + 1, "every variant is drawn by some variation");
    }
}
