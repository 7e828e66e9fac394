//! `sylva`: the native command line of the Sylva renderer.

#[cfg(not(target_arch = "wasm32"))]
mod cli {
    use std::path::PathBuf;

    use anyhow::{bail, Context, Result};
    use clap::{Parser, Subcommand, ValueEnum};
    use glam::DVec3;
    use sylva::camera::Camera;
    use sylva::format::decode_pack;
    use sylva::render::capture::{render_pack_repr, PackRepr, PackView};
    use sylva::render::forest::{PoolConfig, RenderSettings};
    use sylva::render::offscreen::{NamedView, OffscreenScene};
    use sylva::render::GpuContext;
    use sylva::scene::StreamEvent;

    #[derive(Parser)]
    #[command(
        name = "sylva",
        version,
        about = "Sylva forest renderer: headless rendering of Sylva scenes and LoD packs."
    )]
    struct Cli {
        #[command(subcommand)]
        command: Command,
    }

    #[derive(Clone, Copy, ValueEnum)]
    enum View {
        Side,
        Oblique,
        Top,
    }

    #[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
    enum OnlyArg {
        Meshes,
        Ellipsoids,
        Billboards,
    }

    #[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
    enum PackReprArg {
        Mesh,
        Ellipsoids,
        Billboard,
    }

    #[derive(Clone, Copy, ValueEnum)]
    enum SceneView {
        Far,
        Medium,
        Close,
        Top,
    }

    #[derive(Subcommand)]
    enum Command {
        /// Render a scene (or one species pack) headless to a PNG, with stats.
        #[command(
            after_help = "Examples:\n  sylva render --scene demo-scene --view medium --out medium.png --stats medium.json\n  sylva render --scene http://127.0.0.1:8080/scene.json --camera 540000,5359700,300,0,-20 --out a.png\n  sylva render --pack demo-scene/species/beech.pack --view side --out beech.png"
        )]
        Render(RenderArgs),
        /// Run time against image error on a camera path, every method on the same
        /// frames: writes frames.csv, summary.json and SVG plots (pareto,
        /// frame_time, temporal_noise) into --out.
        #[command(
            after_help = "Methods: reference (full mesh everywhere, 2x supersampled; always run), mesh, per-tree,\n  billboard, ellipsoid, sylva, sylva-q0.5, sylva-q0.25, or all.\nPaths: flyover, far, medium, close (360° sweeps), or a JSON file\n  {\"keyframes\": [{\"eye\": [x, y, z], \"heading_deg\": 0, \"pitch_deg\": -10}, ...], \"frames\": 60}\n  in metres from the scene origin.\nExample:\n  sylva bench --scene demo-scene --path flyover --methods all --size 640x360 --out bench-out"
        )]
        Bench {
            /// Scene directory, scene.json path or http(s) URL.
            #[arg(long)]
            scene: String,
            /// Camera path: flyover, far, medium, close or PATH.json.
            #[arg(long, default_value = "flyover")]
            path: String,
            /// Comma-separated methods, or all.
            #[arg(long, default_value = "all")]
            methods: String,
            /// Image size, WxH.
            #[arg(long, default_value = "640x360")]
            size: String,
            /// Frames along the path (a path file's own count wins).
            #[arg(long, default_value_t = 48)]
            frames: usize,
            /// Output directory.
            #[arg(long)]
            out: PathBuf,
            /// Only redraw the plots from --out's frames.csv (no rendering).
            #[arg(long)]
            replot: bool,
            /// The memory model instead: bytes per tree on disk, gzip/brotli and GPU,
            /// per pack, against seed 004 eq. 4.1 (writes memory.json; --scene a directory).
            #[arg(long, conflicts_with_all = ["replot", "stress"])]
            memory: bool,
            /// The stress run instead: Sylva alone along --path, forwards and back,
            /// for --frames frames (10000 is the standard run), streaming without
            /// waiting; fails unless memory stays flat and frame time does not grow
            /// (writes stress.csv, stress.json).
            #[arg(long, conflicts_with = "replot")]
            stress: bool,
            /// Half width of the cross-fade bands for every method but the
            /// reference, as a fraction of each threshold (the fade sweep).
            #[arg(long, default_value_t = 0.12)]
            fade_band: f32,
            /// Prefix-thinning threshold (px) for every method but the reference
            /// (0: off; the thinning comparison).
            #[arg(long, default_value_t = sylva::render::forest::DEFAULT_THIN_PX)]
            thin_px: f32,
        },
        /// One table row per bench output directory (its summary.json) for one
        /// method: median GPU ms, multi-scale RMSE, FLIP, temporal noise, draw calls
        /// (the parameter sweeps: `make sweep-cell-size` and friends).
        BenchTable {
            /// Directories written by `sylva bench --out`.
            #[arg(required = true)]
            dirs: Vec<PathBuf>,
            /// Method to tabulate.
            #[arg(long, default_value = "sylva")]
            method: String,
        },
        /// Print the multi-scale RMSE (seed 002 §4, 0–1) between two images of the same size.
        Compare {
            /// First image (PNG).
            a: PathBuf,
            /// Second image (PNG).
            b: PathBuf,
        },
        /// Serve the browser viewer at / with DIR's scene as its default scene (/scene/).
        Serve {
            /// Scene directory.
            dir: PathBuf,
            /// Port (0 picks a free one).
            #[arg(long, default_value_t = 8080)]
            port: u16,
            /// Address to listen on.
            #[arg(long, default_value = "127.0.0.1")]
            bind: String,
            /// The built viewer (default: web/ of this checkout; `make web` builds it).
            #[arg(long)]
            web: Option<PathBuf>,
            /// On a loopback --bind, also answer requests for this host name
            /// (repeatable). Other names get 403: a web page cannot reach the
            /// server through DNS rebinding.
            #[arg(long = "allow-host", value_name = "NAME")]
            allow_hosts: Vec<String>,
        },
    }

    /// `sylva render`: a scene or one pack to a PNG.
    #[derive(clap::Args)]
    struct RenderArgs {
        /// Scene directory, scene.json path or http(s) URL.
        #[arg(long, conflicts_with = "pack", required_unless_present = "pack")]
        scene: Option<String>,
        /// A single LoD pack to render (one tree, lit).
        #[arg(long)]
        pack: Option<PathBuf>,
        /// Output PNG.
        #[arg(long)]
        out: PathBuf,
        /// Image size, WxH.
        #[arg(long, default_value = "960x540")]
        size: String,
        /// Named scene viewpoint (ignored with --camera).
        #[arg(long, value_enum, default_value_t = SceneView::Medium)]
        view: SceneView,
        /// Camera in the scene CRS: EASTING,NORTHING,HEIGHT,HEADING_DEG,PITCH_DEG.
        #[arg(long, allow_hyphen_values = true)]
        camera: Option<String>,
        /// LoD quality factor (1, 0.5, 0.25: projected sizes are scaled by it).
        #[arg(long, default_value_t = 1.0)]
        quality: f32,
        /// Draw distance in metres.
        #[arg(long, default_value_t = 6000.0)]
        draw_distance: f32,
        /// Colour trees by representation (red mesh0, yellow mesh1, greens ellipsoid
        /// levels, blue billboard).
        #[arg(long)]
        debug_lod: bool,
        /// Draw only one representation family (the benchmark baselines); the
        /// default mixes meshes, ellipsoids and billboards by projected size.
        #[arg(long, value_enum)]
        only: Option<OnlyArg>,
        /// Trees at least this tall on screen (px), and below the simplified mesh,
        /// are drawn with ellipsoids and lines; smaller ones with billboards.
        #[arg(long, default_value_t = sylva::render::forest::DEFAULT_CLUSTER_MIN_PX)]
        ellipsoid_min_px: f32,
        /// Ellipsoids write their exact ray-cast depth per pixel (slower: no early
        /// depth tests); by default they keep their proxy's front-most depth.
        #[arg(long)]
        exact_depth: bool,
        /// Prefix thinning: far batches whose trees are below this many pixels
        /// tall draw an even subset of them, scaled up to keep the canopy's
        /// coverage (0 turns it off).
        #[arg(long, default_value_t = sylva::render::forest::DEFAULT_THIN_PX)]
        thin_px: f32,
        /// Draw the boxes of the batches that pass the batch test.
        #[arg(long)]
        debug_bounds: bool,
        /// Write frame statistics as JSON here.
        #[arg(long)]
        stats: Option<PathBuf>,
        /// Give up waiting for data after this many seconds.
        #[arg(long, default_value_t = 120.0)]
        timeout: f64,
        /// Exit 0 although files of the view failed to load or did not arrive
        /// in time (the image shows what loaded; the stats list the failures).
        /// Without it such a render writes its PNG and stats and exits 1.
        #[arg(long)]
        allow_partial: bool,
        /// Pack view (with --pack).
        #[arg(long, value_enum, default_value_t = View::Oblique)]
        pack_view: View,
        /// What to draw with --pack: mesh (level --level), ellipsoids (cluster
        /// level --level: ellipsoids + lines) or billboard.
        #[arg(long, value_enum, default_value_t = PackReprArg::Mesh)]
        repr: PackReprArg,
        /// Mesh or cluster level (with --pack).
        #[arg(long, default_value_t = 0)]
        level: usize,
    }

    /// The cameras of `--path` over `scene`: a named path laid over the scene's
    /// bounds (the ground found at its centre) or a JSON keyframe file.
    fn path_cameras(scene: &str, path: &str, frames: usize) -> Result<Vec<Camera>> {
        use sylva::bench::{self as b, NamedPath};
        if frames < 2 {
            bail!("--frames {frames}: need at least 2");
        }
        // The manifest gives the bounds the named paths are laid over.
        let mut probe = OffscreenScene::open(scene, 16, 16, PoolConfig::default())
            .map_err(|e| anyhow::anyhow!("{e}"))
            .with_context(|| format!("opening {scene}"))?;
        for e in probe.load_view(&Camera::default(), 120.0) {
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
                if p.keyframes
                    .iter()
                    .any(|k| !k.eye.iter().chain([&k.heading_deg, &k.pitch_deg]).all(|v| v.is_finite()))
                {
                    bail!("{file}: keyframes must be finite numbers");
                }
                let n = p.frames.unwrap_or(frames).max(2);
                (p.keyframes, n)
            }
        };
        Ok(b::interpolate(&keys, frames))
    }

    fn bench(
        scene: &str,
        path: &str,
        methods: Vec<sylva::bench::Method>,
        size: &str,
        frames: usize,
        out: &std::path::Path,
    ) -> Result<()> {
        use sylva::bench as b;
        let (w, h) = parse_size(size)?;
        let cameras = path_cameras(scene, path, frames)?;
        std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
        let total = methods.len() * cameras.len();
        let started = std::time::Instant::now();
        let mut done = 0usize;
        let run = b::run(scene, &cameras, &methods, w, h, &mut |m, i, n| {
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
            "methods": run.summary,
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
        eprintln!(
            "wrote frames.csv, summary.json, pareto.svg, frame_time.svg, temporal_noise.svg to {}",
            out.display()
        );
        Ok(())
    }

    /// `--thin-px` of `render` and `bench`.
    fn check_thin_px(thin_px: f32) -> Result<()> {
        if !(thin_px.is_finite() && thin_px >= 0.0) {
            bail!("--thin-px {thin_px}: must be a number of pixels ≥ 0 (0 turns thinning off)");
        }
        Ok(())
    }

    fn parse_size(s: &str) -> Result<(u32, u32)> {
        let (w, h) = s.split_once(['x', 'X']).with_context(|| format!("--size {s:?}: expected WxH, e.g. 512x512"))?;
        let (w, h): (u32, u32) = (w.trim().parse()?, h.trim().parse()?);
        if w == 0 || h == 0 || w > 8192 || h > 8192 {
            bail!("--size {s}: each side must be 1–8192 pixels");
        }
        Ok((w, h))
    }

    fn parse_camera(text: &str, origin: [f64; 3]) -> Result<Camera> {
        let v: Vec<f64> = text.split(',').map(|p| p.trim().parse::<f64>()).collect::<Result<_, _>>().map_err(|_| {
            anyhow::anyhow!("--camera {text:?}: expected EASTING,NORTHING,HEIGHT,HEADING_DEG,PITCH_DEG (numbers)")
        })?;
        if v.len() != 5 || v.iter().any(|x| !x.is_finite()) {
            bail!("--camera {text:?}: expected five finite numbers: EASTING,NORTHING,HEIGHT,HEADING_DEG,PITCH_DEG");
        }
        Ok(Camera {
            eye_m: DVec3::new(v[0] - origin[0], v[1] - origin[1], v[2] - origin[2]),
            heading_rad: v[3].to_radians(),
            pitch_rad: v[4].clamp(-90.0, 90.0).to_radians(),
            ..Camera::default()
        })
    }

    #[allow(clippy::too_many_arguments)]
    fn render_scene(
        scene: &str,
        out: &PathBuf,
        (w, h): (u32, u32),
        view: SceneView,
        camera: Option<&str>,
        settings: RenderSettings,
        stats_path: Option<&PathBuf>,
        timeout: f64,
        allow_partial: bool,
    ) -> Result<()> {
        let mut off = OffscreenScene::open(scene, w, h, PoolConfig::default())?;
        off.settings = settings;
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

    fn stress(scene: &str, path: &str, size: &str, frames: usize, out: &std::path::Path) -> Result<()> {
        use sylva::bench::stress;
        let (w, h) = parse_size(size)?;
        // The path once at 200 frames, then forwards and back for --frames.
        let pass = path_cameras(scene, path, 200)?;
        let period = 2 * (pass.len() - 1);
        let cameras = stress::ping_pong(&pass, frames.max(2));
        std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
        let started = std::time::Instant::now();
        let (records, summary) = stress::run(scene, &cameras, period, w, h, RenderSettings::default(), &mut |i, n| {
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
            "{} frames: GPU ms median {:.2} over the second pass, {:.2} over the last; RSS {:.0} MB max in the warm-up pass, max {:.0} MB, end {:.0} MB; GPU {:.0} MB max; up to {} of {} trees resident; {:.1} MB fetched; {} non-finite frames",
            summary.frames,
            summary.gpu_ms_first.median,
            summary.gpu_ms_last.median,
            mb(summary.rss_after_first),
            mb(summary.rss_max),
            mb(summary.rss_end),
            mb(summary.gpu_bytes_max),
            summary.trees_resident_max,
            summary.trees_total,
            mb(summary.bytes_fetched),
            summary.non_finite_frames
        );
        eprintln!("wrote stress.csv and stress.json to {}", out.display());
        if !summary.passed {
            bail!("stress run failed: memory grew more than 10 % after the warm-up pass, frame time grew more than 25 %, or a frame was not finite");
        }
        Ok(())
    }

    /// `sylva render`: `--scene` to a PNG with stats, or `--pack` (one tree).
    fn render(args: RenderArgs) -> Result<()> {
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

    /// `sylva bench-table`: one Markdown row per bench output directory.
    fn bench_table(dirs: &[PathBuf], method: &str) -> Result<()> {
        println!("| run | GPU ms | cull ms | MS-RMSE | FLIP | temporal noise | draw calls | batches | packs MB |");
        println!("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |");
        for d in dirs {
            let p = d.join("summary.json");
            let text = std::fs::read_to_string(&p).with_context(|| format!("cannot read {}", p.display()))?;
            let v: serde_json::Value =
                serde_json::from_str(&text).with_context(|| format!("{}: not JSON", p.display()))?;
            let m = &v["methods"][&method];
            if m.is_null() {
                bail!("{}: no method {method:?}", p.display());
            }
            let med = |k: &str| m[k]["median"].as_f64().unwrap_or(f64::NAN);
            // The scene's batches and pack bytes, where it is a local directory.
            let scene = std::path::PathBuf::from(v["scene"].as_str().unwrap_or_default());
            let (batches, packs) = std::fs::read(scene.join("scene.json"))
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

    /// `sylva compare`: the multi-scale RMSE of two PNGs.
    fn compare(a: &PathBuf, b: &PathBuf) -> Result<()> {
        let load =
            |p: &PathBuf| image::open(p).with_context(|| format!("cannot read {}", p.display())).map(|i| i.to_rgba8());
        let (ia, ib) = (load(a)?, load(b)?);
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
        println!("{:.6}", sylva::metrics::multiscale_rmse(ia.as_raw(), ib.as_raw(), w, h));
        Ok(())
    }

    /// `sylva serve`: the viewer and a scene over HTTP until the process ends.
    fn serve(dir: PathBuf, port: u16, bind: &str, web: Option<PathBuf>, allow_hosts: Vec<String>) -> Result<()> {
        if !dir.join("scene.json").is_file() {
            bail!("{} has no scene.json: not a Sylva scene directory (bake one with sylva-bake)", dir.display());
        }
        let web = web.unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("web"));
        if !web.join("pkg").join("sylva_bg.wasm").is_file() {
            bail!("{} has no built viewer (pkg/sylva_bg.wasm): run `make web` first", web.display());
        }
        let config =
            sylva::serve::ServeConfig { allowed_hosts: allow_hosts, ..sylva::serve::ServeConfig::new(web, dir) };
        sylva::serve::serve(config, &format!("{bind}:{port}"), |addr| {
            println!("serving the Sylva viewer on http://{addr}/");
            use std::io::Write as _;
            let _ = std::io::stdout().flush();
        })
        .with_context(|| format!("cannot listen on {bind}:{port}"))?;
        Ok(())
    }

    /// `sylva bench --replot`: redraws the plots of an earlier run from its frames.csv.
    fn replot(out: &std::path::Path, path: &str, size: &str) -> Result<()> {
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
            adapter: String::new(),
        };
        sylva::bench::write_plots(out, &run, &format!("{path}, {size}"))?;
        eprintln!("redrew the plots in {}", out.display());
        Ok(())
    }

    /// `sylva bench --memory`: bytes per tree on disk, compressed and on the GPU.
    fn memory(scene: &str, out: &std::path::Path) -> Result<()> {
        let m = sylva::bench::memory::measure(std::path::Path::new(&scene))?;
        print!("{}", sylva::bench::memory::report(&m));
        std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
        std::fs::write(out.join("memory.json"), serde_json::to_string_pretty(&m)?)?;
        eprintln!("wrote {}", out.join("memory.json").display());
        Ok(())
    }

    pub fn main() -> Result<()> {
        sylva::render::context::ensure_runtime_dir();
        match Cli::parse().command {
            Command::Bench { out, replot: true, path, size, .. } => replot(&out, &path, &size),
            Command::Bench { scene, out, memory: true, .. } => memory(&scene, &out),
            Command::Bench { scene, path, size, frames, out, stress: true, .. } => {
                stress(&scene, &path, &size, frames, &out)
            }
            Command::Bench { scene, path, methods, size, frames, out, fade_band, thin_px, .. } => {
                if !(0.0..0.5).contains(&fade_band) {
                    bail!("--fade-band {fade_band}: must be in [0, 0.5)");
                }
                check_thin_px(thin_px)?;
                let mut methods = sylva::bench::methods(&methods)?;
                for m in methods.iter_mut().filter(|m| m.name != "reference") {
                    m.settings.fade_band = fade_band;
                    m.settings.thin_px = thin_px;
                }
                bench(&scene, &path, methods, &size, frames, &out)
            }
            Command::BenchTable { dirs, method } => bench_table(&dirs, &method),
            Command::Compare { a, b } => compare(&a, &b),
            Command::Serve { dir, port, bind, web, allow_hosts } => serve(dir, port, &bind, web, allow_hosts),
            Command::Render(args) => render(args),
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
