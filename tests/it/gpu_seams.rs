//! No seams on the ground (issue 49): where two terrain tiles drape different
//! ground images, the images are filtered across their shared edge as within
//! one image (`photo_across` in `shaders/terrain.wgsl`).

use glam::DVec3;
use sylva::camera::Camera;
use sylva::offscreen::OffscreenScene;
use sylva::render::forest::{PoolConfig, Representations};
use sylva::render::shadow::ShadowQuality;
use sylva::scene::imagery::ImageryChoice;

const W: u32 = 320;
const H: u32 = 180;

fn open() -> OffscreenScene {
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        std::env::set_var("XDG_RUNTIME_DIR", "/tmp");
    }
    let scene = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/forest-small");
    let pools = PoolConfig { instances: 1 << 16, batches: 1 << 12, items: 1 << 17, species: 8 };
    OffscreenScene::open(scene, W, H, pools).expect("a GPU adapter (mesa-vulkan-drivers)")
}

fn luma(img: &[u8], x: usize, y: usize) -> f32 {
    let p = &img[(y * W as usize + x) * 4..];
    0.2126 * f32::from(p[0]) + 0.7152 * f32::from(p[1]) + 0.0722 * f32::from(p[2])
}

#[test]
fn ground_images_meet_without_a_seam_at_a_tile_edge() {
    let mut off = open();
    // The ground alone: no trees, no canopy, no shadows.
    off.settings.shadows = ShadowQuality::Off;
    off.settings.canopy = false;
    off.settings.representations = Representations { meshes: false, clusters: false, billboards: false, clouds: false };
    off.load_view(&Camera::default(), 30.0);
    // The fixture's finest ground images are 512 m squares meeting along
    // x = 0. An eye on that line, looking north along it (the README's
    // close-up stood so), sees the edge run up the image's middle: the two
    // images meet between columns W/2 − 1 and W/2 on every row of ground.
    let y = -300.0;
    let probe = Camera { eye_m: DVec3::new(0.0, y, 400.0), pitch_rad: -1.5, ..Camera::default() };
    off.load_view(&probe, 30.0);
    let ground = off.stream.ground_height_at(0.0, y as f32).expect("ground under the eye");
    let cam = Camera {
        eye_m: DVec3::new(0.0, y, f64::from(ground) + 1.7),
        heading_rad: 0.0,
        pitch_rad: -10f64.to_radians(),
        ..Camera::default()
    };
    let draw = |off: &mut OffscreenScene, choice: ImageryChoice| {
        off.stream.set_imagery(choice);
        off.load_view(&cam, 30.0);
        off.render(&cam, false);
        off.read_image()
    };
    let plain = draw(&mut off, ImageryChoice::Off);
    let img = draw(&mut off, ImageryChoice::Scene);
    // The rows of ground: the lower half of the image (the eye looks down 10°).
    let rows = (H as usize / 2 + 8)..H as usize;
    let mid = W as usize / 2;
    let (mut across, mut beside, mut draped) = (0.0f32, 0.0f32, 0.0f32);
    for y in rows.clone() {
        across += (luma(&img, mid, y) - luma(&img, mid - 1, y)).abs();
        beside += 0.5
            * ((luma(&img, mid - 1, y) - luma(&img, mid - 2, y)).abs()
                + (luma(&img, mid + 1, y) - luma(&img, mid, y)).abs());
        for x in (0..W as usize).step_by(8) {
            draped += (luma(&img, x, y) - luma(&plain, x, y)).abs();
        }
    }
    let n = rows.len() as f32;
    let draped = draped / (n * (W / 8) as f32);
    eprintln!(
        "per row: across the edge {:.2}, beside it {:.2}; images against none {draped:.1}",
        across / n,
        beside / n
    );
    assert!(draped > 2.5, "the ground images are not draped ({draped:.1} levels from the plain ground)");
    // One column further is one column further, on either side of the edge as beside it.
    assert!(
        across <= 2.0 * beside + 0.5 * n,
        "a seam: {:.2} levels a row across the edge, {:.2} beside it",
        across / n,
        beside / n
    );
}

/// The sun's visibility in the cascade-debug image's pixel (its one lit
/// channel is 0.5 + 0.5 × visibility, sRGB-encoded) and the cascade by its
/// colour (0 red, 1 green), or `None` for a tree's pixel or the sky.
fn cascade_pixel(img: &[u8], i: usize) -> Option<(usize, f32)> {
    let p = &img[i * 4..i * 4 + 3];
    let lin = |c: u8| {
        let c = f32::from(c) / 255.0;
        if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    };
    let k = (0..2).find(|&k| p[k] > 60 && (0..3).all(|j| j == k || p[j] <= 2))?;
    Some((k, (2.0 * lin(p[k]) - 1.0).clamp(0.0, 1.0)))
}

#[test]
fn the_first_two_cascades_give_the_ground_the_same_light() {
    // No seam where one shadow cascade hands over to the next: the ground the
    // first cascade holds (its finer map) takes, in the mean, the light the
    // second's (coarser) gives it. The forest's dappled shade on the open
    // ground south of it, the sun low in the north; the first cascade's
    // ground shaded once by it and once by the second
    // (`RenderSettings::debug_next_cascade`), compared pixel by pixel.
    let mut off = open();
    let (az, el) = (10f32.to_radians(), 12f32.to_radians());
    off.settings.lighting =
        sylva::render::Lighting::for_sun(glam::Vec3::new(az.sin() * el.cos(), az.cos() * el.cos(), el.sin()), 12.0);
    off.settings.shadows = ShadowQuality::High;
    off.settings.debug_cascades = true;
    let cam = Camera { eye_m: DVec3::new(0.0, -260.0, 80.0), pitch_rad: -16f64.to_radians(), ..Camera::default() };
    off.load_view(&cam, 30.0);
    let compare = |off: &mut OffscreenScene| {
        off.settings.debug_next_cascade = false;
        off.render(&cam, false);
        let own = off.read_image();
        off.settings.debug_next_cascade = true;
        off.render(&cam, false);
        let next = off.read_image();
        let (mut a, mut b, mut n, mut shaded) = (0.0f64, 0.0f64, 0usize, 0usize);
        for i in 0..(W * H) as usize {
            if let (Some((0, va)), Some((0, vb))) = (cascade_pixel(&own, i), cascade_pixel(&next, i)) {
                a += f64::from(va);
                b += f64::from(vb);
                n += 1;
                shaded += usize::from(va < 0.5);
            }
        }
        (a / n.max(1) as f64, b / n.max(1) as f64, n, shaded)
    };
    let soft = compare(&mut off);
    off.settings.light_parts = sylva::render::sky_light::LightParts(
        sylva::render::sky_light::LightParts::ALL.0 & !sylva::lod::shared::LIGHT_SOFT_SHADOWS,
    );
    let fixed = compare(&mut off);
    for (name, (a, b, n, shaded)) in [("soft", soft), ("fixed PCF", fixed)] {
        eprintln!(
            "{name}: the first cascade's ground {n} px ({shaded} shaded): sun {a:.3} from it, {b:.3} from the next"
        );
    }
    let (a, b, n, shaded) = soft;
    assert!(n > 3000, "the first cascade holds {n} px of ground: camera misplaced?");
    assert!(shaded * 10 > n && shaded * 10 < 9 * n, "{shaded} of {n} px shaded: no dappled shade to compare");
    assert!((a - b).abs() < 0.04, "the sun on the same ground: {a:.3} from the first cascade, {b:.3} from the second");
}
