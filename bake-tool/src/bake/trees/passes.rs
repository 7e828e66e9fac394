//! Passes 2 and 3 of the placements: the tree density (for the cell size) and
//! the trees themselves, in memory or partitioned by tile into bucket files.

use std::collections::{BTreeMap, HashSet};

use anyhow::Result;

use crate::bake::batching::{self, SceneTree};
use crate::bake::bucket::{BucketWriter, TreeSource};
use crate::input::placements::{self, Placement, PlacementSource};
use crate::out_dir::OutDir;

use super::*;

/// Pass 2: the cell size from the density of the trees.
pub(super) fn density_pass(source: &PlacementSource, to_tree: &TreeOf<'_>) -> Result<u32> {
    let mut cells = HashSet::new();
    let mut trees = 0u64;
    source.for_each(&mut |p| {
        if let Ok((t, _)) = to_tree(&p) {
            trees += 1;
            cells.insert(batching::cell64(t.pos));
        }
        Ok(())
    })?;
    Ok(batching::cell_size_for(trees, cells.len() as u64, 500.0))
}

/// Pass 2 of a stand map: the cells its stands cover (points 32 m apart on
/// average, no tree grown) and their expected stems.
pub(super) fn density_stands(source: &PlacementSource, to_tree: &TreeOf<'_>) -> Result<u32> {
    let mut cells = HashSet::new();
    source.for_each_preview(0.0, 1.0 / 1024.0, &mut |p| {
        if let Ok((t, _)) = to_tree(&p) {
            cells.insert(batching::cell64(t.pos));
        }
        Ok(())
    })?;
    let trees: f64 = source.stand_plans().iter().map(|p| p.expected).sum();
    Ok(batching::cell_size_for(trees.round() as u64, cells.len().max(1) as u64, 500.0))
}

/// Pass 3: the trees, in memory or partitioned by tile into bucket files; the
/// report of every row skipped and why, and the summary per species label.
#[allow(clippy::too_many_arguments)] // the pass's inputs, each used once
pub(super) fn tree_pass(
    opts: &TreeOptions<'_>,
    source: &PlacementSource,
    sample: &Sample,
    cell_size_m: u32,
    to_tree: &TreeOf<'_>,
    crown_radius: &dyn Fn(&SceneTree) -> f64,
    keep: &dyn Fn(&crate::input::stands::StandPlan) -> bool,
    out: &OutDir,
    log: &dyn Fn(&str),
) -> Result<Pass3> {
    let buckets = sample.report.kept.div_ceil(opts.bucket_trees.max(1)).max(1);
    log(&format!(
        "pass 3/3: trees{}",
        if buckets > 1 {
            format!(" into {buckets} bucket files by tile (--bucket-trees {})", opts.bucket_trees)
        } else {
            String::new()
        }
    ));
    let mut unmapped: BTreeMap<String, u64> = BTreeMap::new();
    let mut summary: BTreeMap<String, SpeciesSummary> = BTreeMap::new();
    let mut note = |p: &Placement, t: &SceneTree, f: &Facts| {
        let label = p.species.as_deref().unwrap_or("(no species)");
        if !summary.contains_key(label) {
            let first = SpeciesSummary {
                model: t.species as usize,
                trees: 0,
                height: (f.height_m, f.height_m),
                dbh: None,
                crown: None,
                aspect: None,
                aspect_clamped: 0,
                ground_near: 0,
                from_dbh: 0,
                dbh_rows: 0,
                dbh_big: 0,
                dbh_small: 0,
            };
            summary.insert(label.to_string(), first);
        }
        let Some(s) = summary.get_mut(label) else { return };
        s.trees += 1;
        s.height = widen(Some(s.height), f.height_m);
        if let Some(d) = f.dbh_cm {
            s.dbh = Some(widen(s.dbh, d));
            s.dbh_rows += 1;
            s.dbh_big += u64::from(d > 150.0);
            s.dbh_small += u64::from(d < 3.0);
        }
        if let Some(c) = f.crown_m {
            s.crown = Some(widen(s.crown, c));
            s.aspect = Some(widen(s.aspect, f.aspect));
            s.aspect_clamped += u64::from(f.aspect_clamped);
        }
        s.from_dbh += u64::from(f.from == HeightFrom::Dbh);
        s.ground_near += u64::from(f.ground_near);
    };
    let mut ours = placements::Report::default();
    let mut outside = Outside { bounds: [f64::MAX, f64::MAX, f64::MIN, f64::MIN], ..Outside::default() };
    // Every tree of every shard goes into the fitted ground, so shards agree on it.
    let mut fit = sample.ground_region.map(crate::bake::ground::GroundFit::new);
    // Likewise the canopy cover (2 m cells).
    let mut canopy = crate::bake::ground_material::CanopyCover::new(sample.canopy_region, 2.0);
    let mut fit_add = |t: &SceneTree| {
        if let Some(f) = fit.as_mut() {
            f.add(t.pos.x, t.pos.y, t.pos.z);
        }
        // (The ground under the crowns of the latest date: a tree gone by then left none.)
        if !t.dated {
            canopy.add(t.pos.x, t.pos.y, crown_radius(t));
        }
    };
    // A stand map's ground and cover come from every stand's trees as uniform
    // points (as many as its stems, none grown), so a shard that grows only
    // its own stands agrees on them; only the terrain uses them, which shard
    // 0 writes (the other shards skip them).
    let stands = !source.stand_plans().is_empty();
    if stands && opts.shard.is_none_or(|(i, _)| i == 0) {
        source.for_each_preview(1.0, 0.0, &mut |p| {
            if let Ok((t, _)) = to_tree(&p) {
                fit_add(&t);
            }
            Ok(())
        })?;
    }
    let mut fit_add = |t: &SceneTree| {
        if !stands {
            fit_add(t);
        }
    };
    let mut skip = |p: &Placement, why: &str| match why {
        OUTSIDE_DEM => {
            outside.trees += 1;
            let b = &mut outside.bounds;
            *b = [b[0].min(p.x), b[1].min(p.y), b[2].max(p.x), b[3].max(p.y)];
            if outside.rows.len() < 5 {
                outside.rows.push(p.row);
            }
            ours.skip(why, p.row);
        }
        "outlier" => {
            ours.skip(&format!("farther than {} km from the median position (outlier)", opts.max_extent_km), p.row)
        }
        "unmapped" => {
            let label = p.species.as_deref().unwrap_or("");
            *unmapped.entry(if label.is_empty() { "(no species)".into() } else { label.to_string() }).or_default() += 1;
        }
        other => ours.skip(other, p.row),
    };
    let (mut report, trees) = if buckets > 1 {
        let dir = out.scratch("buckets");
        let mut writer = BucketWriter::new(&dir, buckets as u32, cell_size_m, opts.tile_cells)?;
        let report = source.for_each_in(keep, &mut |p| {
            let placed = to_tree(&p);
            if let Ok((t, _)) = &placed {
                fit_add(t);
            }
            match placed {
                Ok((t, f))
                    if opts.shard.is_none_or(|(i, n)| {
                        let (x, y) = batching::tile_of(t.pos, cell_size_m, opts.tile_cells);
                        batching::shard_of_tile(x, y, n) == i
                    }) =>
                {
                    note(&p, &t, &f);
                    writer.push(&t)?
                }
                Ok(_) => {}
                Err(why) => skip(&p, why),
            }
            Ok(())
        })?;
        (report, writer.finish()?)
    } else {
        let mut trees = Vec::with_capacity(sample.report.kept as usize / opts.shard.map_or(1, |(_, n)| n as usize));
        let report = source.for_each_in(keep, &mut |p| {
            match to_tree(&p) {
                Ok((t, f)) => {
                    fit_add(&t);
                    note(&p, &t, &f);
                    trees.push(t);
                }
                Err(why) => skip(&p, why),
            }
            Ok(())
        })?;
        (report, TreeSource::Memory(trees))
    };
    for (reason, (n, rows)) in ours.skipped {
        let e = report.skipped.entry(reason).or_insert((0, Vec::new()));
        e.0 += n;
        e.1.extend(rows);
        e.1.truncate(5);
    }
    report.duplicate_coordinates = sample.duplicates;
    for line in report.lines() {
        log(&format!("placements: {line}"));
    }
    if sample.duplicates > 0 && sample.seen as usize > DUPLICATE_CHECK_ROWS {
        log(&format!("placements: (duplicates counted among the first {DUPLICATE_CHECK_ROWS} rows)"));
    }
    for (label, n) in &unmapped {
        log(&format!(
            "placements: skipped {n} rows of species {label:?}: no --map pattern matches and no --default-model"
        ));
    }
    outside.rows_read = report.rows;
    Ok(Pass3 { trees, summary, outside, fit, canopy })
}

/// What pass 3 makes: the trees, the summary per species label, the trees
/// outside every DEM and the ground fitted to the trees (without a DEM).
pub(super) struct Pass3 {
    pub(super) trees: TreeSource,
    pub(super) summary: BTreeMap<String, SpeciesSummary>,
    pub(super) outside: Outside,
    pub(super) fit: Option<crate::bake::ground::GroundFit>,
    pub(super) canopy: crate::bake::ground_material::CanopyCover,
}

/// Trees outside every DEM: how many, where (placement coordinates) and which rows.
#[derive(Debug, Default)]
pub(super) struct Outside {
    pub(super) trees: u64,
    pub(super) bounds: [f64; 4],
    pub(super) rows: Vec<u64>,
    /// Rows read in all.
    pub(super) rows_read: u64,
}
