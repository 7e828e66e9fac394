//! Terrain end to end: a synthetic GeoTIFF DEM of steep hills under a small
//! forest, baked, streamed and drawn by the native renderer (lavapipe): the
//! ground is drawn wherever the DEM has data with no background showing
//! through seams between levels, the levels follow the view, the stream's
//! ground heights match the DEM, and the trees stand on it.

use std::path::Path;

use crate::common::{run, tmp, write_geotiff_dem};
use glam::DVec3;
use sylva::camera::Camera;
use sylva::offscreen::OffscreenScene;
use sylva::render::forest::PoolConfig;

const W: u32 = 256;
const H: u32 = 160;

/// Steep hills: 120 m of relief over a few hundred metres (DEM CRS metres).
fn hills(x: f64, y: f64) -> f64 {
    let (u, v) = (x - 500_000.0, y - 5_299_400.0);
    400.0 + 50.0 * (u / 70.0).sin() * (v / 55.0).cos() + 15.0 * (u / 23.0 + v / 31.0).sin() + 0.05 * u
}

/// Bakes `dir/trees.csv` with the oak `model` on `dem` (plus `extra` flags)
/// into `dir/scene`: the scene and the bake's output.
fn bake(
    dir: &Path,
    model: &Path,
    dem: &Path,
    extra: &[&std::ffi::OsStr],
) -> (std::path::PathBuf, std::process::Output) {
    let scene = dir.join("scene");
    let o = run(crate::common::bin()
        .arg("bake")
        .arg("--model")
        .arg(format!("oak={}", model.display()))
        .arg("--placements")
        .arg(dir.join("trees.csv"))
        .args(["--input-crs", "EPSG:32633", "--no-clusters", "--billboard-size", "16", "--texture-size", "16"])
        .arg("--dem")
        .arg(dem)
        .args(extra)
        .arg("--out")
        .arg(&scene));
    (scene, o)
}

fn open(scene: &Path) -> OffscreenScene {
    sylva::render::context::ensure_runtime_dir();
    let pools = PoolConfig { instances: 1 << 14, batches: 1 << 10, items: 1 << 15, species: 4 };
    OffscreenScene::open(scene.to_str().unwrap(), W, H, pools).expect("a GPU adapter (lavapipe)")
}

fn render(off: &mut OffscreenScene, cam: &Camera) -> Vec<u8> {
    off.load_view(cam, 30.0);
    off.render(cam, false);
    off.read_image()
}

#[test]
fn the_ground_of_a_dem_is_drawn_without_cracks_and_the_trees_stand_on_it() {
    let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/models/eztree_oak_medium.glb");
    if !model.exists() {
        eprintln!("skipping: {} not present", model.display());
        return;
    }
    let dir = tmp("terrain-render");
    let dem = dir.join("hills.tif");
    write_geotiff_dem(&dem, 300, 2.0, hills); // 600 m × 600 m
                                              // 120 trees in the middle of the DEM.
    let mut csv = String::from("id,x,y,height\n");
    for i in 0..120 {
        csv += &format!("{i},{},{},14\n", 500_250 + (i % 12) * 9, 5_299_650 - (i / 12) * 9);
    }
    std::fs::write(dir.join("trees.csv"), csv).unwrap();
    let (scene, o) = bake(&dir, &model, &dem, &[]);
    let log = String::from_utf8_lossy(&o.stderr);
    assert!(log.contains("terrain: ") && log.contains("2.00 m finest spacing"), "{log}");
    let mut off = open(&scene);
    off.load_view(&Camera::default(), 30.0);
    let m = off.stream.manifest().unwrap().clone();
    let t = m.terrain.clone().expect("a terrain entry");
    assert!(t.levels >= 4, "{t:?}");
    let origin = DVec3::from(m.origin_m);
    let rel = |x: f64, y: f64| DVec3::new(x - origin.x, y - origin.y, 0.0);
    let ground = |x: f64, y: f64| hills(x, y) - origin.z;

    // Cameras over the hills, low and looking down across them, so every pixel
    // is ground within the DEM; at a coarse 12 px threshold the terrain is a
    // mix of levels with steps of pixels between them (without skirts this
    // shows ~30 background pixels). Any pixel left as the background is a
    // crack (or a missing tile).
    let mut levels_seen = std::collections::BTreeSet::new();
    for (k, (x, y, heading)) in
        [(500_150.0, 5_299_850.0, 135f64), (500_450.0, 5_299_850.0, 225.0), (500_300.0, 5_299_450.0, 10.0)]
            .into_iter()
            .enumerate()
    {
        let mut eye = rel(x, y);
        eye.z = ground(x, y) + 70.0;
        let cam = Camera { eye_m: eye, heading_rad: heading.to_radians(), pitch_rad: -0.75, ..Camera::default() };
        off.settings.draw_distance_m = 1.0; // ground only
                                            // Levels in debug colours, none of them near the background's.
        off.settings.debug_lod = true;
        let config = sylva::scene::StreamConfig { terrain_error_px: 12.0, ..off.stream.config() };
        off.stream.set_config(config);
        off.settings.terrain = false;
        let background = render(&mut off, &cam);
        off.settings.terrain = true;
        let img = render(&mut off, &cam);
        levels_seen.extend(off.stream.terrain_draws().iter().map(|d| d.key.0));
        let through = img.chunks_exact(4).zip(background.chunks_exact(4)).filter(|(a, b)| a[..3] == b[..3]).count();
        assert!(
            through == 0,
            "camera {k}: {through} background pixels show through the ground ({} tiles drawn)",
            off.stream.terrain_draws().len()
        );
    }
    assert!(levels_seen.len() >= 2, "the views drew one level only: {levels_seen:?}");

    // The stream's ground (walking, flyTo, no tunnelling) is the DEM's, bilinear
    // between 2 m vertices, once the finest tiles there are resident.
    for (x, y) in [(500_260.0, 5_299_640.0), (500_100.0, 5_299_500.0), (500_555.0, 5_299_455.0)] {
        let p = rel(x, y);
        let cam = Camera { eye_m: DVec3::new(p.x, p.y, ground(x, y) + 2.0), pitch_rad: -1.5, ..Camera::default() };
        off.load_view(&cam, 30.0);
        let h = off.stream.ground_height_at(p.x as f32, p.y as f32).unwrap();
        assert!((f64::from(h) - ground(x, y)).abs() < 0.6, "ground at {x}, {y}: {h} vs {}", ground(x, y));
    }

    // The trees stand on the ground: each tree's base is the DEM's height there
    // (bilinear between 2 m pixels: within the curvature over a pixel).
    let tiles = sylva::format::index::read_all_tiles(&scene, &m).unwrap();
    let mut checked = 0;
    for te in tiles {
        let tile = sylva::format::Tile::decode(&te.url, &std::fs::read(scene.join(&te.url)).unwrap(), 1).unwrap();
        for b in &tile.batches {
            for i in &tile.instances[b.instance_offset as usize..(b.instance_offset + b.instance_count) as usize] {
                let p = i.decode(b).position_m;
                let (x, y) = (origin.x + f64::from(p[0]), origin.y + f64::from(p[1]));
                assert!(
                    (f64::from(p[2]) - ground(x, y)).abs() < 0.3,
                    "tree at {x}, {y} at {} m, ground {}",
                    p[2],
                    ground(x, y)
                );
                checked += 1;
            }
        }
    }
    assert_eq!(checked, 120);
    std::fs::remove_dir_all(&dir).ok();
}

/// Red and blue 40 m squares (UTM metres), the orthophoto's pattern.
fn checker(x: f64, y: f64) -> [u8; 3] {
    if ((x / 40.0).floor() + (y / 40.0).floor()) as i64 % 2 == 0 {
        [200, 40, 40]
    } else {
        [40, 60, 200]
    }
}

/// Green and yellow squares of 0.0005° (about 40 × 55 m): the XYZ source's pattern.
fn lonlat_checker(lon: f64, lat: f64) -> [u8; 3] {
    if ((lon * 2000.0).floor() + (lat * 2000.0).floor()) as i64 % 2 == 0 {
        [30, 190, 40]
    } else {
        [230, 220, 30]
    }
}

/// Pixels whose hue is clearly `which`: 0 red, 1 green, 2 blue (count only
/// strongly tinted pixels: the ground material and the sky are neither).
fn tinted(img: &[u8], which: usize) -> usize {
    img.chunks_exact(4)
        .filter(|p| {
            let c = [i32::from(p[0]), i32::from(p[1]), i32::from(p[2])];
            (0..3).filter(|&k| k != which).all(|k| c[which] > c[k] + 50)
        })
        .count()
}

#[test]
fn ground_imagery_is_baked_from_an_ortho_and_an_xyz_source_drapes_the_terrain() {
    let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/models/eztree_oak_medium.glb");
    if !model.exists() {
        eprintln!("skipping: {} not present", model.display());
        return;
    }
    let dir = tmp("terrain-imagery");
    let dem = dir.join("hills.tif");
    write_geotiff_dem(&dem, 300, 2.0, hills); // x 500000–500600, y 5299400–5300000
    let ortho = dir.join("ortho.tif");
    // 1 m pixels over x 500050–500550, y 5299450–5299950.
    crate::common::write_geotiff_ortho(&ortho, (500, 500), 1.0, (500_050.0, 5_299_950.0), checker);
    std::fs::write(dir.join("trees.csv"), "id,x,y,height\n1,500020,5299420,12\n2,500030,5299420,12\n").unwrap();
    let (scene, o) = bake(&dir, &model, &dem, &["--ortho".as_ref(), ortho.as_os_str(), "--no-attributes".as_ref()]);
    let log = String::from_utf8_lossy(&o.stderr);
    assert!(log.contains("imagery: ") && log.contains("ortho.tif"), "{log}");
    let m = sylva::format::Manifest::decode("scene.json", &std::fs::read(scene.join("scene.json")).unwrap()).unwrap();
    assert_eq!(m.version, 12, "the geographic fit needs manifest version 12");
    let t = m.terrain.clone().unwrap();
    let i = t.imagery.clone().expect("an imagery entry");
    let origin = DVec3::from(m.origin_m);
    assert!(
        (i.extent_m[0] + origin.x - 500_050.0).abs() < 1e-6 && (i.extent_m[3] + origin.y - 5_299_950.0).abs() < 1e-6
    );
    assert_eq!(i.resolution_m, 1.0);
    // The finest images have pixels of at most 1 m (the photo's).
    assert!(t.tile_size_m(i.levels - 1) / 256.0 <= 1.0 + 1e-9, "{t:?}");
    assert!(i.levels >= 2 && i.tiles >= 5, "{i:?}");
    // An image of the finest level holds the photo where it is (JPEG: within a few levels).
    let mut checked = 0;
    for x in 0..(1u32 << (i.levels - 1)) {
        for y in 0..(1u32 << (i.levels - 1)) {
            let l = i.levels - 1;
            let Ok(bytes) = std::fs::read(scene.join(i.tile_url(l, x, y))) else { continue };
            assert!(t.has_imagery(l, x, y));
            let img = sylva::format::imagery::decode_image("img", &bytes, 256).unwrap();
            let [ox, oy] = t.tile_origin_m(l, x, y);
            let s = t.tile_size_m(l);
            for (pi, pj) in [(40u32, 40u32), (128, 128), (200, 90), (90, 220)] {
                let (mx, my) = (
                    origin.x + ox + s * (f64::from(pi) + 0.5) / 256.0,
                    origin.y + oy + s * (1.0 - (f64::from(pj) + 0.5) / 256.0),
                );
                let inside = (500_052.0..500_548.0).contains(&mx) && (5_299_452.0..5_299_948.0).contains(&my);
                let near_edge = [mx, my].iter().any(|v| (v.rem_euclid(40.0) - 20.0).abs() > 17.0);
                if !inside || near_edge {
                    continue;
                }
                let at = ((pj * 256 + pi) * 4) as usize;
                let want = checker(mx, my);
                for k in 0..3 {
                    let d = (i32::from(img.pixels[at + k]) - i32::from(want[k])).abs();
                    assert!(
                        d < 30,
                        "image {l}/{x}/{y} pixel {pi},{pj} at {mx:.1},{my:.1}: {:?} vs {want:?}",
                        &img.pixels[at..at + 3]
                    );
                }
                checked += 1;
            }
        }
    }
    assert!(checked >= 8, "only {checked} pixels checked");

    // Drawn: looking down on the photo's middle, the ground shows its red and
    // blue squares; without imagery neither colour.
    let mut off = open(&scene);
    off.settings.draw_distance_m = 1.0; // ground only
    let (cx, cy) = (500_300.0, 5_299_700.0);
    let eye = DVec3::new(cx - origin.x, cy - origin.y, hills(cx, cy) - origin.z + 160.0);
    let cam = Camera { eye_m: eye, pitch_rad: -1.5, ..Camera::default() };
    let img = render(&mut off, &cam);
    if let Ok(d) = std::env::var("SYLVA_TEST_IMAGES") {
        image::save_buffer(Path::new(&d).join("imagery-ortho.png"), &img, W, H, image::ColorType::Rgba8).unwrap();
    }
    let (red, blue) = (tinted(&img, 0), tinted(&img, 2));
    let all = (W * H) as usize;
    assert!(red > all / 5 && blue > all / 5, "red {red}, blue {blue} of {all} pixels");
    assert!(off.stream.stats().imagery_drawn > 0);
    off.stream.set_imagery(sylva::scene::imagery::ImageryChoice::Off);
    let plain = render(&mut off, &cam);
    assert_eq!((tinted(&plain, 0), tinted(&plain, 2)), (0, 0), "the ground material is neither red nor blue");

    // An XYZ source on a local server replaces it, reprojected from Web
    // Mercator onto the scene's UTM terrain.
    let (template, served) = crate::common::xyz_server(lonlat_checker);
    let src = sylva::scene::imagery::XyzSource::new(&template, 19).unwrap();
    off.stream.set_imagery(sylva::scene::imagery::ImageryChoice::Xyz(src));
    let img = render(&mut off, &cam);
    if let Ok(d) = std::env::var("SYLVA_TEST_IMAGES") {
        image::save_buffer(Path::new(&d).join("imagery-xyz.png"), &img, W, H, image::ColorType::Rgba8).unwrap();
    }
    assert!(served.load(std::sync::atomic::Ordering::SeqCst) > 0, "the tile server was not asked");
    let (green, yellow) =
        (tinted(&img, 1), img.chunks_exact(4).filter(|p| p[0] > 150 && p[1] > 150 && p[2] < 90).count());
    assert!(green > all / 5 && yellow > all / 5, "green {green}, yellow {yellow} of {all}");
    assert_eq!((tinted(&img, 0), tinted(&img, 2)), (0, 0), "the baked photo is replaced");
    // Each composed image holds the source's colour at its pixels' lon/lat.
    let geo = sylva::geo::GeoFrame::new(&m.crs.proj4, m.origin_m).unwrap();
    let mut compared = 0;
    for d in off.stream.terrain_draws() {
        let Some(di) = &d.imagery else { continue };
        let k = di.key.1;
        let [ox, oy] = t.tile_origin_m(k.0, k.1, k.2);
        let s = t.tile_size_m(k.0);
        for (pi, pj) in [(30u32, 30u32), (128, 128), (220, 60), (60, 200), (170, 170)] {
            let p =
                DVec3::new(ox + s * (f64::from(pi) + 0.5) / 256.0, oy + s * (1.0 - (f64::from(pj) + 0.5) / 256.0), 0.0);
            let (lon, lat, _) = geo.to_geo(p).unwrap();
            let edge = [lon * 2000.0, lat * 2000.0].iter().any(|v| (v.fract().abs() - 0.5).abs() > 0.42);
            if edge {
                continue;
            }
            let at = ((pj * 256 + pi) * 4) as usize;
            let want = lonlat_checker(lon, lat);
            let got = &di.tile.rgba[at..at + 4];
            assert!(
                (0..3).all(|c| (i32::from(got[c]) - i32::from(want[c])).abs() < 12) && got[3] == 255,
                "image {k:?} pixel {pi},{pj} at {lon:.6},{lat:.6}: {got:?} vs {want:?}"
            );
            compared += 1;
        }
    }
    assert!(compared >= 10, "only {compared} pixels compared");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn geomorphing_hides_level_changes_as_the_camera_moves() {
    let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/models/eztree_oak_medium.glb");
    if !model.exists() {
        eprintln!("skipping: {} not present", model.display());
        return;
    }
    let dir = tmp("terrain-morph");
    let dem = dir.join("hills.tif");
    write_geotiff_dem(&dem, 300, 2.0, hills);
    std::fs::write(dir.join("trees.csv"), "id,x,y,height\n1,500020,5299420,12\n").unwrap();
    let (scene, _) = bake(&dir, &model, &dem, &["--plain-ground".as_ref()]);
    let mut off = open(&scene);
    off.load_view(&Camera::default(), 30.0);
    let origin = DVec3::from(off.stream.manifest().unwrap().origin_m);
    off.settings.draw_distance_m = 1.0; // ground only
                                        // A low oblique view over the hills. The selection threshold falls in small
                                        // steps, which is what nearing the ground does to the projected errors:
                                        // wherever a tile is replaced by its children between two steps, the
                                        // image before and after should be the same (the children start out
                                        // morphed onto their parent's surface).
    let (x, y) = (500_300.0, 5_299_430.0);
    let cam = Camera {
        eye_m: DVec3::new(x - origin.x, y - origin.y, hills(x, y) - origin.z + 90.0),
        pitch_rad: -0.5,
        ..Camera::default()
    };
    let at = |off: &mut OffscreenScene, threshold: f32| {
        let config = sylva::scene::StreamConfig { terrain_error_px: threshold, ..off.stream.config() };
        off.stream.set_config(config);
        let img = render(off, &cam);
        let mut keys: Vec<TerrainKeyOf> = off.stream.terrain_draws().iter().map(|d| d.key).collect();
        keys.sort_unstable();
        (img, keys)
    };
    // Thresholds where the selection changes, each bracketed to 0.2 % (so the
    // morph factors of the other tiles barely move between the two images).
    let mut switches = Vec::new();
    let mut hi = (48.0f32, at(&mut off, 48.0).1);
    for k in 1..48 {
        let t = 48.0 * 0.93f32.powi(k);
        let keys = at(&mut off, t).1;
        if keys != hi.1 {
            let (mut a, mut b) = (hi.0, t);
            while a / b > 1.002 {
                let m = (a * b).sqrt();
                if at(&mut off, m).1 == hi.1 {
                    a = m;
                } else {
                    b = m;
                }
            }
            switches.push((a, b));
        }
        hi = (t, keys);
    }
    // Pixels that change visibly (by more than 3 levels) across the switches.
    let popped = |off: &mut OffscreenScene| -> usize {
        switches
            .iter()
            .map(|&(a, b)| {
                let (before, after) = (at(off, a).0, at(off, b).0);
                if let Ok(d) = std::env::var("SYLVA_TEST_IMAGES") {
                    let tag = if off.settings.terrain_morph { "m" } else { "p" };
                    for (name, img) in [("a", &before), ("b", &after)] {
                        let path = Path::new(&d).join(format!("switch-{tag}-{a:.3}-{name}.png"));
                        image::save_buffer(path, img, W, H, image::ColorType::Rgba8).unwrap();
                    }
                }
                before
                    .chunks_exact(4)
                    .zip(after.chunks_exact(4))
                    .filter(|(p, q)| (0..3).any(|c| p[c].abs_diff(q[c]) > 3))
                    .count()
            })
            .sum()
    };
    let morphed = popped(&mut off);
    off.settings.terrain_morph = false;
    let popping = popped(&mut off);
    eprintln!("{} level changes: {morphed} pixels changed with geomorphing, {popping} without", switches.len());
    assert!(switches.len() >= 3, "the thresholds should change the levels ({switches:?})");
    // (Measured on lavapipe: 3 level changes, 2 pixels with geomorphing, 24 without.)
    assert!(popping >= 12, "without geomorphing level changes should pop ({popping} pixels)");
    assert!(morphed * 4 < popping, "geomorphing should hide the pops: {morphed} pixels vs {popping} without");
    std::fs::remove_dir_all(&dir).ok();
}

type TerrainKeyOf = sylva::scene::terrain::TerrainKey;
