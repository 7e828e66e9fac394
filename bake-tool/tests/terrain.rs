//! Terrain end to end: a synthetic GeoTIFF DEM of steep hills under a small
//! forest, baked, streamed and drawn by the native renderer (lavapipe): the
//! ground is drawn wherever the DEM has data with no background showing
//! through seams between levels, the levels follow the view, the stream's
//! ground heights match the DEM, and the trees stand on it.

mod common;

use std::path::Path;

use common::{run, tmp, write_geotiff_dem};
use glam::DVec3;
use sylva::camera::Camera;
use sylva::render::forest::PoolConfig;
use sylva::render::offscreen::OffscreenScene;

const W: u32 = 256;
const H: u32 = 160;

/// Steep hills: 120 m of relief over a few hundred metres (DEM CRS metres).
fn hills(x: f64, y: f64) -> f64 {
    let (u, v) = (x - 500_000.0, y - 5_299_400.0);
    400.0 + 50.0 * (u / 70.0).sin() * (v / 55.0).cos() + 15.0 * (u / 23.0 + v / 31.0).sin() + 0.05 * u
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
    let scene = dir.join("scene");
    let o = run(common::bin()
        .arg("bake")
        .arg("--model")
        .arg(format!("oak={}", model.display()))
        .arg("--placements")
        .arg(dir.join("trees.csv"))
        .args(["--input-crs", "EPSG:32633", "--no-clusters", "--billboard-size", "16", "--texture-size", "16"])
        .arg("--dem")
        .arg(&dem)
        .arg("--out")
        .arg(&scene));
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
