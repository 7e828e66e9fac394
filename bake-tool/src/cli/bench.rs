//! `sylva-bake bench-clusters`: the cluster bake of one model, timed.

use std::time::Instant;

use anyhow::{bail, Result};
use sylva_bake::input::gltf_import::Classifier;
use sylva_bake::pack::PackOptions;

use super::*;

pub(crate) fn bench_clusters(model: Option<&std::path::Path>, leaves: Option<usize>, tries: usize) -> Result<()> {
    let model = match (model, leaves) {
        (Some(p), _) => sylva_bake::input::gltf_import::import(p, &Classifier::default())?,
        (None, Some(n)) => sylva_bake::demo::tree_with_leaves(n, 1),
        (None, None) => bail!("give --model or --leaves"),
    };
    let (leaf_tris, branch_tris) = model.triangle_counts();
    log(&format!("model: {leaf_tris} leaf + {branch_tris} branch triangles"));
    let gpu = sylva::render::GpuContext::new_headless_blocking()?;
    let pipelines = sylva::render::capture::CapturePipelines::new(&gpu.device, wgpu::TextureFormat::Rgba8UnormSrgb);
    let opts = PackOptions { cluster_tries: tries, ..PackOptions::default() };
    let no_clusters = PackOptions { clusters: false, ..opts.clone() };
    let t0 = Instant::now();
    sylva_bake::pack::build_pack("bench", &model, &no_clusters, &gpu, &pipelines, &log)?;
    let without = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let built = sylva_bake::pack::build_pack("bench", &model, &opts, &gpu, &pipelines, &log)?;
    let with = t1.elapsed().as_secs_f64();
    let decoded = sylva::format::decode_pack("bench", &built.bytes)?;
    let summary = sylva_bake::inspect::pack_summary(&decoded, built.bytes.len() as u64);
    let levels: Vec<_> = summary["levels"]
        .as_array()
        .into_iter()
        .flatten()
        .filter(|l| matches!(l["kind"].as_str(), Some("ellipsoids" | "lines")))
        .cloned()
        .collect();
    let out = serde_json::json!({
        "leaf_triangles": leaf_tris,
        "branch_triangles": branch_tris,
        "cluster_seconds": with - without,
        "pack_seconds": with,
        "threads": rayon::current_num_threads(),
        "adapter": gpu.adapter_summary(),
        "levels": levels,
    });
    println!("{}", serde_json::to_string_pretty(&out)?);
    Ok(())
}
