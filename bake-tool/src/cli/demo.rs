//! `sylva-bake demo`: the procedural demo scene, a valley or a country.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Result};
use clap::Args;
use sylva_bake::bake::bucket::TreeSource;
use sylva_bake::bake::SceneInput;
use sylva_bake::input::reproject::Crs;
use sylva_bake::out_dir::OutDir;

use super::*;

#[derive(Args)]
pub(crate) struct DemoArgs {
    #[command(flatten)]
    pub(crate) output: OutArgs,
    /// Number of trees.
    #[arg(long, default_value_t = 100_000)]
    pub(crate) trees: usize,
    /// Random seed (same seed → same bytes).
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// Also write the layout as a lon/lat placements CSV (input for `bake` benchmarks).
    #[arg(long, value_name = "PATH.csv")]
    pub(crate) write_placements: Option<PathBuf>,
    /// No terrain tiles (the trees still stand on the demo's hills).
    #[arg(long)]
    pub(crate) no_terrain: bool,
    /// The land: `valley`, a forest valley a few km across (held in memory);
    /// `country`, an island country of hills, lakes, farmland and woods, about
    /// 100 km across for 10^8 trees, generated block by block and streamed
    /// into bucket files (bounded memory, coarser ground: 16 m terrain, 8 m
    /// imagery); `auto`, the valley up to 10^7 trees and the country above.
    #[arg(long, value_enum, default_value_t = DemoLayout::Auto)]
    pub(crate) layout: DemoLayout,
    /// Trees held in memory at once while tiling the country; the rest wait in
    /// bucket files inside --out (about 56 bytes per tree).
    #[arg(long, default_value_t = 4_000_000, value_parser = clap::value_parser!(u64).range(1..))]
    pub(crate) bucket_trees: u64,
    #[command(flatten)]
    pub(crate) pack: PackArgs,
}

/// `demo --layout`.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum DemoLayout {
    Auto,
    Valley,
    Country,
}

/// The tree count above which `--layout auto` makes the country.
pub(crate) const COUNTRY_ABOVE: usize = 10_000_000;

pub(crate) fn demo(args: &DemoArgs) -> Result<()> {
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
    let species = sylva_bake::demo::demo_models(args.seed);
    let trees = sylva_bake::demo::demo_layout(args.trees, args.seed);
    if let Some(path) = &args.write_placements {
        let mut csv = PlacementsCsv::create(path, &species, sylva_bake::demo::DEMO_EPSG)?;
        csv.write(&trees, sylva_bake::demo::DEMO_ORIGIN)?;
        csv.finish()?;
        log(&format!("wrote {} placements to {}", trees.len(), path.display()));
    }
    // The demo's hills as terrain: the trees' extent and 200 m around, at 8 m.
    let ground = |x: f64, y: f64| Some(sylva_bake::demo::ground(x, y) as f32 - sylva_bake::demo::DEMO_ORIGIN.z as f32);
    let bounds = trees.iter().fold([f64::MAX, f64::MAX, f64::MIN, f64::MIN], |b, t| {
        [b[0].min(t.pos.x), b[1].min(t.pos.y), b[2].max(t.pos.x), b[3].max(t.pos.y)]
    });
    let margin = ((bounds[2] - bounds[0]).max(bounds[3] - bounds[1]) * 0.25).max(200.0);
    let region = [bounds[0] - margin, bounds[1] - margin, bounds[2] + margin, bounds[3] + margin];
    let terrain = (!args.no_terrain).then(|| sylva_bake::bake::terrain::TerrainSource {
        height: &ground,
        region,
        resolution_m: 4.0,
        source: "demo valley".into(),
    });
    // Its ground imagery: the forest floor under the demo's crowns, the stream and its meadows.
    let mut canopy = sylva_bake::bake::ground_material::CanopyCover::new(bounds, 2.0);
    for t in &trees {
        canopy.add(t.pos.x, t.pos.y, sylva_bake::demo::crown_radius_m(t.species, t.scale));
    }
    let colour = |x: f64, y: f64| {
        let slope = sylva_bake::bake::ground_material::slope_of(&ground, x, y, 1.0);
        Some(sylva_bake::demo::ground_colour(x, y, canopy.at(x, y), slope))
    };
    let imagery = terrain.as_ref().map(|_| sylva_bake::bake::imagery::ImagerySource {
        colour: &colour,
        extent_m: region,
        resolution_m: sylva_bake::bake::ground_material::FLOOR_RESOLUTION_M,
        supersample: 2,
        source: "demo forest floor, stream and meadows".into(),
    });
    let cell_size_m = args.pack.cell_size(&trees)?;
    bake_demo(args, out, started, (terrain, imagery), species, TreeSource::Memory(trees), cell_size_m)
}

/// Bakes a demo scene (valley or country) from its ground, species and trees.
pub(crate) fn bake_demo(
    args: &DemoArgs,
    out: OutDir,
    started: Instant,
    (terrain, imagery): (
        Option<sylva_bake::bake::terrain::TerrainSource<'_>>,
        Option<sylva_bake::bake::imagery::ImagerySource<'_>>,
    ),
    species: Vec<(String, sylva_bake::input::gltf_import::ImportedModel)>,
    trees: TreeSource,
    cell_size_m: u32,
) -> Result<()> {
    let input = SceneInput {
        terrain,
        imagery,
        cell_size_m,
        species,
        trees,
        crs: Crs::projected(sylva_bake::demo::DEMO_EPSG)?,
        origin_m: sylva_bake::demo::DEMO_ORIGIN,
        tile_cells: args.pack.tile_cells,
        pack: args.pack.options()?,
        debug_dump: args.pack.debug_dump.clone(),
        pack_cache: args.pack.pack_cache.clone(),
        shard: args.pack.shard,
        index_node_tiles: args.pack.index_node_tiles,
        canopy_cell_m: args.pack.canopy_cell,
        attributes: None,
        text_ids: None,
        timeline: None,
    };
    let s = sylva_bake::bake::bake_scene(&input, out, &log)?;
    report_summary(&s, &args.output.out, started);
    Ok(())
}

/// `demo --layout country`: the trees generated row by row of blocks into
/// bucket files by tile, the ground from the country's fields.
pub(crate) fn demo_country(args: &DemoArgs, out: OutDir, started: Instant) -> Result<()> {
    let trees = args.trees as u64;
    log(&format!("demo: a country of {trees} trees, seed {}", args.seed));
    let land = sylva_bake::demo::country::Country::new(trees, args.seed)?;
    let side_km = land.half_m / 500.0;
    log(&format!(
        "country: {side_km:.0} × {side_km:.0} km, {} blocks of {} m",
        land.blocks().pow(2),
        sylva_bake::demo::country::BLOCK_M
    ));
    let species = sylva_bake::demo::demo_models(args.seed);
    let cell_size_m = match args.pack.cell_size {
        Some(_) => args.pack.cell_size(&[])?,
        None => sylva_bake::bake::batching::cell_size_for(trees, land.forest_cells64(), 500.0),
    };
    let buckets = trees.div_ceil(args.bucket_trees).max(1) as u32;
    let mut csv = match &args.write_placements {
        Some(path) => Some(PlacementsCsv::create(path, &species, sylva_bake::demo::DEMO_EPSG)?),
        None => None,
    };
    let dir = out.scratch("buckets");
    let mut writer = sylva_bake::bake::bucket::BucketWriter::new(&dir, buckets, cell_size_m, args.pack.tile_cells)?;
    let t0 = Instant::now();
    let mut made = 0u64;
    let mut reported = 0u64;
    for row in 0..land.blocks() {
        let trees_of_row = land.row(row, made);
        made += trees_of_row.len() as u64;
        if let Some(w) = csv.as_mut() {
            w.write(&trees_of_row, sylva_bake::demo::DEMO_ORIGIN)?;
        }
        for t in &trees_of_row {
            let mine = args.pack.shard.is_none_or(|(i, n)| {
                let (x, y) = sylva_bake::bake::batching::tile_of(t.pos, cell_size_m, args.pack.tile_cells);
                sylva_bake::bake::batching::shard_of_tile(x, y, n) == i
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
    let terrain = (!args.no_terrain).then(|| sylva_bake::bake::terrain::TerrainSource {
        height: &ground,
        region: land.extent(),
        resolution_m: 16.0,
        source: "synthetic country".into(),
    });
    let colour = |x: f64, y: f64| Some(land.colour(x, y));
    let imagery = terrain.as_ref().map(|_| sylva_bake::bake::imagery::ImagerySource {
        colour: &colour,
        extent_m: land.extent(),
        resolution_m: 8.0,
        supersample: 2,
        source: "synthetic country: sea, lakes, fields, woods".into(),
    });
    bake_demo(args, out, started, (terrain, imagery), species, source, cell_size_m)
}
