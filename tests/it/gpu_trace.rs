//! The tracer's geometry (issue 48): each fixture species' BVH against brute
//! force on the CPU, and the WGSL walk (`shaders/trace.wgsl`) against its CPU
//! twin (`src/trace/`) on the same random rays — through the species' full
//! meshes and through a dense synthetic cloud of leaf cards. Fixture packs:
//! `make fixtures`.

use glam::Vec3;
use sylva::bench::trace::rays_at;
use sylva::format::decode_pack;
use sylva::render::trace::TraceProbe;
use sylva::render::GpuContext;
use sylva::trace::bvh::{mesh_triangles, Bvh, MAX_DEPTH};
use sylva::trace::{brute_force, Ray, Triangle};

const SPECIES: [&str; 3] = ["beech", "birch", "spruce"];

use sylva::trace::Xorshift32 as Rng;

/// A fixture species' full mesh (level 0), in model space at scale 1, and its bounds.
fn species(name: &str) -> (Vec<Triangle>, Vec3, Vec3) {
    let path = format!("{}/tests/fixtures/forest-small/species/{name}.pack", env!("CARGO_MANIFEST_DIR"));
    let bytes = std::fs::read(&path).expect("fixture pack (make fixtures)");
    let pack = decode_pack(&path, &bytes).expect("fixture pack decodes");
    let level = &pack.meta.mesh_levels[0];
    let tris = mesh_triangles(level, &pack.mesh_vertices(0), &pack.mesh_indices(0));
    assert_eq!(tris.len() as u32 * 3, level.index_count, "{name}: every triangle read");
    (tris, pack.meta.bounds_min.into(), pack.meta.bounds_max.into())
}

/// A fixture species as the tracer holds it (`TraceSpecies::of_pack`).
fn traced(name: &str) -> sylva::trace::scene::TraceSpecies {
    let path = format!("{}/tests/fixtures/forest-small/species/{name}.pack", env!("CARGO_MANIFEST_DIR"));
    let bytes = std::fs::read(&path).expect("fixture pack (make fixtures)");
    let pack = decode_pack(&path, &bytes).expect("fixture pack decodes");
    sylva::trace::scene::TraceSpecies::of_pack(&pack).expect("a traceable pack")
}

/// 20,000 leaf cards of 10 cm in a 4 m crown: deep trees, many near misses.
fn leaf_cloud(rng: &mut Rng) -> Vec<Triangle> {
    (0..20_000)
        .map(|_| {
            let a = rng.inside(Vec3::splat(-2.0), Vec3::splat(2.0));
            let d = Vec3::splat(-0.1);
            Triangle::new(a, a + rng.inside(d, -d), a + rng.inside(d, -d))
        })
        .collect()
}

#[test]
fn a_species_hierarchy_finds_what_brute_force_finds() {
    let mut rng = Rng(0x1234_5678);
    for name in SPECIES {
        let (tris, min, max) = species(name);
        let bvh = Bvh::build(&tris);
        assert!(bvh.depth() <= MAX_DEPTH);
        let rays = rays_at(min, max, 1500, rng.0);
        rng.unit();
        let mut hits = 0;
        for ray in &rays {
            let (a, b) = (bvh.intersect(ray), brute_force(&tris, ray));
            assert_eq!(a.map(|h| (h.t, h.triangle)), b.map(|h| (h.t, h.triangle)), "{name}: {ray:?}");
            hits += usize::from(a.is_some());
        }
        // A walk that found nothing would agree with a brute force that found nothing.
        assert!(hits > rays.len() / 10, "{name}: {hits} of {} rays hit", rays.len());
    }
}

#[test]
fn the_gpu_walk_finds_the_hits_its_cpu_twin_finds() {
    let ctx = GpuContext::new_headless_blocking().expect("a GPU adapter (install mesa-vulkan-drivers for lavapipe)");
    let probe = TraceProbe::new(&ctx.device);
    let mut rng = Rng(0x9e37_79b9);
    let mut cases: Vec<(String, Vec<Triangle>, Vec3, Vec3)> = SPECIES
        .iter()
        .map(|n| {
            let (t, a, b) = species(n);
            (n.to_string(), t, a, b)
        })
        .collect();
    cases.push(("leaf cloud".into(), leaf_cloud(&mut rng), Vec3::splat(-2.0), Vec3::splat(2.0)));
    for (name, tris, min, max) in cases {
        let bvh = Bvh::build(&tris);
        let rays = rays_at(min, max, 4096, rng.0);
        rng.unit();
        let gpu = probe.trace(&ctx, &bvh, &rays);
        assert_eq!(gpu.len(), rays.len());
        let (mut hits, mut differ) = (0, Vec::new());
        for (ray, g) in rays.iter().zip(&gpu) {
            let c = bvh.intersect(ray);
            let same = match (c, g) {
                (None, None) => true,
                // The GPU may fuse multiply-adds: the same triangle at the
                // same distance to rounding.
                (Some(c), Some(g)) => c.triangle == g.triangle && (c.t - g.t).abs() <= 1e-5 * c.t.max(1.0),
                _ => false,
            };
            hits += usize::from(c.is_some());
            if !same {
                differ.push((ray, c, *g));
            }
        }
        assert!(hits > rays.len() / 10, "{name}: {hits} of {} rays hit", rays.len());
        // Rounding may flip a ray that grazes an edge; no more than one in a thousand.
        assert!(
            differ.len() <= rays.len() / 1000,
            "{name}: {} rays differ, e.g. {:?}",
            differ.len(),
            &differ[..differ.len().min(3)]
        );
    }
}

#[test]
fn the_gpu_two_level_walk_finds_the_trees_its_cpu_twin_finds() {
    use sylva::trace::scene::{Instance, TraceScene, TraceSpecies};
    let ctx = GpuContext::new_headless_blocking().expect("a GPU adapter (install mesa-vulkan-drivers for lavapipe)");
    let probe = TraceProbe::new(&ctx.device);
    let mut rng = Rng(0x0bad_cafe);
    // The species as the tracer holds them: full meshes with their materials
    // and full-resolution textures, leaf cards alpha-tested.
    let species: Vec<TraceSpecies> = SPECIES.iter().map(|n| traced(n)).collect();
    assert!(
        species.iter().all(|s| s.materials.iter().any(|m| m.alpha_cutoff > 0.0 && m.size > 0)),
        "textured leaf cards"
    );
    // A stand of 600 trees of the three species over 120 × 120 m, each turned,
    // scaled and stretched as a batch's instances are.
    let trees: Vec<Instance> = (0..600)
        .map(|i| Instance {
            position: rng.inside(Vec3::ZERO, Vec3::new(120.0, 120.0, 2.0)),
            yaw: rng.unit() * std::f32::consts::TAU,
            scale: 0.6 + rng.unit() * 0.8,
            aspect: 0.8 + rng.unit() * 0.4,
            species: i % 3,
            tint: (i % 32) as u8 + 1,
        })
        .collect();
    let scene = TraceScene::build(species, &trees);
    assert_eq!(scene.instances.len(), trees.len());
    // Rays across the stand from above its crowns and from its edges.
    let rays: Vec<Ray> = (0..4096)
        .map(|_| {
            let origin = rng.inside(Vec3::new(-20.0, -20.0, 5.0), Vec3::new(140.0, 140.0, 60.0));
            let target = rng.inside(Vec3::ZERO, Vec3::new(120.0, 120.0, 20.0));
            Ray { origin, dir: target - origin, t_max: 1.5 }
        })
        .collect();
    let gpu = probe.trace_scene(&ctx, &scene, &rays);
    let arrays = scene.arrays();
    let (mut hits, mut differ, mut trees_hit) = (0, Vec::new(), std::collections::BTreeSet::new());
    for (ray, g) in rays.iter().zip(&gpu) {
        let c = scene.intersect(ray);
        let same = match (c, g) {
            (None, None) => true,
            (Some(c), Some(g)) => {
                // The same tree in the same slot, the same triangle (by the
                // mesh's index and by its place in the GPU's arrays).
                let inst = scene.instances[c.slot as usize];
                c.instance == g.instance
                    && c.slot == g.slot
                    && inst.id == c.instance
                    && c.hit.triangle == g.hit.triangle
                    && g.hit.index == arrays.species[inst.species_index() as usize].tri_base + c.hit.index
                    && (c.hit.t - g.hit.t).abs() <= 1e-4 * c.hit.t.max(1.0)
                    && (c.hit.u - g.hit.u).abs() < 1e-3
                    && (c.hit.v - g.hit.v).abs() < 1e-3
            }
            _ => false,
        };
        if let Some(c) = c {
            hits += 1;
            trees_hit.insert(c.instance);
        }
        if !same {
            differ.push((ray, c, *g));
        }
    }
    assert!(hits > 400 && trees_hit.len() > 100, "{hits} rays hit {} trees", trees_hit.len());
    // The GPU's sin and cos may differ from the CPU's in the last bits: a ray
    // grazing an edge may flip; no more than one in a hundred.
    assert!(
        differ.len() <= rays.len() / 100,
        "{} rays differ, e.g. {:?}",
        differ.len(),
        &differ[..differ.len().min(3)]
    );
}

/// Walks a top level from its root: every tree in exactly one leaf (of one
/// tree), every inner node's box the union of its children's; the leaves'
/// boxes in leaf order.
fn check_top(top: &[sylva::trace::bvh::BvhNode], trees: usize) -> Vec<(Vec3, Vec3)> {
    assert_eq!(top.len(), 2 * trees - 1, "2n - 1 nodes");
    let mut seen = vec![0u32; trees];
    let mut leaves = vec![(Vec3::ZERO, Vec3::ZERO); trees];
    let mut stack = vec![0usize];
    let mut visited = 0;
    while let Some(i) = stack.pop() {
        visited += 1;
        assert!(visited <= top.len(), "a node reached twice");
        let n = top[i];
        if n.count > 0 {
            assert_eq!(n.count, 1, "a leaf holds one tree");
            seen[n.first as usize] += 1;
            leaves[n.first as usize] = (n.min.into(), n.max.into());
            continue;
        }
        let (a, b) = (top[n.first as usize], top[n.first as usize + 1]);
        for k in 0..3 {
            assert_eq!(n.min[k], a.min[k].min(b.min[k]), "node {i}: its box is its children's");
            assert_eq!(n.max[k], a.max[k].max(b.max[k]), "node {i}: its box is its children's");
        }
        stack.extend([n.first as usize, n.first as usize + 1]);
    }
    assert!(seen.iter().all(|&c| c == 1), "every tree in exactly one leaf");
    leaves
}

/// The top level the GPU builds (`render::top_level`: Morton codes, a
/// bitonic sort, Karras 2012's splits, refits) holds every tree once, boxes
/// each as the CPU places it, and leads the walk to the trees the CPU's
/// binned-SAH top level leads it to — on a stand with trees standing on the
/// same spot (equal codes) and the ground beside them (an instance without a
/// tint, last: a leaf beside the trees' hierarchy at the root), and on scenes
/// of one, two and three trees.
#[test]
fn the_top_level_built_on_the_gpu_holds_every_tree_and_finds_what_the_cpu_finds() {
    use sylva::render::top_level::TopLevel;
    use sylva::trace::scene::{Instance, TraceScene, TraceSpecies};
    let ctx = GpuContext::new_headless_blocking().expect("a GPU adapter (install mesa-vulkan-drivers for lavapipe)");
    let probe = TraceProbe::new(&ctx.device);
    let top_level = TopLevel::new(&ctx.device);
    let mut species: Vec<TraceSpecies> = SPECIES.iter().map(|n| traced(n)).collect();
    // The ground: a 200 m square, one opaque "species" of two triangles.
    let corner = |x: f32, y: f32| Vec3::new(x, y, 0.0);
    let (a, b, c, d) = (corner(-25.0, -25.0), corner(175.0, -25.0), corner(175.0, 175.0), corner(-25.0, 175.0));
    species.push(TraceSpecies::opaque(Bvh::build(&[Triangle::new(a, b, c), Triangle::new(a, c, d)])));
    let mut rng = Rng(0x5eed_0048);
    let mut trees: Vec<Instance> = (0..700)
        .map(|i| Instance {
            position: rng.inside(Vec3::ZERO, Vec3::new(150.0, 150.0, 3.0)),
            yaw: rng.unit() * std::f32::consts::TAU,
            scale: 0.6 + rng.unit() * 0.8,
            aspect: 0.8 + rng.unit() * 0.4,
            species: i % 3,
            tint: 1,
        })
        .collect();
    // Twenty trees on one spot, and one of a species past the list (left out).
    for i in 0..20 {
        trees.push(Instance { yaw: i as f32, ..trees[7] });
    }
    trees.push(Instance { species: 9, ..trees[3] });
    trees.push(Instance { position: Vec3::ZERO, yaw: 0.0, scale: 1.0, aspect: 1.0, species: 3, tint: 0 });
    for n in [1, 2, 3, trees.len()] {
        let cpu = TraceScene::build(species.clone(), &trees[..n]);
        let placed = TraceScene::place(species.clone(), &trees[..n]);
        assert!(placed.top.is_empty());
        let gpu = top_level.built(&ctx, &placed);
        let kept = placed.instances.len();
        assert_eq!(kept, n.min(trees.len() - 1), "the tree of no species is left out");
        let ground = n == trees.len();
        assert_eq!(placed.top_level_trees(), Some(((kept - usize::from(ground)) as u32, ground)));
        let leaves = check_top(&gpu.top, kept);
        // The trees in curve order: the same trees, each boxed as the CPU boxes it.
        let ids = |s: &TraceScene| {
            let mut v: Vec<u32> = s.instances.iter().map(|i| i.id).collect();
            v.sort_unstable();
            v
        };
        assert_eq!(ids(&gpu), ids(&cpu));
        for (inst, (lo, hi)) in gpu.instances.iter().zip(&leaves) {
            let (a, b) = cpu.placed_box(inst);
            let tol = 1e-4 * (b - a).length().max(1.0);
            assert!((*lo - a).abs().max_element() <= tol && (*hi - b).abs().max_element() <= tol, "tree {}", inst.id);
        }
        if n < 100 {
            continue;
        }
        // The ground beside the trees at the root, and last.
        assert_eq!((gpu.top[1].count, gpu.top[1].first), (1, kept as u32 - 1));
        assert_eq!(gpu.instances.last().unwrap().tint(), 0);
        // In curve order: neighbours in the list stand near each other.
        let step: f32 = gpu
            .instances
            .windows(2)
            .map(|w| (Vec3::from(w[0].position) - Vec3::from(w[1].position)).length())
            .sum::<f32>();
        let loaded: f32 = placed
            .instances
            .windows(2)
            .map(|w| (Vec3::from(w[0].position) - Vec3::from(w[1].position)).length())
            .sum::<f32>();
        assert!(step < loaded / 4.0, "curve order walks {step:.0} m, the loaded order {loaded:.0} m");
        let rays: Vec<Ray> = (0..4096)
            .map(|_| {
                let origin = rng.inside(Vec3::new(-20.0, -20.0, 5.0), Vec3::new(170.0, 170.0, 60.0));
                let target = rng.inside(Vec3::ZERO, Vec3::new(150.0, 150.0, 20.0));
                Ray { origin, dir: target - origin, t_max: 1.5 }
            })
            .collect();
        let hits = probe.trace_scene(&ctx, &gpu, &rays);
        let (mut met, mut differ) = (0, 0);
        for (ray, g) in rays.iter().zip(&hits) {
            let c = cpu.intersect(ray);
            met += usize::from(c.is_some());
            let same = match (c, g) {
                (None, None) => true,
                (Some(c), Some(g)) => c.instance == g.instance && (c.hit.t - g.hit.t).abs() <= 1e-4 * c.hit.t.max(1.0),
                _ => false,
            };
            differ += usize::from(!same);
        }
        assert!(met > 400, "{met} rays met trees or the ground");
        assert!(differ <= rays.len() / 100, "{differ} of {} rays differ", rays.len());
    }
    // One tree and the ground: the root over the ground's leaf and the tree's.
    let pair = [trees[0], *trees.last().unwrap()];
    let placed = TraceScene::place(species.clone(), &pair);
    assert_eq!(placed.top_level_trees(), Some((1, true)));
    let gpu = top_level.built(&ctx, &placed);
    check_top(&gpu.top, 2);
    assert_eq!([gpu.top[1].count, gpu.top[1].first, gpu.top[2].count, gpu.top[2].first], [1, 1, 1, 0]);
}

/// The raster's reference (full meshes everywhere, leaf cards alpha-tested at
/// full texture resolution, no shadows, no terrain) and the path tracer under
/// the raster's light, one camera: both see the same forest.
#[test]
fn the_traced_view_covers_what_the_raster_full_mesh_covers() {
    use sylva::offscreen::{NamedView, OffscreenScene};
    use sylva::render::path_trace::{to_srgb8, PathOptions, PathTracer, PathView};
    use sylva::render::settings::{RenderSettings, Representations};
    let scene = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/forest-small");
    let (w, h) = (160, 90);
    let mut off = OffscreenScene::open(scene, w, h, sylva::render::forest::PoolConfig::default()).expect("GPU adapter");
    off.settings = RenderSettings {
        quality: sylva::render::refine::FULL_MESH_QUALITY,
        representations: Representations::MESHES,
        full_res_alpha: true,
        shadows: sylva::render::shadow::ShadowQuality::Off,
        ao: false,
        terrain: false,
        canopy: false,
        ..RenderSettings::default()
    };
    off.load_manifest(60.0);
    let cam = off.named_camera(NamedView::Medium, 60.0).expect("the manifest");
    off.load_view(&cam, 60.0);
    off.render(&cam, false);
    let stats = off.render(&cam, true);
    assert!(stats.instances["mesh0"] > 500, "{:?}", stats.instances);
    let raster = off.read_image();
    let (traced_scene, report) =
        sylva::trace::load::load_dir(std::path::Path::new(scene), cam.eye_m, 2000.0, None).unwrap();
    assert!(report.trees > 1000 && report.instanced_triangles > 1_000_000, "{report:?}");
    let view =
        PathView::under(&off.settings.lighting, cam.eye_m.as_vec3(), cam.forward().as_vec3(), cam.fov_y_rad, None);
    // One ray a pixel through its centre, where the raster's one sample lies.
    let options = PathOptions { spp: 1, simple: true, ground_z: None, jitter: false, ..PathOptions::default() };
    let traced = PathTracer::new(&off.ctx.device)
        .render(&off.ctx, &traced_scene, None, &view, (w, h), &options, &mut |_| {})
        .unwrap();
    let traced = to_srgb8(&traced);
    let (iou, a, b) = sylva::metrics::foliage_iou(&raster, &traced);
    // Trees fill a good part of the view in both (not a blank or a sky).
    let px = (w * h) as usize;
    assert!(a > px / 4 && b > px / 4, "foliage pixels: raster {a}, traced {b} of {px}");
    if let Ok(dir) = std::env::var("SYLVA_TEST_OUT") {
        let save = |name: &str, img: &[u8]| {
            image::save_buffer(format!("{dir}/{name}"), img, w, h, image::ColorType::Rgba8).unwrap()
        };
        save("trace-raster.png", &raster);
        save("trace-traced.png", &traced);
    }
    // Measured 0.9977 (0.9413 against four jittered samples a pixel: edges
    // differ; the 0.95); docs/BENCHMARKS.md.
    assert!(iou >= 0.95, "foliage IoU raster vs traced {iou:.4} ({a} and {b} px)");
}

/// Monte Carlo convergence: against a long run, the error of 4 samples per
/// pixel halves at 16 (error ∝ 1/√samples), on a tiny view of the fixture.
#[test]
fn the_traced_image_converges_at_the_monte_carlo_rate() {
    use sylva::render::path_trace::{PathOptions, PathTracer, PathView};
    let scene = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/forest-small");
    let ctx = GpuContext::new_headless_blocking().expect("a GPU adapter (install mesa-vulkan-drivers for lavapipe)");
    // Above the stand, looking down across it: crowns, gaps and ground.
    let eye = glam::DVec3::new(0.0, -150.0, 90.0);
    let (traced, _) = sylva::trace::load::load_dir(std::path::Path::new(scene), eye, 2000.0, None).unwrap();
    let forward = glam::Vec3::new(0.0, 0.8, -0.6).normalize();
    let view =
        PathView::under(&sylva::render::Lighting::default(), eye.as_vec3(), forward, 50f32.to_radians(), Some(3.0));
    let tracer = PathTracer::new(&ctx.device);
    let size = (32, 18);
    let run = |spp, first_sample| {
        let options = PathOptions { spp, first_sample, ground_z: Some(0.0), ..PathOptions::default() };
        tracer.render(&ctx, &traced, None, &view, size, &options, &mut |_| {}).unwrap()
    };
    // The reference's samples are its own (another start in the sequences).
    let reference = run(64, 1 << 20);
    let rmse = |img: &[[f32; 3]]| {
        let sum: f64 =
            img.iter().zip(&reference).map(|(a, b)| (0..3).map(|c| f64::from(a[c] - b[c]).powi(2)).sum::<f64>()).sum();
        (sum / (img.len() * 3) as f64).sqrt()
    };
    let lit = reference.iter().filter(|p| p.iter().sum::<f32>() > 0.05).count();
    assert!(lit > reference.len() / 2, "{lit} lit pixels of {}", reference.len());
    let (e4, e16) = (rmse(&run(4, 0)), rmse(&run(16, 0)));
    // With the reference's own noise (64 samples) the expected ratio is 0.54.
    let ratio = e16 / e4;
    eprintln!("traced error against 64 spp: 4 spp {e4:.5}, 16 spp {e16:.5} (ratio {ratio:.3})");
    assert!(e4 > 0.0 && (0.35..0.7).contains(&ratio), "error at 4 spp {e4:.5}, at 16 {e16:.5}: ratio {ratio:.3}");
}

/// The clear sky (Preetham et al. 1999) on the GPU is its CPU twin: an empty
/// scene's traced pixels are the sky's radiance in their directions.
#[test]
fn the_gpu_sky_is_its_cpu_twin() {
    use sylva::render::path_trace::{PathOptions, PathTracer, PathView};
    use sylva::trace::scene::TraceScene;
    let ctx = GpuContext::new_headless_blocking().expect("a GPU adapter (install mesa-vulkan-drivers for lavapipe)");
    let sun = glam::Vec3::new(0.3, 0.5, 0.4).normalize();
    let lighting = sylva::render::Lighting { sun_dir: sun, sun_color: glam::Vec3::splat(0.85), ..Default::default() };
    let sky_light = sylva::render::sky_light::SkyLight::new(&lighting, 3.0);
    let sky = sky_light.sky;
    // Looking up: every pixel sees the sky (below the horizon the tracer shows the ground's albedo under it).
    let forward = glam::Vec3::new(0.0, 1.0, 1.2).normalize();
    let view = PathView {
        eye: glam::Vec3::ZERO,
        forward,
        fov_y: 60f32.to_radians(),
        sun_dir: sun,
        sun_color: glam::Vec3::splat(0.85),
        sky_zenith: glam::Vec3::ZERO,
        sky_horizon: glam::Vec3::ZERO,
        ambient: glam::Vec3::ZERO,
        sky: sky_light.uniform(sylva::render::sky_light::LightParts::ALL, 0.3),
    };
    let (w, h) = (16u32, 9u32);
    let options = PathOptions { spp: 16, ground_z: None, ..PathOptions::default() };
    let img = PathTracer::new(&ctx.device)
        .render(&ctx, &TraceScene::default(), None, &view, (w, h), &options, &mut |_| {})
        .unwrap();
    // Each pixel's direction through its centre, as the pass builds it.
    let right = forward.cross(glam::Vec3::Z).normalize();
    let up = right.cross(forward);
    let tan_half = (view.fov_y * 0.5).tan();
    let aspect = w as f32 / h as f32;
    let mut worst = 0f32;
    for y in 0..h {
        for x in 0..w {
            let ndc = ((x as f32 + 0.5) / w as f32 * 2.0 - 1.0, 1.0 - (y as f32 + 0.5) / h as f32 * 2.0);
            let d = (forward + right * tan_half * aspect * ndc.0 + up * tan_half * ndc.1).normalize();
            assert!(d.z > 0.0);
            let cpu = sky.radiance(d);
            let gpu = glam::Vec3::from(img[(y * w + x) as usize]);
            assert!(cpu.min_element() > 0.0, "a lit sky: {cpu}");
            worst = worst.max(((gpu - cpu).abs() / cpu).max_element());
        }
    }
    // (The GPU averages 16 jittered directions across each pixel.)
    assert!(worst < 0.05, "largest relative difference {worst}");
}

/// Light transport against hand-worked cases: a ground under the sun at the
/// zenith and a black sky reflects `albedo × sun_color`; under a uniform sky
/// alone, a white ground reflects the sky's radiance.
#[test]
fn the_tracer_lights_a_plane_as_the_rendering_equation_says() {
    use sylva::render::path_trace::{PathOptions, PathTracer, PathView};
    use sylva::trace::scene::TraceScene;
    let ctx = GpuContext::new_headless_blocking().expect("a GPU adapter (install mesa-vulkan-drivers for lavapipe)");
    let tracer = PathTracer::new(&ctx.device);
    let mut view = PathView {
        eye: glam::Vec3::new(0.0, 0.0, 10.0),
        forward: glam::Vec3::new(0.0, 0.2, -1.0).normalize(),
        fov_y: 30f32.to_radians(),
        sun_dir: glam::Vec3::Z,
        sun_color: glam::Vec3::new(0.9, 0.6, 0.3),
        sky_zenith: glam::Vec3::ZERO,
        sky_horizon: glam::Vec3::ZERO,
        ambient: glam::Vec3::ZERO,
        sky: sylva::render::gpu_data::SkyUniform::default(),
    };
    let albedo = glam::Vec3::new(0.5, 0.25, 1.0);
    let options =
        PathOptions { spp: 8, ground_z: Some(0.0), ground_albedo: albedo, bounces: 0, ..PathOptions::default() };
    let mean = |img: &[[f32; 3]]| img.iter().fold(glam::Vec3::ZERO, |a, p| a + glam::Vec3::from(*p)) / img.len() as f32;
    // The sun alone: albedo × sun_color × cos 0 (a disk of 0.27°: cos ≈ 1).
    let sun = mean(&tracer.render(&ctx, &TraceScene::default(), None, &view, (8, 8), &options, &mut |_| {}).unwrap());
    let want = albedo * view.sun_color;
    assert!((sun - want).abs().max_element() < 1e-3, "sun-lit ground {sun}, expected {want}");
    // A uniform sky of radiance L alone (the sun below the horizon): a white
    // Lambertian plane reflects L (its cosine-weighted integral over π).
    view.sun_dir = -glam::Vec3::Z;
    view.sky_zenith = glam::Vec3::splat(0.4);
    view.sky_horizon = glam::Vec3::splat(0.4);
    let white = PathOptions { spp: 64, ground_albedo: glam::Vec3::ONE, ..options };
    let sky = mean(&tracer.render(&ctx, &TraceScene::default(), None, &view, (8, 8), &white, &mut |_| {}).unwrap());
    assert!((sky - glam::Vec3::splat(0.4)).abs().max_element() < 0.02, "sky-lit ground {sky}, expected 0.4");
    // An HDR environment with a small bright patch (a sun) over a dim sky:
    // the ground reflects albedo/π × ∫ L cos θ dω, summed over the map's
    // texels on the CPU — the importance sampling and its weights against
    // the surface's own sampling leave the estimate unbiased.
    use sylva::trace::environment::Environment;
    let (w, h) = (64u32, 32u32);
    let texels: Vec<[f32; 3]> = (0..w * h)
        .map(|k| {
            let (i, j) = (k % w, k / w);
            if (40..42).contains(&i) && (6..8).contains(&j) {
                [300.0, 250.0, 200.0]
            } else {
                [0.05, 0.08, 0.15]
            }
        })
        .collect();
    let env = Environment::new(w, h, texels).unwrap();
    let mut irradiance = glam::Vec3::ZERO;
    let n = 256;
    for b in 0..n * n {
        // (Each texel's solid angle, finely: cos θ over the upper hemisphere.)
        let (u, v) = ((b % n) as f32 + 0.5, (b / n) as f32 + 0.5);
        let (u, v) = (u / n as f32, v / n as f32);
        let d = Environment::direction([u, v]);
        if d.z > 0.0 {
            let d_omega =
                2.0 * std::f32::consts::PI * std::f32::consts::PI * (v * std::f32::consts::PI).sin() / (n * n) as f32;
            irradiance += env.radiance(d) * d.z * d_omega;
        }
    }
    let want = glam::Vec3::ONE * 0.5 * irradiance / std::f32::consts::PI;
    let half = PathOptions { spp: 256, ground_albedo: glam::Vec3::splat(0.5), ..options };
    let lit =
        mean(&tracer.render(&ctx, &TraceScene::default(), Some(&env), &view, (8, 8), &half, &mut |_| {}).unwrap());
    let rel = ((lit - want).abs() / want).max_element();
    assert!(rel < 0.03, "environment-lit ground {lit}, expected {want} ({rel:.3} off)");
}
