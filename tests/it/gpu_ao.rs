//! Each tree's own ambient occlusion, baked into its pack (`bake-tool/src/pack/ao.rs`)
//! and sampled by every level of detail: with it on, the tree is darker inside its
//! crown by about as much at every level (mesh, simplified mesh, ellipsoids and
//! lines, billboards), and the image metric between a level and the full mesh is
//! no worse than without it. Fixture packs: `make fixtures`.

use sylva::format::decode_pack;
use sylva::format::pack::{ao_from_snorm8, kind};
use sylva::metrics::multiscale_rmse;
use sylva::render::capture::{PackRepr, PackView, TreeRenderer};
use sylva::render::GpuContext;

use crate::common::tree_brightness;

const SPECIES: [&str; 3] = ["beech", "birch", "spruce"];
const SIZE: u32 = 128;
const BG: [f64; 4] = [0.62, 0.74, 0.86, 1.0];

#[test]
fn occlusion_darkens_every_level_alike() {
    let ctx = GpuContext::new_headless_blocking().expect("a GPU adapter (install mesa-vulkan-drivers for lavapipe)");
    // One renderer with the trees' own occlusion and one without, for every image.
    let with_ao = TreeRenderer::new(&ctx);
    let mut without_ao = TreeRenderer::new(&ctx);
    without_ao.ao = false;
    let mut rows = Vec::new();
    let mut failures = Vec::new();
    for species in SPECIES {
        let path = format!("{}/tests/fixtures/forest-small/species/{species}.pack", env!("CARGO_MANIFEST_DIR"));
        let bytes = std::fs::read(&path).expect("fixture pack (make fixtures)");
        let pack = decode_pack(&path, &bytes).expect("fixture pack decodes");
        // Baked: the vertices carry occlusion, the billboards their array.
        let baked: Vec<f32> = pack.mesh_vertices(0).iter().map(|v| ao_from_snorm8(v.normal_oct[2])).collect();
        assert!(baked.iter().any(|&v| v < 0.5), "{species}: no vertex is occluded (baked without AO?)");
        assert!(pack.section(kind::BILLBOARD_AO, 0).is_some(), "{species}: no billboard occlusion");
        let clusters = pack.meta.clusters.as_ref().expect("cluster levels");
        // The finest cluster level drawn below the simplified mesh, as the viewer draws it.
        let mesh1_px = pack.meta.mesh_levels[1].select_px;
        let cluster =
            clusters.ellipsoid_levels.iter().position(|l| l.select_px < mesh1_px).expect("a level below mesh 1");
        let reprs = [
            ("mesh 1", PackRepr::Mesh(1)),
            ("ellipsoids", PackRepr::Cluster(cluster)),
            ("billboard", PackRepr::Billboard),
        ];
        for view in [PackView::Side, PackView::Oblique] {
            let render = |repr, ao| {
                let r = if ao { &with_ao } else { &without_ao };
                r.render_pack(&ctx, &pack, repr, view, [SIZE, SIZE], BG).expect("representation")
            };
            let background = render(PackRepr::Mesh(0), false)[..4].to_vec();
            let mask_of = |img: &[u8]| -> Vec<bool> {
                img.chunks(4).map(|p| p.iter().zip(&background).take(3).any(|(a, b)| a.abs_diff(*b) > 2)).collect()
            };
            let (mesh_on, mesh_off) = (render(PackRepr::Mesh(0), true), render(PackRepr::Mesh(0), false));
            let mesh_mask = mask_of(&mesh_off);
            let (on, n) = tree_brightness(&mesh_on, &mesh_mask);
            let (off, _) = tree_brightness(&mesh_off, &mesh_mask);
            let mesh_ratio = on / off;
            assert!(n > 500, "{species} {view:?}: the tree covers {n} pixels");
            assert!(mesh_ratio < 0.95, "{species} {view:?}: occlusion darkens the full mesh only to {mesh_ratio:.3}");
            for (name, repr) in reprs {
                let (img_on, img_off) = (render(repr, true), render(repr, false));
                let mask = mask_of(&img_off);
                let ratio = tree_brightness(&img_on, &mask).0 / tree_brightness(&img_off, &mask).0;
                let e_on = multiscale_rmse(&img_on, &mesh_on, SIZE, SIZE);
                let e_off = multiscale_rmse(&img_off, &mesh_off, SIZE, SIZE);
                rows.push(format!(
                    "{species:6} {view:8?} {name:10}: darkened to {ratio:.3} (full mesh {mesh_ratio:.3}); error against the full mesh {e_on:.4} with, {e_off:.4} without"
                ));
                if (ratio - mesh_ratio).abs() >= 0.05 {
                    failures.push(format!(
                        "{species} {view:?} {name}: darkened to {ratio:.3}, the full mesh to {mesh_ratio:.3}"
                    ));
                }
                if e_on > e_off * 1.1 + 0.002 {
                    failures.push(format!(
                        "{species} {view:?} {name}: occlusion pushes the level away from the mesh: {e_on:.4} vs {e_off:.4}"
                    ));
                }
            }
        }
    }
    println!("{}", rows.join("\n"));
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
