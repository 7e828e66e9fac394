//! `sylva-bake`: turns glTF trees and tree placements into a Sylva scene
//! (LoD packs + grouped-batch tiles + manifest). See `--help`.

mod allometry;
mod ao;
mod attributes;
mod bake;
mod batching;
mod bucket;
mod canopy;
mod cloud;
mod clusters;
mod country;
mod demo;
use sylva_bake::{gltf_import, placements, reproject};
mod inspect;
mod merge;
mod out_dir;
mod pack_build;
mod rng;
mod scene_write;
mod tiles3d;

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand};
use glam::DVec3;
use sylva::format::canopy::FINEST_CELL_M;

use bake::{trees, SceneInput, SceneSummary};
use batching::{default_cell_size, SceneTree, MAX_CELL_SIZE_M};
use bucket::TreeSource;
use gltf_import::Classifier;
use out_dir::OutDir;
use pack_build::{FarBake, PackOptions};
use reproject::{Crs, Reprojector};
use sylva::format::index::DEFAULT_NODE_TILES;

#[derive(Parser)]
#[command(
    name = "sylva-bake",
    version,
    about = "Bake glTF trees and tree placements into a Sylva scene (LoD packs + grouped-batch tiles)."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Bake real models and placements into a scene directory.
    #[command(
        after_help = "Example:\n  sylva-bake bake --model oak=oak.glb --model pine=pine.glb \\\n    --placements trees.csv --map 'quercus*=oak' --map 'pinus*=pine' --default-model oak --out scene/"
    )]
    Bake(Box<BakeArgs>),
    /// Make a complete procedural demo scene (three species, UTM 33N, no input files).
    Demo(DemoArgs),
    /// Benchmark the cluster-level bake (seed 002) of one model: timing and,
    /// per level, primitives, bytes, select_px and image error, as JSON.
    #[command(
        after_help = "Examples:\n  sylva-bake bench-clusters --model oak.glb\n  sylva-bake bench-clusters --leaves 27000"
    )]
    BenchClusters {
        /// A glTF/GLB tree.
        #[arg(long, conflicts_with = "leaves", required_unless_present = "leaves")]
        model: Option<PathBuf>,
        /// A procedural broadleaf with about this many leaves instead.
        #[arg(long)]
        leaves: Option<usize>,
        /// EM starts per level.
        #[arg(long, default_value_t = 4)]
        tries: usize,
    },
    /// Join the outputs of a sharded bake (`bake --shard I/N`) into one scene,
    /// byte-identical to a single-process bake.
    #[command(
        after_help = "Example:\n  for i in 0 1 2 3; do sylva-bake bake ... --shard $i/4 --out part-$i & done; wait\n  sylva-bake merge part-0 part-1 part-2 part-3 --out scene/"
    )]
    Merge {
        /// The shard output directories (any order; all N of them).
        #[arg(required = true)]
        dirs: Vec<PathBuf>,
        #[command(flatten)]
        output: OutArgs,
        /// Most tiles per index node (the value the shards were baked with).
        #[arg(long, default_value_t = DEFAULT_NODE_TILES, value_parser = clap::value_parser!(u32).range(1..=4096))]
        index_node_tiles: u32,
        /// Width of the finest canopy cells, metres (the value the shards were baked with).
        #[arg(long, default_value_t = FINEST_CELL_M, value_parser = parse_canopy_cell)]
        canopy_cell: f64,
    },
    /// Export a baked scene as an OGC 3D Tiles 1.1 tileset (CesiumJS and other
    /// 3D Tiles viewers): tileset.json with the scene's index as its hierarchy,
    /// per tile a GLB of crossed billboard quads (the far tier) refined by GLBs of
    /// coarse and full meshes, every tree an instance (EXT_mesh_gpu_instancing)
    /// placed through WGS84; the scene's terrain as ground tiles draped with
    /// its ground images.
    #[command(
        name = "export-3dtiles",
        after_help = "Examples:\n  sylva-bake export-3dtiles scene/ --out scene-3dtiles/\n  sylva serve scene-3dtiles/   # then http://127.0.0.1:8080/cesium.html\n\n  # On Cesium World Terrain (ellipsoidal) with DEM heights over the geoid, N = 47.3 m there:\n  sylva-bake export-3dtiles scene/ --out scene-3dtiles/ --no-ground --height-offset 47.3"
    )]
    Export3dTiles {
        /// The baked scene folder (with scene.json).
        scene: PathBuf,
        /// A new or empty folder for the tileset (nothing is overwritten).
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
        /// Leave the ground out (the scene's terrain and imagery, exported
        /// by default): for a portal that shows its own terrain.
        #[arg(long)]
        no_ground: bool,
        /// Metres added to every height, trees and ground: the geoid's
        /// undulation at the scene (e.g. from GeographicLib's GeoidEval) when
        /// its heights are above the geoid, as most DEMs and inventories give
        /// them, and the portal's terrain is ellipsoidal (Cesium World
        /// Terrain). 0 takes the heights as ellipsoidal.
        #[arg(long, value_name = "METRES", default_value_t = 0.0, allow_negative_numbers = true)]
        height_offset: f64,
    },
    /// Summarise a scene directory, scene.json, .pack, .tile or .ids file.
    Inspect {
        /// Scene directory or file.
        path: PathBuf,
        /// Print one JSON object instead of text (keys in docs/FORMAT.md).
        #[arg(long)]
        json: bool,
    },
}

#[derive(Args, Clone)]
struct PackArgs {
    /// Billboard elevation angles over 0–90° (seed 004 alg. 3.1).
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(2..=64))]
    billboard_angles: u32,
    /// Billboard azimuths around the tree.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=16))]
    billboard_azimuths: u32,
    /// Billboard resolution per layer (power of two).
    #[arg(long, default_value_t = 128)]
    billboard_size: u32,
    /// Far-field representations to bake: multi-view impostors (blended views
    /// over the hemisphere, the tree keeps its shape all round), seed 004's
    /// view-angle billboards, or both (the viewer draws the impostors).
    #[arg(long, value_enum, default_value_t = FarBake::Both)]
    far_tier: FarBake,
    /// Impostor views per side of the hemi-octahedral grid (grid² views).
    #[arg(long, default_value_t = pack_build::DEFAULT_IMPOSTOR_GRID, value_parser = clap::value_parser!(u32).range(2..=16))]
    impostor_grid: u32,
    /// Impostor resolution per view (power of two).
    #[arg(long, default_value_t = pack_build::DEFAULT_IMPOSTOR_SIZE)]
    impostor_size: u32,
    /// Planes of the billboard cloud (seed 001: leaves kept exact on planes
    /// fitted to the foliage; e.g. 64). 0 bakes none. The viewer draws it only
    /// when asked (`sylva render --only clouds`, bench method `billboard-cloud`).
    #[arg(long, default_value_t = pack_build::DEFAULT_CLOUD_PLANES, value_parser = clap::value_parser!(u32).range(0..=1024))]
    cloud_planes: u32,
    /// Material texture size (power of two).
    #[arg(long, default_value_t = 512)]
    texture_size: u32,
    /// Do not add the simplified mesh level.
    #[arg(long)]
    no_simplified_level: bool,
    /// Do not add clustered-ellipsoid and line levels (seed 002).
    #[arg(long)]
    no_clusters: bool,
    /// Do not bake each tree's own ambient occlusion (darker inside the crown,
    /// alike at every level of detail); the viewer then draws crowns unoccluded.
    #[arg(long)]
    no_ao: bool,
    /// EM starts per cluster level; the one with the lowest image error is kept.
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=32))]
    cluster_tries: u32,
    /// Write billboard layers as PNG strips into this directory.
    #[arg(long, value_name = "DIR")]
    debug_dump: Option<PathBuf>,
    /// Keep the species packs built in this folder, and take a pack from it when
    /// the same model is baked again with the same pack options by the same
    /// sylva-bake on the same GPU and driver: re-bakes of an inventory then skip the packs (seconds to
    /// minutes a species). Delete the folder to free its space.
    #[arg(long, value_name = "DIR", env = "SYLVA_BAKE_PACK_CACHE")]
    pack_cache: Option<PathBuf>,
    /// Batch grid cell size in metres (default: from the data's density; at most 655).
    #[arg(long)]
    cell_size: Option<u32>,
    /// Grid cells per tile side.
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(1..=256))]
    tile_cells: u32,
    /// Most tiles per node of the hierarchical tile index; scenes with more tiles
    /// than this get one (`merge` must be given the same value).
    #[arg(long, default_value_t = DEFAULT_NODE_TILES, value_parser = clap::value_parser!(u32).range(1..=4096))]
    index_node_tiles: u32,
    /// Width of the finest canopy raster cells, metres: what far views draw where
    /// trees are a pixel or two (finer: sharper forest edges from afar, more
    /// bytes; `merge` must be given the same value).
    #[arg(long, default_value_t = FINEST_CELL_M, value_parser = parse_canopy_cell)]
    canopy_cell: f64,
    /// Bake only shard I of N of the tile grid (0-based), e.g. 0/4, as one task of
    /// an array job; join the N outputs with `sylva-bake merge`. Shard 0 also bakes
    /// the species packs. Every shard reads the whole input.
    #[arg(long, value_name = "I/N", value_parser = parse_shard)]
    shard: Option<(u32, u32)>,
}

fn parse_delimiter(s: &str) -> Result<u8, String> {
    match s {
        "tab" | "\\t" | "\t" => Ok(b'\t'),
        _ if s.len() == 1 && s.is_ascii() => Ok(s.as_bytes()[0]),
        _ => Err(format!("{s:?}: one ASCII character, e.g. ';' or tab")),
    }
}

fn parse_shard(s: &str) -> Result<(u32, u32), String> {
    let (i, n) = s.split_once('/').ok_or_else(|| format!("{s:?}: expected I/N, e.g. 0/4"))?;
    let i: u32 = i.trim().parse().map_err(|_| format!("{s:?}: I must be a whole number"))?;
    let n: u32 = n.trim().parse().map_err(|_| format!("{s:?}: N must be a whole number"))?;
    if n == 0 || n > 65_536 || i >= n {
        return Err(format!("{s:?}: need 0 ≤ I < N ≤ 65536"));
    }
    Ok((i, n))
}

impl PackArgs {
    fn options(&self) -> Result<PackOptions> {
        for (name, v, max) in [
            ("--billboard-size", self.billboard_size, 2048),
            ("--texture-size", self.texture_size, 4096),
            ("--impostor-size", self.impostor_size, 1024),
        ] {
            if !v.is_power_of_two() || v < 4 || v > max {
                bail!("{name} {v}: must be a power of two between 4 and {max}");
            }
        }
        // The capture holds every view at twice the size (colour, normal,
        // occlusion, depth: 16 bytes a texel) until the mips are built.
        let capture_bytes = u64::from(self.impostor_grid).pow(2) * (2 * u64::from(self.impostor_size)).pow(2) * 16;
        if capture_bytes > 1 << 30 {
            bail!(
                "--impostor-grid {} with --impostor-size {} needs {:.1} GiB while baking: at most 1 GiB \
                 (e.g. --impostor-grid 8 --impostor-size 256)",
                self.impostor_grid,
                self.impostor_size,
                capture_bytes as f64 / f64::from(1u32 << 30)
            );
        }
        if u64::from(self.billboard_angles) * u64::from(self.billboard_azimuths) > 256 {
            bail!("--billboard-angles × --billboard-azimuths must be at most 256 (WebGPU's array layer limit)");
        }
        Ok(PackOptions {
            texture_size: self.texture_size,
            billboard_angles: self.billboard_angles,
            billboard_azimuths: self.billboard_azimuths,
            billboard_size: self.billboard_size,
            simplified_level: !self.no_simplified_level,
            clusters: !self.no_clusters,
            cluster_tries: self.cluster_tries as usize,
            ao: !self.no_ao,
            far_tier: self.far_tier,
            impostor_grid: self.impostor_grid,
            impostor_size: self.impostor_size,
            cloud_planes: self.cloud_planes,
        })
    }

    fn cell_size(&self, trees: &[SceneTree]) -> Result<u32> {
        match self.cell_size {
            Some(c) if c == 0 || c > MAX_CELL_SIZE_M => {
                bail!("--cell-size {c}: must be 1–{MAX_CELL_SIZE_M} m (16-bit positions at ≤ 1 cm)")
            }
            Some(c) => Ok(c),
            None => Ok(default_cell_size(trees, 500.0)),
        }
    }
}

#[derive(Args)]
struct BakeArgs {
    /// A species model: NAME=PATH.glb (repeat for each species).
    #[arg(long = "model", value_name = "NAME=PATH", required = true)]
    models: Vec<String>,
    /// Tree placements: .csv (columns auto-detected) or .geojson points.
    #[arg(long, value_name = "PATH")]
    placements: PathBuf,
    /// Map species labels to models: PATTERN=NAME (case-insensitive; * is a wildcard,
    /// otherwise a substring). Labels equal to a model name map to it without a pattern.
    #[arg(long = "map", value_name = "PATTERN=NAME")]
    maps: Vec<String>,
    /// Model for rows whose species maps to no model. Without it such rows are
    /// skipped and reported, except with a single --model, which every row uses.
    #[arg(long, value_name = "NAME")]
    default_model: Option<String>,
    /// Scene CRS (projected, e.g. EPSG:32631). Default: the UTM zone of lon/lat data, or --input-crs.
    #[arg(long)]
    crs: Option<String>,
    /// CRS of x/y placement columns (required for projected input).
    #[arg(long)]
    input_crs: Option<String>,
    /// Height in metres for rows with neither a height nor a DBH (default: the
    /// median of the given heights).
    #[arg(long)]
    default_height: Option<f32>,
    /// Text encoding of a CSV: auto reads each field as UTF-8 where it is valid
    /// and as Windows-1252/Latin-1 otherwise (counted in the report).
    #[arg(long, value_enum, default_value_t = placements::Encoding::Auto)]
    encoding: placements::Encoding,
    /// CSV field separator (default: detected from the header line: , ; tab |).
    /// With ; or tab, decimal commas (52,37) are read too.
    #[arg(long, value_name = "CHAR", value_parser = parse_delimiter)]
    delimiter: Option<u8>,
    /// The x/longitude and y/latitude columns hold each other's values: swap them.
    #[arg(long)]
    swap_xy: bool,
    /// Use column NAME for ROLE (repeatable), before the names detected by
    /// default. Roles: lon, lat, x, y, z, height, species, dbh, crown_diameter,
    /// crown_radius, yaw, id. E.g. --column species=species_code --column dbh=dbh_mm.
    #[arg(long = "column", value_name = "ROLE=NAME", value_parser = placements::ColumnRole::parse_mapping)]
    columns: Vec<(placements::ColumnRole, String)>,
    /// Unit of a DBH column whose name does not say it (dbh_mm, dbh_cm, dbh_in and dbh_m do).
    #[arg(long, value_enum, value_name = "UNIT")]
    dbh_unit: Option<placements::DbhUnit>,
    /// Keep only these columns as per-tree attributes (comma-separated names;
    /// default: every column but the coordinates and the id). Numbers,
    /// integers, dates (YYYY-MM-DD) and categories are typed from the values;
    /// free text (over 4,096 different values) is left out. Stored per tile in
    /// `.attr` sidecars for picking, styling and search.
    #[arg(long, value_name = "A,B,C", value_delimiter = ',', conflicts_with = "no_attributes")]
    attributes: Option<Vec<String>>,
    /// Keep no per-tree attributes.
    #[arg(long)]
    no_attributes: bool,
    /// Height and crown equations from DBH to use over the built-in ones
    /// (CSV: genus,h_p2,h_p3,h_p4,cw_b0,cw_b1,cw_b2; docs/ALLOMETRY.md). Rows
    /// without a height get one from their DBH; with neither, --default-height.
    #[arg(long, value_name = "FILE.csv")]
    allometry: Option<PathBuf>,
    /// Rows farther than this from the median position are outliers and skipped.
    #[arg(long, default_value_t = 100.0)]
    max_extent_km: f64,
    /// Material/mesh/node name pattern forced to leaves (repeatable; case-insensitive,
    /// `*` is a wildcard like --map's, otherwise a substring; '*' is every name).
    #[arg(long = "leaf-material", value_name = "PATTERN")]
    leaf_materials: Vec<String>,
    /// Material/mesh/node name pattern forced to branches (repeatable, as --leaf-material).
    #[arg(long = "branch-material", value_name = "PATTERN")]
    branch_materials: Vec<String>,
    /// Elevation model, a GeoTIFF (repeat for several tiles; float32, int16 or
    /// uint16 heights, strips or tiles, deflate/LZW, GDAL nodata): every tree
    /// stands on its ground, sampled bilinearly, unless the row has a z (see --z).
    #[arg(long = "dem", value_name = "FILE.tif")]
    dems: Vec<PathBuf>,
    /// CRS of the --dem files, when their GeoKeys name none (or name the wrong one).
    #[arg(long, value_name = "EPSG:xxxx")]
    dem_crs: Option<String>,
    /// How a z column is meant with --dem: absolute (a ground elevation: the DEM
    /// is not used for that row) or relative (height above the DEM's ground).
    #[arg(long, value_enum, default_value_t = bake::ground::ZMode::Absolute)]
    z: bake::ground::ZMode,
    /// No terrain tiles (trees still stand on --dem heights). Without it, a
    /// scene without a DEM gets a ground fitted to its trees' bases.
    #[arg(long)]
    no_terrain: bool,
    /// Vertex spacing of the finest terrain level in metres (default: the
    /// DEM's pixel size; coarser spacing: fewer bytes, smoother ground).
    #[arg(long, value_name = "M")]
    terrain_resolution: Option<f64>,
    /// Trees outside every --dem (or on its nodata pixels): error stops the bake
    /// and says how many and where; skip leaves them out (reported).
    #[arg(long, value_enum, default_value_t = bake::ground::OutsideDem::Error)]
    outside_dem: bake::ground::OutsideDem,
    /// Orthophoto, an RGB(A) GeoTIFF (repeat for several; 8- or 16-bit grey,
    /// RGB or RGBA, strips or tiles, deflate/LZW, GDAL nodata): draped on the
    /// terrain as ground imagery, baked into one 256² JPEG per terrain tile
    /// down to the photo's resolution. Needs terrain (--dem, or a fitted ground).
    #[arg(long = "ortho", value_name = "FILE.tif")]
    orthos: Vec<PathBuf>,
    /// CRS of the --ortho files, when their GeoKeys name none (or name the wrong one).
    #[arg(long, value_name = "EPSG:xxxx")]
    ortho_crs: Option<String>,
    /// Without --ortho the terrain gets a procedural forest floor as its
    /// imagery (litter under the canopy, dry grass in clearings, soil on steep
    /// slopes, from the trees' crowns); this leaves it out (fewer bytes: the
    /// viewer's plain ground material by slope).
    #[arg(long, conflicts_with = "orthos")]
    plain_ground: bool,
    #[command(flatten)]
    pack: PackArgs,
    /// Trees held in memory at once while tiling; larger inputs are partitioned
    /// by tile into temporary bucket files inside --out (about 56 bytes per tree).
    #[arg(long, default_value_t = 4_000_000, value_parser = clap::value_parser!(u64).range(1..))]
    bucket_trees: u64,
    #[command(flatten)]
    output: OutArgs,
}

/// Where a scene is written.
#[derive(Args, Clone)]
struct OutArgs {
    /// Output scene folder. A re-bake replaces only the files an earlier bake
    /// wrote there (listed in its .sylva-bake-files.json), and the new scene
    /// appears whole or not at all. A folder holding other files is refused
    /// (see --force); a symbolic link is followed.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Write into an --out folder that holds files no bake wrote (inputs,
    /// notes): the scene goes beside them, and they are kept.
    #[arg(long)]
    force: bool,
}

#[derive(Args)]
struct DemoArgs {
    #[command(flatten)]
    output: OutArgs,
    /// Number of trees.
    #[arg(long, default_value_t = 100_000)]
    trees: usize,
    /// Random seed (same seed → same bytes).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Also write the layout as a lon/lat placements CSV (input for `bake` benchmarks).
    #[arg(long, value_name = "PATH.csv")]
    write_placements: Option<PathBuf>,
    /// No terrain tiles (the trees still stand on the demo's hills).
    #[arg(long)]
    no_terrain: bool,
    /// The land: `valley`, a forest valley a few km across (held in memory);
    /// `country`, an island country of hills, lakes, farmland and woods, about
    /// 100 km across for 10^8 trees, generated block by block and streamed
    /// into bucket files (bounded memory, coarser ground: 16 m terrain, 8 m
    /// imagery); `auto`, the valley up to 10^7 trees and the country above.
    #[arg(long, value_enum, default_value_t = DemoLayout::Auto)]
    layout: DemoLayout,
    /// Trees held in memory at once while tiling the country; the rest wait in
    /// bucket files inside --out (about 56 bytes per tree).
    #[arg(long, default_value_t = 4_000_000, value_parser = clap::value_parser!(u64).range(1..))]
    bucket_trees: u64,
    #[command(flatten)]
    pack: PackArgs,
}

/// `demo --layout`.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum DemoLayout {
    Auto,
    Valley,
    Country,
}

/// The tree count above which `--layout auto` makes the country.
const COUNTRY_ABOVE: usize = 10_000_000;

fn log(msg: &str) {
    eprintln!("{msg}");
}

fn main() {
    sylva::render::context::ensure_runtime_dir();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Bake(args) => bake(&args),
        Command::Demo(args) => demo(&args),
        Command::BenchClusters { model, leaves, tries } => bench_clusters(model.as_deref(), leaves, tries),
        Command::Export3dTiles { scene, out, no_ground, height_offset } => {
            let started = Instant::now();
            let mut last = Instant::now();
            let options = tiles3d::ExportOptions { ground: !no_ground, height_offset_m: height_offset };
            tiles3d::export(&scene, &out, options, &mut |r| {
                if last.elapsed().as_secs_f64() > 2.0 {
                    log(&format!("exported {} tiles, {} trees…", r.tiles, r.trees));
                    last = Instant::now();
                }
            })
            .map(|r| {
                log(&format!(
                    "wrote {}: tileset.json, {} tiles ({} GLBs), {} trees, {} ground tiles, {:.2} MB in {:.1} s",
                    out.display(),
                    r.tiles,
                    r.glbs,
                    r.trees,
                    r.ground_tiles,
                    r.bytes as f64 / 1e6,
                    started.elapsed().as_secs_f64()
                ));
            })
        }
        Command::Merge { dirs, output, index_node_tiles, canopy_cell } => {
            let started = Instant::now();
            let out = output.out.clone();
            let inputs: Vec<&std::path::Path> = dirs.iter().map(PathBuf::as_path).collect();
            merge::refuse_output_among_inputs(&output.out, &dirs)
                .and_then(|()| OutDir::prepare(&output.out, &inputs, output.force, &log))
                .and_then(|dir| merge::merge(&dirs, dir, index_node_tiles, canopy_cell, &log))
                .map(|m| {
                    log(&format!(
                        "wrote {}: {} trees, {} batches, {} tiles{} in {:.1} s",
                        out.display(),
                        m.counts.trees,
                        m.counts.batches,
                        m.counts.tiles,
                        m.index.as_ref().map_or(String::new(), |i| format!(", {} index nodes", i.nodes)),
                        started.elapsed().as_secs_f64()
                    ));
                })
        }
        Command::Inspect { path, json } => inspect::inspect(&path).map(|v| {
            if json {
                println!("{}", serde_json::to_string_pretty(&v).unwrap_or_default());
            } else {
                print!("{}", inspect::to_text(&v));
            }
        }),
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn report_summary(s: &SceneSummary, out: &std::path::Path, started: Instant) {
    let m = &s.manifest;
    log(&format!(
        "wrote {}: {} trees, {} species, {} batches, {} tiles, {:.2} instance bytes per tree (packs {:.1} s, tiles {:.1} s, total {:.1} s)",
        out.display(),
        m.counts.trees,
        m.species.len(),
        m.counts.batches,
        m.counts.tiles,
        s.instance_bytes as f64 / m.counts.trees.max(1) as f64,
        s.pack_seconds,
        s.tile_seconds,
        started.elapsed().as_secs_f64()
    ));
}

/// `--canopy-cell`: a width in metres from 1 to 10,000.
fn parse_canopy_cell(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|_| format!("{s:?} is not a number of metres"))?;
    if (1.0..=10_000.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{v} m: the finest canopy cells must be 1–10,000 m wide"))
    }
}

fn demo(args: &DemoArgs) -> Result<()> {
    let started = Instant::now();
    if args.trees == 0 {
        bail!("--trees must be at least 1");
    }
    let out = OutDir::prepare(&args.output.out, &[], args.output.force, &log)?;
    let country = match args.layout {
        DemoLayout::Auto => args.trees > COUNTRY_ABOVE,
        DemoLayout::Valley => false,
        DemoLayout::Country => true,
    };
    if country {
        return demo_country(args, out, started);
    }
    log(&format!("demo: {} trees, seed {}", args.trees, args.seed));
    let species = demo::demo_models(args.seed);
    let trees = demo::demo_layout(args.trees, args.seed);
    if let Some(path) = &args.write_placements {
        let mut csv = PlacementsCsv::create(path, &species, demo::DEMO_EPSG)?;
        csv.write(&trees, demo::DEMO_ORIGIN)?;
        csv.finish()?;
        log(&format!("wrote {} placements to {}", trees.len(), path.display()));
    }
    // The demo's hills as terrain: the trees' extent and 200 m around, at 8 m.
    let ground = |x: f64, y: f64| Some(demo::ground(x, y) as f32 - demo::DEMO_ORIGIN.z as f32);
    let bounds = trees.iter().fold([f64::MAX, f64::MAX, f64::MIN, f64::MIN], |b, t| {
        [b[0].min(t.pos.x), b[1].min(t.pos.y), b[2].max(t.pos.x), b[3].max(t.pos.y)]
    });
    let margin = ((bounds[2] - bounds[0]).max(bounds[3] - bounds[1]) * 0.25).max(200.0);
    let region = [bounds[0] - margin, bounds[1] - margin, bounds[2] + margin, bounds[3] + margin];
    let terrain = (!args.no_terrain).then(|| bake::terrain::TerrainSource {
        height: &ground,
        region,
        resolution_m: 4.0,
        source: "demo valley".into(),
    });
    // Its ground imagery: the forest floor under the demo's crowns, the stream and its meadows.
    let mut canopy = bake::ground_material::CanopyCover::new(bounds, 2.0);
    for t in &trees {
        canopy.add(t.pos.x, t.pos.y, demo::crown_radius_m(t.species, t.scale));
    }
    let colour = |x: f64, y: f64| {
        let slope = bake::ground_material::slope_of(&ground, x, y, 1.0);
        Some(demo::ground_colour(x, y, canopy.at(x, y), slope))
    };
    let imagery = terrain.as_ref().map(|_| bake::imagery::ImagerySource {
        colour: &colour,
        extent_m: region,
        resolution_m: bake::ground_material::FLOOR_RESOLUTION_M,
        supersample: 2,
        source: "demo forest floor, stream and meadows".into(),
    });
    let cell_size_m = args.pack.cell_size(&trees)?;
    bake_demo(args, out, started, (terrain, imagery), species, TreeSource::Memory(trees), cell_size_m)
}

/// Bakes a demo scene (valley or country) from its ground, species and trees.
fn bake_demo(
    args: &DemoArgs,
    out: OutDir,
    started: Instant,
    (terrain, imagery): (Option<bake::terrain::TerrainSource<'_>>, Option<bake::imagery::ImagerySource<'_>>),
    species: Vec<(String, gltf_import::ImportedModel)>,
    trees: TreeSource,
    cell_size_m: u32,
) -> Result<()> {
    let input = SceneInput {
        terrain,
        imagery,
        cell_size_m,
        species,
        trees,
        crs: Crs::projected(demo::DEMO_EPSG)?,
        origin_m: demo::DEMO_ORIGIN,
        tile_cells: args.pack.tile_cells,
        pack: args.pack.options()?,
        debug_dump: args.pack.debug_dump.clone(),
        pack_cache: args.pack.pack_cache.clone(),
        shard: args.pack.shard,
        index_node_tiles: args.pack.index_node_tiles,
        canopy_cell_m: args.pack.canopy_cell,
        attributes: None,
        text_ids: None,
    };
    let s = bake::bake_scene(&input, out, &log)?;
    report_summary(&s, &args.output.out, started);
    Ok(())
}

/// `demo --layout country`: the trees generated row by row of blocks into
/// bucket files by tile, the ground from the country's fields.
fn demo_country(args: &DemoArgs, out: OutDir, started: Instant) -> Result<()> {
    let trees = args.trees as u64;
    log(&format!("demo: a country of {trees} trees, seed {}", args.seed));
    let land = country::Country::new(trees, args.seed)?;
    let side_km = land.half_m / 500.0;
    log(&format!("country: {side_km:.0} × {side_km:.0} km, {} blocks of {} m", land.blocks().pow(2), country::BLOCK_M));
    let species = demo::demo_models(args.seed);
    let cell_size_m = match args.pack.cell_size {
        Some(_) => args.pack.cell_size(&[])?,
        None => batching::cell_size_for(trees, land.forest_cells64(), 500.0),
    };
    let buckets = trees.div_ceil(args.bucket_trees).max(1) as u32;
    let mut csv = match &args.write_placements {
        Some(path) => Some(PlacementsCsv::create(path, &species, demo::DEMO_EPSG)?),
        None => None,
    };
    let dir = out.scratch("buckets");
    let mut writer = bucket::BucketWriter::new(&dir, buckets, cell_size_m, args.pack.tile_cells)?;
    let t0 = Instant::now();
    let mut made = 0u64;
    let mut reported = 0u64;
    for row in 0..land.blocks() {
        let trees_of_row = land.row(row, made);
        made += trees_of_row.len() as u64;
        if let Some(w) = csv.as_mut() {
            w.write(&trees_of_row, demo::DEMO_ORIGIN)?;
        }
        for t in &trees_of_row {
            let mine = args.pack.shard.is_none_or(|(i, n)| {
                let (x, y) = batching::tile_of(t.pos, cell_size_m, args.pack.tile_cells);
                batching::shard_of_tile(x, y, n) == i
            });
            if mine {
                writer.push(t)?;
            }
        }
        if made >= reported + trees / 10 || row + 1 == land.blocks() {
            reported = made;
            log(&format!(
                "country: {made} of {trees} trees placed ({:.0} %, {:.0} s)",
                made as f64 * 100.0 / trees.max(1) as f64,
                t0.elapsed().as_secs_f64()
            ));
        }
    }
    if made < trees {
        log(&format!("country: {made} trees placed, not {trees}: some blocks' forest was too scarce for their share"));
    }
    if let Some(w) = csv.take() {
        let path = w.finish()?;
        log(&format!("wrote {made} placements to {}", path.display()));
    }
    let source = writer.finish()?;
    let ground = |x: f64, y: f64| Some(land.ground(x, y) as f32);
    let terrain = (!args.no_terrain).then(|| bake::terrain::TerrainSource {
        height: &ground,
        region: land.extent(),
        resolution_m: 16.0,
        source: "synthetic country".into(),
    });
    let colour = |x: f64, y: f64| Some(land.colour(x, y));
    let imagery = terrain.as_ref().map(|_| bake::imagery::ImagerySource {
        colour: &colour,
        extent_m: land.extent(),
        resolution_m: 8.0,
        supersample: 2,
        source: "synthetic country: sea, lakes, fields, woods".into(),
    });
    bake_demo(args, out, started, (terrain, imagery), species, source, cell_size_m)
}

fn bench_clusters(model: Option<&std::path::Path>, leaves: Option<usize>, tries: usize) -> Result<()> {
    let model = match (model, leaves) {
        (Some(p), _) => gltf_import::import(p, &Classifier::default())?,
        (None, Some(n)) => demo::tree_with_leaves(n, 1),
        (None, None) => bail!("give --model or --leaves"),
    };
    let (leaf_tris, branch_tris) = model.triangle_counts();
    log(&format!("model: {leaf_tris} leaf + {branch_tris} branch triangles"));
    let gpu = sylva::render::GpuContext::new_headless_blocking()?;
    let pipelines = sylva::render::capture::CapturePipelines::new(&gpu.device, wgpu::TextureFormat::Rgba8UnormSrgb);
    let opts = PackOptions { cluster_tries: tries, ..PackOptions::default() };
    let no_clusters = PackOptions { clusters: false, ..opts.clone() };
    let t0 = Instant::now();
    pack_build::build_pack("bench", &model, &no_clusters, &gpu, &pipelines)?;
    let without = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let built = pack_build::build_pack("bench", &model, &opts, &gpu, &pipelines)?;
    let with = t1.elapsed().as_secs_f64();
    let decoded = sylva::format::decode_pack("bench", &built.bytes)?;
    let summary = inspect::pack_summary(&decoded, built.bytes.len() as u64);
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

/// Trees written as a lon/lat CSV (`id,species,lat,lng,z,height`),
/// reprojected from the scene CRS, a batch at a time.
struct PlacementsCsv {
    path: PathBuf,
    w: std::io::BufWriter<std::fs::File>,
    inverse: Reprojector,
    names: Vec<String>,
    heights: Vec<f32>,
}

impl PlacementsCsv {
    fn create(path: &std::path::Path, species: &[(String, gltf_import::ImportedModel)], epsg: u32) -> Result<Self> {
        use std::io::Write as _;
        let inverse = Reprojector::new(Crs::projected(epsg)?, &Crs::from_epsg(4326)?)?;
        if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
            crate::out_dir::create_dir(parent)?;
        }
        let file = std::fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
        let mut w = std::io::BufWriter::new(file);
        writeln!(w, "id,species,lat,lng,z,height")?;
        Ok(Self {
            path: path.to_path_buf(),
            w,
            inverse,
            names: species.iter().map(|(n, _)| n.clone()).collect(),
            heights: species.iter().map(|(_, m)| m.height()).collect(),
        })
    }

    fn write(&mut self, trees: &[SceneTree], origin: DVec3) -> Result<()> {
        use std::io::Write as _;
        for t in trees {
            let (lon, lat) = self.inverse.apply(origin.x + t.pos.x, origin.y + t.pos.y)?;
            let s = t.species as usize;
            writeln!(
                self.w,
                "{},{},{lat:.8},{lon:.8},{:.2},{:.2}",
                t.id,
                self.names[s],
                t.pos.z + origin.z,
                t.scale * self.heights[s]
            )
            .with_context(|| format!("cannot write {}", self.path.display()))?;
        }
        Ok(())
    }

    fn finish(mut self) -> Result<PathBuf> {
        use std::io::Write as _;
        self.w.flush().with_context(|| format!("cannot write {}", self.path.display()))?;
        Ok(self.path)
    }
}

fn split_pair<'a>(flag: &str, s: &'a str) -> Result<(&'a str, &'a str)> {
    match s.split_once('=') {
        Some((a, b)) if !a.trim().is_empty() && !b.trim().is_empty() => Ok((a.trim(), b.trim())),
        _ => bail!("{flag} {s:?}: expected NAME=VALUE"),
    }
}

fn bake(args: &BakeArgs) -> Result<()> {
    if let Some(r) = args.terrain_resolution {
        if !(r.is_finite() && r > 0.0) {
            bail!("--terrain-resolution {r}: must be a positive number of metres");
        }
        if args.dems.is_empty() {
            bail!("--terrain-resolution needs a --dem");
        }
    }
    let started = Instant::now();
    let pack_opts = args.pack.options()?;
    let fixed_cell_size = args.pack.cell_size.map(|_| args.pack.cell_size(&[])).transpose()?;
    // The output folder is checked before any long work.
    let mut inputs: Vec<&std::path::Path> = vec![args.placements.as_path()];
    inputs.extend(args.allometry.as_deref());
    inputs.extend(args.dems.iter().map(PathBuf::as_path));
    inputs.extend(args.orthos.iter().map(PathBuf::as_path));
    if !args.orthos.is_empty() && args.no_terrain {
        bail!("--ortho drapes imagery on the terrain: it cannot be used with --no-terrain");
    }
    let orthos = bake::imagery::Orthos::open(&args.orthos, args.ortho_crs.as_deref(), &log)?;
    for m in &args.models {
        inputs.push(std::path::Path::new(split_pair("--model", m)?.1));
    }
    let allometry = match &args.allometry {
        Some(path) => allometry::Allometry::with_overrides(path)?,
        None => allometry::Allometry::built_in(),
    };
    let out = OutDir::prepare(&args.output.out, &inputs, args.output.force, &log)?;
    let species = import_models(args)?;
    let map = species_map(args, &species)?;
    // Placements, streamed: the file is read from disk on every pass, so inputs
    // larger than memory bake in bounded memory.
    let input_crs = args.input_crs.as_deref().map(Crs::parse).transpose()?;
    let options = trees::TreeOptions {
        placements: &args.placements,
        read: placements::ReadOptions {
            encoding: args.encoding,
            delimiter: args.delimiter,
            swap_xy: args.swap_xy,
            projected: input_crs.as_ref().is_some_and(|c| !c.is_geographic()),
            columns: args.columns.clone(),
            dbh_unit: args.dbh_unit,
            attributes: if args.no_attributes { Some(Vec::new()) } else { args.attributes.clone() },
        },
        crs: args.crs.as_deref(),
        input_crs: args.input_crs.as_deref(),
        max_extent_km: args.max_extent_km,
        default_height: args.default_height,
        cell_size_m: fixed_cell_size,
        bucket_trees: args.bucket_trees,
        tile_cells: args.pack.tile_cells,
        shard: args.pack.shard,
        allometry: &allometry,
        dems: &args.dems,
        dem_crs: args.dem_crs.as_deref(),
        z_mode: args.z,
        outside_dem: args.outside_dem,
        fit_ground: !args.no_terrain,
    };
    let placed = trees::place_trees(&options, &map, &out, &log)?;
    let ground_height = placed.ground.as_ref().map(|(g, _)| {
        let (ox, oy, oz) = (placed.origin_m.x, placed.origin_m.y, placed.origin_m.z);
        move |x: f64, y: f64| g.height_at(x + ox, y + oy).map(|h| h - oz as f32)
    });
    let fitted_height = placed.fitted.as_ref().map(|(f, _)| move |x: f64, y: f64| Some(f.height(x, y)));
    let fitted =
        placed.fitted.as_ref().zip(fitted_height.as_ref()).map(|((f, region), height)| bake::terrain::TerrainSource {
            height,
            region: *region,
            resolution_m: f.cell_m(),
            source: "fitted to the trees' bases (no --dem)".into(),
        });
    let terrain =
        placed.ground.as_ref().zip(ground_height.as_ref()).map(|((g, region), height)| bake::terrain::TerrainSource {
            height,
            region: *region,
            resolution_m: args.terrain_resolution.unwrap_or_else(|| g.resolution_m()),
            source: g.names(),
        });
    let terrain = if args.no_terrain { None } else { terrain.or(fitted) };
    let orthos = if orthos.is_empty() { None } else { Some(orthos.in_scene(&placed.crs)?) };
    let ortho_colour = orthos.as_ref().map(|o| {
        let (ox, oy) = (placed.origin_m.x, placed.origin_m.y);
        move |x: f64, y: f64| o.colour_at(x + ox, y + oy)
    });
    // Without an orthophoto: the forest floor by canopy and slope.
    let height_fn: Option<&(dyn Fn(f64, f64) -> Option<f32> + Sync)> = terrain.as_ref().map(|t| t.height);
    let floor_colour = height_fn.map(|height| {
        let canopy = &placed.canopy;
        move |x: f64, y: f64| {
            let slope = bake::ground_material::slope_of(height, x, y, 1.0);
            height(x, y).map(|_| bake::ground_material::forest_floor(x, y, canopy.at(x, y), slope))
        }
    });
    let imagery = match (&orthos, &ortho_colour) {
        (None, _) if !args.plain_ground => {
            terrain.as_ref().zip(floor_colour.as_ref()).map(|(t, colour)| bake::imagery::ImagerySource {
                colour,
                extent_m: t.region,
                resolution_m: bake::ground_material::FLOOR_RESOLUTION_M,
                supersample: 2,
                source: "procedural forest floor (canopy cover and slope)".into(),
            })
        }
        (Some(o), Some(colour)) => {
            let e = o.scene_extent().context("the --ortho extent cannot be projected into the scene CRS")?;
            let (ox, oy) = (placed.origin_m.x, placed.origin_m.y);
            Some(bake::imagery::ImagerySource {
                colour,
                extent_m: [e[0] - ox, e[1] - oy, e[2] - ox, e[3] - oy],
                resolution_m: o.resolution_m(),
                supersample: 4,
                source: o.names(),
            })
        }
        _ => None,
    };
    let input = SceneInput {
        terrain,
        imagery,
        cell_size_m: placed.cell_size_m,
        species,
        trees: placed.trees,
        crs: placed.crs,
        origin_m: placed.origin_m,
        tile_cells: args.pack.tile_cells,
        pack: pack_opts,
        debug_dump: args.pack.debug_dump.clone(),
        pack_cache: args.pack.pack_cache.clone(),
        shard: args.pack.shard,
        index_node_tiles: args.pack.index_node_tiles,
        canopy_cell_m: args.pack.canopy_cell,
        attributes: placed.attributes,
        text_ids: placed.text_ids,
    };
    log(&format!("batching with {} m cells", input.cell_size_m));
    let s = bake::bake_scene(&input, out, &log)?;
    report_summary(&s, &args.output.out, started);
    Ok(())
}

/// The `--model` files, imported (names unique).
fn import_models(args: &BakeArgs) -> Result<Vec<(String, gltf_import::ImportedModel)>> {
    let classifier =
        Classifier { leaf_patterns: args.leaf_materials.clone(), branch_patterns: args.branch_materials.clone() };
    let mut species: Vec<(String, gltf_import::ImportedModel)> = Vec::new();
    for m in &args.models {
        let (name, path) = split_pair("--model", m)?;
        if species.iter().any(|(n, _)| n.eq_ignore_ascii_case(name)) {
            bail!("--model {name} is given twice");
        }
        let model = gltf_import::import(std::path::Path::new(path), &classifier)?;
        let (leaf, wood) = model.triangle_counts();
        log(&format!(
            "model {name}: {} materials, {leaf} leaf + {wood} branch triangles, height {:.2} (model units)",
            model.materials.len(),
            model.height()
        ));
        for note in &model.notes {
            log(&format!("model {name}: {note}"));
        }
        species.push((name.to_string(), model));
    }
    Ok(species)
}

/// Which model each species label uses, from `--map` and `--default-model`.
fn species_map(args: &BakeArgs, species: &[(String, gltf_import::ImportedModel)]) -> Result<trees::SpeciesMap> {
    let mut map = trees::SpeciesMap {
        names: species.iter().map(|(n, _)| n.clone()).collect(),
        heights: species.iter().map(|(_, m)| m.height()).collect(),
        crown_widths: species.iter().map(|(_, m)| m.crown_width()).collect(),
        maps: Vec::new(),
        default: None,
    };
    for m in &args.maps {
        let (pattern, name) = split_pair("--map", m)?;
        let idx = map.model(name).with_context(|| format!("--map {m}: no --model named {name:?}"))?;
        map.maps.push((pattern.to_string(), idx));
    }
    map.default = match &args.default_model {
        Some(n) => Some(map.model(n).with_context(|| format!("--default-model {n}: no --model with that name"))?),
        None if species.len() == 1 => {
            log(&format!("one --model: every tree uses {} whatever its species label", species[0].0));
            Some(0)
        }
        None => None,
    };
    Ok(map)
}
