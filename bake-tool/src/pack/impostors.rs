//! Multi-view impostors: the tree captured from a hemi-octahedral grid of
//! views (colour, normal and depth per view).

use glam::Vec3;
use sylva::format::pack::{kind, ImpostorMeta, Section, TextureArrayMeta};
use sylva::render::capture::capture_views;
use sylva::render::capture::CapturePipelines;
use sylva::render::impostor;
use sylva::render::mips::{alpha_aware_mips, ColorEncoding};
use sylva::render::GpuContext;

use super::*;

/// The multi-view impostors of a mesh-only pack: `grid`² orthographic views
/// over the upper hemisphere ([`impostor::capture_clip_from_model`]), each
/// framing the bounding sphere, rendered at twice the stored size through the
/// viewer's own mesh pass. Colour mips as the billboards' (alpha-aware, coverage
/// kept); the surface layer (normal, depth, occlusion and leaf flag) averaged
/// weighted by coverage. Sections with `index` (the far-tier state: 0
/// leaf-on, 1 the bare wood, captured without `leaves`); with them the texels
/// covered over every view at the capture's resolution. `variants`: the
/// mesh variants captured, each's grid² views after the previous one's.
#[allow(clippy::too_many_arguments)]
pub(super) fn build_impostors(
    gpu: &GpuContext,
    pipelines: &CapturePipelines,
    decoded: &sylva::format::Pack<'_>,
    (lo, hi): (Vec3, Vec3),
    opts: &PackOptions,
    index: u32,
    leaves: bool,
    variants: u32,
) -> (ImpostorMeta, Vec<Section>, u64) {
    let grid = opts.impostor_grid;
    let center = (lo + hi) * 0.5;
    let radius = ((hi - lo) * 0.5).length().max(1e-3) * 1.01;
    let grid_views: Vec<_> =
        (0..grid * grid).map(|l| impostor::capture_clip_from_model(center, radius, l, grid)).collect();
    let capture_size = opts.impostor_size * 2;
    let mut captured = sylva::render::capture::CapturedBillboards::default();
    for variant in 0..variants {
        captured.append(capture_views(gpu, pipelines, decoded, &grid_views, capture_size, leaves, variant));
    }

    let covered = captured.color.iter().flat_map(|c| c.chunks_exact(4)).filter(|t| t[3] > 0).count() as u64;
    let mut color_chains: Vec<Vec<Vec<u8>>> = Vec::new();
    let mut surface_chains = Vec::new();
    // Per stored mip: Σ coverage × |mean normal| and Σ coverage over all views.
    let mut spread = vec![(0.0f64, 0.0f64); opts.impostor_size.trailing_zeros() as usize + 1];
    for layer in 0..captured.color.len() {
        let color = &captured.color[layer];
        color_chains.push(
            alpha_aware_mips(color, color, capture_size, ColorEncoding::Srgb, Some(BILLBOARD_ALPHA_CUTOFF))[1..]
                .to_vec(),
        );
        // Per texel: normal xyz, depth offset (−1 … 1), occlusion, leaf (0/1),
        // averaged as such down the mips and only then encoded: averaging
        // octahedral codes would bend normals near the fold (downward ones up).
        let surface: Vec<[f32; 6]> = (0..(capture_size * capture_size) as usize)
            .map(|i| {
                let n = &captured.normal[layer][i * 4..i * 4 + 4];
                if color[i * 4 + 3] == 0 {
                    // Background: the plane, open, weighted out of every mip.
                    return [0.0, 0.0, 1.0, 0.0, 1.0, 0.0];
                }
                let normal = Vec3::new(f32::from(n[0]), f32::from(n[1]), f32::from(n[2])) / 127.5 - Vec3::ONE;
                let depth = impostor::depth_to_offset(captured.depth[layer][i]);
                let ao = f32::from(captured.ao[layer][i * 4]) / 255.0;
                [normal.x, normal.y, normal.z, depth, ao, f32::from(u8::from(n[3] > 191))]
            })
            .collect();
        let encode = |t: &[f32; 6]| {
            let e = oct_encode(Vec3::new(t[0], t[1], t[2]).normalize_or(Vec3::Z));
            let unorm = |v: i8| ((f32::from(v) / 127.0 * 0.5 + 0.5) * 255.0).round() as u8;
            let depth = ((t[3] * 0.5 + 0.5).clamp(0.0, 1.0) * 255.0).round() as u8;
            [unorm(e[0]), unorm(e[1]), depth, impostor::pack_ao_leaf(t[4], t[5] >= 0.5)]
        };
        let mips = coverage_weighted_mips(surface, color, capture_size);
        for (l, level) in mips[1..].iter().enumerate() {
            let alpha = &color_chains[layer][l];
            for (i, t) in level.iter().enumerate() {
                let a = f64::from(alpha[i * 4 + 3]) / 255.0;
                spread[l].0 += a * f64::from(Vec3::new(t[0], t[1], t[2]).length().min(1.0));
                spread[l].1 += a;
            }
        }
        surface_chains
            .push(mips[1..].iter().map(|level| level.iter().flat_map(encode).collect()).collect::<Vec<Vec<u8>>>());
    }
    // How much the normals under a texel agree, per mip (1 at full resolution
    // on one leaf; less as texels cover more leaves): the viewer shades the
    // filtered normal with it (`shade_filtered`).
    let normal_length: Vec<f32> =
        spread.iter().map(|(w, n)| if *n > 0.0 { (w / n).clamp(0.0, 1.0) as f32 } else { 1.0 }).collect();
    let texture =
        TextureArrayMeta::plain(opts.impostor_size, grid * grid * variants, opts.impostor_size.trailing_zeros() + 1);
    let sections = vec![
        Section {
            kind: kind::IMPOSTOR_COLOR,
            index,
            count: 0,
            stride: 0,
            data: mip_major(&color_chains, texture.mips),
        },
        Section {
            kind: kind::IMPOSTOR_SURFACE,
            index,
            count: 0,
            stride: 0,
            data: mip_major(&surface_chains, texture.mips),
        },
    ];
    let half_extent = Some((hi - center).max(center - lo).to_array());
    let variants = (variants > 1).then_some(variants);
    (
        ImpostorMeta { grid, texture, center: center.to_array(), radius, normal_length, half_extent, variants },
        sections,
        covered,
    )
}
