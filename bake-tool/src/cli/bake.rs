//! `sylva-bake bake`: real models and placements into a scene.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use glam::DVec3;
use sylva_bake::bake::batching::SceneTree;
use sylva_bake::bake::{trees, SceneInput};
use sylva_bake::input::gltf_import::Classifier;
use sylva_bake::input::reproject::{Crs, Reprojector};
use sylva_bake::out_dir::OutDir;

use super::*;

#[derive(Args)]
pub(crate) struct BakeArgs {
    /// A species model: NAME=PATH.glb, or NAME=library:GENUS[:VARIANT] for a tree of the
    /// built-in library (a genus or archetype that `sylva-bake library list` names:
    /// library:Quercus, library:conifer-spire; variants 0, 1, 2, …) (repeat for each species).
    #[arg(long = "model", value_name = "NAME=PATH")]
    pub(crate) models: Vec<String>,
    /// Tree placements, one point per tree: .csv (columns auto-detected), .geojson,
    /// or a GIS layer of points: Shapefile (.shp with its .dbf; the CRS from its .prj),
    /// GeoPackage (.gpkg; --layer picks a table) or FlatGeobuf (.fgb). Fields are
    /// found by the CSV's names (a .dbf's 10-byte names too: species_co).
    /// Repeat for censuses of the same trees (with --census-date, one per file,
    /// or a census date column), matched by id: the viewer shows the forest at a
    /// date. One file with planting/removal date columns (planted, removed) does too.
    #[arg(long, value_name = "PATH", required_unless_present_any = ["stands", "chm", "dsm"], conflicts_with_all = ["stands", "chm", "dsm"])]
    pub(crate) placements: Vec<PathBuf>,
    /// The date of each --placements census (YYYY-MM-DD), in the files' order:
    /// --placements 2008.csv --placements 2013.csv --census-date 2008-11-07
    /// --census-date 2013-07-01. A tree stands from its first census (trees new at
    /// a later census grow in from the one before) until the first census that
    /// records it dead (a status column: dead, removed, felled…) or lists it no more.
    #[arg(long = "census-date", value_name = "YYYY-MM-DD")]
    pub(crate) census_dates: Vec<String>,
    /// The column holding each row's census date (one file with every census's
    /// rows; default: a column named census_date, census, survey_date or date).
    #[arg(long, value_name = "NAME")]
    pub(crate) census_date_column: Option<String>,
    /// Make the forest at a date from one register's planting and removal date
    /// columns (planted, planting_date, plantdatum, pflanzdatum, …; removed,
    /// removal_date, felled, rooidatum, …; a year alone is its 1 January): a tree
    /// stands from its planting until its removal, planned ones included (the
    /// view without a date shows the day of the bake).
    #[arg(long)]
    pub(crate) timeline: bool,
    /// A canopy height model instead of trees (a GeoTIFF of heights above ground,
    /// e.g. from airborne lidar): each crown found becomes a tree of its height and
    /// crown width (tops by a local-maximum filter whose window grows with height,
    /// Popescu & Wynne 2004; crowns by watershed). Trees under the canopy are not
    /// seen. With --dem the trees stand on it. With --stands (in the CHM's CRS) each
    /// tree's species is drawn by the shares of the stand it stands in.
    #[arg(long, value_name = "FILE.tif")]
    pub(crate) chm: Option<PathBuf>,
    /// A digital surface model instead of a CHM (first returns: the canopy's top,
    /// the ground between crowns), with --dem: the CHM is the DSM minus the DEM
    /// (in one CRS), then found as with --chm (its options apply).
    #[arg(long, value_name = "FILE.tif", conflicts_with = "chm", requires = "dems")]
    pub(crate) dsm: Option<PathBuf>,
    /// The species label of the trees a CHM gives (the library's tree for it).
    #[arg(long, value_name = "NAME", default_value = "broadleaf")]
    pub(crate) chm_species: String,
    /// The lowest tree top in a CHM, metres.
    #[arg(long, value_name = "M", default_value_t = 2.0)]
    pub(crate) chm_min_height: f64,
    /// A leaf-type raster for a CHM's trees (GeoTIFF in the CHM's CRS with the
    /// Copernicus HRL Dominant Leaf Type codes: 1 broadleaved → `broadleaf`,
    /// 2 coniferous → `conifer`; other values: --chm-species). Stands, where
    /// given, come first.
    #[arg(long, value_name = "FILE.tif")]
    pub(crate) chm_leaf_type: Option<PathBuf>,
    /// Points with a species for a CHM's trees (any placements file: a stem map,
    /// plot centres, a street-tree register; lon/lat or another CRS projected into
    /// the CHM's): a tree takes the species of the nearest point within its crown
    /// (+1 m), before stands and leaf types.
    #[arg(long, value_name = "PATH")]
    pub(crate) chm_species_points: Option<PathBuf>,
    /// The CHM's search window for tree tops: A + B·height metres across.
    #[arg(long, value_name = "A,B", default_value = "1.0,0.12")]
    pub(crate) chm_window: String,
    /// A stand map instead of trees: polygons (GeoJSON, Shapefile, GeoPackage,
    /// FlatGeobuf) whose fields give each stand's species mix (one name, or shares:
    /// `Picea abies:60;Fagus sylvatica:40`, or share_<species> fields), stems/ha (or
    /// basal area with a mean DBH), mean or top height, the quadratic mean DBH (dg),
    /// and optionally a Weibull shape, an age and a pattern (regular, clustered,
    /// random). Each stand
    /// becomes one tree per stem, spread by its pattern, the same on every bake
    /// (seeded by its id); each tree's `stand` attribute is its stand's id. The
    /// report gives the first stands one line each (trees, what was assumed), then
    /// counts, and which stands make none and why.
    #[arg(long, value_name = "PATH")]
    pub(crate) stands: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) stand: super::stands::StandArgs,
    /// The GeoPackage table to read (default: its only features table, or its only
    /// table of points).
    #[arg(long, value_name = "NAME")]
    pub(crate) layer: Option<String>,
    /// Map species labels to models: PATTERN=NAME (case-insensitive; * is a wildcard,
    /// otherwise a substring). Labels equal to a model name map to it without a pattern.
    #[arg(long = "map", value_name = "PATTERN=NAME")]
    pub(crate) maps: Vec<String>,
    /// Model for rows whose species maps to no model. Without it such rows take a
    /// tree of the built-in library (unless --library off: then they are skipped and
    /// reported), except with a single --model, which every row uses.
    #[arg(long, value_name = "NAME")]
    pub(crate) default_model: Option<String>,
    /// The built-in species library: `on` (default) gives every species label that no
    /// --model, --map or --default-model takes a tree of its genus (its Latin name,
    /// else a common name in English, Dutch, German, French or Spanish, else its
    /// family's, else the archetype of a leaf-type column's value (leaf_type,
    /// foliage, Blatttyp, …: conifer, broadleaf, palm, shrub), else a conifer or
    /// broadleaf archetype; reported); `off` skips such rows. Without any --model
    /// every species comes from the library.
    #[arg(long, value_name = "on|off", default_value = "on", value_parser = ["on", "off"])]
    pub(crate) library: String,
    /// Scene CRS (projected, e.g. EPSG:32631). Default: the UTM zone of lon/lat data, or --input-crs.
    #[arg(long)]
    pub(crate) crs: Option<String>,
    /// CRS of x/y placement columns (required for projected input, unless the file
    /// names its own: a GeoJSON's crs, a .prj, a GeoPackage's or FlatGeobuf's CRS;
    /// this wins over it).
    #[arg(long)]
    pub(crate) input_crs: Option<String>,
    /// Height in metres for rows with neither a height nor a DBH (default: the
    /// median of the given heights).
    #[arg(long)]
    pub(crate) default_height: Option<f32>,
    /// Text encoding of a CSV: auto reads each field as UTF-8 where it is valid
    /// and as Windows-1252/Latin-1 otherwise (counted in the report).
    #[arg(long, value_enum, default_value_t = sylva_bake::input::placements::Encoding::Auto)]
    pub(crate) encoding: sylva_bake::input::placements::Encoding,
    /// CSV field separator (default: detected from the header line: , ; tab |).
    /// With ; or tab, decimal commas (52,37) are read too.
    #[arg(long, value_name = "CHAR", value_parser = parse_delimiter)]
    pub(crate) delimiter: Option<u8>,
    /// The x/longitude and y/latitude columns hold each other's values: swap them.
    #[arg(long)]
    pub(crate) swap_xy: bool,
    /// Use column NAME for ROLE (repeatable), before the names detected by
    /// default. Roles: lon, lat, x, y, z, height, species, dbh, crown_diameter,
    /// crown_radius, yaw, id. E.g. --column species=species_code --column dbh=dbh_mm.
    #[arg(long = "column", value_name = "ROLE=NAME", value_parser = sylva_bake::input::placements::ColumnRole::parse_mapping)]
    pub(crate) columns: Vec<(sylva_bake::input::placements::ColumnRole, String)>,
    /// Unit of a DBH column whose name does not say it (dbh_mm, dbh_cm, dbh_in and dbh_m do).
    #[arg(long, value_enum, value_name = "UNIT")]
    pub(crate) dbh_unit: Option<sylva_bake::input::placements::DbhUnit>,
    /// Keep only these columns as per-tree attributes (comma-separated names;
    /// default: every column but the coordinates and the id). Numbers,
    /// integers, dates (YYYY-MM-DD) and categories are typed from the values;
    /// free text (over 4,096 different values) is left out. Stored per tile in
    /// `.attr` sidecars for picking, styling and search.
    #[arg(long, value_name = "A,B,C", value_delimiter = ',', conflicts_with = "no_attributes")]
    pub(crate) attributes: Option<Vec<String>>,
    /// Keep no per-tree attributes.
    #[arg(long)]
    pub(crate) no_attributes: bool,
    /// Height and crown equations from DBH to use over the built-in ones
    /// (CSV: genus,h_p2,h_p3,h_p4,cw_b0,cw_b1,cw_b2; docs/ALLOMETRY.md). Rows
    /// without a height get one from their DBH; with neither, --default-height.
    #[arg(long, value_name = "FILE.csv")]
    pub(crate) allometry: Option<PathBuf>,
    /// Species codes to Latin names (CSV, columns found by name: a code column —
    /// sp, spcode, code, SPCD, … — and Latin, SCIENTIFIC_NAME, … or Genus and
    /// Species; optionally Family): a ForestGEO spptable, the US FIA REF_SPECIES
    /// table, any code,latin list. Labels it lists choose their library tree and
    /// allometry by the name.
    #[arg(long, value_name = "FILE.csv")]
    pub(crate) species_table: Option<PathBuf>,
    /// Rows farther than this from the median position are outliers and skipped.
    #[arg(long, default_value_t = 100.0)]
    pub(crate) max_extent_km: f64,
    /// Material/mesh/node name pattern forced to leaves (repeatable; case-insensitive,
    /// `*` is a wildcard like --map's, otherwise a substring; '*' is every name).
    #[arg(long = "leaf-material", value_name = "PATTERN")]
    pub(crate) leaf_materials: Vec<String>,
    /// Material/mesh/node name pattern forced to branches (repeatable, as --leaf-material).
    #[arg(long = "branch-material", value_name = "PATTERN")]
    pub(crate) branch_materials: Vec<String>,
    /// Elevation model, a GeoTIFF (repeat for several tiles; float32, int16 or
    /// uint16 heights, strips or tiles, deflate/LZW, GDAL nodata): every tree
    /// stands on its ground, sampled bilinearly, unless the row has a z (see --z).
    #[arg(long = "dem", value_name = "FILE.tif")]
    pub(crate) dems: Vec<PathBuf>,
    /// CRS of the --dem files, when their GeoKeys name none (or name the wrong one).
    #[arg(long, value_name = "EPSG:xxxx")]
    pub(crate) dem_crs: Option<String>,
    /// How a z column is meant with --dem: absolute (a ground elevation: the DEM
    /// is not used for that row) or relative (height above the DEM's ground).
    #[arg(long, value_enum, default_value_t = sylva_bake::bake::ground::ZMode::Absolute)]
    pub(crate) z: sylva_bake::bake::ground::ZMode,
    /// No terrain tiles (trees still stand on --dem heights). Without it, a
    /// scene without a DEM gets a ground fitted to its trees' bases.
    #[arg(long)]
    pub(crate) no_terrain: bool,
    /// Vertex spacing of the finest terrain level in metres (default: the
    /// DEM's pixel size; coarser spacing: fewer bytes, smoother ground).
    #[arg(long, value_name = "M")]
    pub(crate) terrain_resolution: Option<f64>,
    /// Trees outside every --dem (or on its nodata pixels): error stops the bake
    /// and says how many and where; skip leaves them out (reported).
    #[arg(long, value_enum, default_value_t = sylva_bake::bake::ground::OutsideDem::Error)]
    pub(crate) outside_dem: sylva_bake::bake::ground::OutsideDem,
    /// Orthophoto, an RGB(A) GeoTIFF (repeat for several; 8- or 16-bit grey,
    /// RGB or RGBA, strips or tiles, deflate/LZW, GDAL nodata): draped on the
    /// terrain as ground imagery, baked into one 256² JPEG per terrain tile
    /// down to the photo's resolution. Needs terrain (--dem, or a fitted ground).
    #[arg(long = "ortho", value_name = "FILE.tif")]
    pub(crate) orthos: Vec<PathBuf>,
    /// CRS of the --ortho files, when their GeoKeys name none (or name the wrong one).
    #[arg(long, value_name = "EPSG:xxxx")]
    pub(crate) ortho_crs: Option<String>,
    /// Without --ortho the terrain gets a procedural forest floor as its
    /// imagery (litter under the canopy, dry grass in clearings, soil on steep
    /// slopes, from the trees' crowns); this leaves it out (fewer bytes: the
    /// viewer's plain ground material by slope).
    #[arg(long, conflicts_with = "orthos")]
    pub(crate) plain_ground: bool,
    #[command(flatten)]
    pub(crate) pack: PackArgs,
    /// Trees held in memory at once while tiling; larger inputs are partitioned
    /// by tile into temporary bucket files inside --out (about 56 bytes per tree).
    #[arg(long, default_value_t = 4_000_000, value_parser = clap::value_parser!(u64).range(1..))]
    pub(crate) bucket_trees: u64,
    #[command(flatten)]
    pub(crate) output: OutArgs,
}

/// Trees written as a lon/lat CSV (`id,species,lat,lng,z,height`),
/// reprojected from the scene CRS, a batch at a time.
pub(crate) struct PlacementsCsv {
    pub(crate) path: PathBuf,
    pub(crate) w: std::io::BufWriter<std::fs::File>,
    pub(crate) inverse: Reprojector,
    pub(crate) names: Vec<String>,
    pub(crate) heights: Vec<f32>,
}

impl PlacementsCsv {
    pub(crate) fn create(
        path: &std::path::Path,
        species: &[(String, sylva_bake::input::gltf_import::ImportedModel)],
        epsg: u32,
    ) -> Result<Self> {
        use std::io::Write as _;
        let inverse = Reprojector::new(Crs::projected(epsg)?, &Crs::from_epsg(4326)?)?;
        if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
            sylva_bake::out_dir::create_dir(parent)?;
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

    pub(crate) fn write(&mut self, trees: &[SceneTree], origin: DVec3) -> Result<()> {
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

    pub(crate) fn finish(mut self) -> Result<PathBuf> {
        use std::io::Write as _;
        self.w.flush().with_context(|| format!("cannot write {}", self.path.display()))?;
        Ok(self.path)
    }
}

pub(crate) fn bake(args: &BakeArgs) -> Result<()> {
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
    let placements: &std::path::Path = args
        .placements
        .first()
        .map(PathBuf::as_path)
        .or(args.chm.as_deref())
        .or(args.dsm.as_deref())
        .or(args.stands.as_deref())
        .context("give --placements, --stands, --chm or --dsm")?;
    args.stand.check()?;
    if (args.chm_leaf_type.is_some() || args.chm_species_points.is_some()) && args.chm.is_none() && args.dsm.is_none() {
        bail!("--chm-leaf-type and --chm-species-points give species to the trees of a --chm or --dsm: give one");
    }
    let mut inputs: Vec<&std::path::Path> = vec![placements];
    inputs.extend(args.placements.iter().skip(1).map(PathBuf::as_path));
    inputs.extend(args.stands.as_deref().filter(|s| *s != placements));
    inputs.extend(args.chm_leaf_type.as_deref());
    inputs.extend(args.chm_species_points.as_deref());
    inputs.extend(args.allometry.as_deref());
    inputs.extend(args.species_table.as_deref());
    inputs.extend(args.dems.iter().map(PathBuf::as_path));
    inputs.extend(args.orthos.iter().map(PathBuf::as_path));
    if !args.orthos.is_empty() && args.no_terrain {
        bail!("--ortho drapes imagery on the terrain: it cannot be used with --no-terrain");
    }
    let orthos = sylva_bake::bake::imagery::Orthos::open(&args.orthos, args.ortho_crs.as_deref(), &log)?;
    for m in &args.models {
        let path = split_pair("--model", m)?.1;
        if sylva_bake::library::spec(path).is_none() {
            inputs.push(std::path::Path::new(path));
        }
    }
    let mut allometry = match &args.allometry {
        Some(path) => sylva_bake::input::allometry::Allometry::with_overrides(path)?,
        None => sylva_bake::input::allometry::Allometry::built_in(),
    };
    if let Some(path) = &args.species_table {
        let table = sylva_bake::input::names::SpeciesTable::read(path)?;
        log(&format!("species table {}: {} codes", path.display(), table.len()));
        allometry.species_table = Some(table);
    }
    if args.library == "off" && args.models.is_empty() {
        bail!("no --model and --library off: no tree to draw (give --model NAME=PATH.glb, or leave the library on)");
    }
    let out = OutDir::prepare(&args.output.out, &inputs, args.output.force, &log)?;
    let mut species = import_models(args)?;
    let mut map = species_map(args, &species)?;
    // Placements, streamed: the file is read from disk on every pass, so inputs
    // larger than memory bake in bounded memory.
    let input_crs = args.input_crs.as_deref().map(Crs::parse).transpose()?;
    let read = sylva_bake::input::placements::ReadOptions {
        encoding: args.encoding,
        delimiter: args.delimiter,
        swap_xy: args.swap_xy,
        projected: input_crs.as_ref().is_some_and(|c| !c.is_geographic()),
        geographic_input: input_crs.as_ref().is_some_and(Crs::is_geographic),
        columns: args.columns.clone(),
        dbh_unit: args.dbh_unit,
        attributes: if args.no_attributes { Some(Vec::new()) } else { args.attributes.clone() },
        layer: args.layer.clone(),
        // With --chm the stands give the CHM's trees their species (below).
        stands: args
            .stands
            .as_ref()
            .filter(|_| args.chm.is_none() && args.dsm.is_none())
            .map(|_| std::sync::Arc::new(args.stand.options(&allometry))),
        chm: match args.chm.as_ref().or(args.dsm.as_ref()) {
            Some(_) => {
                let (a, b) = args
                    .chm_window
                    .split_once(',')
                    .and_then(|(a, b)| Some((a.trim().parse::<f64>().ok()?, b.trim().parse::<f64>().ok()?)))
                    .filter(|(a, b)| (0.0..50.0).contains(a) && (0.0..2.0).contains(b) && a + b > 0.0)
                    .with_context(|| format!("--chm-window {}: expected A,B (e.g. 1.0,0.12)", args.chm_window))?;
                if !(0.0..100.0).contains(&args.chm_min_height) {
                    bail!("--chm-min-height {}: metres, 0–100", args.chm_min_height);
                }
                Some(std::sync::Arc::new(sylva_bake::input::chm::ChmOptions {
                    min_height: args.chm_min_height,
                    window_a: a,
                    window_b: b,
                    species: args.chm_species.clone(),
                    species_stands: args
                        .stands
                        .clone()
                        .map(|p| (p, std::sync::Arc::new(args.stand.options(&allometry)))),
                    ground: if args.dsm.is_some() { args.dems.clone() } else { Vec::new() },
                    leaf_type: args.chm_leaf_type.clone(),
                    species_points: args.chm_species_points.clone(),
                }))
            }
            None => None,
        },
        census: None,
    };
    let mut read = read;
    read.census = census_options(args, &read, &allometry)?;
    if args.library == "on" && map.default.is_none() {
        library_fill(placements, &read, &allometry, &mut species, &mut map)?;
    }
    let options = trees::TreeOptions {
        placements,
        read,
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
    let fitted = placed.fitted.as_ref().zip(fitted_height.as_ref()).map(|((f, region), height)| {
        sylva_bake::bake::terrain::TerrainSource {
            height,
            region: *region,
            resolution_m: f.cell_m(),
            source: "fitted to the trees' bases (no --dem)".into(),
        }
    });
    let terrain = placed.ground.as_ref().zip(ground_height.as_ref()).map(|((g, region), height)| {
        sylva_bake::bake::terrain::TerrainSource {
            height,
            region: *region,
            resolution_m: args.terrain_resolution.unwrap_or_else(|| g.resolution_m()),
            source: g.names(),
        }
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
            let slope = sylva_bake::bake::ground_material::slope_of(height, x, y, 1.0);
            height(x, y).map(|_| sylva_bake::bake::ground_material::forest_floor(x, y, canopy.at(x, y), slope))
        }
    });
    let imagery = match (&orthos, &ortho_colour) {
        (None, _) if !args.plain_ground => {
            terrain.as_ref().zip(floor_colour.as_ref()).map(|(t, colour)| sylva_bake::bake::imagery::ImagerySource {
                colour,
                extent_m: t.region,
                resolution_m: sylva_bake::bake::ground_material::FLOOR_RESOLUTION_M,
                supersample: 2,
                source: "procedural forest floor (canopy cover and slope)".into(),
            })
        }
        (Some(o), Some(colour)) => {
            let e = o.scene_extent().context("the --ortho extent cannot be projected into the scene CRS")?;
            let (ox, oy) = (placed.origin_m.x, placed.origin_m.y);
            Some(sylva_bake::bake::imagery::ImagerySource {
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
        timeline: placed.timeline,
    };
    log(&format!("batching with {} m cells", input.cell_size_m));
    let s = sylva_bake::bake::bake_scene(&input, out, &log)?;
    report_summary(&s, &args.output.out, started);
    Ok(())
}

/// Censuses (several --placements, --census-date, a census date column) or
/// one inventory with planting and removal dates: how to merge them, or `None`.
fn census_options(
    args: &BakeArgs,
    read: &sylva_bake::input::placements::ReadOptions,
    allometry: &sylva_bake::input::allometry::Allometry,
) -> Result<Option<std::sync::Arc<sylva_bake::input::placements::census::CensusOptions>>> {
    use sylva_bake::input::placements::census::{has_timeline_columns, CensusOptions};
    let dates = CensusOptions::parse_dates(args.placements.len(), &args.census_dates)?;
    let asked = args.placements.len() > 1 || !dates.is_empty() || args.census_date_column.is_some() || args.timeline;
    if !asked {
        // A register with planting or removal dates: say what --timeline would do.
        if let Some(p) = args.placements.first().filter(|_| args.stands.is_none()) {
            // (Every column: --attributes chooses what is kept, not what is read.)
            let all = sylva_bake::input::placements::ReadOptions { attributes: None, ..read.clone() };
            if let Ok(source) = sylva_bake::input::placements::PlacementSource::open(p, &all) {
                if has_timeline_columns(&source.attribute_names()) {
                    eprintln!(
                        "note: {} has planting or removal dates: --timeline shows the trees standing at a date (setDate, the page's year slider)",
                        p.display()
                    );
                }
            }
        }
        return Ok(None);
    }
    if args.pack.shard.is_some() {
        bail!("censuses (several --placements, --census-date, planting or removal dates) cannot be baked in shards yet: bake them whole");
    }
    let today =
        std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| (d.as_secs() / 86_400) as i64);
    Ok(Some(std::sync::Arc::new(CensusOptions {
        files: args.placements.clone(),
        dates,
        date_column: args.census_date_column.clone(),
        allometry: Some(std::sync::Arc::new(allometry.clone())),
        today,
    })))
}

/// The `--model` files, imported (names unique).
pub(crate) fn import_models(args: &BakeArgs) -> Result<Vec<(String, sylva_bake::input::gltf_import::ImportedModel)>> {
    let classifier =
        Classifier { leaf_patterns: args.leaf_materials.clone(), branch_patterns: args.branch_materials.clone() };
    let mut species: Vec<(String, sylva_bake::input::gltf_import::ImportedModel)> = Vec::new();
    for m in &args.models {
        let (name, path) = split_pair("--model", m)?;
        if species.iter().any(|(n, _)| n.eq_ignore_ascii_case(name)) {
            bail!("--model {name} is given twice");
        }
        let library = sylva_bake::library::spec(path);
        let mut model = match library {
            Some(genus) => sylva_bake::library::model_named(genus)?,
            None => sylva_bake::input::gltf_import::import(std::path::Path::new(path), &classifier)?,
        };
        if library.is_none() {
            // A model of a deciduous genus (by its name) gets the genus's
            // seasons, where its leaves and wood are apart (leaf-off keeps the wood).
            if let Some(autumn) = sylva_bake::library::choose::autumn_of(name) {
                match model.triangle_counts() {
                    (leaf, wood) if leaf > 0 && wood > 0 => {
                        model.autumn = Some(autumn);
                        model.genus = sylva_bake::library::choose::deciduous_genus_of(name).map(str::to_string);
                        log(&format!("model {name}: deciduous by its name: baked in leaf-on, autumn and leaf-off"));
                    }
                    _ => log(&format!(
                        "model {name}: deciduous by its name, but its leaves and wood are not apart \
                         (--leaf-materials, --branch-materials): one state, leaf-on"
                    )),
                }
            }
        }
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

/// Gives every species label of the placements that `map` takes to no model
/// a tree of the built-in library (one model per genus, named after it), and
/// says which label got which and why.
fn library_fill(
    placements: &std::path::Path,
    read: &sylva_bake::input::placements::ReadOptions,
    allometry: &sylva_bake::input::allometry::Allometry,
    species: &mut Vec<(String, sylva_bake::input::gltf_import::ImportedModel)>,
    map: &mut trees::SpeciesMap,
) -> Result<()> {
    use sylva_bake::library;
    /// Most distinct labels read (an inventory with more is no species list).
    const MAX_LABELS: usize = 100_000;
    /// Most labels listed per genus in the log.
    const LISTED: usize = 20;
    log("library: reading the species labels no --model takes…");
    let source = sylva_bake::input::placements::PlacementSource::open(placements, read)?;
    // A leaf-type column (conifer / broadleaf / palm / shrub) places labels nothing else does.
    let attribute_names = source.attribute_names();
    let leaf_column = attribute_names.iter().position(|n| {
        library::choose::LEAF_TYPE_COLUMNS.contains(&sylva_bake::input::names::fold(n).replace(' ', "_").as_str())
    });
    if let Some(c) = leaf_column {
        log(&format!("library: leaf types from the column {:?}", attribute_names[c]));
    }
    let mut labels: std::collections::BTreeMap<String, u64> = std::collections::BTreeMap::new();
    let mut leaf_types: std::collections::BTreeMap<String, String> = std::collections::BTreeMap::new();
    let (mut unmapped, mut beyond) = (0u64, 0u64);
    // A label's trees (`n` of them), with its leaf type if a column gives one.
    let mut count = |label: &str, leaf: Option<&str>, n: u64| {
        let label = label.trim();
        if map.of(label).is_none() {
            if let Some(c) = labels.get_mut(label) {
                *c += n;
                unmapped += n;
            } else if labels.len() < MAX_LABELS {
                labels.insert(label.to_string(), n);
                unmapped += n;
            } else {
                beyond += n;
                return;
            }
            if let Some(t) = leaf.map(str::trim).filter(|t| !t.is_empty()) {
                if !leaf_types.contains_key(label) {
                    leaf_types.insert(label.to_string(), t.to_string());
                }
            }
        }
    };
    let mut visit = |p: sylva_bake::input::placements::Placement| {
        let leaf = leaf_column.and_then(|c| p.attrs.get(c)).and_then(Option::as_deref);
        count(p.species.as_deref().unwrap_or(""), leaf, 1);
        Ok(())
    };
    if !source.stand_plans().is_empty() {
        // A stand map: its mixes name every label (no tree grown).
        for plan in source.stand_plans() {
            for (label, share) in &plan.mix {
                count(label, None, (plan.expected * share).round().max(1.0) as u64);
            }
        }
    } else if leaf_column.is_some() {
        source.for_each_with_attributes(&mut visit)?;
    } else {
        source.for_each(&mut visit)?;
    }
    if beyond > 0 {
        log(&format!(
            "library: more than {MAX_LABELS} distinct species labels: {beyond} trees under the others get no tree (give --default-model)"
        ));
    }
    if labels.is_empty() {
        return Ok(());
    }
    let chosen = library::choose::choose_all(&labels, &leaf_types, allometry);
    log(&format!(
        "library: {unmapped} trees under {} species labels no --model takes, drawn as {} library genera:",
        labels.len(),
        chosen.len()
    ));
    for (genus, rows) in &chosen {
        let g = library::entry(genus).expect("chosen from the library");
        let mut name = genus.to_lowercase();
        if map.model(&name).is_some() {
            name = format!("library-{name}");
        }
        let model = library::model_variants(g, library::VARIANTS);
        let idx = species.len();
        map.names.push(name.clone());
        map.heights.push(model.height());
        map.crown_widths.push(model.crown_width());
        let (leaf, wood) = model.triangle_counts();
        log(&format!(
            "  {name} (library:{genus}, {leaf} leaf + {wood} branch triangles, {} variants):",
            model.variants.len() + 1
        ));
        for (k, (label, why, n)) in rows.iter().enumerate() {
            let shown = if label.is_empty() { "(no species)" } else { label };
            if k < LISTED {
                log(&format!("    {shown:?}: {n} {}, by {why}", if *n == 1 { "tree" } else { "trees" }));
            } else if k == LISTED {
                log(&format!("    … and {} more labels", rows.len() - LISTED));
            }
            map.library.insert(label.to_lowercase(), idx);
        }
        species.push((name, model));
    }
    Ok(())
}

/// Which model each species label uses, from `--map` and `--default-model`.
pub(crate) fn species_map(
    args: &BakeArgs,
    species: &[(String, sylva_bake::input::gltf_import::ImportedModel)],
) -> Result<trees::SpeciesMap> {
    let mut map = trees::SpeciesMap {
        names: species.iter().map(|(n, _)| n.clone()).collect(),
        heights: species.iter().map(|(_, m)| m.height()).collect(),
        crown_widths: species.iter().map(|(_, m)| m.crown_width()).collect(),
        maps: Vec::new(),
        default: None,
        library: std::collections::HashMap::new(),
        given: species.len(),
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
