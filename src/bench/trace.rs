//! `sylva bench --trace`: the path tracer's bottom level on each species' full
//! mesh (issue 48) — the BVH's build time and shape, and rays per second
//! through it on one CPU core (the twin, `trace::bvh`) and on the GPU (the
//! WGSL walk, `render::trace`), with the two's hits compared.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use glam::Vec3;
use serde::Serialize;

use crate::format::pack::decode_pack;
use crate::format::Manifest;
use crate::render::trace::TraceProbe;
use crate::render::GpuContext;
use crate::trace::bvh::{mesh_triangles, Bvh};
use crate::trace::Ray;

/// One species' figures.
#[derive(Debug, Clone, Serialize)]
pub struct SpeciesTrace {
    /// Species name.
    pub name: String,
    /// Triangles of its full mesh.
    pub triangles: usize,
    /// BVH nodes.
    pub nodes: usize,
    /// The deepest leaf.
    pub depth: u32,
    /// BVH bytes as the GPU holds them (nodes and triangles).
    pub bytes: usize,
    /// Build time on one core (ms).
    pub build_ms: f64,
    /// Rays traced.
    pub rays: usize,
    /// Rays that hit the tree.
    pub hits: usize,
    /// Nearest hits per second on one CPU core.
    pub cpu_rays_per_s: f64,
    /// Nearest hits per second on the GPU (one dispatch, waited for).
    pub gpu_rays_per_s: f64,
    /// Rays whose GPU hit differs from the CPU's (a different triangle, or
    /// distances further apart than rounding).
    pub differ: usize,
}

/// The figures of every species of a scene.
#[derive(Debug, Clone, Serialize)]
pub struct TraceReport {
    /// The adapter the GPU figures are of.
    pub adapter: String,
    /// Per species.
    pub species: Vec<SpeciesTrace>,
}

/// `n` rays from around the box `min..max` (up to its size away) towards
/// random points inside it (a fixed sequence: xorshift32 from `seed`).
#[must_use]
pub fn rays_at(min: Vec3, max: Vec3, n: usize, seed: u32) -> Vec<Ray> {
    let mut rng = crate::trace::Xorshift32(seed.max(1));
    let mut unit = move || rng.unit();
    let size = max - min;
    (0..n)
        .map(|_| {
            let origin = min - size + Vec3::new(unit(), unit(), unit()) * size * 3.0;
            let target = min + Vec3::new(unit(), unit(), unit()) * size;
            Ray { origin, dir: target - origin, t_max: 4.0 }
        })
        .collect()
}

/// Measures every species pack of the scene in `dir` with `rays` rays each.
///
/// # Errors
/// Unreadable scene or packs, or no GPU adapter.
pub fn measure(dir: &Path, rays: usize) -> Result<TraceReport> {
    let read = |rel: &str| -> Result<Vec<u8>> {
        let p = dir.join(rel);
        crate::paths::read_regular(&p, None, crate::paths::MAX_SCENE_FILE_BYTES)
            .with_context(|| format!("cannot read {}", p.display()))
    };
    let m = Manifest::decode("scene.json", &read("scene.json")?).map_err(|e| anyhow::anyhow!("{e}"))?;
    let ctx = GpuContext::new_headless_blocking()?;
    let probe = TraceProbe::new(&ctx.device);
    let mut species = Vec::new();
    for s in &m.species {
        let bytes = crate::format::stored::unstore(&s.pack, read(&s.pack)?).map_err(|e| anyhow::anyhow!("{e}"))?;
        let pack = decode_pack(&s.pack, &bytes).map_err(|e| anyhow::anyhow!("{e}"))?;
        let Some(level) = pack.meta.mesh_levels.first() else { continue };
        let tris = mesh_triangles(level, &pack.mesh_vertices(0), &pack.mesh_indices(0));
        let t = Instant::now();
        let bvh = Bvh::build(&tris);
        let build_ms = t.elapsed().as_secs_f64() * 1e3;
        let list = rays_at(pack.meta.bounds_min.into(), pack.meta.bounds_max.into(), rays, 0x5eed_1234);
        let t = Instant::now();
        let cpu: Vec<_> = list.iter().map(|r| bvh.intersect(r)).collect();
        let cpu_s = t.elapsed().as_secs_f64();
        // A first dispatch compiles and warms what the timed one uses.
        let _ = probe.trace(&ctx, &bvh, &list[..list.len().min(64)]);
        let t = Instant::now();
        let gpu = probe.trace(&ctx, &bvh, &list);
        let gpu_s = t.elapsed().as_secs_f64();
        let differ = cpu
            .iter()
            .zip(&gpu)
            .filter(|(c, g)| match (c, g) {
                (None, None) => false,
                (Some(c), Some(g)) => c.triangle != g.triangle || (c.t - g.t).abs() > 1e-5 * c.t.max(1.0),
                _ => true,
            })
            .count();
        species.push(SpeciesTrace {
            name: s.name.clone(),
            triangles: tris.len(),
            nodes: bvh.nodes.len(),
            depth: bvh.depth(),
            bytes: std::mem::size_of_val(&bvh.nodes[..]) + std::mem::size_of_val(&bvh.triangles[..]),
            build_ms,
            rays: list.len(),
            hits: cpu.iter().flatten().count(),
            cpu_rays_per_s: list.len() as f64 / cpu_s.max(1e-9),
            gpu_rays_per_s: list.len() as f64 / gpu_s.max(1e-9),
            differ,
        });
    }
    Ok(TraceReport { adapter: ctx.adapter_summary(), species })
}

/// The report as a table.
#[must_use]
pub fn report(r: &TraceReport) -> String {
    let mut out = format!(
        "BVH per species and rays per second (nearest hit; GPU: {})\n\
         species          triangles    nodes depth   KB  build ms   hits   CPU rays/s (1 core)   GPU rays/s  differ\n",
        r.adapter
    );
    for s in &r.species {
        out += &format!(
            "{:<16} {:>9} {:>8} {:>5} {:>4} {:>9.1} {:>6} {:>21.0} {:>12.0} {:>7}\n",
            s.name,
            s.triangles,
            s.nodes,
            s.depth,
            s.bytes / 1024,
            s.build_ms,
            s.hits,
            s.cpu_rays_per_s,
            s.gpu_rays_per_s,
            s.differ
        );
    }
    out
}
