//! Multi-view impostors (`src/render/impostor.rs`, `shaders/impostor.wgsl`):
//! the shader's view selection and blend weights against the CPU oracle, and
//! a tree seen from all round keeps its silhouette as an impostor where a
//! single-azimuth billboard turns with the camera. Fixture packs: `make fixtures`.

use glam::{Mat4, Vec3};
use sylva::format::decode_pack;
use sylva::metrics::multiscale_rmse;
use sylva::render::billboard::BillboardGpu;
use sylva::render::capture::{PackView, Shot, TreeDraw, TreeRenderer};
use sylva::render::impostor::{blend_views, ImpostorGpu};
use sylva::render::mesh::MeshGpu;
use sylva::render::GpuContext;
use wgpu::util::DeviceExt;

const SPECIES: [&str; 3] = ["beech", "birch", "spruce"];

fn ctx() -> GpuContext {
    GpuContext::new_headless_blocking().expect("a GPU adapter (install mesa-vulkan-drivers for lavapipe)")
}

/// Directions over the whole sphere (below the horizon too: they clamp to it).
fn directions(n: usize) -> Vec<Vec3> {
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
            let a = i as f32 * 2.399_963;
            let r = (1.0 - z * z).sqrt();
            Vec3::new(r * a.cos(), r * a.sin(), z)
        })
        .collect()
}

#[test]
fn shader_view_selection_matches_the_cpu_oracle() {
    let ctx = ctx();
    let dirs = directions(2000);
    for grid in [2u32, 6, 8, 16] {
        let source = format!(
            "{}\n@group(0) @binding(0) var<storage, read> dirs: array<vec4<f32>>;\n\
             @group(0) @binding(1) var<storage, read_write> out: array<vec4<f32>>;\n\
             @compute @workgroup_size(64) fn main(@builtin(global_invocation_id) id: vec3<u32>) {{\n\
               if id.x >= arrayLength(&dirs) {{ return; }}\n\
               let v = impostor_views(dirs[id.x].xyz, {grid}u);\n\
               out[id.x * 2u] = vec4<f32>(vec3<f32>(v.layers), 0.0);\n\
               out[id.x * 2u + 1u] = vec4<f32>(v.weights, 0.0);\n\
             }}",
            include_str!("../../shaders/impostor_views.wgsl")
        );
        let module = ctx.device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("impostor views test"),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let pipeline = ctx.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: None,
            layout: None,
            module: &module,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: None,
        });
        let input: Vec<[f32; 4]> = dirs.iter().map(|d| [d.x, d.y, d.z, 0.0]).collect();
        let dir_buf = ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: None,
            contents: bytemuck::cast_slice(&input),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let out_bytes = (dirs.len() * 32) as u64;
        let out_buf = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: out_bytes,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let read = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: out_bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &pipeline.get_bind_group_layout(0),
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: dir_buf.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: out_buf.as_entire_binding() },
            ],
        });
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &group, &[]);
            pass.dispatch_workgroups((dirs.len() as u32).div_ceil(64), 1, 1);
        }
        enc.copy_buffer_to_buffer(&out_buf, 0, &read, 0, out_bytes);
        ctx.queue.submit([enc.finish()]);
        read.slice(..).map_async(wgpu::MapMode::Read, |r| r.expect("map"));
        ctx.device.poll(wgpu::PollType::wait_indefinitely()).expect("poll");
        let got: Vec<[f32; 4]> = bytemuck::cast_slice(&read.slice(..).get_mapped_range().expect("mapped")).to_vec();
        let mut checked = 0;
        for (i, d) in dirs.iter().enumerate() {
            let want = blend_views(*d, grid);
            let (layers, weights) = (got[i * 2], got[i * 2 + 1]);
            // Weight per view, so a tie on a cell's diagonal (either triangle) still matches.
            let per_view = |pairs: &[(u32, f32)]| {
                let mut m = std::collections::BTreeMap::<u32, f32>::new();
                for (l, w) in pairs {
                    *m.entry(*l).or_default() += w;
                }
                m.retain(|_, w| *w > 1e-3);
                m
            };
            let shader: Vec<(u32, f32)> = (0..3).map(|k| (layers[k] as u32, weights[k])).collect();
            let (a, b) = (per_view(&want), per_view(&shader));
            assert_eq!(
                a.keys().collect::<Vec<_>>(),
                b.keys().collect::<Vec<_>>(),
                "grid {grid}, {d}: {want:?} vs {shader:?}"
            );
            for (l, w) in &a {
                assert!((w - b[l]).abs() < 2e-3, "grid {grid}, {d}, view {l}: {w} vs {}", b[l]);
            }
            checked += 1;
        }
        assert_eq!(checked, dirs.len());
    }
}

/// A perspective camera `distance` from the tree's centre at `azimuth_deg`
/// and `elevation_deg`: (clip_from_eye, eye), camera-relative like the viewer's.
fn camera(center: Vec3, distance: f32, azimuth_deg: f32, elevation_deg: f32) -> (Mat4, Vec3) {
    let (a, e) = (azimuth_deg.to_radians(), elevation_deg.to_radians());
    let dir = Vec3::new(e.cos() * a.cos(), e.cos() * a.sin(), e.sin());
    let eye = center + dir * distance;
    let eye_from_world = glam::camera::rh::view::look_to_mat4(Vec3::ZERO, -dir, Vec3::Z);
    let proj = glam::camera::rh::proj::directx::perspective_infinite_reverse(30f32.to_radians(), 1.0, 0.1);
    (proj * eye_from_world, eye)
}

/// Pixels that differ from the background.
fn silhouette(img: &[u8], bg: &[u8]) -> Vec<bool> {
    img.chunks(4).map(|p| (0..3).any(|k| (i32::from(p[k]) - i32::from(bg[k])).abs() > 6)).collect()
}

fn iou(a: &[bool], b: &[bool]) -> f64 {
    let both = a.iter().zip(b).filter(|(x, y)| **x && **y).count();
    let either = a.iter().zip(b).filter(|(x, y)| **x || **y).count();
    both as f64 / either.max(1) as f64
}

#[test]
fn a_tree_seen_all_round_keeps_its_silhouette() {
    const SIZE: u32 = 128;
    let ctx = ctx();
    let r = TreeRenderer::new(&ctx);
    let bg = [0.62, 0.74, 0.86, 1.0];
    let mut report = Vec::new();
    let (mut imp_total, mut bb_total, mut iou_gain, mut views) = (0.0, 0.0, 0.0, 0.0);
    for species in SPECIES {
        let path = format!("{}/tests/fixtures/forest-small/species/{species}.pack", env!("CARGO_MANIFEST_DIR"));
        let bytes = std::fs::read(&path).expect("fixture pack (make fixtures)");
        let pack = decode_pack(&path, &bytes).expect("fixture pack decodes");
        let mesh = MeshGpu::upload(&ctx.device, &ctx.queue, &r.mesh, &pack);
        let imp =
            ImpostorGpu::upload(&ctx.device, &ctx.queue, 0, &r.impostor, &pack).expect("impostors (make fixtures)");
        let bb = BillboardGpu::upload(&ctx.device, &ctx.queue, 0, &r.billboard, &pack).expect("billboards");
        let (lo, hi) = (Vec3::from(pack.meta.bounds_min), Vec3::from(pack.meta.bounds_max));
        let center = (lo + hi) * 0.5;
        // About 100 px tall: the impostors' band.
        let distance = (hi.z - lo.z) / (100.0 / SIZE as f32) / (15f32.to_radians().tan() * 2.0);
        for (azimuth, elevation) in [(0.0, 5.0), (55.0, 5.0), (130.0, 20.0), (215.0, 5.0), (300.0, 35.0)] {
            let (clip, eye) = camera(center, distance, azimuth, elevation);
            let draw = |what: &TreeDraw<'_>| r.render(&ctx, what, &Shot::square(clip, eye, SIZE), bg);
            let m = draw(&TreeDraw::Mesh(&mesh, 0));
            let i = draw(&TreeDraw::Impostor(&imp));
            let b = draw(&TreeDraw::Billboard(&bb));
            let bg_px = &m[..4];
            let (sm, si, sb) = (silhouette(&m, bg_px), silhouette(&i, bg_px), silhouette(&b, bg_px));
            let drawn = sm.iter().filter(|x| **x).count();
            assert!(drawn > 800, "{species} at {azimuth}°: the mesh covers only {drawn} px");
            let (iou_i, iou_b) = (iou(&sm, &si), iou(&sm, &sb));
            let (err_i, err_b) = (multiscale_rmse(&i, &m, SIZE, SIZE), multiscale_rmse(&b, &m, SIZE, SIZE));
            report.push(format!(
                "{species} az {azimuth:>5.1} el {elevation:>4.1}: IoU impostor {iou_i:.3} billboard {iou_b:.3}; \
                 MS-RMSE impostor {err_i:.4} billboard {err_b:.4}"
            ));
            // Bounds against the mesh at every view (the fixture's impostors are
            // 32² views, blurrier than the 100 px mesh: IoU 0.40–0.79, error 0.044–0.085).
            assert!(
                iou_i >= 0.35 && err_i <= 0.095,
                "{species} at {azimuth}°/{elevation}°: impostor silhouette IoU {iou_i:.3}, MS-RMSE {err_i:.4}"
            );
            imp_total += err_i;
            bb_total += err_b;
            iou_gain += iou_i - iou_b;
            views += 1.0;
        }
    }
    eprintln!("{}", report.join("\n"));
    // All round, the impostors follow the mesh closer than the single-azimuth
    // billboards, which turn with the camera (measured: +0.10 IoU, −22 % error).
    let gain = iou_gain / views;
    assert!(
        imp_total < 0.9 * bb_total && gain > 0.05,
        "impostor error {imp_total:.4} vs billboard {bb_total:.4}, IoU gain {gain:.3}\n{}",
        report.join("\n")
    );
}

/// The LoD policy's time model reads the draws' work from a pipeline-statistics
/// query: the counts repeat exactly, grow with the tree's size on screen, and
/// the modelled time puts the mesh above the impostor above the billboard.
#[test]
fn work_counts_are_exact_and_scale_with_size() {
    use sylva::lod::policy::{modelled_us, CostKind};
    let ctx = ctx();
    if !ctx.device.features().contains(wgpu::Features::PIPELINE_STATISTICS_QUERY) {
        eprintln!("skipped: {} has no pipeline statistics", ctx.adapter_summary());
        return;
    }
    let r = TreeRenderer::new(&ctx);
    let path = format!("{}/tests/fixtures/forest-small/species/beech.pack", env!("CARGO_MANIFEST_DIR"));
    let bytes = std::fs::read(&path).expect("fixture pack (make fixtures)");
    let pack = decode_pack(&path, &bytes).expect("fixture pack decodes");
    let mesh = MeshGpu::upload(&ctx.device, &ctx.queue, &r.mesh, &pack);
    let imp = ImpostorGpu::upload(&ctx.device, &ctx.queue, 0, &r.impostor, &pack).expect("impostors");
    let bb = BillboardGpu::upload(&ctx.device, &ctx.queue, 0, &r.billboard, &pack).expect("billboards");
    let (lo, hi) = (Vec3::from(pack.meta.bounds_min), Vec3::from(pack.meta.bounds_max));
    let work = |what: &TreeDraw<'_>, size: u32| {
        let shot = sylva::render::capture::preview_camera(lo, hi, PackView::Side, [size, size]);
        r.work(&ctx, what, &shot).expect("pipeline statistics")
    };
    for (what, kind) in [
        (TreeDraw::Mesh(&mesh, 0), CostKind::Mesh),
        (TreeDraw::Impostor(&imp), CostKind::Impostor),
        (TreeDraw::Billboard(&bb), CostKind::Billboard),
    ] {
        let (small, big) = (work(&what, 64), work(&what, 256));
        assert_eq!(small, work(&what, 64), "{kind:?}: counts repeat");
        let ratio = big.fragments as f64 / small.fragments.max(1) as f64;
        // Quads: at 16× the pixels, fewer than 16× the fragments where
        // triangles are small (2×2 quads at their edges), never more.
        assert!((3.0..17.0).contains(&ratio), "{kind:?}: 16× the pixels, {ratio:.1}× the fragments");
        assert!(small.fragments > 100 && small.vertices >= 4, "{kind:?}: {small:?}");
    }
    let us = |what: &TreeDraw<'_>, kind| {
        let w = work(what, 128);
        modelled_us(kind, w.vertices, w.fragments)
    };
    let (m, i, b) = (
        us(&TreeDraw::Mesh(&mesh, 0), CostKind::Mesh),
        us(&TreeDraw::Impostor(&imp), CostKind::Impostor),
        us(&TreeDraw::Billboard(&bb), CostKind::Billboard),
    );
    assert!(m > i && i > b, "modelled µs: mesh {m:.1}, impostor {i:.1}, billboard {b:.1}");
}

/// Not a test: the far tiers' error against a supersampled full-resolution
/// mesh at several sizes (`cargo test --release --test it gpu_impostor:: -- --ignored --nocapture`).
#[test]
#[ignore = "a measurement"]
fn far_tier_error_by_size() {
    let ctx = ctx();
    let mut r = TreeRenderer::new(&ctx);
    let bg = [0.42, 0.45, 0.25, 1.0];
    let path = std::env::var("PACK")
        .unwrap_or_else(|_| format!("{}/tests/fixtures/forest-small/species/beech.pack", env!("CARGO_MANIFEST_DIR")));
    let bytes = std::fs::read(&path).expect("pack");
    let pack = decode_pack(&path, &bytes).expect("pack decodes");
    let mesh = MeshGpu::upload(&ctx.device, &ctx.queue, &r.mesh, &pack);
    let imp = ImpostorGpu::upload(&ctx.device, &ctx.queue, 0, &r.impostor, &pack).expect("impostors");
    let bb = BillboardGpu::upload(&ctx.device, &ctx.queue, 0, &r.billboard, &pack).expect("billboards");
    let (lo, hi) = (Vec3::from(pack.meta.bounds_min), Vec3::from(pack.meta.bounds_max));
    let center = (lo + hi) * 0.5;
    const SIZE: u32 = 64;
    for px in [8.0f32, 16.0, 32.0, 56.0] {
        let (mut e_i, mut e_b, mut e_m) = (0.0, 0.0, 0.0);
        let distance = (hi.z - lo.z) / (px / SIZE as f32) / (15f32.to_radians().tan() * 2.0);
        for (azimuth, elevation) in [(0.0, 5.0), (55.0, 10.0), (130.0, 20.0), (215.0, 5.0), (300.0, 30.0)] {
            let (clip, eye) = camera(center, distance, azimuth, elevation);
            r.full_res_alpha = true;
            let big = r.render(&ctx, &TreeDraw::Mesh(&mesh, 0), &Shot::square(clip, eye, SIZE * 4), bg);
            r.full_res_alpha = false;
            let mut reference = vec![0u8; (SIZE * SIZE * 4) as usize];
            for y in 0..SIZE as usize {
                for x in 0..SIZE as usize {
                    for k in 0..4 {
                        let mut sum = 0.0f32;
                        for dy in 0..4 {
                            for dx in 0..4 {
                                let v = f32::from(big[((y * 4 + dy) * SIZE as usize * 4 + x * 4 + dx) * 4 + k]) / 255.0;
                                sum += if k < 3 { v.powf(2.2) } else { v };
                            }
                        }
                        let m = sum / 16.0;
                        reference[(y * SIZE as usize + x) * 4 + k] =
                            ((if k < 3 { m.powf(1.0 / 2.2) } else { m }) * 255.0).round() as u8;
                    }
                }
            }
            let draw = |what: &TreeDraw<'_>| r.render(&ctx, what, &Shot::square(clip, eye, SIZE), bg);
            e_m += multiscale_rmse(&draw(&TreeDraw::Mesh(&mesh, 0)), &reference, SIZE, SIZE);
            e_i += multiscale_rmse(&draw(&TreeDraw::Impostor(&imp)), &reference, SIZE, SIZE);
            e_b += multiscale_rmse(&draw(&TreeDraw::Billboard(&bb)), &reference, SIZE, SIZE);
        }
        eprintln!("{px:>4} px: mesh {:.4} billboard {:.4} impostor {:.4}", e_m / 5.0, e_b / 5.0, e_i / 5.0);
    }
}
