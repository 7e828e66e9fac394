//! The command line: subcommands, their flags and the checks of flag values.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand, ValueEnum};
use glam::DVec3;
use sylva::camera::Camera;

#[derive(Parser)]
#[command(name = "sylva", version, about = "Sylva forest renderer: headless rendering of Sylva scenes and LoD packs.")]
pub(crate) struct Cli {
    #[command(subcommand)]
    pub(crate) command: Command,
}

#[derive(Clone, Copy, ValueEnum)]
pub(crate) enum View {
    Side,
    Oblique,
    Top,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
pub(crate) enum OnlyArg {
    Meshes,
    Ellipsoids,
    Billboards,
    /// Billboard clouds (García et al. 2007).
    Clouds,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
pub(crate) enum PackReprArg {
    Mesh,
    Ellipsoids,
    Billboard,
    /// Multi-view impostors.
    Impostor,
    /// The billboard cloud (García et al. 2007).
    Cloud,
}

#[derive(Clone, Copy, ValueEnum)]
pub(crate) enum FarTierArg {
    Impostors,
    Billboards,
}

#[derive(Clone, Copy, ValueEnum)]
pub(crate) enum SceneView {
    Far,
    Medium,
    Close,
    Top,
}

#[derive(Subcommand)]
pub(crate) enum Command {
    /// Render a scene (or one species pack) headless to a PNG, with stats.
    #[command(
        after_help = "Examples:\n  sylva render --scene demo-scene --view medium --out medium.png --stats medium.json\n  sylva render --scene http://127.0.0.1:8080/scene.json --camera 540000,5359700,300,0,-20 --out a.png\n  sylva render --pack demo-scene/species/beech.pack --view side --out beech.png"
    )]
    Render(Box<RenderArgs>),
    /// Run time against image error on a camera path, every method on the same
    /// frames: writes frames.csv, summary.json and SVG plots (pareto,
    /// frame_time, temporal_noise) into --out.
    #[command(
        after_help = "Methods: reference (full mesh everywhere, 2x supersampled; always run), mesh, per-tree,\n  billboard, impostor, ellipsoid, sylva, sylva-no-canopy (trees at every size, no canopy\n  rasters), sylva-converged (refined at rest), sylva-q0.5,\n  sylva-q0.25, sylva-shadows-low, sylva-shadows-high, or all; mesh-plain-alpha and\n  sylva-plain-alpha (without adaptive transparency) for comparison; sylva-light-PARTS\n  (none, all, or sky, aerial, sky-light, transmission, soft-shadows joined by +).\nPaths: flyover, far, medium, close (360° sweeps), or a JSON file\n  {\"keyframes\": [{\"eye\": [x, y, z], \"heading_deg\": 0, \"pitch_deg\": -10}, ...], \"frames\": 60}\n  in metres from the scene origin.\nExample:\n  sylva bench --scene demo-scene --path flyover --methods all --size 640x360 --out bench-out"
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
        /// per pack, against Eichner 2024, eq. 4.1 (writes memory.json; --scene a directory).
        #[arg(long, conflicts_with_all = ["replot", "stress"])]
        memory: bool,
        /// The path tracer's bottom level instead: each species' BVH over its
        /// full mesh (build time, nodes, depth, bytes) and nearest hits per
        /// second through it on one CPU core and on the GPU, the two's hits
        /// compared (writes trace.json; --scene a directory).
        #[arg(long, conflicts_with_all = ["replot", "stress", "memory"])]
        trace: bool,
        /// --trace: rays per species.
        #[arg(long, default_value_t = 65_536, requires = "trace", value_parser = clap::value_parser!(u32).range(1..=16_777_216))]
        rays: u32,
        /// The stress run instead: Sylva alone along --path, forwards and back,
        /// for --frames frames (10000 is the standard run), streaming without
        /// waiting; fails unless memory stays flat and frame time does not grow
        /// (writes stress.csv, stress.json).
        #[arg(long, conflicts_with = "replot")]
        stress: bool,
        /// --stress: the instance pool's size in trees (default 4,194,304; the
        /// browser viewer holds 2,097,152): a smaller device, whose pools the
        /// path fills (eviction and trimming by prefix, shortened reach).
        #[arg(long, value_name = "TREES", requires = "stress", value_parser = clap::value_parser!(u32).range(4096..))]
        pool_trees: Option<u32>,
        /// Half width of the cross-fade bands for every method but the
        /// reference, as a fraction of each threshold (the fade sweep).
        #[arg(long, default_value_t = 0.12)]
        fade_band: f32,
        /// Prefix-thinning threshold (px) for every method but the reference
        /// (0: off; the thinning comparison).
        #[arg(long, default_value_t = sylva::render::forest::DEFAULT_THIN_PX)]
        thin_px: f32,
        /// Draw every method with the sun's shadows at this quality (off, low,
        /// high), measured against the shadowed reference (full meshes cast
        /// into four 3072² cascades). The methods sylva-shadows-low and
        /// sylva-shadows-high are shadowed in any run.
        #[arg(long, value_name = "off|low|high", default_value = "off")]
        shadows: sylva::render::shadow::ShadowQuality,
        /// Draw every method (the references too) with each tree's own baked
        /// ambient occlusion (on) or without (off).
        #[arg(long, value_name = "on|off", default_value = "on", value_parser = parse_on_off, action = clap::ArgAction::Set)]
        ao: bool,
        /// Draw every method (the references too; not the sylva-light-…
        /// methods, which name their own) with these parts of the light: all
        /// (the default), none (the light before the physical sky), or a comma-separated
        /// list of sky, aerial, sky-light, transmission, soft-shadows. The
        /// trace under the raster's light mirrors them.
        #[arg(long, value_name = "PARTS", default_value = "all")]
        light_parts: sylva::render::sky_light::LightParts,
        /// The air's turbidity for the sky, its light and the aerial
        /// perspective, raster and traced (2 very clear, 3 clear, 6 hazy).
        #[arg(long, default_value_t = 3.0, value_parser = parse_turbidity)]
        turbidity: f32,
        /// Draw every method (the references too) with deciduous species in
        /// this season: leaf-on, autumn or leaf-off.
        #[arg(long, value_name = "leaf-on|autumn|leaf-off", default_value = "leaf-on")]
        season: sylva::render::settings::Season,
        /// Also write every method's frames as PNGs into --out/frames, and per
        /// frame a strip of them side by side in the methods' order, the
        /// reference first (NNN-strip.png), to look at the error. With
        /// --stress: every 10th frame of the first pass as streamed and as
        /// settled (NNN-stream.png, NNN-settled.png), and the share of pixels
        /// where the streamed frame shows ground or sky the settled one covers
        /// (holes, in stress.json).
        #[arg(long, conflicts_with_all = ["replot", "memory"])]
        save_frames: bool,
        /// Supersampling of the references, per axis (N² samples per pixel):
        /// 2 by default; 4 to judge `sylva-converged`, whose 16 jittered steps
        /// sample each pixel more finely than a 2× reference does.
        #[arg(long, value_name = "N", default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=4),
              conflicts_with_all = ["replot", "stress", "memory"])]
        reference_supersample: u32,
        /// The reference every method is also judged against: raster (the
        /// full mesh rasterised and supersampled; always run) or path-traced —
        /// each frame also traced at full detail (issue 48) under the physical
        /// light (sun disk, clear sky, bounces, leaves that transmit) and under
        /// the raster's own light, each method's error against both (the first
        /// geometry and light, the second geometry alone, the difference the
        /// light's; traced.csv, summary.json "path_traced"). A scene directory.
        #[arg(long, value_enum, default_value = "raster", conflicts_with_all = ["replot", "stress", "memory", "trace"])]
        reference: ReferenceArg,
        /// --reference path-traced: samples per pixel of each traced image.
        #[arg(long, default_value_t = 64, value_parser = clap::value_parser!(u32).range(1..=65_536))]
        trace_spp: u32,
        /// --reference path-traced: trees within this many metres of the eye are traced.
        #[arg(long, default_value_t = 2000.0, value_parser = parse_reach)]
        trace_reach: f64,
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
    /// Find trees by their attributes (the inventory's columns the bake kept)
    /// and ids; prints {count, ids, bounds, tiles} as JSON.
    #[command(
        after_help = "Filter (JSON): per attribute a text or list (categories; * is a wildcard), [min, max] with\n  null for an open end, or one value (numbers, integers, dates as YYYY-MM-DD); \"id\": ids.\nExamples:\n  sylva query --scene ams --filter '{\"species\": \"quercus*\", \"dbh\": [30, null]}'\n  sylva query --scene ams --filter '{\"condition\": [\"poor\", \"dead\"]}' --limit 0\n  sylva query --scene plot --date 2019-06-01 --limit 0"
    )]
    Query {
        /// Scene directory (a baked scene with attributes).
        #[arg(long)]
        scene: PathBuf,
        /// The filter, a JSON object (see below); {} matches every tree.
        #[arg(long, default_value = "{}")]
        filter: String,
        /// Most ids listed (the count is always whole).
        #[arg(long, default_value_t = 1000)]
        limit: usize,
        /// The trees standing on this date (YYYY-MM-DD) by the scene's censuses or
        /// planting and removal dates (default: those standing at the latest date).
        #[arg(long, value_name = "YYYY-MM-DD")]
        date: Option<String>,
    },
    /// Say which tree is drawn at a pixel of a view (the id pass the viewer's
    /// click runs), as JSON: {id, species, attributes, lon, lat, height,
    /// position} or null where no tree is drawn there.
    #[command(after_help = "The pixel counts from the top left of an image of --size, seen from --view or --camera as
`sylva render` sees it (same flags).
Examples:
  sylva pick --scene ams --view medium --at 480,300
  sylva pick --scene ams --camera 121000,487000,60,0,-30 --size 1280x720 --at 640,360")]
    Pick(PickArgs),
    /// Print the multi-scale RMSE (Clasen et al. 2010, §4, 0–1) between two images of the same size.
    Compare {
        /// First image (PNG).
        a: PathBuf,
        /// Second image (PNG).
        b: PathBuf,
        /// Stretch the second image to the first's size first (bilinear, as a
        /// browser stretches a canvas drawn at a lower render scale): the error
        /// of a frame the frame-time governor drew smaller.
        #[arg(long)]
        stretch: bool,
        /// Print the agreement of the two images' foliage masks instead
        /// (green-dominant pixels): intersection over union, and each one's
        /// foliage pixels — whether two renderers see the same forest.
        #[arg(long)]
        foliage: bool,
    },
    /// Serve the browser viewer at / with DIR's scene as its default scene (/scene/). DIR may
    /// also be a 3D Tiles export (`sylva-bake export-3dtiles`): CesiumJS shows it at /cesium.html.
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
        /// Pages of this origin (https://portal.example.org; repeatable; * for
        /// any) may show the viewer in a frame and drive it by postMessage.
        /// Without it only pages served here may (frame-ancestors 'self'; the
        /// viewer ignores other pages' messages). See docs/SECURITY.md.
        #[arg(long = "allow-embed", value_name = "ORIGIN", value_parser = sylva::serve::parse_origin)]
        allow_embed: Vec<String>,
        /// The viewer may load scenes (?scene=) and imagery (?imagery=, the
        /// setImagery message) from this origin too (repeatable; * for any).
        /// Without it only from this server.
        #[arg(long = "allow-source", value_name = "ORIGIN", value_parser = sylva::serve::parse_origin)]
        allow_source: Vec<String>,
    },
}

/// The image and the view of `render` and `pick`.
#[derive(clap::Args)]
pub(crate) struct ViewArgs {
    /// Image size, WxH.
    #[arg(long, default_value = "960x540")]
    pub(crate) size: String,
    /// Named scene viewpoint (ignored with --camera).
    #[arg(long, value_enum, default_value_t = SceneView::Medium)]
    pub(crate) view: SceneView,
    /// Camera in the scene CRS: EASTING,NORTHING,HEIGHT,HEADING_DEG,PITCH_DEG.
    #[arg(long, allow_hyphen_values = true)]
    pub(crate) camera: Option<String>,
    /// LoD quality factor (1, 0.5, 0.25: projected sizes are scaled by it).
    #[arg(long, default_value_t = 1.0)]
    pub(crate) quality: f32,
    /// Draw distance in metres (default: none; far tiles are fetched and drawn
    /// as thin prefixes, and full pools shorten the reach by themselves).
    #[arg(long, default_value_t = f32::INFINITY, hide_default_value = true)]
    pub(crate) draw_distance: f32,
    /// Fetch every tile whole instead of the prefix levels far views draw (to
    /// compare bytes; the image is the same).
    #[arg(long)]
    pub(crate) whole_tiles: bool,
    /// Draw every tree however small, instead of the scene's canopy rasters
    /// where trees are under a pixel or two (scenes baked with canopy rasters).
    #[arg(long)]
    pub(crate) no_canopy: bool,
    /// Textures as the GPU takes them best (`auto`: a pack's BC7 or ETC2
    /// variant where the GPU samples it; a CPU rasteriser the plain pack),
    /// `plain` (RGBA8 packs, to compare), or `bc7` / `etc2` (that variant
    /// where the GPU samples it, else the plain pack).
    #[arg(long, value_enum, default_value_t = TexturesArg::Auto)]
    pub(crate) textures: TexturesArg,
}

/// `--light`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum LightArg {
    /// Sun disk, sky, bounces, transmitting leaves.
    Physical,
    /// The raster's simple sun and sky light.
    Raster,
}

/// `sylva render --path-trace --top-level`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum TopLevelArg {
    /// Built on the GPU (a linear BVH).
    Gpu,
    /// Built on the CPU (binned SAH).
    Cpu,
}

/// `--textures`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum TexturesArg {
    /// Block-compressed variants where the GPU samples them.
    Auto,
    /// Plain RGBA8 packs.
    Plain,
    /// BC7 variants where the GPU samples them.
    Bc7,
    /// ETC2 variants where the GPU samples them.
    Etc2,
}

impl TexturesArg {
    /// As the renderer's setting.
    pub(crate) fn choice(self) -> sylva::render::settings::TextureChoice {
        use sylva::format::pack::TexelEncoding;
        use sylva::render::settings::TextureChoice;
        match self {
            TexturesArg::Auto => TextureChoice::Auto,
            TexturesArg::Plain => TextureChoice::Plain,
            TexturesArg::Bc7 => TextureChoice::Only(TexelEncoding::Bc7),
            TexturesArg::Etc2 => TextureChoice::Only(TexelEncoding::Etc2),
        }
    }
}

impl ViewArgs {
    /// The image size, with the quality checked.
    pub(crate) fn checked_size(&self) -> Result<(u32, u32)> {
        if !(self.quality > 0.0 && self.quality <= 16.0) {
            bail!("--quality {}: must be in (0, 16]", self.quality);
        }
        parse_size(&self.size)
    }
}

/// `sylva pick`: the tree at a pixel of a view.
#[derive(clap::Args)]
pub(crate) struct PickArgs {
    /// Scene directory, scene.json path or http(s) URL.
    #[arg(long)]
    pub(crate) scene: String,
    /// The pixel, X,Y from the top left of the image. Repeat it to pick
    /// several pixels of one view (a JSON array is printed then).
    #[arg(long, value_name = "X,Y", required = true)]
    pub(crate) at: Vec<String>,
    /// Image size, view or camera, quality, draw distance (as `sylva render`).
    #[command(flatten)]
    pub(crate) frame: ViewArgs,
    /// Draw only one representation family (as `sylva render --only`).
    #[arg(long, value_enum)]
    pub(crate) only: Option<OnlyArg>,
    /// The far tier where a pack has both (as `sylva render --far-tier`).
    #[arg(long, value_enum, default_value = "impostors")]
    pub(crate) far_tier: FarTierArg,
    /// Leave the terrain out (trees behind hills can then be picked).
    #[arg(long)]
    pub(crate) no_terrain: bool,
    /// Also write the view as a PNG here, the picked pixel marked (to check a pick by eye).
    #[arg(long)]
    pub(crate) out: Option<PathBuf>,
    /// Give up waiting for data after this many seconds.
    #[arg(long, default_value_t = 120.0)]
    pub(crate) timeout: f64,
    /// The view at a date (YYYY-MM-DD), as `sylva render --date`: the seasons,
    /// the sun (noon) and, in a scene with censuses, the trees standing then.
    #[arg(long, value_name = "YYYY-MM-DD")]
    pub(crate) date: Option<String>,
}

/// `sylva render`: a scene or one pack to a PNG.
#[derive(clap::Args)]
pub(crate) struct RenderArgs {
    /// Scene directory, scene.json path or http(s) URL.
    #[arg(long, conflicts_with = "pack", required_unless_present = "pack")]
    pub(crate) scene: Option<String>,
    /// A single LoD pack to render (one tree, lit).
    #[arg(long)]
    pub(crate) pack: Option<PathBuf>,
    /// Output PNG.
    #[arg(long)]
    pub(crate) out: PathBuf,
    /// Image size, view or camera, quality, draw distance.
    #[command(flatten)]
    pub(crate) frame: ViewArgs,
    /// Colour trees by representation (red mesh0, yellow mesh1, greens ellipsoid
    /// levels, blue billboard).
    #[arg(long)]
    pub(crate) debug_lod: bool,
    /// Colour the ground by the shadow cascade that holds it (red, green,
    /// blue, white; black where no cascade's box holds it), as bright as the
    /// sun there, to see where the splits fall.
    #[arg(long)]
    pub(crate) debug_cascades: bool,
    /// Draw only one representation family (the benchmark baselines); the
    /// default mixes meshes, ellipsoids and billboards by projected size.
    #[arg(long, value_enum)]
    pub(crate) only: Option<OnlyArg>,
    /// Trees at least this tall on screen (px), and below the simplified mesh,
    /// are drawn with ellipsoids and lines; smaller ones with billboards.
    #[arg(long, default_value_t = sylva::render::forest::DEFAULT_CLUSTER_MIN_PX)]
    pub(crate) ellipsoid_min_px: f32,
    /// Ellipsoids write their exact ray-cast depth per pixel (slower: no early
    /// depth tests); by default they keep their proxy's front-most depth.
    #[arg(long)]
    pub(crate) exact_depth: bool,
    /// Prefix thinning: far batches whose trees are below this many pixels
    /// tall draw an even subset of them, scaled up to keep the canopy's
    /// coverage (0 turns it off).
    #[arg(long, default_value_t = sylva::render::forest::DEFAULT_THIN_PX)]
    pub(crate) thin_px: f32,
    /// Draw the boxes of the batches that pass the batch test.
    #[arg(long)]
    pub(crate) debug_bounds: bool,
    /// Leave the terrain out: neither fetched nor drawn (the trees over the
    /// plain background; the with/without-terrain comparison).
    #[arg(long)]
    pub(crate) no_terrain: bool,
    /// Ground imagery from an XYZ or WMTS raster source in Web Mercator
    /// instead of the scene's own: a URL template with {z}/{x}/{y} ({-y} for
    /// TMS rows) or WMTS {TileMatrix}/{TileCol}/{TileRow}, reprojected onto
    /// the scene's terrain (e.g. http://127.0.0.1:8080/{z}/{x}/{y}.png).
    #[arg(long, value_name = "URL_TEMPLATE", conflicts_with = "no_imagery")]
    pub(crate) imagery: Option<String>,
    /// Finest zoom level the --imagery source serves.
    #[arg(long, default_value_t = 19)]
    pub(crate) imagery_max_zoom: u8,
    /// No ground imagery (the terrain's own ground material), even where the
    /// scene has baked imagery.
    #[arg(long)]
    pub(crate) no_imagery: bool,
    /// The sun at a local date and time of the scene's place (NOAA solar
    /// position): ISO 8601 such as 2026-06-21T15:00, with Z or ±HH:MM for the
    /// offset from UTC (without one: the whole hour of the place's longitude).
    /// Several, comma-separated, make a shadow study: one image per time,
    /// named OUT-<date>T<hhmm>.png.
    #[arg(long, value_name = "TIME[,TIME…]", conflicts_with = "sun")]
    pub(crate) sun_time: Option<String>,
    /// The sun at an azimuth (degrees clockwise from north) and an elevation
    /// above the horizon: AZIMUTH,ELEVATION (e.g. 225,35).
    #[arg(long, value_name = "AZ,EL", allow_hyphen_values = true)]
    pub(crate) sun: Option<String>,
    /// The sun's shadows: off, low (2 cascades over 300 m, maps of 0.8 texels
    /// per image pixel, 512²–1024²) or high (3 over 600 m, 1.6 texels per
    /// pixel, 512²–2048², softer edges). Trees shade the
    /// ground and each other; casters are picked on the GPU like the view's.
    #[arg(long, value_name = "off|low|high", default_value = "high")]
    pub(crate) shadows: sylva::render::shadow::ShadowQuality,
    /// Each tree's own ambient occlusion, baked into its pack: crowns darker
    /// inside, alike at every level of detail (off: crowns unoccluded).
    #[arg(long, value_name = "on|off", default_value = "on", value_parser = parse_on_off, action = clap::ArgAction::Set)]
    pub(crate) ao: bool,
    /// The far tier where a pack has both: multi-view impostors (the tree keeps
    /// its shape all round) or view-angle billboards.
    #[arg(long, value_enum, default_value = "impostors")]
    pub(crate) far_tier: FarTierArg,
    /// Impostors as the browser draws them while the camera moves (the
    /// frame-time governor, every level but its first): the nearest view alone, at the
    /// depth of each tree's quad (hidden crowns then cost nothing).
    #[arg(long)]
    pub(crate) moving_impostors: bool,
    /// Draw every tree at its full mesh, leaf cards alpha-tested at full
    /// texture resolution: the benchmark's raster reference (and what
    /// --path-trace traces), for comparisons. Slow for large views.
    #[arg(long, conflicts_with_all = ["pack", "only", "path_trace"])]
    pub(crate) full_detail: bool,
    /// Trace the view instead of drawing it (issue 48): every tree within
    /// --reach at its full mesh (leaf cards alpha-tested at full texture
    /// resolution) through a two-level BVH on the GPU, the sun as a disk of
    /// its true size (soft shadows), the sky's light, leaves that transmit,
    /// --bounces bounces, --spp samples per pixel; the scene's terrain within
    /// reach as triangles (a plane at the lowest tree's base where it has
    /// none; no ground with --no-terrain). A scene directory only.
    #[arg(long, conflicts_with_all = ["pack", "converge", "date", "style", "select", "season"])]
    pub(crate) path_trace: bool,
    /// --path-trace: samples per pixel.
    #[arg(long, default_value_t = 64, requires = "path_trace", value_parser = clap::value_parser!(u32).range(1..=65_536))]
    pub(crate) spp: u32,
    /// --path-trace: bounces after the first hit.
    #[arg(long, default_value_t = 2, requires = "path_trace", value_parser = clap::value_parser!(u32).range(0..=16))]
    pub(crate) bounces: u32,
    /// --path-trace: the light — physical (sun disk, sky, bounces, leaves
    /// that transmit) or raster (the raster's simple sun and sky light, no
    /// bounce: the traced geometry under the raster's light).
    #[arg(long, value_enum, default_value = "physical", requires = "path_trace")]
    pub(crate) light: LightArg,
    /// The air's turbidity (Preetham et al. 1999): the clear sky behind the
    /// scene, its light and the aerial perspective, drawn or traced — 2 very
    /// clear, 3 clear, 6 hazy.
    #[arg(long, default_value_t = 3.0, value_parser = parse_turbidity)]
    pub(crate) turbidity: f32,
    /// The parts of the light: all (the default: the light judged against the
    /// path-traced reference), none (the light before the physical sky — a
    /// gradient sky, a grey haze, a flat ambient, leaves lit by a wrap term,
    /// fixed-width shadow filtering), or a
    /// comma-separated list of sky (Preetham's clear sky behind the scene),
    /// aerial (the air between the eye and what it sees), sky-light (the
    /// sky's light on every surface), transmission (leaves that let light
    /// through), soft-shadows (penumbrae as wide as the sun and the
    /// occluder's distance make them). With --path-trace --light raster, the
    /// raster light traced mirrors them.
    #[arg(long, value_name = "PARTS", default_value = "all")]
    pub(crate) light_parts: sylva::render::sky_light::LightParts,
    /// --path-trace: every ray through its pixel's centre, where a
    /// rasteriser's one sample lies (no anti-aliasing): the coverage check
    /// against `--full-detail` (`sylva compare --foliage`).
    #[arg(long, requires = "path_trace")]
    pub(crate) pixel_centres: bool,
    /// --path-trace: who builds the top level over the trees — `gpu` (the
    /// default: a linear BVH sorted along a Morton curve, Karras 2012, in the
    /// first samples' command buffer) or `cpu` (the binned surface area
    /// heuristic, slower to build, a little faster to walk), for comparison.
    #[arg(long, value_enum, default_value_t = TopLevelArg::Gpu, requires = "path_trace")]
    pub(crate) top_level: TopLevelArg,
    /// --path-trace with the physical light: light from an equirectangular HDR
    /// environment (Radiance .hdr or OpenEXR-free float images the image
    /// crate reads; row 0 the zenith, the middle column north) instead of the
    /// sun and the clear sky, importance sampled.
    #[arg(long, value_name = "FILE.hdr", requires = "path_trace")]
    pub(crate) environment: Option<PathBuf>,
    /// --environment: its radiance's scale (exposure).
    #[arg(long, default_value_t = 1.0, requires = "environment", value_parser = parse_environment_scale)]
    pub(crate) environment_scale: f32,
    /// --path-trace: trees within this many metres of the eye (horizontally)
    /// are traced (the top level for a view; memory grows with it).
    #[arg(long, default_value_t = 2000.0, requires = "path_trace", value_parser = parse_reach)]
    pub(crate) reach: f64,
    /// Write the converged image of progressive refinement, as the viewer
    /// shows it once the camera rests: sub-pixel jittered frames accumulate
    /// into an anti-aliased image while the level of detail rises step by step
    /// (projected sizes ×2, ×4, …) towards full meshes.
    #[arg(long, conflicts_with = "pack")]
    pub(crate) converge: bool,
    /// With --converge: jittered frames accumulated per quality level.
    #[arg(long, default_value_t = 16, requires = "converge", value_parser = clap::value_parser!(u32).range(1..=256))]
    pub(crate) converge_frames: u32,
    /// With --converge: quality levels above the normal frame (0–4; each
    /// doubles projected sizes before the LoD choice, the last draws every
    /// tree in view as its full mesh).
    #[arg(long, default_value_t = 3, requires = "converge", value_parser = clap::value_parser!(u32).range(0..=4))]
    pub(crate) converge_levels: u32,
    /// Colour and filter the trees by their attributes (JSON, as the browser's
    /// setStyle): e.g. '{"color": {"by": "species"}}' or '{"filter": {"dbh": [30, null]}}'.
    #[arg(long, value_name = "JSON")]
    pub(crate) style: Option<String>,
    /// Highlight these trees (comma-separated ids: numbers, or an inventory's
    /// text ids such as EY17080).
    #[arg(long, value_name = "ID,…", value_delimiter = ',')]
    pub(crate) select: Vec<String>,
    /// Write frame statistics as JSON here.
    #[arg(long)]
    pub(crate) stats: Option<PathBuf>,
    /// Give up waiting for data after this many seconds.
    #[arg(long, default_value_t = 120.0)]
    pub(crate) timeout: f64,
    /// Exit 0 although files of the view failed to load or did not arrive
    /// in time (the image shows what loaded; the stats list the failures).
    /// Without it such a render writes its PNG and stats and exits 1.
    #[arg(long)]
    pub(crate) allow_partial: bool,
    /// Pack view (with --pack).
    #[arg(long, value_enum, default_value_t = View::Oblique)]
    pub(crate) pack_view: View,
    /// What to draw with --pack: mesh (level --level), ellipsoids (cluster
    /// level --level: ellipsoids + lines) or billboard.
    #[arg(long, value_enum, default_value_t = PackReprArg::Mesh)]
    pub(crate) repr: PackReprArg,
    /// Mesh or cluster level (with --pack).
    #[arg(long, default_value_t = 0)]
    pub(crate) level: usize,
    /// Mesh variant (with --pack; a library tree's are 0–2, see `sylva-bake inspect`);
    /// the far tiers' too where the pack has them per variant (`--far-tier-variants`).
    #[arg(long, default_value_t = 0)]
    pub(crate) variant: u32,
    /// The season deciduous species are drawn in: leaf-on, autumn (their
    /// leaves in their autumn colour) or leaf-off (bare wood). Evergreens, and
    /// packs baked without seasons, look the same in every one.
    #[arg(long, value_name = "leaf-on|autumn|leaf-off", default_value = "leaf-on")]
    pub(crate) season: sylva::render::settings::Season,
    /// A date (YYYY-MM-DD): each deciduous species in the state its genus's leaf
    /// calendar gives there and then (latitude and elevation of the scene's
    /// middle; Hopkins 1918, Čufar et al. 2012 — docs/ARCHITECTURE.md
    /// "Phenology"), over --season; the sun at that date too, at noon, unless
    /// --sun-time or --sun says otherwise.
    #[arg(long, value_name = "YYYY-MM-DD", conflicts_with = "pack")]
    pub(crate) date: Option<String>,
}

/// `--thin-px` of `render` and `bench`.
pub(crate) fn check_thin_px(thin_px: f32) -> Result<()> {
    if !(thin_px.is_finite() && thin_px >= 0.0) {
        bail!("--thin-px {thin_px}: must be a number of pixels ≥ 0 (0 turns thinning off)");
    }
    Ok(())
}

pub(crate) fn parse_size(s: &str) -> Result<(u32, u32)> {
    let (w, h) = s.split_once(['x', 'X']).with_context(|| format!("--size {s:?}: expected WxH, e.g. 512x512"))?;
    let (w, h): (u32, u32) = (w.trim().parse()?, h.trim().parse()?);
    if w == 0 || h == 0 || w > 8192 || h > 8192 {
        bail!("--size {s}: each side must be 1–8192 pixels");
    }
    Ok((w, h))
}

pub(crate) fn parse_camera(text: &str, origin: [f64; 3]) -> Result<Camera> {
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

/// `on`/`off` (also true/false, yes/no, 1/0).
pub(crate) fn parse_on_off(s: &str) -> Result<bool, String> {
    match s.to_ascii_lowercase().as_str() {
        "on" | "true" | "yes" | "1" => Ok(true),
        "off" | "false" | "no" | "0" => Ok(false),
        _ => Err(format!("{s:?}: expected on or off")),
    }
}

/// `sylva bench --reference`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum ReferenceArg {
    /// The full mesh rasterised, supersampled (the methods' own reference).
    Raster,
    /// Also the path tracer's image of each frame, under both lights.
    PathTraced,
}

/// `--environment-scale`: a positive finite number.
fn parse_environment_scale(s: &str) -> Result<f32, String> {
    let v: f32 = s.parse().map_err(|_| format!("{s}: not a number"))?;
    if v.is_finite() && v > 0.0 && v <= 1e6 {
        Ok(v)
    } else {
        Err(format!("{v}: the environment's scale is a positive number (1: as the file has it)"))
    }
}

/// `--turbidity`: a number in 1.7–10 (the clear-sky fit's range).
fn parse_turbidity(s: &str) -> Result<f32, String> {
    let t: f32 = s.trim().parse().map_err(|_| format!("{s:?} is not a number"))?;
    if (1.7..=10.0).contains(&t) {
        Ok(t)
    } else {
        Err(format!("{t}: the clear sky is fitted for turbidity 1.7–10 (2 very clear, 3 clear, 6 hazy)"))
    }
}

/// `--reach`: a positive distance in metres.
fn parse_reach(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(m) if m.is_finite() && m > 0.0 => Ok(m),
        _ => Err(format!("{s:?}: a distance in metres above 0")),
    }
}
