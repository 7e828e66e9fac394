//! A short `sylva bench --stress` run on the fixture scene, alone in its process
//! (it reads the process's resident set): after one warm-up pass along the path
//! and back, memory must stay flat (the median resident set of the last pass
//! against the second's) and every counter finite. Frame time is not
//! asserted here — timing belongs to `make bench-stress`. This is the test that
//! found Mesa 22.3 lavapipe compiling (and leaking) a shader variant per pipeline
//! bind while the view was a uniform buffer: 1.5 MB per frame.
//! At 80×45. The path's level camera 2 m above the ground took 6–8 s a frame
//! on lavapipe (65 % of this test's 87–107 s) until the terrain shader bounded
//! the image uv of the horizon's helper pixels (shaders/terrain.wgsl): 30 s.

use sylva::bench::{self, stress, NamedPath};
use sylva::camera::Camera;
use sylva::offscreen::OffscreenScene;
use sylva::render::forest::{PoolConfig, RenderSettings};

const SCENE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/forest-small");

#[test]
fn memory_stays_flat_along_a_long_path() {
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        std::env::set_var("XDG_RUNTIME_DIR", "/tmp");
    }
    let mut probe = OffscreenScene::open(SCENE, 16, 16, PoolConfig::default()).expect("GPU adapter");
    probe.load_view(&Camera::default(), 60.0);
    let manifest = probe.stream.manifest().expect("manifest").clone();
    drop(probe);
    let pass = bench::interpolate(&bench::named_path(NamedPath::Flyover, &manifest, None), 16);
    let period = 2 * (pass.len() - 1);
    let cameras = stress::ping_pong(&pass, 4 * period);
    let (frames, summary) = stress::run(
        SCENE,
        &cameras,
        period,
        (80, 45),
        (RenderSettings::default(), PoolConfig::default()),
        None,
        &mut |_, _| {},
    )
    .unwrap();
    assert_eq!(frames.len(), 4 * period);
    assert_eq!(summary.non_finite_frames, 0);
    assert!(frames.iter().any(|f| f.drawn > 0), "nothing was drawn");
    assert!(summary.rss_after_first > 0, "no resident set size (/proc missing?)");
    // Medians, pass against pass (the same views): single frames spike by 10-20 MB
    // on lavapipe as the driver takes and returns memory, a leak moves the median.
    let (first, last) = (summary.rss_first.median / 1e6, summary.rss_last.median / 1e6);
    assert!(
        last <= first * 1.10,
        "memory grew from a median {first:.1} MB over the second pass to {last:.1} MB over the last ({} frames later)",
        2 * period
    );
}
