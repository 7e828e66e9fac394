//! GPU tests of the mesh pass and the billboard capture (any adapter; lavapipe on CI).
//! They look at pixels: a test that passed on a black image would be no test.

use sylva::format::pack::{
    kind, DrawRange, MaterialKind, MaterialMeta, MeshLevelMeta, MeshVertex, PackMeta, SeasonMeta, Section,
    TextureArrayMeta, VariantVertex,
};
use sylva::format::{decode_pack, encode_pack};
use sylva::render::capture::{
    capture_billboards, render_pack_preview, BillboardFrame, CapturePipelines, PackRepr, PackView, TreeRenderer,
};
use sylva::render::settings::Season;
use sylva::render::GpuContext;

const TEX: u32 = 16;

/// A "tree": a brown trunk quad (0–6 m) and a green leaf card (alpha-tested disc,
/// 4–10 m), both vertical and facing (1, 1, 0)/√2, so the side views from −y
/// (preview) and +x (capture azimuth 0) both see them and the top view sees them edge-on.
fn toy_pack() -> Vec<u8> {
    toy_pack_with(false)
}

/// The toy tree; with `variant`, a second shape of it (`MVAR`) whose leaf card
/// is half as wide and tall (the trunk the same).
fn toy_pack_with(variant: bool) -> Vec<u8> {
    let q = |v: f32, lo: f32, hi: f32| (((v - lo) / (hi - lo)).clamp(0.0, 1.0) * 65535.0).round() as u16;
    let (lo, hi) = ([-3.0f32, -3.0, 0.0], [3.0f32, 3.0, 10.0]);
    // `t` runs along the card's horizontal direction (1, −1, 0)/√2.
    let vtx = |t: f32, z: f32, u: f32, v: f32, material: u16| MeshVertex {
        position: [
            q(t * std::f32::consts::FRAC_1_SQRT_2, lo[0], hi[0]),
            q(-t * std::f32::consts::FRAC_1_SQRT_2, lo[1], hi[1]),
            q(z, lo[2], hi[2]),
        ],
        material,
        normal_oct: [64, 64, 0, 0],
        uv: [q(u, 0.0, 1.0), q(v, 0.0, 1.0)],
        color: [255; 4],
    };
    // Trunk: 0.6 m wide, 6 m tall; a square leaf card `half` m to each side,
    // from `low` m to 10 m.
    let tree = |half: f32, low: f32| {
        [
            vtx(-0.3, 0.0, 0.0, 1.0, 0),
            vtx(0.3, 0.0, 1.0, 1.0, 0),
            vtx(0.3, 6.0, 1.0, 0.0, 0),
            vtx(-0.3, 6.0, 0.0, 0.0, 0),
            vtx(-half, low, 0.0, 1.0, 1),
            vtx(half, low, 1.0, 1.0, 1),
            vtx(half, 10.0, 1.0, 0.0, 1),
            vtx(-half, 10.0, 0.0, 0.0, 1),
        ]
    };
    // The leaf card: 6 m square from 4 to 10 m; the variant's half as wide and tall.
    let vertices = tree(3.0, 4.0);
    let indices: [u32; 12] = [0, 1, 2, 0, 2, 3, 4, 5, 6, 4, 6, 7];
    let small = tree(1.5, 7.0);
    let variant_vertices: Vec<VariantVertex> = small
        .iter()
        .map(|v| VariantVertex { position: v.position, normal_oct: [v.normal_oct[0], v.normal_oct[1]] })
        .collect();
    // Leaf texture: green disc, transparent outside; mips by the alpha-aware builder.
    let disc: Vec<u8> = (0..TEX * TEX)
        .flat_map(|i| {
            let (x, y) = ((i % TEX) as f32 + 0.5 - TEX as f32 / 2.0, (i / TEX) as f32 + 0.5 - TEX as f32 / 2.0);
            if x * x + y * y < (TEX as f32 * 0.45).powi(2) {
                [40, 160, 40, 255]
            } else {
                [0, 0, 0, 0]
            }
        })
        .collect();
    let chain =
        sylva::render::mips::alpha_aware_mips(&disc, &disc, TEX, sylva::render::mips::ColorEncoding::Srgb, Some(0.5));
    let tex = TextureArrayMeta::plain(TEX, 1, chain.len() as u32);
    let meta = PackMeta {
        name: "toy".into(),
        height_m: 10.0,
        bounds_min: lo,
        bounds_max: hi,
        materials: vec![
            MaterialMeta {
                name: "bark".into(),
                kind: MaterialKind::Branch,
                base_color: [0.25, 0.12, 0.05, 1.0],
                alpha_cutoff: 0.0,
                double_sided: true,
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
            vertex_count: vertices.len() as u32,
            index_count: indices.len() as u32,
            pos_min: lo,
            pos_max: hi,
            uv_min: [0.0, 0.0],
            uv_max: [1.0, 1.0],
            draws: vec![
                DrawRange { material: 0, first_index: 0, index_count: 6 },
                DrawRange { material: 1, first_index: 6, index_count: 6 },
            ],
            select_px: 0.0,
            policy_px: None,
            variants: u32::from(variant),
        }],
        billboards: None,
        clusters: None,
        impostors: None,
        cloud: None,
        season: None,
    };
    let sections = vec![
        Section {
            kind: kind::MESH_VERTICES,
            index: 0,
            count: 8,
            stride: 20,
            data: bytemuck::cast_slice(&vertices).to_vec(),
        },
        Section {
            kind: kind::MESH_INDICES,
            index: 0,
            count: 12,
            stride: 4,
            data: bytemuck::cast_slice(&indices).to_vec(),
        },
        Section { kind: kind::MATERIAL_TEXTURES, index: 0, count: 0, stride: 0, data: chain.concat() },
    ];
    let mut sections = sections;
    if variant {
        sections.push(Section {
            kind: kind::MESH_VARIANTS,
            index: 0,
            count: 8,
            stride: 8,
            data: bytemuck::cast_slice(&variant_vertices).to_vec(),
        });
    }
    encode_pack(&meta, &sections)
}

fn gpu() -> GpuContext {
    std::env::set_var("XDG_RUNTIME_DIR", std::env::var("XDG_RUNTIME_DIR").unwrap_or_else(|_| "/tmp".into()));
    GpuContext::new_headless_blocking().expect("a GPU adapter (install mesa-vulkan-drivers for lavapipe)")
}

fn pixel(img: &[u8], w: u32, x: u32, y: u32) -> [u8; 4] {
    let i = ((y * w + x) * 4) as usize;
    [img[i], img[i + 1], img[i + 2], img[i + 3]]
}

fn write_actual(name: &str, img: &[u8], w: u32, h: u32) -> String {
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
    let path = dir.join(format!("{name}-actual.png"));
    image::save_buffer(&path, img, w, h, image::ColorType::Rgba8).unwrap();
    path.display().to_string()
}

#[test]
fn preview_draws_trunk_and_alpha_tested_leaves() {
    let ctx = gpu();
    let bytes = toy_pack();
    let pack = decode_pack("toy", &bytes).unwrap();
    let (w, h) = (128, 128);
    let bg = [0.0, 0.0, 1.0, 1.0];
    let img = render_pack_preview(&ctx, &pack, 0, PackView::Side, [w, h], bg);
    let saved = write_actual("preview", &img, w, h);
    // Classify pixels: background blue, leaf green, trunk brown.
    let (mut leaf, mut trunk, mut background) = (0, 0, 0);
    for p in img.chunks_exact(4) {
        match p {
            [0, 0, 255, 255] => background += 1,
            [r, g, b, _] if g > r && g > b => leaf += 1,
            [r, g, b, _] if r > g && r > b => trunk += 1,
            _ => {}
        }
    }
    let total = (w * h) as usize;
    assert!(background > total / 4, "too little background ({background}); see {saved}");
    assert!(leaf > total / 20, "leaves missing ({leaf} px); see {saved}");
    assert!(trunk > total / 200, "trunk missing ({trunk} px); see {saved}");
    // The leaf disc is alpha-tested: its card's corners are background.
    // The card spans most of the width near the top; a corner of it must be empty.
    let centre = pixel(&img, w, w / 2, h / 3);
    assert!(centre[1] > centre[2] && centre[1] > centre[0], "crown centre is not green: {centre:?}; see {saved}");
}

/// The toy tree's billboards (variant 0) from `angles` elevations at `size`²,
/// with its leaves or (`leaves` false) its wood alone.
fn capture_toy(ctx: &GpuContext, angles: u32, size: u32, leaves: bool) -> sylva::render::capture::CapturedBillboards {
    let bytes = toy_pack();
    let pack = decode_pack("toy", &bytes).unwrap();
    let pipelines = CapturePipelines::new(&ctx.device, wgpu::TextureFormat::Rgba8UnormSrgb);
    let frame = BillboardFrame::from_bounds(pack.meta.bounds_min.into(), pack.meta.bounds_max.into());
    capture_billboards(ctx, &pipelines, &pack, &frame, angles, 1, size, leaves, 0)
}

#[test]
fn billboard_capture_sees_the_tree_from_every_angle() {
    let ctx = gpu();
    let size = 64;
    let cap = capture_toy(&ctx, 4, size, true);
    assert_eq!(cap.color.len(), 4);
    let coverage: Vec<f64> = cap.color.iter().map(|l| sylva::render::mips::alpha_coverage(l, 0.5)).collect();
    for (k, c) in coverage.iter().enumerate().take(3) {
        assert!(
            *c > 0.02,
            "angle {k} captured nothing ({c}); see {}",
            write_actual(&format!("capture{k}"), &cap.color[k], size, size)
        );
    }
    // Seen from the side (angle 0) the card faces the camera; from the top (angle 3) it is
    // edge-on: (almost) nothing.
    assert!(coverage[3] < coverage[0] * 0.2, "coverage by angle {coverage:?}");
    // Normals are stored for covered texels: from the side the card normal (±x) faces the camera.
    let i = (size / 3 * size + size / 2) as usize * 4;
    let n = &cap.normal[0][i..i + 4];
    assert!(cap.color[0][i + 3] > 0, "no texel at the crown centre");
    assert!((i32::from(n[0]) - 128).abs() > 60, "normal x should be ±0.7, got {n:?}");
    assert!(n[2].abs_diff(128) < 20, "normal z should be 0, got {n:?}");
}

#[test]
fn a_leaf_off_capture_and_draw_keep_the_wood_alone() {
    // The bare tree (a deciduous species' leaf-off far tiers): captured with
    // the leaves left out, only wood texels remain, far fewer of them.
    let ctx = gpu();
    let bytes = toy_pack();
    let pack = decode_pack("toy", &bytes).unwrap();
    let size = 64;
    let leafy = capture_toy(&ctx, 2, size, true);
    let bare = capture_toy(&ctx, 2, size, false);
    let covered =
        |c: &sylva::render::capture::CapturedBillboards| c.color[0].chunks_exact(4).filter(|t| t[3] > 0).count();
    let leaves = |c: &sylva::render::capture::CapturedBillboards| {
        c.normal[0].chunks_exact(4).zip(c.color[0].chunks_exact(4)).filter(|(n, t)| t[3] > 0 && n[3] > 191).count()
    };
    assert!(leaves(&leafy) > 100, "the leafy capture has leaf texels ({})", leaves(&leafy));
    assert_eq!(leaves(&bare), 0, "the bare capture has leaf texels");
    assert!(covered(&bare) > 0, "the bare capture has its trunk");
    assert!(covered(&bare) * 3 < covered(&leafy), "bare {} vs leafy {} texels", covered(&bare), covered(&leafy));
    // Drawn: leaf-off drops the leaf card (the trunk stays); autumn recolours
    // it; an evergreen (no season in its pack) is the same in every season.
    let (w, h) = (96, 96);
    let bg = [0.0, 0.0, 1.0, 1.0];
    let r = TreeRenderer::new(&ctx);
    let deciduous = SeasonMeta { autumn: [220, 60, 20], bare_far: false, bare_cover: 0.2, genus: None };
    let count = |meta: Option<&SeasonMeta>, season: Season| {
        r.set_season(meta, season);
        let img = r.render_pack(&ctx, &pack, PackRepr::Mesh(0), PackView::Side, [w, h], bg).unwrap();
        let (mut green, mut red, mut drawn) = (0usize, 0usize, 0usize);
        for p in img.chunks_exact(4) {
            if p[..3] != [0, 0, 255] {
                drawn += 1;
            }
            match p {
                [r, g, b, _] if g > r && g > b => green += 1,
                [r, g, b, _] if r > g && r > b => red += 1,
                _ => {}
            }
        }
        (green, red, drawn, write_actual(&format!("season-{}", season.name()), &img, w, h))
    };
    let (green_on, red_on, drawn_on, saved_on) = count(Some(&deciduous), Season::LeafOn);
    let (green_autumn, red_autumn, drawn_autumn, saved_autumn) = count(Some(&deciduous), Season::Autumn);
    let (_, _, drawn_off, saved_off) = count(Some(&deciduous), Season::LeafOff);
    assert!(green_on > 200, "leaf-on has its green card ({green_on} px); see {saved_on}");
    assert!(
        green_autumn * 10 < green_on && red_autumn > red_on + green_on / 2,
        "autumn turns the leaves red ({green_autumn} green, {red_autumn} red px); see {saved_autumn}"
    );
    assert_eq!(drawn_autumn, drawn_on, "autumn recolours, it does not change the silhouette");
    assert!(
        drawn_off * 10 <= drawn_on * 3 && drawn_off > 0,
        "leaf-off keeps the trunk only ({drawn_off} of {drawn_on} px); see {saved_off}"
    );
    let (green_ever, _, drawn_ever, _) = count(None, Season::LeafOff);
    assert_eq!((green_ever, drawn_ever), (green_on, drawn_on), "an evergreen keeps its leaves");
    r.set_season(None, Season::LeafOn);
}

#[test]
fn a_tree_draws_its_variant() {
    // The same level, two shapes: a tree of variant 1 draws the smaller card,
    // the trunk unchanged; variant 0 and a variant the level lacks (modulo)
    // draw the level's own.
    let ctx = gpu();
    let bytes = toy_pack_with(true);
    let pack = decode_pack("toy", &bytes).unwrap();
    let (w, h) = (96, 96);
    let bg = [0.0, 0.0, 1.0, 1.0];
    let r = TreeRenderer::new(&ctx);
    let count = |variant: u32| {
        r.set_variant(&ctx, variant);
        let img = r.render_pack(&ctx, &pack, PackRepr::Mesh(0), PackView::Side, [w, h], bg).unwrap();
        let (mut leaf, mut trunk) = (0usize, 0usize);
        for p in img.chunks_exact(4) {
            match p {
                [r, g, b, _] if g > r && g > b => leaf += 1,
                [r, g, b, _] if r > g && r > b => trunk += 1,
                _ => {}
            }
        }
        (leaf, trunk, write_actual(&format!("variant{variant}"), &img, w, h))
    };
    let (leaf0, trunk0, saved0) = count(0);
    let (leaf1, trunk1, saved1) = count(1);
    let (leaf2, _, _) = count(2);
    assert!(leaf0 > 200, "variant 0 drew {leaf0} leaf px; see {saved0}");
    assert!(leaf1 > 20 && leaf1 * 3 < leaf0, "variant 1 drew {leaf1} leaf px, variant 0 {leaf0}; see {saved1}");
    // (The smaller card hides less of the trunk.)
    assert!(trunk0 > 0 && trunk1 > trunk0, "trunk {trunk0} vs {trunk1} px; see {saved1}");
    assert_eq!(leaf2, leaf0, "variant 2 of a level with two is variant 0");
}

#[test]
fn a_tree_shades_with_its_variants_normals() {
    // Two variants with the level's own positions: variant 1 also its normals
    // (drawn exactly as variant 0: a read of the wrong bytes would change it),
    // variant 2 every normal turned straight up (its leaves lit otherwise).
    let ctx = gpu();
    let bytes = toy_pack_with(false);
    let pack = decode_pack("toy", &bytes).unwrap();
    let mut meta = pack.meta.clone();
    meta.mesh_levels[0].variants = 2;
    let own = pack.mesh_vertices(0);
    let same: Vec<VariantVertex> = own
        .iter()
        .map(|v| VariantVertex { position: v.position, normal_oct: [v.normal_oct[0], v.normal_oct[1]] })
        .collect();
    let up: Vec<VariantVertex> =
        own.iter().map(|v| VariantVertex { position: v.position, normal_oct: [0, 0] }).collect();
    let mut sections: Vec<Section> = pack
        .sections
        .iter()
        .filter(|(e, _)| e.kind != kind::META)
        .map(|(e, d)| Section { kind: e.kind, index: e.index, count: e.count, stride: e.stride, data: d.to_vec() })
        .collect();
    let variants: Vec<VariantVertex> = same.into_iter().chain(up).collect();
    sections.push(Section {
        kind: kind::MESH_VARIANTS,
        index: 0,
        count: variants.len() as u32,
        stride: 8,
        data: bytemuck::cast_slice(&variants).to_vec(),
    });
    let bytes = encode_pack(&meta, &sections);
    let pack = decode_pack("toy-normals", &bytes).unwrap();
    let (w, h) = (96, 96);
    let bg = [0.0, 0.0, 1.0, 1.0];
    let r = TreeRenderer::new(&ctx);
    let draw = |variant: u32| {
        r.set_variant(&ctx, variant);
        let img = r.render_pack(&ctx, &pack, PackRepr::Mesh(0), PackView::Side, [w, h], bg).unwrap();
        let green: Vec<u32> =
            img.chunks_exact(4).filter(|p| p[1] > p[0] && p[1] > p[2]).map(|p| u32::from(p[1])).collect();
        let mean = green.iter().sum::<u32>() as f64 / green.len().max(1) as f64;
        (img.clone(), green.len(), mean, write_actual(&format!("normals{variant}"), &img, w, h))
    };
    let (img0, n0, mean0, saved0) = draw(0);
    let (img1, _, _, saved1) = draw(1);
    let (_, n2, mean2, saved2) = draw(2);
    r.set_variant(&ctx, 0);
    assert!(n0 > 200, "variant 0 drew {n0} leaf px; see {saved0}");
    // (Variation 15 and 16 tint alike to within a level: compare loosely.)
    let differ = img0.iter().zip(&img1).filter(|(a, b)| a.abs_diff(**b) > 3).count();
    assert!(differ < 20, "variant 1 (the level's own normals) differs in {differ} bytes; see {saved0}, {saved1}");
    assert_eq!(n2, n0, "the same silhouette");
    assert!((mean2 - mean0).abs() > 8.0, "leaf green {mean0:.1} vs {mean2:.1} with normals up; see {saved2}");
}
