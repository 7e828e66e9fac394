//! `sylva-bake`: turns glTF trees and tree placements into a Sylva scene
//! (LoD packs + grouped-batch tiles + manifest). See `--help`.

mod batching;
mod bucket;
mod clusters;
mod demo;
use sylva_bake::gltf_import;
mod inspect;
mod merge;
mod out_dir;
mod pack_build;
mod placements;
mod reproject;
mod rng;
mod scene_write;

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand};
use glam::DVec3;

use batching::{default_cell_size, SceneTree, MAX_CELL_SIZE_M};
use bucket::TreeSource;
use gltf_import::Classifier;
use out_dir::OutDir;
use pack_build::PackOptions;
use placements::CoordKind;
use placements::{Placement, PlacementSource};
use reproject::{Crs, Reprojector};
use scene_write::{SceneInput, SceneSummary};
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
    Bake(BakeArgs),
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
    /// Material texture size (power of two).
    #[arg(long, default_value_t = 512)]
    texture_size: u32,
    /// Do not add the simplified mesh level.
    #[arg(long)]
    no_simplified_level: bool,
    /// Do not add clustered-ellipsoid and line levels (seed 002).
    #[arg(long)]
    no_clusters: bool,
    /// EM starts per cluster level; the one with the lowest image error is kept.
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=32))]
    cluster_tries: u32,
    /// Write billboard layers as PNG strips into this directory.
    #[arg(long, value_name = "DIR")]
    debug_dump: Option<PathBuf>,
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
        for (name, v, max) in
            [("--billboard-size", self.billboard_size, 2048), ("--texture-size", self.texture_size, 4096)]
        {
            if !v.is_power_of_two() || v < 4 || v > max {
                bail!("{name} {v}: must be a power of two between 4 and {max}");
            }
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
    /// Height in metres for rows without one (default: the median of the given heights).
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
    /// Rows farther than this from the median position are outliers and skipped.
    #[arg(long, default_value_t = 100.0)]
    max_extent_km: f64,
    /// Material/mesh/node name pattern forced to leaves (repeatable).
    #[arg(long = "leaf-material", value_name = "PATTERN")]
    leaf_materials: Vec<String>,
    /// Material/mesh/node name pattern forced to branches (repeatable).
    #[arg(long = "branch-material", value_name = "PATTERN")]
    branch_materials: Vec<String>,
    #[command(flatten)]
    pack: PackArgs,
    /// Trees held in memory at once while tiling; larger inputs are partitioned
    /// by tile into temporary bucket files inside --out (about 48 bytes per tree).
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
    #[command(flatten)]
    pack: PackArgs,
}

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
        Command::Merge { dirs, output, index_node_tiles } => {
            let started = Instant::now();
            let out = output.out.clone();
            let inputs: Vec<&std::path::Path> = dirs.iter().map(PathBuf::as_path).collect();
            OutDir::prepare(&output.out, &inputs, output.force, &log)
                .and_then(|dir| merge::merge(&dirs, dir, index_node_tiles, &log))
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

fn demo(args: &DemoArgs) -> Result<()> {
    let started = Instant::now();
    if args.trees == 0 {
        bail!("--trees must be at least 1");
    }
    let out = OutDir::prepare(&args.output.out, &[], args.output.force, &log)?;
    log(&format!("demo: {} trees, seed {}", args.trees, args.seed));
    let species = demo::demo_models(args.seed);
    let trees = demo::demo_layout(args.trees, args.seed);
    if let Some(path) = &args.write_placements {
        write_placements_csv(path, &trees, &species, demo::DEMO_ORIGIN, demo::DEMO_EPSG)?;
        log(&format!("wrote {} placements to {}", trees.len(), path.display()));
    }
    let input = SceneInput {
        cell_size_m: args.pack.cell_size(&trees)?,
        species,
        trees: TreeSource::Memory(trees),
        crs: Crs::projected(demo::DEMO_EPSG)?,
        origin_m: demo::DEMO_ORIGIN,
        tile_cells: args.pack.tile_cells,
        pack: args.pack.options()?,
        debug_dump: args.pack.debug_dump.clone(),
        shard: args.pack.shard,
        index_node_tiles: args.pack.index_node_tiles,
    };
    let s = scene_write::write_scene(&input, out, &log)?;
    report_summary(&s, &args.output.out, started);
    Ok(())
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

/// Writes trees as a lon/lat CSV (`id,species,lat,lng,z,height`), reprojected from the scene CRS.
fn write_placements_csv(
    path: &std::path::Path,
    trees: &[SceneTree],
    species: &[(String, gltf_import::ImportedModel)],
    origin: DVec3,
    epsg: u32,
) -> Result<()> {
    use std::io::Write as _;
    let inverse = Reprojector::new(Crs::projected(epsg)?, &Crs::from_epsg(4326)?)?;
    let heights: Vec<f32> = species.iter().map(|(_, m)| m.height()).collect();
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        scene_write::create_dir(parent)?;
    }
    let file = std::fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    let mut w = std::io::BufWriter::new(file);
    writeln!(w, "id,species,lat,lng,z,height")?;
    for t in trees {
        let (lon, lat) = inverse.apply(origin.x + t.pos.x, origin.y + t.pos.y)?;
        let s = t.species as usize;
        writeln!(
            w,
            "{},{},{lat:.8},{lon:.8},{:.2},{:.2}",
            t.id,
            species[s].0,
            t.pos.z + origin.z,
            t.scale * heights[s]
        )?;
    }
    w.flush()?;
    Ok(())
}

/// Matches a species label against a `--map` pattern.
fn pattern_matches(pattern: &str, label: &str) -> bool {
    let p = pattern.to_lowercase();
    let l = label.to_lowercase();
    if !p.contains('*') {
        return l.contains(&p);
    }
    // Glob with '*' only.
    let parts: Vec<&str> = p.split('*').collect();
    let mut rest = l.as_str();
    for (i, part) in parts.iter().enumerate() {
        if part.is_empty() {
            continue;
        }
        if i == 0 {
            if !rest.starts_with(part) {
                return false;
            }
            rest = &rest[part.len()..];
        } else if let Some(at) = rest.find(part) {
            rest = &rest[at + part.len()..];
        } else {
            return false;
        }
    }
    parts.last().is_none_or(|last| last.is_empty() || l.ends_with(last))
}

fn split_pair<'a>(flag: &str, s: &'a str) -> Result<(&'a str, &'a str)> {
    match s.split_once('=') {
        Some((a, b)) if !a.trim().is_empty() && !b.trim().is_empty() => Ok((a.trim(), b.trim())),
        _ => bail!("{flag} {s:?}: expected NAME=VALUE"),
    }
}

fn bake(args: &BakeArgs) -> Result<()> {
    let started = Instant::now();
    let pack_opts = args.pack.options()?;
    // The output folder is checked before any long work.
    let mut inputs: Vec<&std::path::Path> = vec![args.placements.as_path()];
    for m in &args.models {
        inputs.push(std::path::Path::new(split_pair("--model", m)?.1));
    }
    let out = OutDir::prepare(&args.output.out, &inputs, args.output.force, &log)?;
    let classifier =
        Classifier { leaf_patterns: args.leaf_materials.clone(), branch_patterns: args.branch_materials.clone() };
    // Models.
    let mut species = Vec::new();
    for m in &args.models {
        let (name, path) = split_pair("--model", m)?;
        if species.iter().any(|(n, _): &(String, _)| n.eq_ignore_ascii_case(name)) {
            bail!("--model {name} is given twice");
        }
        let model = gltf_import::import(std::path::Path::new(path), &classifier)?;
        let (leaf, wood) = model.triangle_counts();
        log(&format!(
            "model {name}: {} materials, {leaf} leaf + {wood} branch triangles, height {:.2} (model units)",
            model.materials.len(),
            model.height()
        ));
        species.push((name.to_string(), model));
    }
    let model_index = |name: &str| species.iter().position(|(n, _)| n.eq_ignore_ascii_case(name));
    let mut maps = Vec::new();
    for m in &args.maps {
        let (pattern, name) = split_pair("--map", m)?;
        let idx = model_index(name).with_context(|| format!("--map {m}: no --model named {name:?}"))?;
        maps.push((pattern.to_string(), idx));
    }
    let default_model = match &args.default_model {
        Some(n) => Some(model_index(n).with_context(|| format!("--default-model {n}: no --model with that name"))?),
        None if species.len() == 1 => {
            log(&format!("one --model: every tree uses {} whatever its species label", species[0].0));
            Some(0)
        }
        None => None,
    };
    // Placements, streamed: CSV is read from disk on every pass, so inputs larger
    // than memory bake in bounded memory (trees are partitioned by tile into
    // bucket files when there are more than --bucket-trees of them).
    let input_crs = args.input_crs.as_deref().map(Crs::parse).transpose()?;
    let read_options = placements::ReadOptions {
        encoding: args.encoding,
        delimiter: args.delimiter,
        swap_xy: args.swap_xy,
        projected: input_crs.as_ref().is_some_and(|c| !c.is_geographic()),
    };
    let source = PlacementSource::open(&args.placements, &read_options)?;
    for note in &source.notes {
        log(&format!("placements: {note}"));
    }
    let started_read = Instant::now();
    // Pass 1: a deterministic sample (all rows up to SAMPLE_ROWS) for the CRS,
    // the medians (origin, outliers, default height) and the row count.
    log("pass 1/3: sampling placements");
    let mut sample: Vec<(f64, f64, Option<f32>, u64)> = Vec::new();
    let mut rng = rng::Rng::new(0x5EED_5A3F_1E00_0001);
    let mut seen = 0u64;
    let mut coords = std::collections::HashSet::new();
    let mut duplicates = 0u64;
    let report1 = source.for_each(&mut |p| {
        seen += 1;
        if coords.len() < DUPLICATE_CHECK_ROWS && !coords.insert((p.x.to_bits(), p.y.to_bits())) {
            duplicates += 1;
        }
        let item = (p.x, p.y, p.height_m, p.row);
        if sample.len() < SAMPLE_ROWS {
            sample.push(item);
        } else {
            // Reservoir sampling: every row ends up in the sample with equal odds.
            let j = rng.next_u64() % seen;
            if j < SAMPLE_ROWS as u64 {
                sample[j as usize] = item;
            }
        }
        Ok(())
    })?;
    drop(coords);
    log(&format!(
        "  {} rows read, {} usable ({:.1} s){}",
        report1.rows,
        report1.kept,
        started_read.elapsed().as_secs_f64(),
        if seen as usize > SAMPLE_ROWS { format!("; medians from a sample of {SAMPLE_ROWS}") } else { String::new() }
    ));
    // Longitude and latitude the other way round: most rows' "latitude" beyond
    // ±90° whose "longitude" would be a latitude.
    if report1.swappable > 0 && report1.swappable * 2 >= report1.rows {
        bail!(
            "placements {}: the x/longitude and y/latitude columns look swapped: {} of {} rows have a latitude \
             beyond ±90° and a longitude that would be a valid latitude; {}",
            args.placements.display(),
            report1.swappable,
            report1.rows,
            if args.swap_xy {
                "they are so with --swap-xy: leave it out"
            } else {
                "pass --swap-xy (or rename the columns)"
            }
        );
    }
    if source.kind == CoordKind::LonLat && !sample.is_empty() {
        let mut lons: Vec<f64> = sample.iter().map(|p| p.0).collect();
        let mut lats: Vec<f64> = sample.iter().map(|p| p.1).collect();
        let (lon, lat) = (median(&mut lons), median(&mut lats));
        // Said plainly, so swapped columns that are both valid (52.37, 4.90) are noticed.
        log(&format!(
            "placements centre: {:.4}°{} {:.4}°{} (if this is not where the trees are, the columns are swapped: --swap-xy)",
            lat.abs(),
            if lat >= 0.0 { "N" } else { "S" },
            lon.abs(),
            if lon >= 0.0 { "E" } else { "W" }
        ));
    }
    // CRS.
    let (src, dst) = match source.kind {
        CoordKind::LonLat => {
            let dst = match &args.crs {
                Some(c) => Crs::parse(c)?,
                None => {
                    let mut lons: Vec<f64> = sample.iter().map(|p| p.0).collect();
                    let mut lats: Vec<f64> = sample.iter().map(|p| p.1).collect();
                    if lons.is_empty() {
                        bail!(
                            "placements {}: no usable rows ({})",
                            args.placements.display(),
                            report1.lines().join("; ")
                        );
                    }
                    Crs::utm_for(median(&mut lons), median(&mut lats))?
                }
            };
            // A GeoJSON may name a geographic CRS of its own (ETRS89, NAD83).
            (Crs::from_epsg(source.declared_epsg.unwrap_or(4326))?, dst)
        }
        CoordKind::Projected => {
            let declared = source.declared_epsg.map(|e| format!("EPSG:{e}"));
            let input = args.input_crs.as_deref().or(declared.as_deref()).or(args.crs.as_deref()).context(
                "the placements have projected x/y coordinates: say which CRS they are in with --input-crs EPSG:xxxx",
            )?;
            if args.input_crs.is_none() && declared.is_some() {
                log(&format!("placements: the GeoJSON names its CRS: {input}"));
            }
            let src = Crs::parse(input)?;
            let dst = Crs::parse(args.crs.as_deref().unwrap_or(input))?;
            (src, dst)
        }
    };
    if dst.is_geographic() {
        bail!("--crs EPSG:{} is geographic; a scene needs a projected CRS in metres (e.g. a UTM zone)", dst.epsg);
    }
    log(&format!("scene CRS EPSG:{}", dst.epsg));
    let reproject = Reprojector::new(src, &dst)?;
    // Medians of the projected sample: outliers are far from them.
    let projected_sample: Vec<(f64, f64, Option<f32>)> =
        sample.iter().filter_map(|&(x, y, h, _)| reproject.apply(x, y).ok().map(|(x, y)| (x, y, h))).collect();
    drop(sample);
    let mut xs: Vec<f64> = projected_sample.iter().map(|p| p.0).collect();
    let mut ys: Vec<f64> = projected_sample.iter().map(|p| p.1).collect();
    if xs.is_empty() {
        bail!("no usable placements ({})", report1.lines().join("; "));
    }
    let (mx, my) = (median(&mut xs), median(&mut ys));
    let limit = args.max_extent_km * 1000.0;
    let inside = |x: f64, y: f64| (x - mx).hypot(y - my) <= limit;
    let mut heights: Vec<f32> = projected_sample.iter().filter(|p| inside(p.0, p.1)).filter_map(|p| p.2).collect();
    let default_height = match args.default_height {
        Some(h) if h.is_finite() && h > 0.0 && h < MAX_TREE_HEIGHT_M => Some(h),
        Some(h) => bail!("--default-height {h}: must be a number of metres above 0 and below {MAX_TREE_HEIGHT_M}"),
        None if !heights.is_empty() => {
            let n = heights.len();
            heights.select_nth_unstable_by(n / 2, f32::total_cmp);
            Some(heights[n / 2])
        }
        None => None,
    };
    drop(projected_sample);
    let origin = DVec3::new((mx / 1000.0).round() * 1000.0, (my / 1000.0).round() * 1000.0, 0.0);
    // (The importer refuses models without height.)
    let model_heights: Vec<f32> = species.iter().map(|(_, m)| m.height()).collect();
    let species_of = |label: &str| {
        model_index(label)
            .or_else(|| maps.iter().find(|(pat, _)| pattern_matches(pat, label)).map(|(_, i)| *i))
            .or(default_model)
    };
    // A usable row as a tree, or why not.
    let to_tree = |p: &Placement| -> Result<SceneTree, &'static str> {
        let Ok((x, y)) = reproject.apply(p.x, p.y) else { return Err("cannot be projected to the scene CRS") };
        if !inside(x, y) {
            return Err("outlier");
        }
        let Some(idx) = species_of(p.species.as_deref().unwrap_or("")) else { return Err("unmapped") };
        let model_h = model_heights[idx];
        let target = p.height_m.or(default_height).unwrap_or(model_h);
        let h = demo::hash64(p.row ^ x.to_bits().rotate_left(17) ^ y.to_bits());
        Ok(SceneTree {
            pos: DVec3::new(x - origin.x, y - origin.y, p.z.unwrap_or(0.0) - origin.z),
            species: idx as u32,
            scale: target / model_h,
            yaw_rad: p.yaw_deg.map_or((h % 3600) as f32 / 3600.0 * std::f32::consts::TAU, f32::to_radians),
            variation: ((h >> 20) % 32) as u8,
            id: p.id.unwrap_or(p.row | 1 << 63),
        })
    };
    // Pass 2: the cell size from the density of the trees (unless given).
    let cell_size_m = match args.pack.cell_size {
        Some(_) => args.pack.cell_size(&[])?,
        None => {
            log("pass 2/3: tree density for the cell size");
            let mut cells = std::collections::HashSet::new();
            let mut trees = 0u64;
            source.for_each(&mut |p| {
                if let Ok(t) = to_tree(&p) {
                    trees += 1;
                    cells.insert(batching::cell64(t.pos));
                }
                Ok(())
            })?;
            batching::cell_size_for(trees, cells.len() as u64, 500.0)
        }
    };
    // Pass 3: the trees, in memory or partitioned by tile into bucket files.
    let buckets = report1.kept.div_ceil(args.bucket_trees.max(1)).max(1);
    log(&format!(
        "pass 3/3: trees{}",
        if buckets > 1 {
            format!(" into {buckets} bucket files by tile (--bucket-trees {})", args.bucket_trees)
        } else {
            String::new()
        }
    ));
    let mut report;
    let mut unmapped: std::collections::BTreeMap<String, u64> = Default::default();
    let mut skip = |p: &Placement, why: &str, report: &mut placements::Report| match why {
        "outlier" => {
            report.skip(&format!("farther than {} km from the median position (outlier)", args.max_extent_km), p.row)
        }
        "unmapped" => {
            let label = p.species.as_deref().unwrap_or("");
            *unmapped.entry(if label.is_empty() { "(no species)".into() } else { label.to_string() }).or_default() += 1;
        }
        other => report.skip(other, p.row),
    };
    let mut our_report = placements::Report::default();
    let trees = if buckets > 1 {
        let dir = out.scratch("buckets");
        let mut writer = bucket::BucketWriter::new(&dir, buckets as u32, cell_size_m, args.pack.tile_cells)?;
        report = source.for_each(&mut |p| {
            match to_tree(&p) {
                Ok(t)
                    if args.pack.shard.is_none_or(|(i, n)| {
                        let (x, y) = batching::tile_of(t.pos, cell_size_m, args.pack.tile_cells);
                        batching::shard_of_tile(x, y, n) == i
                    }) =>
                {
                    writer.push(&t)?
                }
                Ok(_) => {}
                Err(why) => skip(&p, why, &mut our_report),
            }
            Ok(())
        })?;
        writer.finish()?
    } else {
        let mut trees = Vec::with_capacity(report1.kept as usize);
        report = source.for_each(&mut |p| {
            match to_tree(&p) {
                Ok(t) => trees.push(t),
                Err(why) => skip(&p, why, &mut our_report),
            }
            Ok(())
        })?;
        TreeSource::Memory(trees)
    };
    for (reason, (n, rows)) in our_report.skipped {
        let e = report.skipped.entry(reason).or_insert((0, Vec::new()));
        e.0 += n;
        e.1.extend(rows);
        e.1.truncate(5);
    }
    report.duplicate_coordinates = duplicates;
    for line in report.lines() {
        log(&format!("placements: {line}"));
    }
    if duplicates > 0 && seen as usize > DUPLICATE_CHECK_ROWS {
        log(&format!("placements: (duplicates counted among the first {DUPLICATE_CHECK_ROWS} rows)"));
    }
    for (label, n) in &unmapped {
        log(&format!(
            "placements: skipped {n} rows of species {label:?}: no --map pattern matches and no --default-model"
        ));
    }
    log(&format!("read the placements 3 times in {:.1} s", started_read.elapsed().as_secs_f64()));
    let input = SceneInput {
        cell_size_m,
        species,
        trees,
        crs: dst,
        origin_m: origin,
        tile_cells: args.pack.tile_cells,
        pack: pack_opts,
        debug_dump: args.pack.debug_dump.clone(),
        shard: args.pack.shard,
        index_node_tiles: args.pack.index_node_tiles,
    };
    log(&format!("batching with {} m cells", input.cell_size_m));
    let s = scene_write::write_scene(&input, out, &log)?;
    report_summary(&s, &args.output.out, started);
    Ok(())
}

/// Tallest tree height accepted (the tallest known tree is 116 m); placement
/// heights outside (0, this) count as missing.
const MAX_TREE_HEIGHT_M: f32 = 200.0;

/// Rows sampled for the medians; inputs up to this size use every row.
const SAMPLE_ROWS: usize = 1_000_000;
/// Rows checked for repeated coordinates (the check keeps a set of them).
const DUPLICATE_CHECK_ROWS: usize = 10_000_000;

fn median(v: &mut [f64]) -> f64 {
    let n = v.len();
    v.select_nth_unstable_by(n / 2, f64::total_cmp);
    v[n / 2]
}

#[cfg(test)]
mod tests {
    use super::pattern_matches;

    #[test]
    fn patterns() {
        assert!(pattern_matches("quercus*", "Quercus robur"));
        assert!(!pattern_matches("quercus*", "Acer quercus"));
        assert!(pattern_matches("*robur", "Quercus robur"));
        assert!(pattern_matches("oak", "Red Oak"));
        assert!(pattern_matches("q*r", "quercus robur"));
        assert!(!pattern_matches("pinus*", "Quercus"));
    }
}
