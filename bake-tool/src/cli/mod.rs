//! The command line of `sylva-bake`: the subcommands (clap), each run by
//! its own file (`bake.rs`, `demo.rs`, `bench.rs`, `library.rs`; `pack.rs` the options
//! every bake of packs takes); `merge`, `inspect` and `export-3dtiles` call
//! the library directly.

mod bake;
mod bench;
mod demo;
mod library;
mod pack;
mod stands;

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Result};
use clap::{Args, Parser, Subcommand};
use sylva::format::canopy::FINEST_CELL_M;
use sylva::format::index::DEFAULT_NODE_TILES;
use sylva_bake::bake::SceneSummary;
use sylva_bake::out_dir::OutDir;

use bake::{bake, BakeArgs, PlacementsCsv};
use bench::bench_clusters;
use demo::{demo, DemoArgs};
use library::{library, LibraryCommand};
use pack::parse_delimiter;
use pack::PackArgs;
use stands::{stands, StandsArgs};

#[derive(Parser)]
#[command(
    name = "sylva-bake",
    version,
    about = "Bake glTF trees and tree placements into a Sylva scene (LoD packs + grouped-batch tiles)."
)]
pub(crate) struct Cli {
    #[command(subcommand)]
    pub(crate) command: Command,
}

#[derive(Subcommand)]
pub(crate) enum Command {
    /// Bake real models and placements into a scene directory.
    #[command(
        after_help = "Example:\n  sylva-bake bake --model oak=oak.glb --model pine=pine.glb \\\n    --placements trees.csv --map 'quercus*=oak' --map 'pinus*=pine' --default-model oak --out scene/"
    )]
    Bake(Box<BakeArgs>),
    /// Make a complete procedural demo scene (three species, UTM 33N, no input files).
    Demo(DemoArgs),
    /// Benchmark the cluster-level bake (Clasen et al. 2010) of one model: timing and,
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
        /// The season deciduous species are exported in: leaf-on, autumn (leaf
        /// textures in their autumn colour) or leaf-off (no leaves, the bare
        /// wood's far quads). Export one tileset per season to offer them all.
        #[arg(long, value_name = "leaf-on|autumn|leaf-off", default_value = "leaf-on")]
        season: sylva::format::pack::Season,
    },
    /// The built-in species library: trees generated per genus (Weber & Penn 1995),
    /// usable as `--model NAME=library:GENUS[:VARIANT]`.
    #[command(subcommand, after_help = "Example:\n  sylva-bake library list")]
    Library(LibraryCommand),
    /// The trees a stand map makes (as `bake --stands` makes them), written as a
    /// CSV, with a report per stand: to look at in a GIS before a bake, or to
    /// compare with an inventory.
    #[command(
        after_help = "Example:\n  sylva-bake stands district.gpkg --layer bestaende --out trees.csv\n  sylva-bake bake --stands district.gpkg --layer bestaende --out scene/"
    )]
    Stands(StandsArgs),
    /// Add the geographic fit (lon/lat ↔ scene metres, `crs.fit`) to a scene
    /// baked before bakes wrote it: browsers need it for geographic cameras,
    /// links, the sun at a date and XYZ imagery. Rewrites only scene.json.
    #[command(after_help = "Example:\n  sylva-bake geo-fit scene/")]
    GeoFit {
        /// The baked scene folder (with scene.json).
        scene: PathBuf,
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

pub(crate) fn log(msg: &str) {
    eprintln!("{msg}");
}

pub(crate) fn report_summary(s: &SceneSummary, out: &std::path::Path, started: Instant) {
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
pub(crate) fn parse_canopy_cell(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|_| format!("{s:?} is not a number of metres"))?;
    if (1.0..=10_000.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{v} m: the finest canopy cells must be 1–10,000 m wide"))
    }
}

/// Where a scene is written.
#[derive(Args, Clone)]
pub(crate) struct OutArgs {
    /// Output scene folder. A re-bake replaces only the files an earlier bake
    /// wrote there (listed in its .sylva-bake-files.json), and the new scene
    /// appears whole or not at all. A folder holding other files is refused
    /// (see --force); a symbolic link is followed.
    #[arg(long, value_name = "DIR")]
    pub(crate) out: PathBuf,
    /// Write into an --out folder that holds files no bake wrote (inputs,
    /// notes): the scene goes beside them, and they are kept.
    #[arg(long)]
    pub(crate) force: bool,
}

pub(crate) fn split_pair<'a>(flag: &str, s: &'a str) -> Result<(&'a str, &'a str)> {
    match s.split_once('=') {
        Some((a, b)) if !a.trim().is_empty() && !b.trim().is_empty() => Ok((a.trim(), b.trim())),
        _ => bail!("{flag} {s:?}: expected NAME=VALUE"),
    }
}

pub(crate) fn main() {
    sylva::render::context::ensure_runtime_dir();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Bake(args) => bake(&args),
        Command::Demo(args) => demo(&args),
        Command::Library(command) => library(&command),
        Command::Stands(args) => stands(&args),
        Command::BenchClusters { model, leaves, tries } => bench_clusters(model.as_deref(), leaves, tries),
        Command::Export3dTiles { scene, out, no_ground, height_offset, season } => {
            let started = Instant::now();
            let mut last = Instant::now();
            let options = sylva_bake::export::tiles3d::ExportOptions {
                ground: !no_ground,
                height_offset_m: height_offset,
                season,
            };
            sylva_bake::export::tiles3d::export(&scene, &out, options, &mut |r| {
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
            sylva_bake::merge::refuse_output_among_inputs(&output.out, &dirs)
                .and_then(|()| OutDir::prepare(&output.out, &inputs, output.force, &log))
                .and_then(|dir| sylva_bake::merge::merge(&dirs, dir, index_node_tiles, canopy_cell, &log))
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
        Command::GeoFit { scene } => sylva_bake::bake::scene_write::add_geo_fit(&scene, &log).map(|_| ()),
        Command::Inspect { path, json } => sylva_bake::inspect::inspect(&path).map(|v| {
            if json {
                println!("{}", serde_json::to_string_pretty(&v).unwrap_or_default());
            } else {
                print!("{}", sylva_bake::inspect::to_text(&v));
            }
        }),
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
