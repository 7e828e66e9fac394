//! `sylva render`: a scene or one pack, headless, to a PNG with stats.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use sylva::camera::Camera;
use sylva::format::decode_pack;
use sylva::offscreen::{NamedView, OffscreenScene};
use sylva::render::capture::{PackRepr, PackView, TreeRenderer};
use sylva::render::forest::{PoolConfig, RenderSettings};
use sylva::render::refine::RefineConfig;
use sylva::render::GpuContext;
use sylva::scene::imagery::{ImageryChoice, XyzSource};
use sylva::scene::StreamEvent;

use super::args::*;

#[allow(clippy::too_many_arguments)]
pub(crate) fn render_scene(
    scene: &str,
    out: &std::path::Path,
    (w, h): (u32, u32),
    view: SceneView,
    camera: Option<&str>,
    settings: RenderSettings,
    imagery: ImageryChoice,
    sun: &SunArg,
    stats_path: Option<&PathBuf>,
    timeout: f64,
    allow_partial: bool,
    refine: RefineConfig,
    (style, select): (Option<&str>, &[String]),
    date: Option<&str>,
    path: Option<PathTraceArgs>,
) -> Result<()> {
    let mut off = OffscreenScene::open(scene, w, h, PoolConfig::default())?;
    off.settings = settings;
    off.stream.set_imagery(imagery);
    // The manifest first: the named views are derived from its bounds.
    let mut events = off.load_manifest(timeout);
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
    if let Some(text) = date {
        let (d, _) = sylva::render::settings::SeasonDate::at_scene(&manifest, text)
            .map_err(|e| anyhow::anyhow!("--date: {e}"))?;
        off.settings.date = Some(d);
        // A scene with a timeline: the trees standing then, at their size then.
        off.set_day(sylva::format::attributes::parse_date(text));
    }
    if let Some(text) = style {
        let value: serde_json::Value =
            serde_json::from_str(text).map_err(|e| anyhow::anyhow!("--style is not JSON: {e}"))?;
        let species: Vec<String> = manifest.species.iter().map(|s| s.name.clone()).collect();
        let compiled = sylva::scene::style::TreeStyle::parse(manifest.attributes.as_ref(), &species, &value)
            .map_err(|e| anyhow::anyhow!("--style: {e}"))?;
        let legend = compiled.legend_json();
        if let Some(entries) = legend["entries"].as_array().filter(|e| !e.is_empty()) {
            let shown: Vec<String> = entries
                .iter()
                .map(|e| format!("{} {}", e["color"].as_str().unwrap_or(""), e["label"].as_str().unwrap_or("")))
                .collect();
            eprintln!("legend ({}): {}", legend["title"].as_str().unwrap_or(""), shown.join(", "));
        }
        off.set_style(Some(compiled));
    }
    if !select.is_empty() {
        // (A text that is a number as a bake writes it selects that number: `set_selection`.)
        off.select(select.iter().map(|s| sylva::scene::style::TreeId::Text(s.clone())));
    }
    let cam = scene_camera(&mut off, &manifest, view, camera, timeout)?;
    if let Some(path) = path {
        let suns = sun_lighting(sun, &manifest, off.settings.lighting)?;
        return path_trace(&off.ctx, scene, out, (w, h), &cam, &suns, &path, stats_path);
    }
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
    // The sun (one image per time of a shadow study).
    let suns = sun_lighting(sun, &manifest, off.settings.lighting)?;
    let several = suns.len() > 1;
    let mut stats = None;
    for (label, lighting) in suns {
        off.settings.lighting = lighting;
        // A first frame warms pipelines and caches; the second is measured.
        off.render(&cam, false);
        let s = if refine.enabled {
            let (mut s, total) = off.render_converged(&cam, refine, 8 * refine.total_steps(), timeout);
            if !s.refine_converged {
                eprintln!(
                    "warning: the refinement did not converge within --timeout {timeout} s (data kept arriving); \
                     writing step {}",
                    s.refine_step
                );
            }
            if off.refine.dropped() {
                eprintln!(
                    "warning: quality level {} drew more trees than the pools hold: the image stops at level {}",
                    s.refine_level + 1,
                    s.refine_level
                );
            }
            eprintln!(
                "refined in {} steps to quality level {}: {:.1} ms of GPU time in all",
                s.refine_step,
                s.refine_level,
                total.values().sum::<f64>()
            );
            s.gpu_ms = total;
            s
        } else {
            off.render(&cam, true)
        };
        let rgba = off.read_image();
        let path = if several { suffixed(out, &label) } else { out.to_path_buf() };
        image::save_buffer(&path, &rgba, w, h, image::ColorType::Rgba8)
            .with_context(|| format!("cannot write {}", path.display()))?;
        if several || !label.is_empty() {
            eprintln!("{}: {label}", path.display());
        }
        // The stats with the camera rendered, as `--camera` takes it (a named
        // view's camera, to render it again or elsewhere: web/bench-cesium.mjs).
        let mut value = serde_json::to_value(&s)?;
        let o = manifest.origin_m;
        value["camera"] = serde_json::Value::String(format!(
            "{},{},{},{},{}",
            cam.eye_m.x + o[0],
            cam.eye_m.y + o[1],
            cam.eye_m.z + o[2],
            cam.heading_rad.to_degrees(),
            cam.pitch_rad.to_degrees()
        ));
        let json = serde_json::to_string_pretty(&value)?;
        if let Some(p) = stats_path {
            let p = if several { suffixed(p, &label) } else { p.clone() };
            std::fs::write(&p, format!("{json}\n")).with_context(|| format!("cannot write {}", p.display()))?;
        }
        stats = Some(s);
    }
    let stats = stats.context("no sun to render with")?;
    let what = if several {
        format!("{} images beside {}", sun.times.len(), out.display())
    } else {
        out.display().to_string()
    };
    eprintln!(
        "wrote {what} ({w}x{h}) on {}: {} draw calls, instances {:?}, {} tiles resident, {:.1} MB fetched (loaded in {load_s:.1} s)",
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

/// The camera of `--camera` or `--view`.
fn scene_camera(
    off: &mut OffscreenScene,
    manifest: &sylva::format::Manifest,
    view: SceneView,
    camera: Option<&str>,
    timeout: f64,
) -> Result<Camera> {
    Ok(match camera {
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
    })
}

/// The representations `--only` allows, and whether the LoD policy applies.
fn representations(only: Option<OnlyArg>) -> (sylva::render::forest::Representations, bool) {
    use sylva::render::forest::Representations;
    // `--only` draws every baked level of the family (no LoD policy).
    let r = match only {
        None => Representations::default(),
        Some(OnlyArg::Meshes) => Representations::MESHES,
        Some(OnlyArg::Ellipsoids) => Representations::CLUSTERS,
        Some(OnlyArg::Billboards) => Representations::BILLBOARDS,
        Some(OnlyArg::Clouds) => Representations::CLOUDS,
    };
    (r, only.is_none())
}

fn far_tier_of(arg: FarTierArg) -> sylva::render::settings::FarTier {
    match arg {
        FarTierArg::Impostors => sylva::render::settings::FarTier::Impostors,
        FarTierArg::Billboards => sylva::render::settings::FarTier::Billboards,
    }
}

/// `sylva pick`: the tree drawn at a pixel, as JSON on stdout.
pub(crate) fn pick(args: PickArgs) -> Result<()> {
    let (w, h) = args.frame.checked_size()?;
    let mut pixels = Vec::new();
    for at in &args.at {
        let (x, y) = at
            .split_once(',')
            .and_then(|(x, y)| Some((x.trim().parse::<u32>().ok()?, y.trim().parse::<u32>().ok()?)))
            .with_context(|| format!("--at {at:?}: expected X,Y in whole pixels, e.g. 480,300"))?;
        if x >= w || y >= h {
            bail!("--at {x},{y} is outside the {w}x{h} image (--size)");
        }
        pixels.push([x, y]);
    }
    let scene = args.scene.as_str();
    let mut off = OffscreenScene::open(scene, w, h, PoolConfig::default())?;
    let (representations, lod_policy) = representations(args.only);
    off.settings = RenderSettings {
        quality: args.frame.quality,
        draw_distance_m: args.frame.draw_distance,
        whole_tiles: args.frame.whole_tiles,
        textures: args.frame.textures.choice(),
        canopy: !args.frame.no_canopy,
        terrain: !args.no_terrain,
        far_tier: far_tier_of(args.far_tier),
        representations,
        lod_policy,
        ..RenderSettings::default()
    };
    let events = off.load_manifest(args.timeout);
    let Some(manifest) = off.stream.manifest().cloned() else {
        let why = events.iter().find_map(|e| match e {
            StreamEvent::Fatal { message } => Some(message.clone()),
            _ => None,
        });
        bail!("cannot load the scene {scene}: {}", why.unwrap_or_else(|| "timed out".into()));
    };
    if let Some(text) = &args.date {
        let (d, _) = sylva::render::settings::SeasonDate::at_scene(&manifest, text)
            .map_err(|e| anyhow::anyhow!("--date: {e}"))?;
        off.settings.date = Some(d);
        // A scene with a timeline: the trees standing then, at their size then.
        off.set_day(sylva::format::attributes::parse_date(text));
    }
    let cam = scene_camera(&mut off, &manifest, args.frame.view, args.frame.camera.as_deref(), args.timeout)?;
    off.load_view(&cam, args.timeout);
    if !off.stream.is_settled() {
        eprintln!("warning: not everything the view needs arrived within --timeout {} s", args.timeout);
    }
    // The frame the user would click on, finished (its GPU time is not the pick's).
    off.render(&cam, true);
    let geo = sylva::geo::GeoFrame::for_scene(&manifest.crs, manifest.origin_m).ok();
    let view = cam.view_data(w, h);
    let mut answers = Vec::new();
    for &[x, y] in &pixels {
        let t = std::time::Instant::now();
        let instance = off.pick_blocking(&view, [x, y]);
        let gpu_ms = t.elapsed().as_secs_f64() * 1e3;
        let located = instance.and_then(|i| off.stream.locate_instance(i));
        let answer = match &located {
            None => serde_json::Value::Null,
            Some(tree) => {
                let read = |url: &str| sylva::scene::fetch::fetch_once(url).map_err(|e| anyhow::anyhow!("{e}"));
                let (tile, ids) = (read(&tree.tile_url)?, read(&tree.ids_url)?);
                let attr = match manifest.attributes {
                    Some(_) => Some(read(&tree.attributes_url)?),
                    None => None,
                };
                let files = [tree.tile_url.as_str(), tree.ids_url.as_str(), tree.attributes_url.as_str()];
                sylva::scene::query::describe_tree(
                    &manifest,
                    geo.as_ref(),
                    [&tile, &ids],
                    attr.as_deref(),
                    files,
                    tree.index,
                )
                .map_err(|e| anyhow::anyhow!("{e}"))?
            }
        };
        let total_ms = t.elapsed().as_secs_f64() * 1e3;
        eprintln!(
            "picked {x},{y} of {w}x{h}: {} (cull and id pass {gpu_ms:.1} ms, with the tree's files {total_ms:.1} ms)",
            match &located {
                Some(t) => format!("tree {} of {}", t.index, t.tile_url),
                None => "no tree".into(),
            }
        );
        answers.push(answer);
    }
    if let Some(out) = &args.out {
        off.render(&cam, false);
        let mut rgba = off.read_image();
        // A red cross, 9 px, centred on each pixel picked.
        for &[x, y] in &pixels {
            for d in -4i64..=4 {
                for (px, py) in [(i64::from(x) + d, i64::from(y)), (i64::from(x), i64::from(y) + d)] {
                    if (0..i64::from(w)).contains(&px) && (0..i64::from(h)).contains(&py) {
                        let k = ((py as usize) * w as usize + px as usize) * 4;
                        rgba[k..k + 4].copy_from_slice(&[255, 0, 0, 255]);
                    }
                }
            }
        }
        image::save_buffer(out, &rgba, w, h, image::ColorType::Rgba8)
            .with_context(|| format!("cannot write {}", out.display()))?;
    }
    let json = if answers.len() == 1 { answers.remove(0) } else { serde_json::Value::Array(answers) };
    println!("{}", serde_json::to_string_pretty(&json)?);
    Ok(())
}

/// How `--sun-time` / `--sun` set the light.
#[derive(Debug, Clone, Default)]
pub(crate) struct SunArg {
    /// Local times of the scene's place (several: a shadow study).
    pub times: Vec<sylva::sun::SunTime>,
    /// Azimuth and elevation, degrees.
    pub angles: Option<(f64, f64)>,
}

impl SunArg {
    /// From the flags' text.
    pub(crate) fn parse(times: Option<&str>, angles: Option<&str>) -> Result<Self> {
        let times = match times {
            Some(t) => t
                .split(',')
                .map(|t| sylva::sun::SunTime::parse(t).map_err(|e| anyhow::anyhow!("--sun-time: {e}")))
                .collect::<Result<_>>()?,
            None => Vec::new(),
        };
        let angles = match angles {
            Some(a) => {
                let v: Vec<f64> =
                    a.split(',').map(|x| x.trim().parse::<f64>()).collect::<Result<_, _>>().map_err(|_| {
                        anyhow::anyhow!("--sun {a:?}: expected AZIMUTH,ELEVATION in degrees (e.g. 225,35)")
                    })?;
                match v[..] {
                    [az, el] if az.is_finite() && (-90.0..=90.0).contains(&el) => Some((az, el)),
                    _ => bail!("--sun {a:?}: expected AZIMUTH,ELEVATION in degrees, elevation −90–90 (e.g. 225,35)"),
                }
            }
            None => None,
        };
        Ok(Self { times, angles })
    }
}

/// The lights to render with, each with a label (the time or the angles;
/// empty for the default light).
fn sun_lighting(
    sun: &SunArg,
    m: &sylva::format::Manifest,
    default: sylva::render::Lighting,
) -> Result<Vec<(String, sylva::render::Lighting)>> {
    if sun.times.is_empty() && sun.angles.is_none() {
        return Ok(vec![(String::new(), default)]);
    }
    let geo =
        sylva::geo::GeoFrame::for_scene(&m.crs, m.origin_m).map_err(|e| anyhow::anyhow!("--sun-time/--sun: {e}"))?;
    let centre = sylva::render::Lighting::sun_point(m);
    if let Some((az, el)) = sun.angles {
        let l = sylva::render::Lighting::at_angles(&geo, centre, az, el).map_err(|e| anyhow::anyhow!("--sun: {e}"))?;
        return Ok(vec![(format!("sun azimuth {az:.1}°, elevation {el:.1}°"), l)]);
    }
    sun.times
        .iter()
        .map(|t| {
            let (l, p) =
                sylva::render::Lighting::at_time(&geo, centre, t).map_err(|e| anyhow::anyhow!("--sun-time: {e}"))?;
            let (lon, _) = geo.to_geo(centre).map(|(lon, lat, _)| (lon, lat)).unwrap_or((0.0, 0.0));
            let off = t.offset_min(lon);
            Ok((
                format!(
                    "{:04}-{:02}-{:02}T{:02}{:02}{}{:02}{:02}: sun azimuth {:.1}°, elevation {:.1}°",
                    t.year,
                    t.month,
                    t.day,
                    t.hour,
                    t.minute,
                    if off < 0 { '-' } else { '+' },
                    off.abs() / 60,
                    off.abs() % 60,
                    p.azimuth_deg,
                    p.elevation_deg
                ),
                l,
            ))
        })
        .collect()
}

/// `out.png` + label `2026-06-21T1500+0200: …` → `out-2026-06-21T1500.png`.
fn suffixed(path: &std::path::Path, label: &str) -> PathBuf {
    let tag: String = label.chars().take(15).filter(|c| c.is_ascii_alphanumeric() || *c == '-').collect();
    let stem = path.file_stem().map_or_else(String::new, |s| s.to_string_lossy().into_owned());
    let ext = path.extension().map_or_else(String::new, |e| format!(".{}", e.to_string_lossy()));
    path.with_file_name(format!("{stem}-{tag}{ext}"))
}

/// `sylva render`: `--scene` to a PNG with stats, or `--pack` (one tree).
pub(crate) fn render(args: RenderArgs) -> Result<()> {
    let RenderArgs {
        far_tier,
        moving_impostors,
        scene,
        pack,
        out,
        frame,
        debug_lod,
        debug_cascades,
        only,
        ellipsoid_min_px,
        exact_depth,
        thin_px,
        debug_bounds,
        no_terrain,
        imagery,
        imagery_max_zoom,
        no_imagery,
        sun_time,
        sun,
        shadows,
        ao,
        converge,
        converge_frames,
        converge_levels,
        style,
        select,
        stats,
        timeout,
        allow_partial,
        pack_view,
        level,
        repr,
        variant,
        season,
        date,
        full_detail,
        path_trace,
        spp,
        bounces,
        light,
        reach,
        turbidity,
        light_parts,
        environment,
        environment_scale,
        pixel_centres,
        top_level,
    } = args;
    let (w, h) = frame.checked_size()?;
    let ViewArgs { view, camera, quality, draw_distance, whole_tiles, no_canopy, textures, .. } = frame;
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
    if let Some(d) = &date {
        sylva::sun::SunTime::parse(&format!("{}T12:00", d.trim())).map_err(|e| {
            anyhow::anyhow!(
                "--date {d:?}: expected a date YYYY-MM-DD, e.g. 2026-10-20 ({})",
                e.split_once(": ").map_or(e.as_str(), |(_, why)| why.split(" (expected").next().unwrap_or(why))
            )
        })?;
    }
    // One control: a date moves the sun to it too (at noon) unless told otherwise.
    let sun_time = match (&date, sun_time, &sun) {
        (Some(d), None, None) => Some(format!("{}T12:00", d.trim())),
        (_, t, _) => t,
    };
    let sun = SunArg::parse(sun_time.as_deref(), sun.as_deref())?;
    if let Some(scene) = scene {
        if path_trace {
            let dir = std::path::Path::new(&scene);
            let dir = if dir.is_file() { dir.parent().unwrap_or(dir) } else { dir };
            if !dir.join("scene.json").is_file() {
                bail!("--path-trace reads a scene directory (or its scene.json), not {scene}");
            }
        }
        let (mut representations, lod_policy) = representations(only);
        let mut quality = quality;
        if full_detail {
            representations = sylva::render::settings::Representations::MESHES;
            quality = sylva::render::refine::FULL_MESH_QUALITY;
        }
        let settings = RenderSettings {
            full_res_alpha: full_detail,
            quality,
            draw_distance_m: draw_distance,
            whole_tiles,
            textures: textures.choice(),
            canopy: !no_canopy,
            debug_lod,
            debug_cascades,
            debug_bounds,
            cluster_min_px: ellipsoid_min_px,
            cluster_exact_depth: exact_depth,
            thin_px,
            terrain: !no_terrain,
            shadows,
            ao,
            far_tier: far_tier_of(far_tier),
            moving_impostors,
            lod_policy,
            representations,
            season,
            light_parts,
            turbidity,
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
            &sun,
            stats.as_ref(),
            timeout,
            allow_partial,
            RefineConfig { enabled: converge, jitter_frames: converge_frames, levels: converge_levels },
            (style.as_deref(), &select),
            date.as_deref(),
            path_trace.then_some(PathTraceArgs {
                spp,
                bounces,
                simple: light == LightArg::Raster,
                reach_m: reach,
                no_ground: no_terrain,
                turbidity,
                light_parts,
                environment_scale,
                environment,
                jitter: !pixel_centres,
                cpu_top: top_level == super::args::TopLevelArg::Cpu,
            }),
        );
    }
    let pack = pack.expect("clap requires --scene or --pack");
    let bytes = sylva::paths::read_regular(&pack, None, sylva::paths::MAX_SCENE_FILE_BYTES)
        .with_context(|| format!("cannot read {}", pack.display()))?;
    let bytes = sylva::format::stored::unstore(&pack.display().to_string(), bytes)?;
    let decoded = decode_pack(&pack.display().to_string(), &bytes)?;
    let repr = match repr {
        PackReprArg::Mesh => {
            if level >= decoded.meta.mesh_levels.len() {
                bail!("--level {level}: the pack has {} mesh levels", decoded.meta.mesh_levels.len());
            }
            let variants = decoded.meta.mesh_levels[level].variants + 1;
            if variant >= variants {
                bail!("--variant {variant}: mesh level {level} has {variants} variant(s), 0–{}", variants - 1);
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
        PackReprArg::Impostor => {
            if decoded.meta.impostors.is_none() {
                bail!("the pack has no impostors (bake it with --far-tier impostors or both)");
            }
            PackRepr::Impostor
        }
        PackReprArg::Cloud => {
            if decoded.meta.cloud.is_none() {
                bail!("the pack has no billboard cloud (bake it with --cloud-planes 64)");
            }
            PackRepr::Cloud
        }
    };
    let gpu = GpuContext::new_headless_blocking()?;
    let sampled = sylva::render::mesh::block_formats(&gpu.device);
    if let Some(e) = decoded.meta.unsampled(&sampled) {
        bail!(
            "{}: its textures are {} blocks, which this GPU ({}) does not sample; render the plain pack beside it",
            pack.display(),
            e.name(),
            gpu.adapter_summary()
        );
    }
    let view = match pack_view {
        View::Side => PackView::Side,
        View::Oblique => PackView::Oblique,
        View::Top => PackView::Top,
    };
    let mut renderer = TreeRenderer::new(&gpu);
    renderer.ao = ao;
    renderer.light_parts = light_parts;
    if variant > 0 {
        renderer.set_variant(&gpu, variant);
    }
    renderer.set_season(decoded.meta.season.as_ref(), season);
    let rgba = renderer
        .render_pack(&gpu, &decoded, repr, view, [w, h], [0.62, 0.74, 0.86, 1.0])
        .context("the pack lacks that representation")?;
    image::save_buffer(&out, &rgba, w, h, image::ColorType::Rgba8)
        .with_context(|| format!("cannot write {}", out.display()))?;
    eprintln!("wrote {} ({w}x{h}, {} on {})", out.display(), decoded.meta.name, gpu.adapter_summary());
    Ok(())
}

/// `sylva render --path-trace`'s options.
#[derive(Debug, Clone)]
pub(crate) struct PathTraceArgs {
    /// `--environment-scale`.
    pub(crate) environment_scale: f32,
    /// `--environment FILE.hdr`: the sky and the sun from an HDR map.
    pub(crate) environment: Option<PathBuf>,
    /// Not `--pixel-centres`.
    pub(crate) jitter: bool,
    /// `--top-level cpu`.
    pub(crate) cpu_top: bool,
    pub(crate) spp: u32,
    pub(crate) bounces: u32,
    pub(crate) simple: bool,
    pub(crate) reach_m: f64,
    /// `--no-terrain`: no ground plane either.
    pub(crate) no_ground: bool,
    /// The clear sky's turbidity.
    pub(crate) turbidity: f32,
    /// The raster light's parts (`--light raster` mirrors them).
    pub(crate) light_parts: sylva::render::sky_light::LightParts,
}

/// `sylva render --path-trace`: the view traced at full detail (issue 48).
#[allow(clippy::too_many_arguments)]
fn path_trace(
    ctx: &sylva::render::GpuContext,
    scene: &str,
    out: &std::path::Path,
    (w, h): (u32, u32),
    cam: &sylva::camera::Camera,
    suns: &[(String, sylva::render::Lighting)],
    args: &PathTraceArgs,
    stats_path: Option<&PathBuf>,
) -> Result<()> {
    use sylva::render::path_trace::{to_srgb8, PathOptions, PathTracer, PathView};
    let dir = std::path::Path::new(scene);
    let dir = if dir.is_file() { dir.parent().unwrap_or(dir) } else { dir };
    if !dir.join("scene.json").is_file() {
        bail!("--path-trace reads a scene directory (or its scene.json), not {scene}");
    }
    if args.environment.is_some() && args.simple {
        bail!("--environment lights the physical light; --light raster has its own sky");
    }
    let t = std::time::Instant::now();
    let (traced, report) = sylva::trace::load::load_dir(
        dir,
        cam.eye_m,
        args.reach_m,
        (!args.no_ground).then_some(PathOptions::default().ground_albedo),
    )
    .map_err(|e| anyhow::anyhow!("{e}"))?;
    let traced = if args.cpu_top {
        let t = std::time::Instant::now();
        let traced = traced.with_cpu_top();
        eprintln!("top level built on the CPU (binned SAH) in {:.3} s", t.elapsed().as_secs_f64());
        traced
    } else {
        traced
    };
    let load_s = t.elapsed().as_secs_f64();
    eprintln!(
        "tracing {} of {} trees within {} m ({:.1} M instanced triangles; species {}) and {}, {:.1} MB on the GPU, loaded in {:.1} s",
        report.trees,
        report.trees_in_scene,
        args.reach_m,
        report.instanced_triangles as f64 / 1e6,
        report.species_triangles.iter().map(|(n, t)| format!("{n} {t}")).collect::<Vec<_>>().join(", "),
        if report.terrain_triangles > 0 {
            format!("{} terrain triangles", report.terrain_triangles)
        } else if args.no_ground {
            "no ground".to_string()
        } else {
            format!("a ground plane at {:.1} m", report.ground_z)
        },
        report.bytes as f64 / 1e6,
        load_s
    );
    let environment = match &args.environment {
        Some(p) => {
            let env = sylva::trace::environment::Environment::from_file(p)
                .map_err(|e| anyhow::anyhow!("--environment: {e}"))?;
            eprintln!("environment {} ({}×{} texels, importance sampled)", p.display(), env.width, env.height);
            Some(env)
        }
        None => None,
    };
    let tracer = PathTracer::new(&ctx.device);
    let several = suns.len() > 1;
    for (label, lighting) in suns {
        // The physical light: Preetham et al.'s clear sky and the air; the
        // raster light: its parts as the raster draws them.
        // (An HDR environment is the sky and the light: no clear sky, no air from it.)
        let parts = match (args.simple, environment.is_some()) {
            (true, _) => args.light_parts,
            (false, false) => sylva::render::sky_light::LightParts::ALL,
            (false, true) => sylva::render::sky_light::LightParts::NONE,
        };
        let view = PathView::under_parts(
            lighting,
            cam.eye_m.as_vec3(),
            cam.forward().as_vec3(),
            cam.fov_y_rad,
            args.turbidity,
            parts,
        );
        let options = PathOptions {
            spp: args.spp,
            bounces: args.bounces,
            simple: args.simple,
            // The terrain where the scene has it, else a plane at the lowest tree's base.
            ground_z: (!args.no_ground && report.terrain_triangles == 0).then_some(report.ground_z),
            environment_scale: args.environment_scale,
            jitter: args.jitter,
            ..PathOptions::default()
        };
        let t = std::time::Instant::now();
        let mut last = std::time::Instant::now();
        let image = tracer
            .render(ctx, &traced, environment.as_ref(), &view, (w, h), &options, &mut |done| {
                if done == 0 && traced.top.is_empty() {
                    eprintln!("uploaded, top level built on the GPU, in {:.3} s", t.elapsed().as_secs_f64());
                } else if last.elapsed().as_secs_f64() > 5.0 {
                    eprintln!("  {done} of {} samples per pixel ({:.0} s)", args.spp, t.elapsed().as_secs_f64());
                    last = std::time::Instant::now();
                }
            })
            .map_err(|e| anyhow::anyhow!("--path-trace: {e}"))?;
        let trace_s = t.elapsed().as_secs_f64();
        let path = if several { suffixed(out, label) } else { out.to_path_buf() };
        image::save_buffer(&path, &to_srgb8(&image), w, h, image::ColorType::Rgba8)
            .with_context(|| format!("cannot write {}", path.display()))?;
        let paths = u64::from(w) * u64::from(h) * u64::from(args.spp);
        eprintln!(
            "wrote {} ({w}x{h}, {} spp, {} bounces, {} light) in {:.1} s: {:.2} M paths/s on {}",
            path.display(),
            args.spp,
            args.bounces,
            if args.simple { "raster" } else { "physical" },
            trace_s,
            paths as f64 / trace_s.max(1e-9) / 1e6,
            ctx.adapter_summary()
        );
        if let Some(p) = stats_path {
            let p = if several { suffixed(p, label) } else { p.clone() };
            let stats = serde_json::json!({
                "renderer": "path-trace",
                "trees": report.trees,
                "trees_in_scene": report.trees_in_scene,
                "instanced_triangles": report.instanced_triangles,
                "terrain_triangles": report.terrain_triangles,
                "gpu_bytes": report.bytes,
                "spp": args.spp,
                "bounces": args.bounces,
                "light": if args.simple { "raster" } else { "physical" },
                "load_s": load_s,
                "trace_s": trace_s,
                "paths_per_s": paths as f64 / trace_s.max(1e-9),
                "adapter": ctx.adapter_summary(),
            });
            std::fs::write(&p, serde_json::to_string_pretty(&stats)?)
                .with_context(|| format!("cannot write {}", p.display()))?;
        }
    }
    Ok(())
}
