//! GPU tests of the sun's shadows on `tests/fixtures/forest-small` (lavapipe):
//! the casters each cascade's cull pass picks against the CPU oracle; one tree's
//! shadow on the ground where the CPU puts it (its mesh projected along the sun
//! onto the terrain); no acne on sunlit ground; shadows only ever darken.

use std::path::{Path, PathBuf};

use glam::{DVec3, Vec3};
use sylva::camera::Camera;
use sylva::format::pack::decode_pack;
use sylva::format::Manifest;
use sylva::lod::select::{cpu_select, unpack_item_y};
use sylva::offscreen::{NamedView, OffscreenScene};
use sylva::render::forest::{PoolConfig, Representations};
use sylva::render::gpu_data::{Repr, REPR_COUNT};
use sylva::render::shadow::ShadowQuality;
use sylva::render::Lighting;

const W: u32 = 320;
const H: u32 = 240;

fn fixture() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/forest-small")
}

fn open(scene: &Path) -> OffscreenScene {
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        std::env::set_var("XDG_RUNTIME_DIR", "/tmp");
    }
    let pools = PoolConfig { instances: 1 << 16, batches: 1 << 12, items: 1 << 17, species: 8 };
    OffscreenScene::open(scene.to_str().unwrap(), W, H, pools).expect("a GPU adapter (mesa-vulkan-drivers)")
}

/// The light of a sun at `azimuth` (degrees clockwise from north = +y) and `elevation`.
fn sun(azimuth: f32, elevation: f32) -> Lighting {
    let (a, e) = (azimuth.to_radians(), elevation.to_radians());
    Lighting::for_sun(Vec3::new(a.sin() * e.cos(), a.cos() * e.cos(), e.sin()), elevation)
}

fn render(off: &mut OffscreenScene, cam: &Camera) -> Vec<u8> {
    off.load_view(cam, 30.0);
    off.render(cam, false);
    off.read_image()
}

fn luma(p: &[u8]) -> f32 {
    0.2126 * f32::from(p[0]) + 0.7152 * f32::from(p[1]) + 0.0722 * f32::from(p[2])
}

#[test]
fn shadow_casters_match_the_cpu_oracle_in_every_cascade() {
    let mut off = open(&fixture());
    off.load_view(&Camera::default(), 30.0);
    off.settings.shadows = ShadowQuality::High;
    off.settings.lighting = sun(200.0, 35.0);
    let mut per_repr = [0usize; REPR_COUNT as usize];
    let mut cascades_checked = 0;
    for view in [NamedView::Close, NamedView::Medium] {
        let cam = off.named_camera(view, 30.0).unwrap();
        off.load_view(&cam, 30.0);
        off.render(&cam, false);
        let cascades = off.renderer.last_cascades().to_vec();
        assert_eq!(cascades.len(), 3, "{view:?}: high quality draws three cascades");
        for (i, cascade) in cascades.iter().enumerate() {
            off.rerun_cascade_cull(i);
            let (gpu, batches, instances, visible) = off.read_selection();
            let oracle = cpu_select(cascade, &batches, &instances, off.renderer.species_table());
            assert_eq!(visible as usize, oracle.visible_batches.len(), "{view:?} cascade {i}: visible batches");
            for (slot, (g, c)) in gpu.iter().zip(&oracle.slots).enumerate() {
                let key = |v: &Vec<(u32, u32)>| {
                    let mut k: Vec<(u32, u32)> = v.iter().map(|&(i, y)| (i, unpack_item_y(y).1)).collect();
                    k.sort_unstable();
                    k
                };
                assert_eq!(key(g), key(c), "{view:?} cascade {i} slot {slot}: GPU and CPU casters differ");
                per_repr[slot % REPR_COUNT as usize] += c.len();
            }
            assert_eq!(oracle.dropped, 0);
            cascades_checked += 1;
        }
    }
    assert_eq!(cascades_checked, 6);
    // The representation follows the shadow texel: meshes near, billboards far.
    let meshes = per_repr[Repr::Mesh0 as usize] + per_repr[Repr::Mesh1 as usize];
    let clusters: usize = Repr::CLUSTERS.iter().map(|r| per_repr[*r as usize]).sum();
    assert!(meshes > 0 && clusters > 0 && per_repr[Repr::Billboard as usize] > 0, "casters {per_repr:?}");
}

/// A copy of the fixture holding one tree: the first of the batch nearest the
/// middle of the trees, on the fixture's terrain; `copies` times over in the
/// same spot (one tree to the eye, a dense stand to the batch's density).
fn single_tree_copy(dst: &Path, copies: u32) {
    let src = fixture();
    let bytes = std::fs::read(src.join("scene.json")).unwrap();
    let m = Manifest::decode("scene.json", &bytes).unwrap();
    let tiles = sylva::format::index::read_all_tiles(&src, &m).unwrap();
    let mid = DVec3::from(m.bounds.min.map(f64::from)).lerp(DVec3::from(m.bounds.max.map(f64::from)), 0.5);
    // (distance, tile url, batch index)
    let mut best = (f64::MAX, String::new(), 0usize);
    for t in &tiles {
        let tb = std::fs::read(src.join(&t.url)).unwrap();
        let tile = sylva::format::Tile::decode(&t.url, &tb, m.species.len() as u32).unwrap();
        for (i, b) in tile.batches.iter().enumerate() {
            let d = (DVec3::from(b.center_m.map(f64::from)) - mid).truncate().length();
            if b.instance_count > 0 && d < best.0 {
                best = (d, t.url.clone(), i);
            }
        }
    }
    let (_, url, index) = best;
    let species = {
        let t = tiles.iter().find(|t| t.url == url).unwrap();
        let tile = sylva::format::Tile::decode(&t.url, &std::fs::read(src.join(&t.url)).unwrap(), 3).unwrap();
        tile.batches[index].species as usize
    };
    let keep = url.clone();
    crate::common::rewritten_copy(
        &src,
        dst,
        |m| {
            m.tiles.retain(|t| t.url == keep);
            m.counts.trees = u64::from(copies);
            m.counts.batches = 1;
            m.counts.tiles = 1;
            m.home = None;
            for s in &mut m.species {
                s.trees = 0;
            }
            m.species[species].trees = u64::from(copies);
        },
        |tile, t| {
            let mut b = tile.batches[index];
            let first = tile.instances[b.instance_offset as usize];
            b.instance_offset = 0;
            b.instance_count = copies;
            tile.batches = vec![b];
            tile.instances = vec![first; copies as usize];
            t.trees = u64::from(copies);
            t.batches = 1;
        },
    );
}

/// The tree's shadow as the CPU casts it: every triangle of its finest mesh
/// level moved along the sun onto the terrain, rasterised into 5 cm cells of
/// the ground plane. Returns the shadowed cells' ground points.
fn cpu_shadow(off: &mut OffscreenScene, scene: &Path, sun_dir: Vec3) -> Vec<DVec3> {
    let (_, batches, instances, _) = off.read_selection();
    let b = batches.iter().find(|b| b.instance_count > 0).expect("the tree is resident");
    let tree = instances[b.instance_offset as usize].decode(b);
    let m = off.stream.manifest().unwrap().clone();
    let pack_bytes = std::fs::read(scene.join(&m.species[b.species as usize].pack)).unwrap();
    let pack = decode_pack("pack", &pack_bytes).unwrap();
    let level = &pack.meta.mesh_levels[0];
    let vertices = pack.mesh_vertices(0);
    let indices = pack.mesh_indices(0);
    let (lo, hi) = (Vec3::from(level.pos_min), Vec3::from(level.pos_max));
    let base = DVec3::from(tree.position_m.map(f64::from));
    let sun = sun_dir.as_dvec3();
    let (s, c) = f64::from(tree.yaw_rad).sin_cos();
    let ground =
        |p: DVec3| f64::from(off.stream.ground_height_at(p.x as f32, p.y as f32).unwrap_or(tree.position_m[2]));
    let on_ground: Vec<DVec3> = vertices
        .iter()
        .map(|v| {
            let q = lo + Vec3::from(v.position.map(f32::from)) / 65535.0 * (hi - lo);
            let q = q.as_dvec3() * f64::from(tree.scale);
            let q = DVec3::new(q.x * f64::from(tree.aspect), q.y * f64::from(tree.aspect), q.z);
            let p = base + DVec3::new(c * q.x - s * q.y, s * q.x + c * q.y, q.z);
            // Down the sun's ray until it meets the ground.
            let mut t = 0.0;
            for _ in 0..6 {
                let at = p - sun * t;
                t += (at.z - ground(at)) / sun.z;
            }
            p - sun * t
        })
        .collect();
    let cell = 0.05;
    let mut cells = std::collections::HashSet::new();
    for tri in indices.chunks_exact(3) {
        let [a, b, c] = [0, 1, 2].map(|k| on_ground[tri[k] as usize]);
        let (x0, x1) = (a.x.min(b.x).min(c.x), a.x.max(b.x).max(c.x));
        let (y0, y1) = (a.y.min(b.y).min(c.y), a.y.max(b.y).max(c.y));
        let area = (b - a).truncate().perp_dot((c - a).truncate());
        if area.abs() < 1e-12 {
            continue;
        }
        for i in (x0 / cell).floor() as i64..=(x1 / cell).ceil() as i64 {
            for j in (y0 / cell).floor() as i64..=(y1 / cell).ceil() as i64 {
                let p = glam::DVec2::new((i as f64 + 0.5) * cell, (j as f64 + 0.5) * cell);
                let w0 = (b - a).truncate().perp_dot(p - a.truncate()) / area;
                let w1 = (c - b).truncate().perp_dot(p - b.truncate()) / area;
                let w2 = (a - c).truncate().perp_dot(p - c.truncate()) / area;
                if w0 >= 0.0 && w1 >= 0.0 && w2 >= 0.0 {
                    cells.insert((i, j));
                }
            }
        }
    }
    cells
        .into_iter()
        .map(|(i, j)| {
            let (x, y) = ((i as f64 + 0.5) * cell, (j as f64 + 0.5) * cell);
            DVec3::new(x, y, ground(DVec3::new(x, y, 0.0)))
        })
        .collect()
}

/// Pixel of the scene-relative point `p` seen by `cam` (None off screen).
fn pixel(cam: &Camera, p: DVec3) -> Option<(usize, usize)> {
    let v = cam.view_data(W, H);
    let c = v.clip_from_eye * (p - cam.eye_m).as_vec3().extend(1.0);
    if c.w <= 0.0 {
        return None;
    }
    let (x, y) = ((c.x / c.w * 0.5 + 0.5) * W as f32, (0.5 - c.y / c.w * 0.5) * H as f32);
    ((0.0..W as f32).contains(&x) && (0.0..H as f32).contains(&y)).then_some((x as usize, y as usize))
}

fn centroid(pixels: &[(usize, usize)]) -> (f64, f64) {
    let n = pixels.len().max(1) as f64;
    let (sx, sy) = pixels.iter().fold((0.0, 0.0), |(a, b), &(x, y)| (a + x as f64, b + y as f64));
    (sx / n, sy / n)
}

#[test]
fn a_single_tree_casts_its_shadow_where_the_cpu_puts_it_without_acne() {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("shadow-one-tree-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    single_tree_copy(&dir, 1);
    let mut off = open(&dir);
    let m = {
        let events = off.load_view(&Camera::default(), 30.0);
        off.stream.manifest().unwrap_or_else(|| panic!("the copy's manifest does not load: {events:?}")).clone()
    };
    let tile = &m.tiles[0];
    let c = DVec3::from(tile.bounds.min.map(f64::from)).lerp(DVec3::from(tile.bounds.max.map(f64::from)), 0.5);
    // Load the tree, then find it.
    let above = Camera { eye_m: DVec3::new(c.x, c.y, c.z + 300.0), pitch_rad: -1.5, ..Camera::default() };
    off.load_view(&above, 30.0);
    off.render(&above, false);
    let (_, batches, instances, _) = off.read_selection();
    let b = batches.iter().find(|b| b.instance_count > 0).expect("the tree is resident");
    let tree = instances[b.instance_offset as usize].decode(b);
    let base = DVec3::from(tree.position_m.map(f64::from));
    let height = f64::from(m.species[b.species as usize].height_m * tree.scale);

    // The sun in the south-east, 40° up: the shadow falls to the north-west.
    let light = sun(135.0, 40.0);
    off.settings.lighting = light;
    let reach = height / 40f64.to_radians().tan();
    let toward = DVec3::new(-light.sun_dir.x as f64, -light.sun_dir.y as f64, 0.0).normalize();
    let look_at = base + toward * (reach * 0.5);
    let cam = Camera {
        eye_m: DVec3::new(look_at.x, look_at.y, base.z + 2.2 * height + 20.0),
        pitch_rad: -std::f64::consts::FRAC_PI_2 + 1e-4,
        ..Camera::default()
    };
    off.settings.shadows = ShadowQuality::Off;
    off.settings.representations = Representations { meshes: false, clusters: false, billboards: false, clouds: false };
    let bare = render(&mut off, &cam);
    off.settings.representations = Representations::MESHES;
    off.settings.quality = 1.0e6; // the finest mesh, as the CPU casts it
    let lit_mesh = render(&mut off, &cam);
    off.settings.shadows = ShadowQuality::High;
    let shaded = render(&mut off, &cam);
    let cpu = cpu_shadow(&mut off, &dir, light.sun_dir);
    std::fs::remove_dir_all(&dir).ok();

    let px = |img: &[u8], i: usize| -> [u8; 4] { img[i * 4..i * 4 + 4].try_into().unwrap() };
    let differs = |a: [u8; 4], b: [u8; 4]| (0..3).any(|k| a[k].abs_diff(b[k]) > 2);
    let n = (W * H) as usize;
    // Pixels of the tree itself (it hides part of its shadow from above).
    let tree_px: Vec<bool> = (0..n).map(|i| differs(px(&lit_mesh, i), px(&bare, i))).collect();
    let tree_count = tree_px.iter().filter(|t| **t).count();
    assert!(tree_count > 200, "the tree covers {tree_count} px: nothing drawn?");
    // Shadows only darken: no pixel is brighter with them.
    let brighter = (0..n).filter(|&i| luma(&px(&shaded, i)) > luma(&px(&lit_mesh, i)) + 1.5).count();
    assert_eq!(brighter, 0, "pixels brighter with shadows on");
    // The image's shadow: ground pixels at least 12 % darker with shadows on.
    let image: Vec<(usize, usize)> = (0..n)
        .filter(|&i| !tree_px[i] && luma(&px(&shaded, i)) < 0.88 * luma(&px(&lit_mesh, i)))
        .map(|i| (i % W as usize, i / W as usize))
        .collect();
    // The CPU's, on the same screen and without the tree's pixels.
    let mut cpu_mask = vec![false; n];
    for p in &cpu {
        if let Some((x, y)) = pixel(&cam, *p) {
            cpu_mask[y * W as usize + x] = true;
        }
    }
    let expected: Vec<(usize, usize)> =
        (0..n).filter(|&i| cpu_mask[i] && !tree_px[i]).map(|i| (i % W as usize, i / W as usize)).collect();
    assert!(expected.len() > 300, "the CPU shadow covers {} px: camera misplaced?", expected.len());
    if let Some(dump) = std::env::var_os("SYLVA_SHADOW_DUMP") {
        // The images and the two shadows (red: image only, blue: CPU only, magenta: both).
        let dump = PathBuf::from(dump);
        let mut marks = lit_mesh.clone();
        for &(x, y) in &image {
            marks[(y * W as usize + x) * 4] = 255;
        }
        for &(x, y) in &expected {
            marks[(y * W as usize + x) * 4 + 2] = 255;
        }
        for (name, img) in [("lit", &lit_mesh), ("shaded", &shaded), ("marks", &marks)] {
            image::save_buffer(dump.join(format!("shadow-{name}.png")), img, W, H, image::ColorType::Rgba8).unwrap();
        }
    }
    let (gx, gy) = centroid(&image);
    let (cx, cy) = centroid(&expected);
    let ratio = image.len() as f64 / expected.len() as f64;
    eprintln!(
        "shadow: image {} px at ({gx:.1}, {gy:.1}), CPU {} px at ({cx:.1}, {cy:.1}), ratio {ratio:.2}",
        image.len(),
        expected.len()
    );
    assert!(((gx - cx).powi(2) + (gy - cy).powi(2)).sqrt() < 4.0, "the shadow's centroid is off");
    // Leaves' alpha holes let light through that the CPU's solid triangles block.
    assert!((0.4..1.2).contains(&ratio), "the shadow's area is off: ratio {ratio:.2}");
    // No acne: sunlit ground away from the CPU's shadow is not darkened anywhere.
    let near_shadow = |i: usize| {
        let (x, y) = ((i % W as usize) as i64, (i / W as usize) as i64);
        (-4..=4).any(|dy| {
            (-4..=4).any(|dx| {
                let (xx, yy) = (x + dx, y + dy);
                xx >= 0 && yy >= 0 && xx < W as i64 && yy < H as i64 && cpu_mask[(yy * W as i64 + xx) as usize]
            })
        })
    };
    let speckles = (0..n)
        .filter(|&i| !tree_px[i] && !near_shadow(i) && luma(&px(&shaded, i)) < luma(&px(&lit_mesh, i)) - 2.0)
        .count();
    assert_eq!(speckles, 0, "sunlit ground darkened outside the tree's shadow (acne)");
}

/// Mean luminance of the tree's pixels (those that differ from `bare`) in the
/// top and the bottom third of its rows on screen, and how many there are.
fn crown_thirds(img: &[u8], bare: &[u8]) -> (f32, f32, usize) {
    let tree: Vec<usize> =
        (0..(W * H) as usize).filter(|&i| (0..3).any(|k| img[i * 4 + k].abs_diff(bare[i * 4 + k]) > 2)).collect();
    let rows: Vec<usize> = tree.iter().map(|i| i / W as usize).collect();
    let (top, bottom) = (rows.iter().min().copied().unwrap_or(0), rows.iter().max().copied().unwrap_or(0));
    let third = (bottom - top) / 3;
    let mean = |f: &dyn Fn(usize) -> bool| {
        let v: Vec<f32> = tree.iter().filter(|&&i| f(i / W as usize)).map(|&i| luma(&img[i * 4..i * 4 + 4])).collect();
        v.iter().sum::<f32>() / v.len().max(1) as f32
    };
    (mean(&|r| r <= top + third), mean(&|r| r >= bottom - third), tree.len())
}

#[test]
fn a_dense_stand_darkens_its_lower_crowns_alike_at_every_level() {
    // The same tree alone, and as a stand of 60 in its batch (all in one spot,
    // so the image shows one tree): the stand's crowns lose sky and sun low
    // down, their tops stay lit — in meshes, ellipsoids and billboards alike.
    let base = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("canopy-{}", std::process::id()));
    let mut ratios = Vec::new();
    for (family, only) in [
        ("meshes", Representations::MESHES),
        ("ellipsoids", Representations::CLUSTERS),
        ("billboards", Representations::BILLBOARDS),
    ] {
        let mut measured = Vec::new();
        for copies in [1, 60] {
            let dir = base.join(format!("{family}-{copies}"));
            let _ = std::fs::remove_dir_all(&dir);
            single_tree_copy(&dir, copies);
            let mut off = open(&dir);
            off.load_view(&Camera::default(), 30.0);
            let m = off.stream.manifest().expect("manifest").clone();
            let c = DVec3::from(m.tiles[0].bounds.min.map(f64::from))
                .lerp(DVec3::from(m.tiles[0].bounds.max.map(f64::from)), 0.5);
            let above = Camera { eye_m: c + DVec3::Z * 300.0, pitch_rad: -1.5, ..Camera::default() };
            off.load_view(&above, 30.0);
            off.render(&above, false);
            let (_, batches, instances, _) = off.read_selection();
            let b = batches.iter().find(|b| b.instance_count > 0).unwrap();
            let tree = instances[b.instance_offset as usize].decode(b);
            let h = f64::from(m.species[b.species as usize].height_m * tree.scale);
            // From the side, level with the middle of the crown, the sun behind the eye.
            let at = DVec3::from(tree.position_m.map(f64::from)) + DVec3::Z * (0.5 * h);
            let cam = Camera::look_at(at + DVec3::new(0.0, -1.6 * h, 0.0), at);
            off.settings.lighting = sun(190.0, 35.0);
            off.settings.shadows = ShadowQuality::Off;
            off.settings.representations =
                Representations { meshes: false, clusters: false, billboards: false, clouds: false };
            let bare = render(&mut off, &cam);
            off.settings.representations = only;
            // Levels by family: the full mesh, the finest ellipsoids, billboards at any size.
            off.settings.quality = if family == "meshes" { 1.0e6 } else { 1.0 };
            off.settings.cluster_min_px = 0.0;
            let img = render(&mut off, &cam);
            measured.push(crown_thirds(&img, &bare));
            std::fs::remove_dir_all(&dir).ok();
        }
        let [(top1, low1, n1), (top60, low60, n60)] = [measured[0], measured[1]];
        assert!(n1 > 500 && n60 > 500, "{family}: the tree covers {n1} / {n60} px");
        eprintln!("{family}: alone top {top1:.1} bottom {low1:.1}; in a stand top {top60:.1} bottom {low60:.1}");
        // Tops barely change, the lower crown darkens clearly.
        assert!(top60 > 0.85 * top1, "{family}: the stand's crown tops darkened too much");
        let ratio = low60 / low1;
        assert!(ratio < 0.85, "{family}: the lower crown of a dense stand is not darker ({ratio:.2})");
        ratios.push(ratio);
    }
    // The same tree looks equally dark at every level of detail.
    let (lo, hi) = ratios.iter().fold((f32::MAX, f32::MIN), |(l, h), r| (l.min(*r), h.max(*r)));
    assert!(hi - lo < 0.15, "levels darken differently: {ratios:?}");
}
