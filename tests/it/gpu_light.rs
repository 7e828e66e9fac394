//! The light of issue 49 on single trees: leaves that transmit as the path
//! tracer's do (`shaders/light.wgsl`), at every level of detail.

use glam::Vec3;
use sylva::format::decode_pack;
use sylva::render::capture::{BillboardFrame, PackRepr, PackView, TreeRenderer};
use sylva::render::{GpuContext, Lighting};

use crate::common::tree_brightness;

const SIZE: u32 = 128;
const BG: [f64; 4] = [0.62, 0.74, 0.86, 1.0];

/// A tree with the sun behind it glows where its leaves let the light
/// through: brighter with the tracer's transmittance (0.3 of the albedo)
/// than with leaves that transmit nothing, at every level of detail, by a
/// ratio within bounds; with the sun behind the camera the same leaves,
/// reflecting 0.7 of their albedo instead of all of it, are darker.
#[test]
fn back_lit_leaves_glow_at_every_level_of_detail() {
    let ctx = GpuContext::new_headless_blocking().expect("a GPU adapter (install mesa-vulkan-drivers for lavapipe)");
    let path = format!("{}/tests/fixtures/forest-small/species/beech.pack", env!("CARGO_MANIFEST_DIR"));
    let bytes = std::fs::read(&path).expect("fixture pack (make fixtures)");
    let pack = decode_pack(&path, &bytes).expect("fixture pack decodes");
    // The side view looks along -dir (dir: from the tree towards the eye).
    let (dir, _) = BillboardFrame::view_axes(0.0, -std::f32::consts::FRAC_PI_2);
    let behind = Vec3::new(-dir.x, -dir.y, 0.36).normalize();
    let in_front = Vec3::new(dir.x, dir.y, 0.36).normalize();
    let clusters = pack.meta.clusters.as_ref().expect("cluster levels");
    let mut reprs =
        vec![("mesh 0", PackRepr::Mesh(0)), ("mesh 1", PackRepr::Mesh(1)), ("billboard", PackRepr::Billboard)];
    if !clusters.ellipsoid_levels.is_empty() {
        reprs.push(("ellipsoids", PackRepr::Cluster(clusters.ellipsoid_levels.len() / 2)));
    }
    let mut rows = Vec::new();
    let mut failures = Vec::new();
    let mut drawn = 0;
    for (name, repr) in reprs.into_iter().chain([("impostor", PackRepr::Impostor), ("cloud", PackRepr::Cloud)]) {
        let render = |sun: Vec3, transmit: f32| {
            let mut r = TreeRenderer::new(&ctx);
            r.lighting = Lighting::for_sun(sun, 20.0);
            r.leaf_transmit = transmit;
            r.light_parts = sylva::render::sky_light::LightParts::ALL;
            r.render_pack(&ctx, &pack, repr, PackView::Side, [SIZE, SIZE], BG)
        };
        let Some(off) = render(behind, 0.0) else {
            assert!(matches!(name, "impostor" | "cloud"), "the fixture has no {name}");
            continue;
        };
        drawn += 1;
        let background = off[..4].to_vec();
        let mask: Vec<bool> =
            off.chunks(4).map(|p| p.iter().zip(&background).take(3).any(|(a, b)| a.abs_diff(*b) > 2)).collect();
        let on = render(behind, 0.3).expect("drawn once");
        let (b_off, n) = tree_brightness(&off, &mask);
        let (b_on, _) = tree_brightness(&on, &mask);
        let back = b_on / b_off;
        let (f_off, _) = tree_brightness(&render(in_front, 0.0).expect("drawn once"), &mask);
        let (f_on, _) = tree_brightness(&render(in_front, 0.3).expect("drawn once"), &mask);
        let front = f_on / f_off;
        rows.push(format!(
            "{name:10}: {n} px; back-lit {b_off:.1} -> {b_on:.1} (x{back:.3}); front-lit {f_off:.1} -> {f_on:.1} (x{front:.3})"
        ));
        if n < 300 {
            failures.push(format!("{name}: the tree covers {n} pixels"));
        }
        if !(1.05..2.0).contains(&back) {
            failures.push(format!("{name}: back-lit leaves that transmit are x{back:.3} as bright (want 1.05–2)"));
        }
        if !(0.6..0.99).contains(&front) {
            failures.push(format!("{name}: front-lit leaves that transmit are x{front:.3} as bright (want 0.6–0.99)"));
        }
    }
    println!("{}", rows.join("\n"));
    assert!(drawn >= 4, "only {drawn} levels drawn");
    assert!(failures.is_empty(), "{}\n{}", failures.join("\n"), rows.join("\n"));
}
