//! GPU tests of the cluster pass (Clasen et al. 2010, §5): ray-cast ellipsoids and capsule
//! lines against CPU ray casts of the same records, depth between intersecting
//! primitives, and the three representations of one tree side by side.

use glam::{DVec3, Mat4, Quat, Vec3};
use sylva::format::cluster::{Ellipsoid, Line, PackedEllipsoid, PackedLine};
use sylva::format::decode_pack;
use sylva::metrics::multiscale_rmse;
use sylva::render::capture::{BillboardFrame, PackRepr, PackView, Shot, TreeDraw, TreeRenderer};
use sylva::render::cluster::ClusterGpu;
use sylva::render::GpuContext;

const SIZE: u32 = 96;
const LO: Vec3 = Vec3::new(-5.0, -5.0, 0.0);
const HI: Vec3 = Vec3::new(5.0, 5.0, 10.0);

fn gpu() -> GpuContext {
    GpuContext::new_headless_blocking().expect("a GPU adapter (install mesa-vulkan-drivers for lavapipe)")
}

struct Rng(u64);

impl Rng {
    fn f(&mut self) -> f32 {
        self.0 = self.0.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.f()
    }
}

fn upload(ctx: &GpuContext, r: &TreeRenderer, ells: &[Ellipsoid], lines: &[Line]) -> ClusterGpu {
    ClusterGpu::from_level(&ctx.device, &ctx.queue, &r.cluster, ells, lines, (LO, HI), (0.0, 0.0), [0.9; 3], None)
}

/// The ray through the centre of pixel (x, y), as the shader builds it.
fn pixel_ray(inv: &glam::DMat4, x: u32, y: u32) -> (DVec3, DVec3) {
    let ndc = glam::DVec2::new(
        (f64::from(x) + 0.5) / f64::from(SIZE) * 2.0 - 1.0,
        1.0 - (f64::from(y) + 0.5) / f64::from(SIZE) * 2.0,
    );
    let n = *inv * glam::DVec4::new(ndc.x, ndc.y, 1.0, 1.0);
    let m = *inv * glam::DVec4::new(ndc.x, ndc.y, 0.5, 1.0);
    let pn = n.truncate() / n.w;
    let pm = m.truncate() / m.w;
    (pn, (pm - pn).normalize())
}

/// Nearest hit distance of a ray with an ellipsoid (decoded like the shader).
fn hit_ellipsoid(e: &Ellipsoid, o: DVec3, d: DVec3) -> Option<f64> {
    let q = e.rotation.as_dquat();
    let r = e.radii.as_dvec3();
    let axes = [q * DVec3::X / r.x, q * DVec3::Y / r.y, q * DVec3::Z / r.z];
    let oc = o - e.center.as_dvec3();
    let lo = DVec3::new(oc.dot(axes[0]), oc.dot(axes[1]), oc.dot(axes[2]));
    let ld = DVec3::new(d.dot(axes[0]), d.dot(axes[1]), d.dot(axes[2]));
    let (a, b, c) = (ld.dot(ld), lo.dot(ld), lo.dot(lo) - 1.0);
    let disc = b * b - a * c;
    (disc >= 0.0).then(|| (-b - disc.sqrt()) / a).filter(|t| *t >= 0.0)
}

/// Whether a ray meets a capsule, and the distance of its closest approach to the
/// axis (the entry point is up to one radius nearer).
fn hit_capsule(l: &Line, o: DVec3, d: DVec3) -> Option<f64> {
    let (a, b) = (l.a.as_dvec3(), l.b.as_dvec3());
    let r = f64::from(l.radius_a + l.radius_b) * 0.5;
    let ab = b - a;
    // Closest points between the ray (infinite line) and the segment.
    let w = o - a;
    let (aa, bb, cc, dd, ee) = (d.dot(d), d.dot(ab), ab.dot(ab), d.dot(w), ab.dot(w));
    let den = aa * cc - bb * bb;
    let mut s = if den.abs() > 1e-12 { ((bb * ee - cc * dd) / den).max(0.0) } else { 0.0 };
    let mut u = ((ee + bb * s) / cc).clamp(0.0, 1.0);
    s = ((a + ab * u - o).dot(d) / aa).max(0.0);
    u = ((o + d * s - a).dot(ab) / cc).clamp(0.0, 1.0);
    ((o + d * s).distance(a + ab * u) <= r).then_some(s)
}

/// Pixels where `want` and `got` (coverage masks) disagree away from edges of `want`,
/// and the number of disagreements on edges.
fn compare(want: &[bool], got: &[bool]) -> (usize, usize, usize) {
    let n = SIZE as i32;
    let at = |x: i32, y: i32| want[(y.clamp(0, n - 1) * n + x.clamp(0, n - 1)) as usize];
    let (mut inner, mut edge, mut covered) = (0, 0, 0);
    for y in 0..n {
        for x in 0..n {
            let i = (y * n + x) as usize;
            covered += usize::from(want[i]);
            if want[i] != got[i] {
                let is_edge = [(-1, 0), (1, 0), (0, -1), (0, 1)].iter().any(|(dx, dy)| at(x + dx, y + dy) != want[i]);
                if is_edge {
                    edge += 1;
                } else {
                    inner += 1;
                }
            }
        }
    }
    (inner, edge, covered)
}

fn camera(elevation: f32, azimuth: f32) -> (Mat4, glam::DMat4) {
    let clip = BillboardFrame::from_bounds(LO, HI).clip_from_model(elevation.to_radians(), azimuth.to_radians());
    (clip, clip.as_dmat4().inverse())
}

#[test]
fn ray_cast_ellipsoids_match_the_cpu_reference() {
    let ctx = gpu();
    let r = TreeRenderer::new(&ctx);
    let mut rng = Rng(11);
    let mut shapes = vec![
        Vec3::new(2.0, 0.05, 0.05), // thin needle
        Vec3::new(2.5, 2.5, 0.03),  // flat disc
        Vec3::new(1.5, 1.0, 0.6),
    ];
    for _ in 0..5 {
        shapes.push(Vec3::new(rng.range(0.2, 3.0), rng.range(0.05, 2.0), rng.range(0.02, 1.5)));
    }
    for (case, radii) in shapes.into_iter().enumerate() {
        let e = Ellipsoid {
            center: Vec3::new(rng.range(-1.5, 1.5), rng.range(-1.5, 1.5), rng.range(3.0, 7.0)),
            rotation: Quat::from_euler(
                glam::EulerRot::ZYX,
                rng.range(0.0, 6.3),
                rng.range(-1.5, 1.5),
                rng.range(0.0, 6.3),
            ),
            radii,
            color: Vec3::splat(0.9),
            noise_level: 0.0,
        };
        // What the GPU reads: the quantised record.
        let q = PackedEllipsoid::encode(&e, LO, HI).decode(LO, HI);
        let c = upload(&ctx, &r, &[e], &[]);
        for (elev, az) in [(0.0, 0.0), (35.0, 70.0), (89.0, 10.0)] {
            let (clip, inv) = camera(elev, az);
            let img =
                r.render(&ctx, &TreeDraw::Cluster(&c, 0), &Shot::square(clip, Vec3::ZERO, SIZE), [0.0, 0.0, 0.0, 1.0]);
            let got: Vec<bool> = img.chunks(4).map(|p| p[0].max(p[1]).max(p[2]) > 6).collect();
            let want: Vec<bool> = (0..SIZE * SIZE)
                .map(|i| {
                    let (o, d) = pixel_ray(&inv, i % SIZE, i / SIZE);
                    hit_ellipsoid(&q, o, d).is_some()
                })
                .collect();
            let (inner, edge, covered) = compare(&want, &got);
            assert!(covered > 0, "case {case}: the ellipsoid is on screen");
            assert_eq!(inner, 0, "case {case} {radii:?} view ({elev}, {az}): {inner} pixels disagree inside");
            assert!(
                edge <= covered / 10 + 4,
                "case {case} view ({elev}, {az}): {edge} edge pixels of {covered} disagree"
            );
        }
    }
}

#[test]
fn intersecting_ellipsoids_and_lines_keep_correct_depth() {
    let ctx = gpu();
    let r = TreeRenderer::new(&ctx);
    let red = Ellipsoid {
        center: Vec3::new(0.0, 0.0, 5.0),
        rotation: Quat::from_rotation_y(0.4),
        radii: Vec3::new(3.0, 1.2, 0.8),
        color: Vec3::new(0.9, 0.05, 0.05),
        noise_level: 0.0,
    };
    let blue = Ellipsoid {
        center: Vec3::new(0.5, 0.3, 5.5),
        rotation: Quat::from_rotation_x(0.9),
        radii: Vec3::new(1.0, 2.5, 1.0),
        color: Vec3::new(0.05, 0.05, 0.9),
        noise_level: 0.0,
    };
    // A line through both (drawn in the line colour, light grey).
    let line = Line { a: Vec3::new(-3.0, -1.0, 2.0), b: Vec3::new(3.0, 1.5, 8.0), radius_a: 0.3, radius_b: 0.3 };
    let c = upload(&ctx, &r, &[red, blue], &[line]);
    let decoded: Vec<Ellipsoid> =
        [red, blue].iter().map(|e| PackedEllipsoid::encode(e, LO, HI).decode(LO, HI)).collect();
    let dl = PackedLine::encode(&line, LO, HI).decode(LO, HI);
    for (elev, az) in [(0.0, 0.0), (30.0, 200.0), (60.0, 95.0)] {
        let (clip, inv) = camera(elev, az);
        let img =
            r.render(&ctx, &TreeDraw::Cluster(&c, 0), &Shot::square(clip, Vec3::ZERO, SIZE), [0.0, 0.0, 0.0, 1.0]);
        // Per pixel: which primitive is nearest (0 none, 1 red, 2 blue, 3 line).
        let want: Vec<u8> = (0..SIZE * SIZE)
            .map(|i| {
                let (o, d) = pixel_ray(&inv, i % SIZE, i / SIZE);
                let hits = [hit_ellipsoid(&decoded[0], o, d), hit_ellipsoid(&decoded[1], o, d), hit_capsule(&dl, o, d)];
                hits.iter()
                    .enumerate()
                    .filter_map(|(k, h)| h.map(|t| (t, k as u8 + 1)))
                    .min_by(|a, b| a.0.total_cmp(&b.0))
                    .map_or(0, |x| x.1)
            })
            .collect();
        let got: Vec<u8> = img
            .chunks(4)
            .map(|p| {
                let (r, g, b) = (i32::from(p[0]), i32::from(p[1]), i32::from(p[2]));
                if r.max(g).max(b) <= 6 {
                    0
                } else if g > 40 && (r - b).abs() < 40 {
                    3
                } else if r > b {
                    1
                } else {
                    2
                }
            })
            .collect();
        if elev == 0.0 {
            let out = concat!(env!("CARGO_MANIFEST_DIR"), "/target/tmp");
            std::fs::create_dir_all(out).ok();
            image::save_buffer(format!("{out}/cluster-depth.png"), &img, SIZE, SIZE, image::ColorType::Rgba8).ok();
        }
        for k in 1..=3u8 {
            let (inner, edge, covered) = compare(
                &want.iter().map(|w| *w == k).collect::<Vec<_>>(),
                &got.iter().map(|g| *g == k).collect::<Vec<_>>(),
            );
            assert!(covered > 20, "primitive {k} visible in view ({elev}, {az})");
            // The CPU capsule depth is its closest approach, up to a radius behind
            // the true entry: allow a few pixels where a line meets an ellipsoid.
            assert!(
                inner <= covered / 20 + 2,
                "view ({elev}, {az}): primitive {k} wrong on {inner} inner pixels of {covered}"
            );
            assert!(edge <= covered / 5 + 6, "view ({elev}, {az}): primitive {k} wrong on {edge} edge pixels");
        }
    }
}

#[test]
fn three_representations_of_one_tree_side_by_side() {
    let ctx = gpu();
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/forest-small/species/beech.pack");
    let bytes = std::fs::read(path).expect("fixture pack (make fixtures)");
    let pack = decode_pack(path, &bytes).expect("fixture pack decodes");
    let clusters = pack.meta.clusters.as_ref().expect("the fixture pack has cluster levels");
    // The finest cluster level drawn below the simplified mesh, at the size it is drawn at.
    let mesh1_px = pack.meta.mesh_levels[1].select_px;
    let (level, meta) = clusters
        .ellipsoid_levels
        .iter()
        .enumerate()
        .find(|(_, l)| l.select_px < mesh1_px)
        .expect("a level below mesh 1");
    let size = 128;
    let bg = [0.62, 0.74, 0.86, 1.0];
    let renderer = TreeRenderer::new(&ctx);
    let render =
        |repr| renderer.render_pack(&ctx, &pack, repr, PackView::Side, [size, size], bg).expect("representation");
    let mesh = render(PackRepr::Mesh(0));
    let cluster = render(PackRepr::Cluster(level));
    let billboard = render(PackRepr::Billboard);
    let empty: Vec<u8> = mesh.chunks(4).flat_map(|_| [158u8, 189, 219, 255]).collect();
    let e_cluster = multiscale_rmse(&cluster, &mesh, size, size);
    let e_billboard = multiscale_rmse(&billboard, &mesh, size, size);
    let e_empty = multiscale_rmse(&empty, &mesh, size, size);
    // Side by side for looking at: mesh | ellipsoids + lines | billboard.
    let mut strip = vec![0u8; (size * size * 4 * 3) as usize];
    for (k, img) in [&mesh, &cluster, &billboard].iter().enumerate() {
        for y in 0..size as usize {
            let row = &img[y * size as usize * 4..(y + 1) * size as usize * 4];
            let at = (y * 3 * size as usize + k * size as usize) * 4;
            strip[at..at + row.len()].copy_from_slice(row);
        }
    }
    let out = concat!(env!("CARGO_MANIFEST_DIR"), "/target/tmp");
    std::fs::create_dir_all(out).ok();
    image::save_buffer(format!("{out}/representations.png"), &strip, size * 3, size, image::ColorType::Rgba8).ok();
    println!(
        "level {level} ({} ellipsoids): cluster {e_cluster:.4}, billboard {e_billboard:.4}, empty {e_empty:.4}",
        meta.count
    );
    assert!(e_empty > 0.04, "the tree covers the image: {e_empty}");
    assert!(e_cluster < e_empty * 0.6, "ellipsoids + lines look like the tree: {e_cluster} vs empty {e_empty}");
    assert!(e_billboard < e_empty * 0.6, "billboard looks like the tree: {e_billboard} vs empty {e_empty}");
}
