//! Every struct shared between Rust and WGSL has the same members at the same
//! offsets, and the same size: the composed WGSL is reflected with naga and
//! compared with the Rust types (`offset_of!`, `size_of`). A field added,
//! renamed or moved on one side only fails here, not as garbage on the GPU.

use std::mem::{offset_of, size_of};

use sylva::format::tile::GpuBatch;
use sylva::render::gpu_data::{
    CullDispatch, DrawArgs, DrawParams, GpuMaterial, GpuSpecies, MeshUniform, SkyUniform, ViewUniform,
};

/// The composed `shader` (`shaders::ALL`), parsed by naga.
fn parse(shader: &str) -> naga::Module {
    let source = sylva::render::shaders::ALL.iter().find(|(n, _)| *n == shader).expect("shader").1.source();
    naga::front::wgsl::parse_str(&source).expect("valid WGSL")
}

/// A WGSL struct of the composed `shader`: its members (name, byte offset) and size.
fn wgsl_struct(shader: &str, name: &str) -> (Vec<(String, u32)>, u32) {
    let module = parse(shader);
    // Layouts as WGSL computes them (naga's `Layouter`, as wgpu uses).
    let mut layouter = naga::proc::Layouter::default();
    layouter.update(module.to_ctx()).expect("layout");
    let (handle, ty) = module.types.iter().find(|(_, t)| t.name.as_deref() == Some(name)).expect("struct in WGSL");
    let naga::TypeInner::Struct { members, span } = &ty.inner else { panic!("{name} is no struct") };
    assert_eq!(layouter[handle].size, *span);
    (members.iter().map(|m| (m.name.clone().unwrap_or_default(), m.offset)).collect(), *span)
}

/// Checks `name` in WGSL against the Rust members `(name, offset)` and size.
/// `rust_size` may exceed the WGSL size only by trailing padding up to `padded_to`.
fn check(shader: &str, name: &str, rust: &[(&str, usize)], rust_size: usize, padded_to: Option<usize>) {
    let (wgsl, wgsl_size) = wgsl_struct(shader, name);
    let wgsl: Vec<(&str, usize)> = wgsl.iter().map(|(n, o)| (n.as_str(), *o as usize)).collect();
    assert_eq!(wgsl, rust, "{name}: members (name, offset) of WGSL vs Rust");
    match padded_to {
        None => assert_eq!(wgsl_size as usize, rust_size, "{name}: size"),
        Some(p) => assert!(
            wgsl_size as usize <= rust_size && rust_size == p,
            "{name}: {wgsl_size} B in WGSL, {rust_size} B in Rust"
        ),
    }
}

macro_rules! members {
    ($t:ty: $($f:ident),* $(,)?) => { [$((stringify!($f), offset_of!($t, $f))),*] };
}

#[test]
fn the_terrain_structs_match_their_wgsl_twins() {
    use sylva::render::terrain::{GpuTerrainDraw, TerrainParams};
    check(
        "terrain",
        "TerrainDraw",
        &members!(GpuTerrainDraw: origin_m, slot, size_m, range_m, morph, skirt_m, image_uv, layer, across_x, across_y, pad2, image_across),
        size_of::<GpuTerrainDraw>(),
        None,
    );
    check(
        "terrain",
        "TerrainParams",
        &members!(TerrainParams: grid, words, threshold_px, debug),
        size_of::<TerrainParams>(),
        None,
    );
}

#[test]
fn the_canopy_raster_matches_its_wgsl_twin() {
    use sylva::render::canopy::GpuCanopyRaster;
    check(
        "canopy",
        "CanopyRaster",
        &members!(GpuCanopyRaster: origin_m, size_m, cells, z_min, z_span, height_max, slot, stand_in, tallest_ratio),
        size_of::<GpuCanopyRaster>(),
        None,
    );
}

#[test]
fn shared_structs_match_their_wgsl_twins() {
    // Every pass composes shaders/layout.wgsl: check in each where the struct is used.
    for shader in ["cull", "mesh", "billboard", "cluster"] {
        check(
            shader,
            "View",
            &members!(ViewUniform: clip_from_eye, eye_hi, eye_lo, frustum, sun_dir, sun_color, ambient, lod, params, eye_from_clip, viewport,
                shadow_from_eye, shadow_texel, shadow, canopy, sky),
            size_of::<ViewUniform>(),
            None,
        );
        check(
            shader,
            "Sky",
            &members!(SkyUniform: sh, perez, zenith, sun, rayleigh, mie, air, parts),
            size_of::<SkyUniform>(),
            None,
        );
        check(
            shader,
            "Batch",
            &members!(GpuBatch: origin_m, instance_offset, center_m, radius_m, half_extent_m, instance_count, species,
                xy_step_m, z_step_m, scale_min, scale_log2_step, max_height_m, flags, crown),
            size_of::<GpuBatch>(),
            None,
        );
        check(
            shader,
            "Species",
            &members!(GpuSpecies: sphere, select, lower_px, slot_base, slot_cap, index_count),
            size_of::<GpuSpecies>(),
            None,
        );
        // Bound with a dynamic offset: the Rust struct pads to wgpu's 256-byte alignment
        // (the padding is one trailing member, `pad`, after the WGSL members).
        check(
            shader,
            "DrawParams",
            &members!(DrawParams: ids, bb_center, bb_size, cluster, cluster_noise, bounds_min, bounds_extent, line_color, ao_field_min, ao_field_size, season),
            size_of::<DrawParams>(),
            Some(256),
        );
    }
}

#[test]
fn mesh_pass_structs_and_indirect_args_match() {
    check(
        "mesh",
        "MeshParams",
        &members!(MeshUniform: pos_min, pos_extent, uv_min, uv_extent, cloud),
        size_of::<MeshUniform>(),
        None,
    );
    check(
        "mesh",
        "Material",
        &members!(GpuMaterial: base_color, alpha_cutoff, layer, kind, coverage),
        size_of::<GpuMaterial>(),
        None,
    );
    assert_eq!(offset_of!(DrawParams, pad), 176, "DrawParams: the padding follows the WGSL members");
    // The cull pass writes indirect arguments as atomic words (no WGSL struct to
    // reflect): the Rust twin must have wgpu's layout.
    use wgpu::util::DrawIndexedIndirectArgs as W;
    assert_eq!(
        [
            offset_of!(DrawArgs, count),
            offset_of!(DrawArgs, instance_count),
            offset_of!(DrawArgs, first),
            offset_of!(DrawArgs, base_vertex_or_first_instance),
            offset_of!(DrawArgs, first_instance),
            size_of::<DrawArgs>()
        ],
        [
            offset_of!(W, index_count),
            offset_of!(W, instance_count),
            offset_of!(W, first_index),
            offset_of!(W, base_vertex),
            offset_of!(W, first_instance),
            size_of::<W>()
        ]
    );
}

/// Bytes of the global variable `name` of the composed `shader`.
fn wgsl_global_size(shader: &str, name: &str) -> u32 {
    let module = parse(shader);
    let mut layouter = naga::proc::Layouter::default();
    layouter.update(module.to_ctx()).expect("layout");
    let (_, var) = module.global_variables.iter().find(|(_, v)| v.name.as_deref() == Some(name)).expect("global");
    layouter[var.ty].size
}

/// The value of the `u32` constant `name` of the composed `shader`.
fn wgsl_const(shader: &str, name: &str) -> usize {
    let module = parse(shader);
    let (_, c) = module.constants.iter().find(|(_, c)| c.name.as_deref() == Some(name)).expect("constant");
    match module.global_expressions[c.init] {
        naga::Expression::Literal(naga::Literal::U32(v)) => v as usize,
        ref other => panic!("{name} is {other:?}"),
    }
}

#[test]
fn the_cull_counter_and_argument_words_match() {
    // `control` and `args` are arrays of atomic words in WGSL: their word
    // indices are named constants there, compared with the Rust twins here.
    use sylva::render::gpu_data::CullControl;
    let word = |bytes: usize| bytes / size_of::<u32>();
    assert_eq!(wgsl_const("cull", "CONTROL_WORDS"), word(size_of::<CullControl>()));
    assert_eq!(wgsl_const("cull", "CONTROL_BATCHES_VISIBLE"), word(offset_of!(CullControl, batches_visible)));
    assert_eq!(wgsl_const("cull", "CONTROL_INSTANCES_TESTED"), word(offset_of!(CullControl, instances_tested)));
    assert_eq!(wgsl_const("cull", "CONTROL_ITEMS_DROPPED"), word(offset_of!(CullControl, items_dropped)));
    assert_eq!(wgsl_const("cull", "ARGS_WORDS"), word(size_of::<DrawArgs>()));
    assert_eq!(wgsl_const("cull", "ARGS_INSTANCE_COUNT"), word(offset_of!(DrawArgs, instance_count)));
    assert_eq!(wgsl_const("cull", "DISPATCH_BOUNDS_DRAW"), word(offset_of!(CullDispatch, bounds_draw)));
    // Batch flags and the crown-aspect bits the shaders decode.
    use sylva::format::tile::{BATCH_CROWN_ASPECT, BATCH_DENSITY_ORDERED};
    assert_eq!(wgsl_const("cull", "BATCH_DENSITY_ORDERED"), BATCH_DENSITY_ORDERED as usize);
    assert_eq!(wgsl_const("cull", "BATCH_CROWN_ASPECT"), BATCH_CROWN_ASPECT as usize);
    assert_eq!(wgsl_const("cull", "BATCH_PARTIAL"), sylva::format::tile::BATCH_PARTIAL as usize);
    assert_eq!(wgsl_const("cull", "PARTIAL_COUNT_SHIFT"), sylva::format::tile::PARTIAL_COUNT_SHIFT as usize);
    // The ground images' side, which the terrain's blend across image edges measures texels by.
    assert_eq!(wgsl_const("terrain", "IMAGE_TEXELS"), sylva::scene::imagery::IMAGE_PX as usize);
}

#[test]
fn the_cull_dispatch_words_match() {
    // `prepare_dispatch` writes `array<u32, 8>`: the dispatch, then the bounds
    // overlay's non-indexed indirect draw at word 4.
    assert_eq!(wgsl_global_size("cull", "dispatch_args") as usize, size_of::<CullDispatch>());
    assert_eq!(CullDispatch::BOUNDS_DRAW_OFFSET, 16);
    assert_eq!(size_of::<[u32; 4]>(), size_of::<wgpu::util::DrawIndirectArgs>());
}

#[test]
fn a_moved_member_is_caught() {
    // The check itself must fail on a wrong offset (here: two members swapped).
    let mut wrong = members!(GpuBatch: origin_m, instance_offset, center_m, radius_m, half_extent_m, instance_count,
        species, xy_step_m, z_step_m, scale_min, scale_log2_step, max_height_m, flags, crown);
    wrong.swap(12, 13);
    let caught = std::panic::catch_unwind(|| check("cull", "Batch", &wrong, size_of::<GpuBatch>(), None));
    let message = caught.expect_err("a swapped pair of members went unnoticed");
    let text = message.downcast_ref::<String>().map_or("", String::as_str);
    assert!(text.contains("Batch: members (name, offset)"), "failed for another reason: {text}");
}

#[test]
fn the_tracer_structs_match_their_wgsl_twins() {
    use sylva::render::trace::{GpuHit, ProbeRay};
    use sylva::trace::bvh::{BvhNode, GpuTriangle};
    let shader = "trace_probe";
    check(shader, "BvhNode", &members!(BvhNode: min, first, max, count), size_of::<BvhNode>(), None);
    check(
        shader,
        "TraceTriangle",
        &members!(GpuTriangle: v0, id, e1, material, e2, color, uv),
        size_of::<GpuTriangle>(),
        None,
    );
    check(shader, "TraceHit", &members!(GpuHit: t, triangle, u, v, index), size_of::<GpuHit>(), None);
    check(shader, "ProbeRay", &members!(ProbeRay: origin, t_max, dir, pad), size_of::<ProbeRay>(), None);
}

#[test]
fn the_tracer_scene_structs_match_their_wgsl_twins() {
    use sylva::render::trace::{GpuSceneHit, GpuTraceParams};
    use sylva::trace::scene::{GpuInstance, GpuSpeciesBvh, GpuTraceMaterial};
    let shader = "trace_scene_probe";
    check(
        shader,
        "TraceInstance",
        &members!(GpuInstance: position, yaw, scale_xy, scale_z, species, id),
        size_of::<GpuInstance>(),
        None,
    );
    check(
        shader,
        "TraceSpecies",
        &members!(GpuSpeciesBvh: node_base, tri_base, node_count, material_base, uv_min, uv_extent),
        size_of::<GpuSpeciesBvh>(),
        None,
    );
    check(
        shader,
        "TraceMaterial",
        &members!(GpuTraceMaterial: base_color, alpha_cutoff, texel_base, size, kind),
        size_of::<GpuTraceMaterial>(),
        None,
    );
    check(
        shader,
        "TraceParams",
        &members!(GpuTraceParams: top_base, instance_count, pad0, pad1),
        size_of::<GpuTraceParams>(),
        None,
    );
    check(shader, "SceneHit", &members!(GpuSceneHit: instance, slot, hit), size_of::<GpuSceneHit>(), None);
}

#[test]
fn the_path_tracer_params_match_their_wgsl_twin() {
    use sylva::render::path_trace::PathParams;
    check(
        "path_trace",
        "PathParams",
        &members!(PathParams: forward, right, up, sun_dir, sun_color, sky_zenith, sky_horizon, ground, ambient, width, height,
            sample, samples, bounces, simple, leaf_transmit, eye_z, origin, env, sampling, sky),
        size_of::<PathParams>(),
        None,
    );
}
