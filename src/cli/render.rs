//! `sylva render`: a scene or one pack, headless, to a PNG with stats.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use sylva::camera::Camera;
use sylva::format::decode_pack;
use sylva::render::capture::{render_pack_repr, PackRepr, PackView};
use sylva::render::forest::{PoolConfig, RenderSettings};
use sylva::render::offscreen::{NamedView, OffscreenScene};
use sylva::render::GpuContext;
use sylva::scene::imagery::{ImageryChoice, XyzSource};
use sylva::scene::StreamEvent;

use super::args::*;

#[allow(clippy::too_many_arguments)]
pub(crate) fn render_scene(
    scene: &str,
    out: &PathBuf,
    (w, h): (u32, u32),
    view: SceneView,
    camera: Option<&str>,
    settings: RenderSettings,
    imagery: ImageryChoice,
    stats_path: Option<&PathBuf>,
    timeout: f64,
    allow_partial: bool,
) -> Result<()> {
    let mut off = OffscreenScene::open(scene, w, h, PoolConfig::default())?;
    off.settings = settings;
    off.stream.set_imagery(imagery);
    // The manifest first: the named views are derived from its bounds.
    let mut events = off.load_view(&Camera::default(), timeout);
    let manifest = match off.stream.manifest() {
        Some(m) => m.clone(),
        None => {
            let why = events.iter().find_map(|e| match e {
                StreamEvent::Fatal { message } => Some(message.clone()),
                _ => None,
            });
            bail!("cannot load the scene {scene}: {}", why.unwrap_or_else(|| "timed out".into()));
        }
    };
    let cam = match camera {
        Some(text) => parse_camera(text, manifest.origin_m)?,
        None => {
            let named = match view {
                SceneView::Far => NamedView::Far,
                SceneView::Medium => NamedView::Medium,
                SceneView::Close => NamedView::Close,
                SceneView::Top => NamedView::Top,
            };
            off.named_camera(named, timeout).context("the scene manifest is not loaded")?
        }
    };
    let t = std::time::Instant::now();
    events.extend(off.load_view(&cam, timeout));
    let load_s = t.elapsed().as_secs_f64();
    for e in &events {
        if let StreamEvent::Failed { url, message, retrying } = e {
            eprintln!("warning: {message}{}", if *retrying { " (retrying)" } else { "" });
            let _ = url;
        }
    }
    let settled = off.stream.is_settled();
    // A first frame warms pipelines and caches; the second is measured.
    off.render(&cam, false);
    let stats = off.render(&cam, true);
    let rgba = off.read_image();
    image::save_buffer(out, &rgba, w, h, image::ColorType::Rgba8)
        .with_context(|| format!("cannot write {}", out.display()))?;
    let json = serde_json::to_string_pretty(&stats)?;
    if let Some(p) = stats_path {
        std::fs::write(p, format!("{json}\n")).with_context(|| format!("cannot write {}", p.display()))?;
    }
    eprintln!(
        "wrote {} ({w}x{h}) on {}: {} draw calls, instances {:?}, {} tiles resident, {:.1} MB fetched (loaded in {load_s:.1} s)",
        out.display(),
        off.ctx.adapter_summary(),
        stats.draw_calls,
        stats.instances,
        stats.tiles_resident,
        stats.bytes_fetched as f64 / 1e6
    );
    // What could be drawn is drawn; a render that lacks part of its view fails
    // (unless --allow-partial), so a script does not publish it unawares.
    let mut missing = Vec::new();
    if !settled {
        missing.push(format!("not everything the view needs arrived within --timeout {timeout} s"));
    }
    if !stats.failed.is_empty() {
        // (The list holds at most 64; the stream counts them all.)
        let failed = off.stream.stats().broken;
        let shown: Vec<String> = stats.failed.iter().take(5).map(|f| f.url.clone()).collect();
        missing.push(format!(
            "{failed} file{} could not be loaded ({}{})",
            if failed == 1 { "" } else { "s" },
            shown.join(", "),
            if failed as usize > shown.len() { ", …" } else { "" }
        ));
    }
    if !missing.is_empty() {
        let what = missing.join("; ");
        if allow_partial {
            eprintln!("warning: the render is incomplete: {what} (accepted: --allow-partial)");
        } else {
            bail!(
                "the render is incomplete: {what}. {} shows the rest and the stats list the failures; pass \
                 --allow-partial to accept an incomplete render",
                out.display()
            );
        }
    }
    Ok(())
}

/// `sylva render`: `--scene` to a PNG with stats, or `--pack` (one tree).
pub(crate) fn render(args: RenderArgs) -> Result<()> {
    let RenderArgs {
        scene,
        pack,
        out,
        size,
        view,
        camera,
        quality,
        draw_distance,
        debug_lod,
        only,
        ellipsoid_min_px,
        exact_depth,
        thin_px,
        debug_bounds,
        no_terrain,
        imagery,
        imagery_max_zoom,
        no_imagery,
        stats,
        timeout,
        allow_partial,
        pack_view,
        level,
        repr,
    } = args;
    let (w, h) = parse_size(&size)?;
    if !(quality > 0.0 && quality <= 16.0) {
        bail!("--quality {quality}: must be in (0, 16]");
    }
    if ellipsoid_min_px.is_nan() || ellipsoid_min_px < 0.0 {
        bail!("--ellipsoid-min-px {ellipsoid_min_px}: must be ≥ 0 (inf turns ellipsoids off)");
    }
    check_thin_px(thin_px)?;
    let imagery = match (imagery, no_imagery) {
        (_, true) => ImageryChoice::Off,
        (Some(t), false) => {
            ImageryChoice::Xyz(XyzSource::new(&t, imagery_max_zoom).map_err(|e| anyhow::anyhow!("--imagery: {e}"))?)
        }
        (None, false) => ImageryChoice::Scene,
    };
    if let Some(scene) = scene {
        use sylva::render::forest::Representations;
        let settings = RenderSettings {
            quality,
            draw_distance_m: draw_distance,
            debug_lod,
            debug_bounds,
            cluster_min_px: ellipsoid_min_px,
            cluster_exact_depth: exact_depth,
            thin_px,
            terrain: !no_terrain,
            representations: match only {
                None => Representations::ALL,
                Some(OnlyArg::Meshes) => Representations::MESHES,
                Some(OnlyArg::Ellipsoids) => Representations::CLUSTERS,
                Some(OnlyArg::Billboards) => Representations::BILLBOARDS,
            },
            ..RenderSettings::default()
        };
        return render_scene(
            &scene,
            &out,
            (w, h),
            view,
            camera.as_deref(),
            settings,
            imagery,
            stats.as_ref(),
            timeout,
            allow_partial,
        );
    }
    let pack = pack.expect("clap requires --scene or --pack");
    let bytes = std::fs::read(&pack).with_context(|| format!("cannot read {}", pack.display()))?;
    let decoded = decode_pack(&pack.display().to_string(), &bytes)?;
    let repr = match repr {
        PackReprArg::Mesh => {
            if level >= decoded.meta.mesh_levels.len() {
                bail!("--level {level}: the pack has {} mesh levels", decoded.meta.mesh_levels.len());
            }
            PackRepr::Mesh(level)
        }
        PackReprArg::Ellipsoids => {
            let n = decoded.meta.clusters.as_ref().map_or(0, |c| c.ellipsoid_levels.len());
            if level >= n {
                bail!("--level {level}: the pack has {n} cluster levels");
            }
            PackRepr::Cluster(level)
        }
        PackReprArg::Billboard => {
            if decoded.meta.billboards.is_none() {
                bail!("the pack has no billboards");
            }
            PackRepr::Billboard
        }
    };
    let gpu = GpuContext::new_headless_blocking()?;
    let view = match pack_view {
        View::Side => PackView::Side,
        View::Oblique => PackView::Oblique,
        View::Top => PackView::Top,
    };
    let rgba = render_pack_repr(&gpu, &decoded, repr, view, w, h, [0.62, 0.74, 0.86, 1.0])
        .context("the pack lacks that representation")?;
    image::save_buffer(&out, &rgba, w, h, image::ColorType::Rgba8)
        .with_context(|| format!("cannot write {}", out.display()))?;
    eprintln!("wrote {} ({w}x{h}, {} on {})", out.display(), decoded.meta.name, gpu.adapter_summary());
    Ok(())
}
