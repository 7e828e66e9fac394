//! GPU tests of progressive refinement (`src/render/refine.rs`) on
//! `tests/fixtures/forest-small`: a resting camera's image converges towards
//! the accuracy reference (every tree a full mesh, 2× supersampled), its error
//! falling step by step; the first step is the plain frame; a converged
//! refinement draws no scene; a camera move starts over at once.

use std::path::PathBuf;

use sylva::bench::downsample;
use sylva::camera::Camera;
use sylva::metrics::multiscale_rmse;
use sylva::offscreen::{NamedView, OffscreenScene};
use sylva::render::forest::{PoolConfig, RenderSettings, Representations};
use sylva::render::refine::{RefineConfig, FULL_MESH_QUALITY};

use crate::common::foliage_share;

const W: u32 = 192;
const H: u32 = 108;

fn open(w: u32, h: u32) -> OffscreenScene {
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        std::env::set_var("XDG_RUNTIME_DIR", "/tmp");
    }
    let scene = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/forest-small");
    let pools = PoolConfig { instances: 1 << 16, batches: 1 << 12, items: 1 << 17, species: 8 };
    OffscreenScene::open(scene.to_str().unwrap(), w, h, pools)
        .expect("a GPU adapter (install mesa-vulkan-drivers for lavapipe)")
}

fn plain(off: &mut OffscreenScene, cam: &Camera) -> Vec<u8> {
    off.load_view(cam, 30.0);
    off.render(cam, false);
    off.read_image()
}

fn max_difference(a: &[u8], b: &[u8]) -> u8 {
    a.iter().zip(b).map(|(x, y)| x.abs_diff(*y)).max().unwrap_or(0)
}

#[test]
fn refinement_converges_towards_the_reference_and_starts_over_on_a_move() {
    let mut reference = open(2 * W, 2 * H);
    reference.load_view(&Camera::default(), 30.0);
    let cam = reference.named_camera(NamedView::Medium, 30.0).expect("manifest");
    reference.settings = RenderSettings {
        quality: FULL_MESH_QUALITY,
        representations: Representations::MESHES,
        full_res_alpha: true,
        ..RenderSettings::default()
    };
    let truth = downsample(&plain(&mut reference, &cam), 2 * W, 2 * H, 2);
    let share = foliage_share(&truth);
    assert!(share > 0.05, "the reference shows the forest: foliage share {share:.3}");
    // The plain frame's own representations, 2× supersampled (quality ½ keeps
    // the same levels of detail): what level 0's jittered frames converge to.
    reference.settings = RenderSettings { quality: 0.5, ..RenderSettings::default() };
    let smooth = downsample(&plain(&mut reference, &cam), 2 * W, 2 * H, 2);
    drop(reference);

    let mut off = open(W, H);
    let single = plain(&mut off, &cam);
    let config = RefineConfig { enabled: true, jitter_frames: 6, levels: 2 };
    off.refine.config = config;
    let mut errors = Vec::new();
    let mut aliasing = Vec::new();
    let mut first = None;
    for step in 0..config.total_steps() {
        off.load_view(&cam, 30.0);
        let s = off.render(&cam, true);
        let img = off.read_image();
        assert_eq!(s.refine_step, step + 1, "steps count up while the camera rests");
        assert!(s.draw_calls > 0, "step {step} draws the scene");
        first.get_or_insert_with(|| img.clone());
        errors.push(multiscale_rmse(&img, &truth, W, H));
        aliasing.push(multiscale_rmse(&img, &smooth, W, H));
        if s.refine_converged {
            assert_eq!(step + 1, config.total_steps(), "converged after every level's frames");
        }
    }
    // The first step at rest is the plain frame (through the accumulation's
    // 16-bit float image and back).
    let first = first.unwrap();
    let d = max_difference(&first, &single);
    assert!(d <= 1, "the first refinement step differs from the plain frame by {d} levels");
    eprintln!("error by step: {errors:.5?}\naliasing by step: {aliasing:.5?}");
    // Level 0: the jittered frames anti-alias the plain frame (its error
    // against its own supersampled image falls step by step).
    let j = config.jitter_frames as usize;
    let steps = [0, 1, 3, j - 1];
    for w in steps.windows(2) {
        let (a, b) = (aliasing[w[0]], aliasing[w[1]]);
        assert!(b <= a + 1e-4, "aliasing rose from step {} to {}: {aliasing:.5?}", w[0], w[1]);
    }
    assert!(aliasing[j - 1] < 0.8 * aliasing[0], "level 0 anti-aliased: {aliasing:.5?}");
    // The finer levels, each shown once converged, come closer to the
    // reference level by level.
    let levels = [j - 1, 2 * j - 1, 3 * j - 1];
    for w in levels.windows(2) {
        assert!(errors[w[1]] < errors[w[0]], "the error rose from step {} to {}: {errors:.5?}", w[0], w[1]);
    }
    // While a finer level accumulates apart, the converged coarser image stays.
    for i in j..2 * j - 1 {
        assert_eq!(errors[i], errors[j - 1], "step {i} shows level 0's converged image");
    }
    let (e0, e_end) = (errors[0], errors[errors.len() - 1]);
    assert!(e_end < 0.7 * e0, "converged error {e_end:.5} against the single frame's {e0:.5}");

    // Converged: the scene is not drawn again, the image stays.
    let converged = off.read_image();
    let s = off.render(&cam, true);
    assert!(s.refine_converged && s.draw_calls == 0, "a converged refinement draws nothing: {s:?}");
    assert_eq!(off.read_image(), converged);

    // A move starts over at once: the next frame is the moved camera's plain frame.
    let moved = Camera { heading_rad: cam.heading_rad + 0.02, ..cam };
    off.load_view(&moved, 30.0);
    let s = off.render(&moved, true);
    assert_eq!((s.refine_step, s.refine_level, s.refine_converged), (1, 0, false));
    let img = off.read_image();
    off.refine.config.enabled = false;
    let d = max_difference(&img, &plain(&mut off, &moved));
    assert!(d <= 1, "after a move the image is the plain frame (differs by {d} levels)");
}
