//! Frame benchmarks of the renderer (issue 3), measured side by side in one run:
//! CPU frame time and draw calls against tree count, grouped-batch culling
//! against per-tree and no culling at far/medium/close views, a far view with
//! everything beyond the draw distance against an empty scene, and GPU memory
//! per resident tree.
//!
//! Run `make bench-render` (bakes the scenes into target/bench once), or
//! `cargo bench --bench frame -- DIR_10K DIR_100K DIR_1M`.
//! GPU times are wall time around submit + wait (lavapipe's compute timestamps
//! are unreliable); compare ratios, not absolute numbers, on a CPU adapter.

use std::time::Instant;

use glam::DVec3;
use sylva::camera::Camera;
use sylva::format::Manifest;
use sylva::offscreen::{FrameStats, NamedView, OffscreenScene};
use sylva::render::forest::{CullingMode, PoolConfig, Representations};

const W: u32 = 960;
const H: u32 = 540;
const FRAMES: usize = 7;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

struct Measured {
    cpu_ms: f64,
    cull_ms: f64,
    draw_ms: f64,
    last: FrameStats,
}

fn measure(off: &mut OffscreenScene, cam: &Camera) -> Measured {
    for _ in 0..2 {
        off.render(cam, true);
    }
    let (mut cpu, mut cull, mut draw) = (Vec::new(), Vec::new(), Vec::new());
    let mut last = FrameStats::default();
    for _ in 0..FRAMES {
        last = off.render(cam, true);
        cpu.push(last.frame_cpu_ms);
        cull.push(last.gpu_ms["cull"]);
        draw.push(last.gpu_ms["draw"]);
    }
    Measured { cpu_ms: median(cpu), cull_ms: median(cull), draw_ms: median(draw), last }
}

fn open(scene: &str) -> OffscreenScene {
    let mut off = OffscreenScene::open(scene, W, H, PoolConfig::default()).expect("GPU adapter");
    off.load_view(&Camera::default(), 120.0);
    off
}

/// Makes every tile resident (top view), then returns the scene.
fn open_resident(scene: &str) -> (OffscreenScene, Manifest) {
    let mut off = open(scene);
    let m = off.stream.manifest().expect("manifest").clone();
    let top = off.named_camera(NamedView::Top, 120.0).unwrap();
    off.load_view(&top, 300.0);
    (off, m)
}

/// Each representation family drawn alone at the distances where Sylva uses
/// meshes, ellipsoids and billboards (trees about 200, 70 and 25 px tall), with
/// the image error of each against the meshes.
fn representations(off: &mut OffscreenScene, m: &Manifest) {
    let c = DVec3::from(m.bounds.min.map(f64::from)).lerp(DVec3::from(m.bounds.max.map(f64::from)), 0.5);
    let height_m: f64 = 24.0; // the demo species are 19–28 m tall
    let px_per_m = f64::from(Camera::default().view_data(W, H).px_per_m_at_1m);
    println!("\n## Representations at the distances where each is used ({W}x{H}, {} trees)\n", m.counts.trees);
    println!("| trees tall | method | cull ms | draw ms | total ms | vs meshes | instances drawn | error vs meshes |");
    println!("| --- | --- | --- | --- | --- | --- | --- | --- |");
    let methods: [(&str, Representations, bool); 6] = [
        ("meshes", Representations::MESHES, true),
        ("ellipsoids", Representations::CLUSTERS, false),
        ("ellipsoids, exact depth", Representations::CLUSTERS, true),
        ("billboards", Representations::BILLBOARDS, false),
        ("sylva (mixed)", Representations::ALL, false),
        ("sylva (mixed), exact depth", Representations::ALL, true),
    ];
    for target_px in [200.0, 70.0, 25.0] {
        let d = height_m * px_per_m / target_px;
        let (s, co) = 35f64.to_radians().sin_cos();
        let cam = Camera::look_at(c + DVec3::new(0.0, -d * co, d * s), c);
        off.load_view(&cam, 120.0);
        let mut base_ms = 0.0;
        let mut reference = Vec::new();
        for (name, reprs, exact) in methods {
            off.settings.representations = reprs;
            off.settings.cluster_exact_depth = exact;
            let r = measure(off, &cam);
            let img = off.read_image();
            let total = r.cull_ms + r.draw_ms;
            if reference.is_empty() {
                reference = img.clone();
                base_ms = total;
            }
            let err = sylva::metrics::multiscale_rmse(&img, &reference, W, H);
            println!(
                "| {target_px:.0} px | {name} | {:.1} | {:.1} | {:.1} | {:.2}x | {} | {:.4} |",
                r.cull_ms,
                r.draw_ms,
                total,
                total / base_ms,
                r.last.instances.values().sum::<u64>(),
                err
            );
        }
    }
    off.settings.representations = Representations::ALL;
    off.settings.cluster_exact_depth = false;
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).filter(|a| !a.starts_with("--")).collect();
    let scenes: Vec<String> = if args.is_empty() {
        ["target/bench/demo-10k", "target/bench/demo-100k", "target/bench/demo-1m"].map(String::from).to_vec()
    } else {
        args
    };
    if let Some(missing) = scenes.iter().find(|s| !std::path::Path::new(s).join("scene.json").exists()) {
        eprintln!("{missing} is missing: run `make bench-render` (it bakes the scenes first)");
        return;
    }
    let started = Instant::now();
    println!("## CPU frame time and draw calls vs tree count (medium view, {W}x{H})\n");
    println!("| trees | draw calls | instances drawn | frame CPU ms | cull ms | draw ms |");
    println!("| --- | --- | --- | --- | --- | --- |");
    let mut cpu_by_size = Vec::new();
    for scene in &scenes {
        let (mut off, m) = open_resident(scene);
        let cam = off.named_camera(NamedView::Medium, 120.0).unwrap();
        off.load_view(&cam, 120.0);
        let r = measure(&mut off, &cam);
        let drawn: u64 = r.last.instances.values().sum();
        println!(
            "| {} | {} | {} | {:.3} | {:.1} | {:.1} |",
            m.counts.trees, r.last.draw_calls, drawn, r.cpu_ms, r.cull_ms, r.draw_ms
        );
        cpu_by_size.push(r.cpu_ms);
    }
    let spread =
        cpu_by_size.iter().cloned().fold(f64::MIN, f64::max) / cpu_by_size.iter().cloned().fold(f64::MAX, f64::min);
    println!("\nCPU frame time, largest / smallest scene: {spread:.2}x\n");

    let big = scenes.get(1).unwrap_or(&scenes[0]);
    let (mut off, m) = open_resident(big);
    println!("## Culling: grouped batches vs per-tree vs none ({} trees resident)\n", m.counts.trees);
    println!("| view | mode | cull ms | draw ms | total ms | vs batches | instances drawn | batches visible |");
    println!("| --- | --- | --- | --- | --- | --- | --- | --- |");
    for view in [NamedView::Far, NamedView::Medium, NamedView::Close] {
        let cam = off.named_camera(view, 120.0).unwrap();
        off.load_view(&cam, 120.0);
        let mut base = 0.0;
        for mode in [CullingMode::Batches, CullingMode::PerTree, CullingMode::None] {
            off.settings.culling = mode;
            let r = measure(&mut off, &cam);
            let total = r.cull_ms + r.draw_ms;
            if mode == CullingMode::Batches {
                base = total;
            }
            println!(
                "| {view:?} | {mode:?} | {:.1} | {:.1} | {:.1} | {:.2}x | {} | {} |",
                r.cull_ms,
                r.draw_ms,
                total,
                total / base,
                r.last.instances.values().sum::<u64>(),
                r.last.batches_visible
            );
        }
        off.settings.culling = CullingMode::Batches;
    }

    representations(&mut off, &m);

    // Everything resident, the camera far away with every tree beyond the draw distance,
    // against a renderer with no resident tree at all.
    let c = DVec3::from(m.bounds.min.map(f64::from)).lerp(DVec3::from(m.bounds.max.map(f64::from)), 0.5);
    let far = Camera::look_at(c + DVec3::new(0.0, -20_000.0, 500.0), c);
    off.settings.draw_distance_m = 5_000.0;
    let beyond = measure(&mut off, &far);
    let empty_dir = std::env::temp_dir().join(format!("sylva-empty-{}", std::process::id()));
    std::fs::create_dir_all(&empty_dir).unwrap();
    let empty = Manifest {
        species: vec![],
        tiles: vec![],
        counts: sylva::format::Counts { trees: 0, batches: 0, tiles: 0 },
        ..m.clone()
    };
    std::fs::write(empty_dir.join("scene.json"), empty.encode()).unwrap();
    let mut none = open(empty_dir.to_str().unwrap());
    none.settings.draw_distance_m = 5_000.0;
    let nothing = measure(&mut none, &far);
    let t_beyond = beyond.cull_ms + beyond.draw_ms;
    let t_empty = nothing.cull_ms + nothing.draw_ms;
    println!("\n## Far view, every tree beyond the draw distance vs an empty scene\n");
    println!("| scene | batches tested | cull ms | draw ms | total ms | ratio |");
    println!("| --- | --- | --- | --- | --- | --- |");
    println!(
        "| {} trees resident | {} | {:.2} | {:.2} | {:.2} | {:.2}x |",
        m.counts.trees,
        beyond.last.batches_tested,
        beyond.cull_ms,
        beyond.draw_ms,
        t_beyond,
        t_beyond / t_empty
    );
    println!("| empty | 0 | {:.2} | {:.2} | {:.2} | 1.00x |", nothing.cull_ms, nothing.draw_ms, t_empty);
    let _ = std::fs::remove_dir_all(&empty_dir);

    let s = off.render(&far, true);
    println!("\n## GPU memory\n");
    println!(
        "{} trees resident; pools + packs {:.1} MB; instance data 8 B/tree + batch records {:.2} B/tree; pools are preallocated for {} trees ({:.1} MB).",
        s.trees_resident,
        s.gpu_bytes as f64 / 1e6,
        80.0 * m.counts.batches as f64 / m.counts.trees as f64,
        PoolConfig::default().instances,
        PoolConfig::default().bytes() as f64 / 1e6,
    );
    eprintln!("benchmark took {:.0} s", started.elapsed().as_secs_f64());
}
