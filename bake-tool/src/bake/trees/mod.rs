//! Stage 1 of `sylva-bake bake`: tree placements (any CRS, larger than memory)
//! into scene trees, in three streamed passes over the file (a stand map's
//! first two, and its ground's, over points spread over its stands: its trees
//! are grown once, in pass 3):
//!
//! 1. a deterministic sample (every row up to [`SAMPLE_ROWS`]): row count,
//!    swapped columns, the scene CRS, the medians (origin, outliers) and the
//!    default height;
//! 2. the tree density, for the cell size (unless given);
//! 3. the trees, in memory or partitioned by tile into bucket files.

use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Result};
use glam::DVec3;

use super::ground::{Dems, OutsideDem, ZMode};
use crate::bake::batching::SceneTree;
use crate::bake::bucket::TreeSource;
use crate::input::allometry::Allometry;
use crate::input::placements::{CoordKind, Placement, PlacementSource, ReadOptions};
use crate::input::reproject::{Crs, Reprojector};
use crate::out_dir::OutDir;
use crate::patterns::pattern_matches;
use crate::rng;

mod passes;
mod sample;
mod summary;

use passes::*;
use sample::*;
use summary::*;

/// Tallest tree height accepted (the tallest known tree is 116 m); placement
/// heights outside (0, this) count as missing.
pub const MAX_TREE_HEIGHT_M: f32 = 200.0;

/// Crown aspects (crown width over height, relative to the model's) are kept
/// within this factor of the model's proportions; beyond it a crown width is
/// more likely a unit or column mistake than a tree.
pub const MAX_CROWN_ASPECT: f32 = 4.0;

/// Rows sampled for the medians; inputs up to this size use every row.
const SAMPLE_ROWS: usize = 1_000_000;
/// Rows checked for repeated coordinates (the check keeps a set of them).
const DUPLICATE_CHECK_ROWS: usize = 10_000_000;

/// How to read and place the trees.
pub struct TreeOptions<'a> {
    /// The placements file.
    pub placements: &'a Path,
    /// Encoding, delimiter, swapped columns.
    pub read: ReadOptions,
    /// The scene CRS (`--crs`), if given.
    pub crs: Option<&'a str>,
    /// The placements' CRS (`--input-crs`), if given.
    pub input_crs: Option<&'a str>,
    /// Outliers lie farther than this from the median position.
    pub max_extent_km: f64,
    /// Height of rows without one (default: the median of the given heights).
    pub default_height: Option<f32>,
    /// A fixed cell size (checked), or `None` to derive it from the density.
    pub cell_size_m: Option<u32>,
    /// Trees held in memory at once; more go to bucket files.
    pub bucket_trees: u64,
    /// Cells per tile side.
    pub tile_cells: u32,
    /// Keep only the trees of shard `.0` of `.1` (bucketed bakes).
    pub shard: Option<(u32, u32)>,
    /// Heights and crowns from DBH where a row has no height.
    pub allometry: &'a Allometry,
    /// Elevation models (`--dem`): the trees' ground.
    pub dems: &'a [std::path::PathBuf],
    /// CRS of the DEMs (`--dem-crs`), over their GeoKeys.
    pub dem_crs: Option<&'a str>,
    /// How a z column is meant with a DEM.
    pub z_mode: ZMode,
    /// Trees outside every DEM: stop or leave them out.
    pub outside_dem: OutsideDem,
    /// Without a DEM, fit a ground surface to the trees' bases for the terrain.
    pub fit_ground: bool,
}

/// Why a row outside every DEM is skipped (and, by default, stops the bake).
const OUTSIDE_DEM: &str = "outside every --dem (or where it has no data)";

/// Where a tree's height came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum HeightFrom {
    /// The height column.
    Given,
    /// The DBH, through the allometry.
    Dbh,
    /// `--default-height` or the median of the given heights.
    Default,
    /// The model's own height.
    Model,
}

/// What a row told about its tree, for the summary.
#[derive(Debug, Clone, Copy)]
struct Facts {
    height_m: f32,
    from: HeightFrom,
    dbh_cm: Option<f32>,
    crown_m: Option<f32>,
    /// Crown width over height relative to the model's (1 without a crown width).
    aspect: f32,
    /// The aspect was clamped to [`MAX_CROWN_ASPECT`].
    aspect_clamped: bool,
    /// The tree lies just off the DEM's data: its ground is the nearest valid pixel's.
    ground_near: bool,
}

/// Which model each species label uses.
pub struct SpeciesMap {
    /// Model names.
    pub names: Vec<String>,
    /// Model heights at scale 1.
    pub heights: Vec<f32>,
    /// Model crown widths at scale 1 ([`crate::input::gltf_import::ImportedModel::crown_width`]).
    pub crown_widths: Vec<f32>,
    /// `--map` patterns and their model.
    pub maps: Vec<(String, usize)>,
    /// The model of labels nothing maps.
    pub default: Option<usize>,
    /// Labels the library chose a model for (lowercase, exact), after
    /// everything above.
    pub library: std::collections::HashMap<String, usize>,
    /// How many of `names` the user gave (`--model`): only they take a label
    /// by name (a library model named `acer` must not take the label `Acer`
    /// from a `--map`).
    pub given: usize,
}

impl SpeciesMap {
    /// The model named `name` (case-insensitive).
    #[must_use]
    pub fn model(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n.eq_ignore_ascii_case(name))
    }

    /// The model of a species label: a given model of that name, else a
    /// `--map` pattern, else the default, else the library's choice.
    #[must_use]
    pub fn of(&self, label: &str) -> Option<usize> {
        self.names[..self.given.min(self.names.len())]
            .iter()
            .position(|n| n.eq_ignore_ascii_case(label))
            .or_else(|| self.maps.iter().find(|(pat, _)| pattern_matches(pat, label)).map(|(_, i)| *i))
            .or(self.default)
            .or_else(|| {
                if self.library.is_empty() {
                    None
                } else {
                    self.library.get(&label.trim().to_lowercase()).copied()
                }
            })
    }
}

/// The placed trees and the frame they are in.
pub struct PlacedTrees {
    /// Trees relative to `origin_m`.
    pub trees: TreeSource,
    /// The scene CRS.
    pub crs: Crs,
    /// Scene origin in CRS coordinates (a round kilometre near the median).
    pub origin_m: DVec3,
    /// Batch cell size, metres.
    pub cell_size_m: u32,
    /// The DEMs in the scene CRS, if any, and the region their terrain covers
    /// (metres relative to the origin: min x, min y, max x, max y).
    pub ground: Option<(super::ground::Ground, [f64; 4])>,
    /// Without a DEM: a ground fitted to the trees' bases and its region.
    pub fitted: Option<(super::ground::FittedGround, [f64; 4])>,
    /// The crown cover of every tree (of every shard), for the procedural ground material.
    pub canopy: super::ground_material::CanopyCover,
    /// The placements' other columns as per-tree attributes, if any are kept.
    pub attributes: Option<crate::input::attributes::AttributeTable>,
    /// The text ids of the rows that have one (none: every id is a number).
    pub text_ids: Option<TextIds>,
    /// The trees' timeline (censuses, planting and removal dates), if any.
    pub timeline: Option<sylva::format::timeline::Timeline>,
}

/// The text ids of an inventory (`EY17080`), by input row: what a tree whose
/// id is no whole number is called in its owner's system. Held for every row
/// (all shards), 8 bytes a row with one plus its text.
#[derive(Debug, Clone, Default)]
pub struct TextIds {
    /// Rows with a text id, rising.
    rows: Vec<u32>,
    /// The byte end of each row's text in `text`.
    ends: Vec<u32>,
    text: String,
}

impl TextIds {
    /// Reads the text ids of `source` (one pass).
    ///
    /// # Errors
    /// An unreadable placements file, or more than 4 GiB of text ids.
    pub fn read(source: &PlacementSource) -> Result<Self> {
        let mut out = Self::default();
        let mut unordered = false;
        source.for_each(&mut |p| {
            if let (None, Some(t), Ok(row)) = (p.id, p.id_text.as_deref(), u32::try_from(p.row)) {
                unordered |= out.rows.last().is_some_and(|&r| r >= row);
                out.text.push_str(t);
                out.rows.push(row);
                out.ends.push(u32::try_from(out.text.len()).map_err(|_| anyhow::anyhow!("over 4 GiB of text ids"))?);
            }
            Ok(())
        })?;
        if unordered {
            // (Rows are read in order; kept general.)
            let mut by_row: Vec<(u32, String)> =
                (0..out.rows.len()).map(|k| (out.rows[k], out.get_at(k).to_string())).collect();
            by_row.sort_by_key(|(r, _)| *r);
            by_row.dedup_by_key(|(r, _)| *r);
            out = Self::default();
            for (r, t) in by_row {
                out.text.push_str(&t);
                out.rows.push(r);
                out.ends.push(out.text.len() as u32);
            }
        }
        Ok(out)
    }

    fn get_at(&self, k: usize) -> &str {
        let start = if k == 0 { 0 } else { self.ends[k - 1] as usize };
        &self.text[start..self.ends[k] as usize]
    }

    /// The text id of input row `row`, if it has one.
    #[must_use]
    pub fn get(&self, row: u32) -> Option<&str> {
        self.rows.binary_search(&row).ok().map(|k| self.get_at(k))
    }

    /// The rows with a text id.
    #[must_use]
    #[allow(clippy::len_without_is_empty)] // (never empty: made only when a row has one)
    pub fn len(&self) -> usize {
        self.rows.len()
    }
}

/// Reads, checks and places the trees (see the module docs).
pub fn place_trees(
    opts: &TreeOptions<'_>,
    species: &SpeciesMap,
    out: &OutDir,
    log: &dyn Fn(&str),
) -> Result<PlacedTrees> {
    let source = PlacementSource::open(opts.placements, &opts.read)?;
    // DEMs are read before any long work, so a bad file fails fast.
    let dems = Dems::open(opts.dems, opts.dem_crs, log)?;
    if dems.is_empty() && opts.z_mode == ZMode::Relative {
        bail!("--z relative needs a --dem (z is then the height above its ground)");
    }
    for note in &source.notes {
        log(&format!("placements: {note}"));
    }
    let started = Instant::now();
    let stands = !source.stand_plans().is_empty();
    let mut sample = if stands {
        log("pass 1/3: sampling the stands (points spread over them; no tree grown)");
        sample_stands(&source)?
    } else {
        log("pass 1/3: sampling placements");
        sample_pass(&source)?
    };
    if stands {
        log(&format!(
            "  about {} trees in {} stands ({} points spread over them, {:.1} s)",
            sample.report.rows,
            source.stand_plans().len(),
            sample.rows.len(),
            started.elapsed().as_secs_f64()
        ));
    } else {
        log(&format!(
            "  {} rows read, {} usable ({:.1} s){}",
            sample.report.rows,
            sample.report.kept,
            started.elapsed().as_secs_f64(),
            if sample.seen as usize > SAMPLE_ROWS {
                format!("; medians from a sample of {SAMPLE_ROWS}")
            } else {
                String::new()
            }
        ));
    }
    check_swapped(opts, &sample.report)?;
    if source.kind == CoordKind::LonLat && !sample.rows.is_empty() {
        let mut lons: Vec<f64> = sample.rows.iter().map(|p| p.0).collect();
        let mut lats: Vec<f64> = sample.rows.iter().map(|p| p.1).collect();
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
    let (src, dst) = choose_crs(opts, &source, &sample, log)?;
    let ground = if dems.is_empty() { None } else { Some(dems.in_scene(&dst)?) };
    let reproject = Reprojector::new(src, &dst)?;
    // Medians of the projected sample: outliers are far from them.
    // (The sample is not needed after this: up to tens of MB freed before pass 2.)
    let projected: Vec<(f64, f64, Option<f32>)> = std::mem::take(&mut sample.rows)
        .into_iter()
        .filter_map(|(x, y, h, _)| reproject.apply(x, y).ok().map(|(x, y)| (x, y, h)))
        .collect();
    let mut xs: Vec<f64> = projected.iter().map(|p| p.0).collect();
    let mut ys: Vec<f64> = projected.iter().map(|p| p.1).collect();
    if xs.is_empty() {
        bail!("no usable placements ({})", sample.report.lines().join("; "));
    }
    let (mx, my) = (median(&mut xs), median(&mut ys));
    let limit = opts.max_extent_km * 1000.0;
    let inside = |x: f64, y: f64| (x - mx).hypot(y - my) <= limit;
    // The trees' extent from the sample, outliers left out (the same in every
    // shard): the terrain covers it.
    let sample_box =
        projected.iter().filter(|p| inside(p.0, p.1)).fold([f64::MAX, f64::MAX, f64::MIN, f64::MIN], |b, p| {
            [b[0].min(p.0), b[1].min(p.1), b[2].max(p.0), b[3].max(p.1)]
        });
    let default_height = match opts.default_height {
        Some(h) if h.is_finite() && h > 0.0 && h < MAX_TREE_HEIGHT_M => Some(h),
        Some(h) => bail!("--default-height {h}: must be a number of metres above 0 and below {MAX_TREE_HEIGHT_M}"),
        None => {
            let mut heights: Vec<f32> = projected.iter().filter(|p| inside(p.0, p.1)).filter_map(|p| p.2).collect();
            let n = heights.len();
            (n > 0).then(|| *heights.select_nth_unstable_by(n / 2, f32::total_cmp).1)
        }
    };
    drop(projected);
    let origin = DVec3::new((mx / 1000.0).round() * 1000.0, (my / 1000.0).round() * 1000.0, 0.0);
    // The equations of each species label, looked up once per label.
    let equations_of: std::cell::RefCell<std::collections::HashMap<String, &crate::input::allometry::Equations>> =
        std::cell::RefCell::default();
    let equations_for = |label: &str| {
        let mut cache = equations_of.borrow_mut();
        if let Some(e) = cache.get(label) {
            return *e;
        }
        let e = opts.allometry.for_label(label);
        cache.insert(label.to_string(), e);
        e
    };
    // A usable row as a tree (and what it said), or why not.
    let to_tree = |p: &Placement| -> Result<(SceneTree, Facts), &'static str> {
        let Ok((x, y)) = reproject.apply(p.x, p.y) else { return Err("cannot be projected to the scene CRS") };
        if !inside(x, y) {
            return Err("outlier");
        }
        let label = p.species.as_deref().unwrap_or("");
        let Some(idx) = species.of(label) else { return Err("unmapped") };
        // (The importer refuses models without height.)
        let model_h = species.heights[idx];
        let equations = (p.dbh_cm.is_some() || p.crown_m.is_some()).then(|| equations_for(label));
        let from_dbh = p.dbh_cm.zip(equations).map(|(d, e)| e.height.metres(f64::from(d)) as f32);
        let (target, from) = match (p.height_m, from_dbh.filter(|h| *h > 0.0 && *h < MAX_TREE_HEIGHT_M), default_height)
        {
            (Some(h), _, _) => (h, HeightFrom::Given),
            (None, Some(h), _) => (h, HeightFrom::Dbh),
            (None, None, Some(h)) => (h, HeightFrom::Default),
            (None, None, None) => (model_h, HeightFrom::Model),
        };
        let crown_m = p.crown_m.or_else(|| p.dbh_cm.zip(equations).map(|(d, e)| e.crown.metres(f64::from(d)) as f32));
        // Crown width and height scale the model separately: the crown's aspect
        // relative to the model's proportions.
        let model_w = species.crown_widths[idx];
        let raw =
            crown_m.filter(|c| c.is_finite() && *c > 0.0 && model_w > 0.0).map(|c| (c / model_w) / (target / model_h));
        let aspect = raw.map_or(1.0, |a| a.clamp(1.0 / MAX_CROWN_ASPECT, MAX_CROWN_ASPECT));
        let aspect_clamped = raw.is_some_and(|a| a != aspect);
        let mut facts =
            Facts { height_m: target, from, dbh_cm: p.dbh_cm, crown_m, aspect, aspect_clamped, ground_near: false };
        // Ground: a given absolute z, else the DEM (plus a relative z), else 0.
        // Just off the DEM's data (within NEAR_EDGE_PIXELS): its nearest valid height.
        let z = match (&ground, p.z, opts.z_mode) {
            (None, z, _) => z.unwrap_or(0.0),
            (Some(_), Some(z), ZMode::Absolute) => z,
            (Some(g), z, _) => match g.height_at(x, y) {
                Some(h) => f64::from(h) + z.unwrap_or(0.0),
                None => match g.height_near(x, y) {
                    Some(h) => {
                        facts.ground_near = true;
                        f64::from(h) + z.unwrap_or(0.0)
                    }
                    None => return Err(OUTSIDE_DEM),
                },
            },
        };
        let h = rng::hash64(p.row ^ x.to_bits().rotate_left(17) ^ y.to_bits());
        let tree = SceneTree {
            pos: DVec3::new(x - origin.x, y - origin.y, z - origin.z),
            species: idx as u32,
            scale: target / model_h,
            aspect,
            yaw_rad: p.yaw_deg.map_or((h % 3600) as f32 / 3600.0 * std::f32::consts::TAU, f32::to_radians),
            variation: ((h >> 20) % 32) as u8,
            id: p.id.unwrap_or(p.row | 1 << 63),
            row: u32::try_from(p.row).unwrap_or(0),
            dated: p.dated,
        };
        Ok((tree, facts))
    };
    let cell_size_m = match opts.cell_size_m {
        Some(c) => c,
        None => {
            log("pass 2/3: tree density for the cell size");
            if stands {
                density_stands(&source, &to_tree)?
            } else {
                density_pass(&source, &to_tree)?
            }
        }
    };
    if ground.is_none() && opts.fit_ground {
        // The trees' extent and 100 m around (or a quarter of it).
        let b = sample_box;
        let margin = ((b[2] - b[0]).max(b[3] - b[1]) * 0.25).max(100.0);
        sample.ground_region = Some([
            b[0] - margin - origin.x,
            b[1] - margin - origin.y,
            b[2] + margin - origin.x,
            b[3] + margin - origin.y,
        ]);
    }
    let b = sample_box;
    sample.canopy_region =
        [b[0] - 50.0 - origin.x, b[1] - 50.0 - origin.y, b[2] + 50.0 - origin.x, b[3] + 50.0 - origin.y];
    let crown_radius = |t: &SceneTree| {
        let w = species.crown_widths[t.species as usize];
        let h = species.heights[t.species as usize];
        let r = if w > 0.0 { 0.5 * w * t.aspect } else { 0.2 * h };
        f64::from(r * t.scale)
    };
    // A sharded bake grows the stands whose box touches one of its tiles.
    let grown = std::cell::Cell::new(0u64);
    let keep = |plan: &crate::input::stands::StandPlan| {
        let keep = opts
            .shard
            .is_none_or(|(i, n)| stand_in_shard(plan, &reproject, origin, cell_size_m, opts.tile_cells, i, n));
        grown.set(grown.get() + u64::from(keep));
        keep
    };
    let Pass3 { trees, summary, outside, fit, canopy } =
        tree_pass(opts, &source, &sample, cell_size_m, &to_tree, &crown_radius, &keep, out, log)?;
    if stands {
        log(&format!(
            "stands: {} of {} grown{}",
            grown.get(),
            source.stand_plans().len(),
            opts.shard.map_or(String::new(), |(i, n)| format!(" (those touching shard {i}/{n}'s tiles)"))
        ));
    }
    if outside.trees > 0 && opts.outside_dem == OutsideDem::Error {
        let b = outside.bounds;
        bail!(
            "{} of {} trees fall outside every --dem or on its nodata pixels: they lie within x {:.6}–{:.6}, \
             y {:.6}–{:.6} (placement coordinates), e.g. rows {:?}; {}. Add a DEM that covers them, or pass \
             --outside-dem skip to leave them out",
            outside.trees,
            outside.rows_read,
            b[0],
            b[2],
            b[1],
            b[3],
            outside.rows,
            ground.as_ref().map(super::ground::Ground::describe).unwrap_or_default()
        );
    }
    log_summary(&summary, species, log);
    if stands {
        log(&format!("grew {} stands once in {:.1} s", grown.get(), started.elapsed().as_secs_f64()));
    } else {
        log(&format!("read the placements 3 times in {:.1} s", started.elapsed().as_secs_f64()));
    }
    // The terrain: the trees' extent (outliers left out) and a margin of a
    // quarter of it (at least 500 m: the hills around a plot) around, within the DEMs.
    let ground = ground.map(|g| {
        let b = sample_box;
        let margin = ((b[2] - b[0]).max(b[3] - b[1]) * 0.25).max(500.0);
        let mut region = [b[0] - margin, b[1] - margin, b[2] + margin, b[3] + margin];
        // Within the DEMs (their extents in the scene CRS).
        if let Some(e) = g.scene_extent() {
            region = [region[0].max(e[0]), region[1].max(e[1]), region[2].min(e[2]), region[3].min(e[3])];
        }
        (g, [region[0] - origin.x, region[1] - origin.y, region[2] - origin.x, region[3] - origin.y])
    });
    let fitted = fit.and_then(super::ground::GroundFit::finish).zip(sample.ground_region);
    let attributes = if source.attribute_names().is_empty() {
        None
    } else {
        let started = Instant::now();
        log(if stands {
            "attributes: each tree's stand (from the stand map, no tree grown)"
        } else {
            "attributes: typing and coding the other columns (2 passes)"
        });
        let table = crate::input::attributes::AttributeTable::build(&source, log)?;
        log(&format!("  ({:.1} s)", started.elapsed().as_secs_f64()));
        table
    };
    // A timeline whose columns were not all kept would draw the gone trees at every date.
    for name in &source.timeline_filled {
        if attributes.as_ref().is_none_or(|a| a.schema.column(name).is_none()) {
            bail!("the censuses' column {name:?} was not kept as an attribute (see the attributes' log above)");
        }
    }
    let text_ids = if sample.report.text_ids.0 > 0 {
        let ids = TextIds::read(&source)?;
        log(&format!("ids: {} trees have a text id, kept as their id", ids.len()));
        Some(ids)
    } else {
        None
    };
    let timeline = source.timeline.clone();
    Ok(PlacedTrees {
        trees,
        crs: dst,
        origin_m: origin,
        cell_size_m,
        ground,
        fitted,
        canopy,
        attributes,
        text_ids,
        timeline,
    })
}

/// Whether a stand's box (its corners and edge midpoints projected, a metre
/// around) touches a tile of shard `index` of `count`; a box that cannot be
/// projected, or spans over a million tiles, is kept.
fn stand_in_shard(
    plan: &crate::input::stands::StandPlan,
    reproject: &Reprojector,
    origin: DVec3,
    cell_size_m: u32,
    tile_cells: u32,
    index: u32,
    count: u32,
) -> bool {
    let [x0, y0, x1, y1] = plan.bbox;
    let (xm, ym) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
    let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
    for (x, y) in [(x0, y0), (x1, y0), (x0, y1), (x1, y1), (xm, y0), (xm, y1), (x0, ym), (x1, ym)] {
        let Ok((x, y)) = reproject.apply(x, y) else { return true };
        lo = [lo[0].min(x), lo[1].min(y)];
        hi = [hi[0].max(x), hi[1].max(y)];
    }
    let tile = |x: f64, y: f64| {
        crate::bake::batching::tile_of(DVec3::new(x - origin.x, y - origin.y, 0.0), cell_size_m, tile_cells)
    };
    // A metre and a thousandth around: a lon/lat box's edges bow a little once projected.
    let m = 1.0 + 1e-3 * (hi[0] - lo[0]).max(hi[1] - lo[1]);
    let ((tx0, ty0), (tx1, ty1)) = (tile(lo[0] - m, lo[1] - m), tile(hi[0] + m, hi[1] + m));
    if !(lo[0].is_finite() && lo[1].is_finite() && hi[0].is_finite() && hi[1].is_finite())
        || (i128::from(tx1) - i128::from(tx0) + 1) * (i128::from(ty1) - i128::from(ty0) + 1) > 1_000_000
    {
        return true;
    }
    (ty0..=ty1).any(|ty| (tx0..=tx1).any(|tx| crate::bake::batching::shard_of_tile(tx, ty, count) == index))
}

/// A usable row as a tree and what it said, or why not.
type TreeOf<'a> = dyn Fn(&Placement) -> Result<(SceneTree, Facts), &'static str> + 'a;
