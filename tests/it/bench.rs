//! `sylva bench` end to end on the small fixture scene: every output is written,
//! the reference has no error, the other methods a plausible one.

use sylva::bench::{self, NamedPath};
use sylva::camera::Camera;
use sylva::offscreen::OffscreenScene;
use sylva::render::forest::PoolConfig;

const SCENE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/forest-small");

#[test]
fn bench_writes_frames_summary_and_plots() {
    let mut probe = OffscreenScene::open(SCENE, 16, 16, PoolConfig::default()).expect("GPU adapter");
    probe.load_view(&Camera::default(), 60.0);
    let manifest = probe.stream.manifest().expect("manifest").clone();
    drop(probe);
    let cameras = bench::interpolate(&bench::named_path(NamedPath::Medium, &manifest, None), 3);
    let methods = bench::methods("sylva,billboard", sylva::render::shadow::ShadowQuality::Off).unwrap();
    let (w, h) = (160, 90);
    let mut calls = 0;
    let run = bench::run(SCENE, &cameras, &methods, w, h, None, None, &mut |_, _, _| calls += 1).unwrap();
    assert_eq!(calls, 9, "progress once per frame and method");
    assert_eq!(run.frames.len(), 9);
    let reference = &run.summary["reference"];
    assert_eq!(reference.error.median, 0.0);
    for name in ["sylva", "billboard"] {
        let m = &run.summary[name];
        assert!(m.error.median > 0.0 && m.error.median < 0.15, "{name}: error {}", m.error.median);
        assert!(m.gpu_ms.median > 0.0 && m.draw_calls.median >= 1.0, "{name}");
        assert!(m.temporal_noise.median.is_finite());
        assert!(m.flip.median > 0.0 && m.flip.median < 0.5, "{name}: FLIP {}", m.flip.median);
    }
    for r in &run.frames {
        let drawn: u64 = r.instances.values().sum();
        assert!(drawn > 0, "{} frame {} draws trees", r.method, r.frame);
    }
    let dir = std::env::temp_dir().join(format!("sylva-bench-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    bench::write_csv(&dir, &run.frames).unwrap();
    bench::write_plots(&dir, &run, "test").unwrap();
    let csv = std::fs::read_to_string(dir.join("frames.csv")).unwrap();
    assert_eq!(csv.lines().count(), 10, "header + 9 frames");
    assert!(csv.starts_with("method,frame,gpu_ms"));
    let back = bench::read_csv(&dir.join("frames.csv")).unwrap();
    assert_eq!(back.len(), run.frames.len());
    for (a, b) in back.iter().zip(&run.frames) {
        assert_eq!((&a.method, a.frame, a.draw_calls), (&b.method, b.frame, b.draw_calls));
        assert!((a.error - b.error).abs() < 1e-5 && (a.flip - b.flip).abs() < 1e-5);
    }
    for plot in ["pareto.svg", "frame_time.svg", "temporal_noise.svg"] {
        let svg = std::fs::read_to_string(dir.join(plot)).unwrap();
        assert!(svg.starts_with("<svg") && svg.contains("sylva") && svg.len() > 2000, "{plot}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bench_judges_every_method_against_the_path_traced_reference_under_both_lights() {
    let cameras =
        [Camera { eye_m: glam::DVec3::new(0.0, -190.0, 60.0), heading_rad: 0.0, pitch_rad: -0.3, ..Camera::default() }];
    let methods = bench::methods("sylva", sylva::render::shadow::ShadowQuality::Off).unwrap();
    let traced = bench::TracedReference {
        spp: 4,
        bounces: 2,
        reach_m: 300.0,
        turbidity: 3.0,
        raster_parts: sylva::render::sky_light::LightParts::ALL,
    };
    let (w, h) = (96, 54);
    let mut calls = Vec::new();
    let run = bench::run(SCENE, &cameras, &methods, w, h, None, Some(traced), &mut |m, _, _| calls.push(m.to_string()))
        .unwrap();
    assert_eq!(calls, ["reference", "sylva", "path-traced"]);
    let summary = bench::summarise_traced(&run.traced);
    let names: Vec<&str> = summary.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, ["reference", "sylva", bench::TRACED_RASTER_LIGHT]);
    let get = |n: &str| &summary.iter().find(|(m, _)| m == n).unwrap().1;
    // The raster's full mesh and the trace under the raster's light see the
    // same forest on the same ground (imagery draped as the raster drapes it).
    let reference = get("reference");
    assert!(reference.foliage_iou.median > 0.85, "foliage IoU {}", reference.foliage_iou.median);
    assert!(reference.geometry_error.median < 0.06, "geometry error {}", reference.geometry_error.median);
    // The raster's light is not the physical light: its error is the light's.
    let light = get(bench::TRACED_RASTER_LIGHT);
    assert!(light.error.median > 0.02, "the raster light against the physical {}", light.error.median);
    assert!(reference.error.median > reference.geometry_error.median);
    let sylva = get("sylva");
    assert!(sylva.error.median > 0.0 && sylva.geometry_error.median > 0.0 && sylva.flip.median > 0.0);
    let dir = std::env::temp_dir().join(format!("sylva-bench-traced-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    bench::write_traced_csv(&dir, &run.traced).unwrap();
    let csv = std::fs::read_to_string(dir.join("traced.csv")).unwrap();
    assert!(csv.starts_with("method,frame,error,flip,geometry_error,light_error,foliage_iou"));
    assert_eq!(csv.lines().count(), 4, "header + 3 rows");
    std::fs::remove_dir_all(&dir).ok();
    // A URL is not a directory the tracer reads.
    let err =
        bench::run("http://127.0.0.1:9/scene.json", &cameras, &methods, w, h, None, Some(traced), &mut |_, _, _| {})
            .err()
            .expect("refused");
    assert!(err.to_string().contains("scene directory"), "{err}");
}

#[test]
fn bench_trace_measures_every_species_and_the_gpu_agrees() {
    let r = sylva::bench::trace::measure(std::path::Path::new(SCENE), 512).expect("GPU adapter");
    let names: Vec<&str> = r.species.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names.len(), 3, "{names:?}");
    for s in &r.species {
        assert!(s.triangles > 500 && s.nodes > 100 && s.depth >= 8, "{s:?}");
        assert_eq!(s.bytes, s.nodes * 32 + s.triangles * 64);
        assert!(s.hits > 100 && s.hits < s.rays, "{}: {} of {} rays hit", s.name, s.hits, s.rays);
        assert!(s.differ <= 1, "{}: {} hits differ", s.name, s.differ);
        assert!(s.cpu_rays_per_s > 0.0 && s.gpu_rays_per_s > 0.0);
    }
    assert!(sylva::bench::trace::report(&r).contains("beech"));
}
