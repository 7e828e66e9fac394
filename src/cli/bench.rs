//! `sylva bench` (paths, stress, memory, replot) and `sylva bench-table`.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use sylva::camera::Camera;
use sylva::offscreen::OffscreenScene;
use sylva::render::forest::{PoolConfig, RenderSettings};
use sylva::scene::StreamEvent;

use super::args::*;

/// The cameras of `--path` over `scene`: a named path laid over the scene's
/// bounds (the ground found at its centre) or a JSON keyframe file.
pub(crate) fn path_cameras(scene: &str, path: &str, frames: usize) -> Result<Vec<Camera>> {
    use sylva::bench::{self as b, NamedPath};
    if frames < 2 {
        bail!("--frames {frames}: need at least 2");
    }
    // The manifest gives the bounds the named paths are laid over.
    let mut probe = OffscreenScene::open(scene, 16, 16, PoolConfig::default())
        .map_err(|e| anyhow::anyhow!("{e}"))
        .with_context(|| format!("opening {scene}"))?;
    for e in probe.load_manifest(120.0) {
        if let StreamEvent::Fatal { message } = e {
            bail!("{scene}: {message}");
        }
    }
    let manifest = probe.stream.manifest().context("the scene manifest did not load in 120 s")?.clone();
    // The ground at the centre, for the paths that go down to eye height.
    let lo = glam::DVec3::from(manifest.bounds.min.map(f64::from));
    let hi = glam::DVec3::from(manifest.bounds.max.map(f64::from));
    let c = (lo + hi) * 0.5;
    let down = Camera {
        eye_m: glam::DVec3::new(c.x, c.y, hi.z + 300.0),
        pitch_rad: -std::f64::consts::FRAC_PI_2,
        ..Camera::default()
    };
    probe.load_view(&down, 120.0);
    let ground = probe.stream.ground_height_at(c.x as f32, c.y as f32).map(f64::from);
    drop(probe);
    let (keys, frames) = match path {
        "flyover" => (b::named_path(NamedPath::Flyover, &manifest, ground), frames),
        "far" => (b::named_path(NamedPath::Far, &manifest, ground), frames),
        "medium" => (b::named_path(NamedPath::Medium, &manifest, ground), frames),
        "close" => (b::named_path(NamedPath::Close, &manifest, ground), frames),
        file => {
            let text = std::fs::read_to_string(file)
                .with_context(|| format!("--path {file}: not flyover|far|medium|close and not a readable file"))?;
            let p: b::PathFile =
                serde_json::from_str(&text).with_context(|| format!("{file}: not a path file (see --help)"))?;
            if p.keyframes.len() < 2 {
                bail!("{file}: a path needs at least two keyframes");
            }
            if p.keyframes.iter().any(|k| !k.eye.iter().chain([&k.heading_deg, &k.pitch_deg]).all(|v| v.is_finite())) {
                bail!("{file}: keyframes must be finite numbers");
            }
            let n = p.frames.unwrap_or(frames).max(2);
            (p.keyframes, n)
        }
    };
    Ok(b::interpolate(&keys, frames))
}

#[allow(clippy::too_many_arguments)]
pub(crate) fn bench(
    scene: &str,
    path: &str,
    methods: Vec<sylva::bench::Method>,
    size: &str,
    frames: usize,
    out: &std::path::Path,
    save_frames: bool,
    traced: Option<sylva::bench::TracedReference>,
) -> Result<()> {
    use sylva::bench as b;
    let (w, h) = parse_size(size)?;
    // WebGPU's default texture limit bounds the supersampled targets.
    let ss = methods.iter().map(|m| m.supersample.max(1)).max().unwrap_or(1);
    if w.max(h) * ss > 8192 {
        bail!("--size {w}x{h} at {ss}× supersampling needs {} px a side; the most is 8192", w.max(h) * ss);
    }
    let cameras = path_cameras(scene, path, frames)?;
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let total = (methods.len() + usize::from(traced.is_some())) * cameras.len();
    let started = std::time::Instant::now();
    let mut done = 0usize;
    let frames_dir = out.join("frames");
    if save_frames {
        std::fs::create_dir_all(&frames_dir).with_context(|| format!("cannot create {}", frames_dir.display()))?;
    }
    let frames_at = save_frames.then_some(frames_dir.as_path());
    let run = b::run(scene, &cameras, &methods, w, h, frames_at, traced, &mut |m, i, n| {
        done += 1;
        let eta = started.elapsed().as_secs_f64() / done as f64 * (total - done) as f64;
        let bar = "#".repeat(done * 30 / total.max(1));
        eprint!("\r[{bar:<30}] {done}/{total} {m} frame {}/{n}, ~{eta:.0} s left   ", i + 1);
    })?;
    eprintln!();
    b::write_csv(out, &run.frames)?;
    let summary = serde_json::json!({
        "scene": scene,
        "path": path,
        "size": [w, h],
        "frames": cameras.len(),
        "adapter": run.adapter,
        "reference_supersample": methods.iter().find(|m| m.reference.is_none()).map_or(2, |m| m.supersample),
        "methods": run.summary,
        "path_traced": traced.map(|t| serde_json::json!({
            "spp": t.spp,
            "bounces": t.bounces,
            "reach_m": t.reach_m,
            "turbidity": t.turbidity,
            "methods": b::summarise_traced(&run.traced).into_iter().collect::<std::collections::BTreeMap<_, _>>(),
        })),
    });
    std::fs::write(out.join("summary.json"), serde_json::to_string_pretty(&summary)?)?;
    b::write_plots(out, &run, &format!("{path}, {w}x{h}"))?;
    eprintln!("{:<14} {:>9} {:>9} {:>9} {:>9} {:>10}", "method", "gpu ms", "cpu ms", "ms-rmse", "flip", "t. noise");
    for (name, m) in &run.summary {
        eprintln!(
            "{name:<14} {:>9.2} {:>9.3} {:>9.4} {:>9.4} {:>10.5}",
            m.gpu_ms.median, m.cpu_ms.median, m.error.median, m.flip.median, m.temporal_noise.median
        );
    }
    if traced.is_some() {
        b::write_traced_csv(out, &run.traced)?;
        eprintln!("against the path-traced reference (ms-rmse; geometry: against the trace under the raster's light):");
        eprintln!("{:<26} {:>9} {:>9} {:>9} {:>9} {:>9}", "method", "ms-rmse", "flip", "geometry", "light", "iou");
        for (name, m) in b::summarise_traced(&run.traced) {
            eprintln!(
                "{name:<26} {:>9.4} {:>9.4} {:>9.4} {:>9.4} {:>9.4}",
                m.error.median, m.flip.median, m.geometry_error.median, m.light_error.median, m.foliage_iou.median
            );
        }
    }
    eprintln!("wrote frames.csv, summary.json, pareto.svg, frame_time.svg, temporal_noise.svg to {}", out.display());
    Ok(())
}

pub(crate) fn stress(
    scene: &str,
    path: &str,
    size: &str,
    frames: usize,
    out: &std::path::Path,
    save_frames: bool,
    pool_trees: Option<u32>,
) -> Result<()> {
    use sylva::bench::stress;
    use sylva::render::forest::PoolConfig;
    let (w, h) = parse_size(size)?;
    // The path once at 200 frames, then forwards and back for --frames.
    let pass = path_cameras(scene, path, 200)?;
    let period = 2 * (pass.len() - 1);
    let cameras = stress::ping_pong(&pass, frames.max(2));
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let started = std::time::Instant::now();
    let frames_dir = out.join("frames");
    let holes = save_frames.then_some(stress::HoleCheck { dir: frames_dir.as_path(), every: 10 });
    let pools = pool_trees.map_or_else(PoolConfig::default, |n| PoolConfig { instances: n, ..PoolConfig::default() });
    let (records, summary) =
        stress::run(scene, &cameras, period, (w, h), (RenderSettings::default(), pools), holes, &mut |i, n| {
            if i % 50 == 0 || i + 1 == n {
                let done = (i + 1) as f64;
                let eta = started.elapsed().as_secs_f64() / done * (n as f64 - done);
                let bar = "#".repeat((i + 1) * 30 / n.max(1));
                eprint!("\r[{bar:<30}] frame {}/{n}, ~{eta:.0} s left   ", i + 1);
            }
        })?;
    eprintln!();
    stress::write(out, &records, &summary)?;
    let mb = |b: u64| b as f64 / 1e6;
    eprintln!(
        "{} frames: GPU ms median {:.2} over the second pass, {:.2} over the last; RSS median {:.0} MB over the second pass, {:.0} MB over the last (max {:.0} MB, end {:.0} MB); GPU {:.0} MB max; up to {} of {} trees resident; {:.1} MB fetched; {} non-finite frames",
        summary.frames,
        summary.gpu_ms_first.median,
        summary.gpu_ms_last.median,
        summary.rss_first.median / 1e6,
        summary.rss_last.median / 1e6,
        mb(summary.rss_max),
        mb(summary.rss_end),
        mb(summary.gpu_bytes_max),
        summary.trees_resident_max,
        summary.trees_total,
        mb(summary.bytes_fetched),
        summary.non_finite_frames
    );
    if save_frames {
        eprintln!(
            "holes (streamed frame lighter than settled where the settled one is covered): at most {:.2} % of the pixels over {} frames of the first pass (darker: at most {:.2} %); frames in {}",
            summary.hole_fraction_max * 100.0,
            summary.holes.len(),
            summary.holes.iter().map(|f| f.darker * 100.0).fold(0.0, f64::max),
            frames_dir.display()
        );
    }
    eprintln!(
        "pools: full in {} frames (reach shortened), {} tile trims to fewer prefix levels",
        summary.pools_full_frames, summary.tiles_trimmed
    );
    eprintln!("wrote stress.csv and stress.json to {}", out.display());
    if !summary.passed {
        bail!("stress run failed: the median resident set grew more than 10 % from the second pass to the last, frame time grew more than 25 %, or a frame was not finite");
    }
    Ok(())
}

/// `sylva bench-table`: one Markdown row per bench output directory.
pub(crate) fn bench_table(dirs: &[PathBuf], method: &str) -> Result<()> {
    println!("| run | GPU ms | cull ms | MS-RMSE | FLIP | temporal noise | draw calls | batches | packs MB |");
    println!("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |");
    for d in dirs {
        let p = d.join("summary.json");
        let text = std::fs::read_to_string(&p).with_context(|| format!("cannot read {}", p.display()))?;
        let v: serde_json::Value = serde_json::from_str(&text).with_context(|| format!("{}: not JSON", p.display()))?;
        let m = &v["methods"][&method];
        if m.is_null() {
            bail!("{}: no method {method:?}", p.display());
        }
        let med = |k: &str| m[k]["median"].as_f64().unwrap_or(f64::NAN);
        // The scene's batches and pack bytes, where it is a local directory.
        let scene = std::path::PathBuf::from(v["scene"].as_str().unwrap_or_default());
        let (batches, packs) = sylva::paths::read_regular(&scene.join("scene.json"), None, 1 << 26)
            .ok()
            .and_then(|b| sylva::format::Manifest::decode("scene.json", &b).ok())
            .map_or((String::from("?"), String::from("?")), |man| {
                let bytes: u64 = man
                    .species
                    .iter()
                    .filter_map(|s| std::fs::metadata(scene.join(&s.pack)).ok())
                    .map(|md| md.len())
                    .sum();
                (man.counts.batches.to_string(), format!("{:.2}", bytes as f64 / 1e6))
            });
        // Median cull ms from frames.csv.
        let cull = sylva::bench::read_csv(&d.join("frames.csv")).map_or(f64::NAN, |frames| {
            sylva::bench::Stat::of(frames.iter().filter(|r| r.method == method).map(|r| r.cull_ms)).median
        });
        println!(
            "| {} | {:.2} | {:.2} | {:.4} | {:.4} | {:.5} | {:.0} | {batches} | {packs} |",
            d.display(),
            med("gpu_ms"),
            cull,
            med("error"),
            med("flip"),
            med("temporal_noise"),
            med("draw_calls")
        );
    }
    Ok(())
}

/// `sylva bench --replot`: redraws the plots of an earlier run from its frames.csv.
pub(crate) fn replot(out: &std::path::Path, path: &str, size: &str) -> Result<()> {
    let frames = sylva::bench::read_csv(&out.join("frames.csv"))?;
    let mut names: Vec<String> = Vec::new();
    for f in &frames {
        if !names.contains(&f.method) {
            names.push(f.method.clone());
        }
    }
    let run = sylva::bench::BenchRun {
        summary: sylva::bench::summarise(&frames, &names),
        frames,
        traced: Vec::new(),
        adapter: String::new(),
    };
    sylva::bench::write_plots(out, &run, &format!("{path}, {size}"))?;
    eprintln!("redrew the plots in {}", out.display());
    Ok(())
}

/// `sylva bench --trace`: the tracer's BVH per species and rays per second.
pub(crate) fn trace(scene: &str, out: &std::path::Path, rays: usize) -> Result<()> {
    let r = sylva::bench::trace::measure(std::path::Path::new(&scene), rays)?;
    print!("{}", sylva::bench::trace::report(&r));
    std::fs::create_dir_all(out)?;
    std::fs::write(out.join("trace.json"), serde_json::to_string_pretty(&r)?)?;
    eprintln!("wrote {}", out.join("trace.json").display());
    Ok(())
}

/// `sylva bench --memory`: bytes per tree on disk, compressed and on the GPU.
pub(crate) fn memory(scene: &str, out: &std::path::Path) -> Result<()> {
    let m = sylva::bench::memory::measure(std::path::Path::new(&scene))?;
    print!("{}", sylva::bench::memory::report(&m));
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    std::fs::write(out.join("memory.json"), serde_json::to_string_pretty(&m)?)?;
    eprintln!("wrote {}", out.join("memory.json").display());
    Ok(())
}
