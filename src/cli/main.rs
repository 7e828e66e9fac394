//! `sylva`: the native command line of the Sylva renderer. One function per
//! subcommand: `render` ([`render`]), `bench` and `bench-table` ([`bench`]),
//! `compare` and `serve` (here); flags in [`args`].

#[cfg(not(target_arch = "wasm32"))]
mod args;
#[cfg(not(target_arch = "wasm32"))]
mod bench;
#[cfg(not(target_arch = "wasm32"))]
mod render;

#[cfg(not(target_arch = "wasm32"))]
mod cli {
    use std::path::PathBuf;

    use anyhow::{bail, Context, Result};
    use clap::Parser;

    use super::args::*;
    use super::bench::*;
    use super::render::*;

    /// `sylva compare`: the multi-scale RMSE of two PNGs.
    fn compare(a: &PathBuf, b: &PathBuf, stretch: bool, foliage: bool) -> Result<()> {
        let load =
            |p: &PathBuf| image::open(p).with_context(|| format!("cannot read {}", p.display())).map(|i| i.to_rgba8());
        let (ia, mut ib) = (load(a)?, load(b)?);
        if stretch && ia.dimensions() != ib.dimensions() {
            let (w, h) = ia.dimensions();
            ib = image::imageops::resize(&ib, w, h, image::imageops::FilterType::Triangle);
        }
        if ia.dimensions() != ib.dimensions() {
            bail!(
                "{} is {:?} but {} is {:?}: sizes must match",
                a.display(),
                ia.dimensions(),
                b.display(),
                ib.dimensions()
            );
        }
        let (w, h) = ia.dimensions();
        if foliage {
            let (iou, na, nb) = sylva::metrics::foliage_iou(ia.as_raw(), ib.as_raw());
            println!("foliage IoU {iou:.4} ({na} and {nb} foliage pixels of {})", w * h);
            return Ok(());
        }
        println!("{:.6}", sylva::metrics::multiscale_rmse(ia.as_raw(), ib.as_raw(), w, h));
        Ok(())
    }

    /// `sylva serve`: the viewer and a scene over HTTP until the process ends.
    fn serve(
        dir: PathBuf,
        port: u16,
        bind: &str,
        web: Option<PathBuf>,
        config: impl FnOnce(PathBuf, PathBuf) -> sylva::serve::ServeConfig,
    ) -> Result<()> {
        // A scene, or a 3D Tiles export of one (`sylva-bake export-3dtiles`) for web/cesium.html.
        let tileset = dir.join("tileset.json").is_file();
        if !dir.join("scene.json").is_file() && !tileset {
            bail!(
                "{} has no scene.json: not a Sylva scene directory (bake one with sylva-bake), nor a 3D Tiles export (no tileset.json)",
                dir.display()
            );
        }
        let web = web.unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("web"));
        if !web.join("pkg").join("sylva_bg.wasm").is_file() {
            bail!("{} has no built viewer (pkg/sylva_bg.wasm): run `make web` first", web.display());
        }
        let mut config = config(web, dir);
        if config
            .adopt_policy_file()
            .map_err(|e| anyhow::anyhow!("{e}: fix it, or give --allow-embed/--allow-source"))?
        {
            println!("embedding as the viewer folder's sylva-embed.json says");
        }
        let embedding = if config.embed_parents.is_empty() {
            "only pages served here may show it in a frame (--allow-embed ORIGIN adds a portal)".to_string()
        } else {
            format!("pages of {} may show it in a frame and drive it", config.embed_parents.join(", "))
        };
        sylva::serve::serve(config, &format!("{bind}:{port}"), |addr| {
            if tileset {
                println!("serving the 3D Tiles export in CesiumJS on http://{addr}/cesium.html (tileset at /scene/tileset.json)");
            }
            println!("serving the Sylva viewer on http://{addr}/");
            println!("{embedding}");
            use std::io::Write as _;
            let _ = std::io::stdout().flush();
        })
        .with_context(|| format!("cannot listen on {bind}:{port}"))?;
        Ok(())
    }

    pub fn main() -> Result<()> {
        sylva::render::context::ensure_runtime_dir();
        match Cli::parse().command {
            Command::Bench { out, replot: true, path, size, .. } => replot(&out, &path, &size),
            Command::Bench { scene, out, memory: true, .. } => memory(&scene, &out),
            Command::Bench { scene, out, trace: true, rays, .. } => trace(&scene, &out, rays as usize),
            Command::Bench { scene, path, size, frames, out, stress: true, save_frames, pool_trees, .. } => {
                stress(&scene, &path, &size, frames, &out, save_frames, pool_trees)
            }
            Command::Bench {
                scene,
                path,
                methods,
                size,
                frames,
                out,
                fade_band,
                thin_px,
                shadows,
                ao,
                light_parts,
                turbidity,
                season,
                save_frames,
                reference_supersample,
                reference,
                trace_spp,
                trace_reach,
                ..
            } => {
                if !(0.0..0.5).contains(&fade_band) {
                    bail!("--fade-band {fade_band}: must be in [0, 0.5)");
                }
                check_thin_px(thin_px)?;
                let mut methods = sylva::bench::methods(&methods, shadows)?;
                for m in &mut methods {
                    m.settings.ao = ao;
                    m.settings.season = season;
                    m.settings.turbidity = turbidity;
                    // The methods that name their own parts (sylva-light-…) keep them.
                    if !m.name.starts_with("sylva-light-") {
                        m.settings.light_parts = light_parts;
                    }
                }
                for m in methods.iter_mut() {
                    if m.reference.is_some() {
                        m.settings.fade_band = fade_band;
                        m.settings.thin_px = thin_px;
                    } else {
                        m.supersample = reference_supersample;
                    }
                }
                let traced = (reference == ReferenceArg::PathTraced).then_some(sylva::bench::TracedReference {
                    spp: trace_spp,
                    bounces: 2,
                    reach_m: trace_reach,
                    turbidity,
                    raster_parts: light_parts,
                });
                bench(&scene, &path, methods, &size, frames, &out, save_frames, traced)
            }
            Command::BenchTable { dirs, method } => bench_table(&dirs, &method),
            Command::Compare { a, b, stretch, foliage } => compare(&a, &b, stretch, foliage),
            Command::Query { scene, filter, limit, date } => {
                let filter: serde_json::Value =
                    serde_json::from_str(&filter).map_err(|e| anyhow::anyhow!("--filter is not JSON: {e}"))?;
                let found = sylva::scene::query::query_dir_at(&scene, &filter, limit, date.as_deref())
                    .map_err(|e| anyhow::anyhow!("{}: {e}", scene.display()))?;
                println!("{}", serde_json::to_string_pretty(&found.to_json())?);
                Ok(())
            }
            Command::Serve { dir, port, bind, web, allow_hosts, allow_embed, allow_source } => {
                let config = |web, dir| sylva::serve::ServeConfig {
                    allowed_hosts: allow_hosts,
                    embed_parents: allow_embed,
                    embed_sources: allow_source,
                    ..sylva::serve::ServeConfig::new(web, dir)
                };
                serve(dir, port, &bind, web, config)
            }
            Command::Render(args) => render(*args),
            Command::Pick(args) => pick(args),
        }
    }
}

#[cfg(not(target_arch = "wasm32"))]
fn main() {
    if let Err(e) = cli::main() {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

#[cfg(target_arch = "wasm32")]
fn main() {}
