//! Pass 1 of the placements: a deterministic sample of the rows (row count,
//! duplicates), the checks it allows (swapped columns) and the scene CRS it
//! chooses; `median` for the stage's medians (origin, outliers, default height,
//! which `place_trees` takes from the sample).

use std::collections::HashSet;

use anyhow::{bail, Context, Result};

use crate::input::placements::{self, CoordKind, PlacementSource};
use crate::input::reproject::Crs;
use crate::rng;

use super::*;

/// What pass 1 learns.
pub(super) struct Sample {
    /// (x, y, height, row) of up to [`SAMPLE_ROWS`] rows.
    pub(super) rows: Vec<(f64, f64, Option<f32>, u64)>,
    /// Rows seen.
    pub(super) seen: u64,
    /// Rows repeating an earlier row's coordinates (among the first [`DUPLICATE_CHECK_ROWS`]).
    pub(super) duplicates: u64,
    pub(super) report: placements::Report,
    /// Without a DEM: the region (relative metres) over which pass 3 fits a
    /// ground surface to the trees' bases (every shard fits the same one).
    pub(super) ground_region: Option<[f64; 4]>,
    /// The region (relative metres) of the canopy cover grid: the trees and 50 m around.
    pub(super) canopy_region: [f64; 4],
}

/// Pass 1: a deterministic reservoir sample, the row count and repeated coordinates.
pub(super) fn sample_pass(source: &PlacementSource) -> Result<Sample> {
    let mut rows: Vec<(f64, f64, Option<f32>, u64)> = Vec::new();
    let mut rng = rng::Rng::new(0x5EED_5A3F_1E00_0001);
    let mut seen = 0u64;
    let mut coords = HashSet::new();
    let mut duplicates = 0u64;
    let report = source.for_each(&mut |p| {
        seen += 1;
        if coords.len() < DUPLICATE_CHECK_ROWS && !coords.insert((p.x.to_bits(), p.y.to_bits())) {
            duplicates += 1;
        }
        let item = (p.x, p.y, p.height_m, p.row);
        if rows.len() < SAMPLE_ROWS {
            rows.push(item);
        } else {
            // Reservoir sampling: every row ends up in the sample with equal odds.
            let j = rng.next_u64() % seen;
            if j < SAMPLE_ROWS as u64 {
                rows[j as usize] = item;
            }
        }
        Ok(())
    })?;
    Ok(Sample { rows, seen, duplicates, report, ground_region: None, canopy_region: [0.0; 4] })
}

/// Pass 1 of a stand map: its stands' trees as uniform points (up to
/// [`SAMPLE_ROWS`] in all, no tree grown); the counts are the stands' expected stems.
pub(super) fn sample_stands(source: &PlacementSource) -> Result<Sample> {
    let total: f64 = source.stand_plans().iter().map(|p| p.expected).sum();
    let rate = (SAMPLE_ROWS as f64 / total.max(1.0)).min(1.0);
    let mut rows: Vec<(f64, f64, Option<f32>, u64)> = Vec::new();
    let points = source.for_each_preview(rate, 0.0, &mut |p| {
        if rows.len() < SAMPLE_ROWS {
            rows.push((p.x, p.y, p.height_m, p.row));
        }
        Ok(())
    })?;
    let made = total.round() as u64;
    // The stands' expected stems stand for the rows; the points' skips (e.g.
    // lon/lat out of range) are said as they are.
    let report =
        placements::Report { rows: made, kept: made, skipped: points.skipped, ..placements::Report::default() };
    Ok(Sample { rows, seen: made, duplicates: 0, report, ground_region: None, canopy_region: [0.0; 4] })
}

/// Longitude and latitude the other way round: most rows' "latitude" beyond
/// ±90° whose "longitude" would be a latitude.
pub(super) fn check_swapped(opts: &TreeOptions<'_>, report: &placements::Report) -> Result<()> {
    if report.swappable > 0 && report.swappable * 2 >= report.rows {
        bail!(
            "placements {}: the x/longitude and y/latitude columns look swapped: {} of {} rows have a latitude \
             beyond ±90° and a longitude that would be a valid latitude; {}",
            opts.placements.display(),
            report.swappable,
            report.rows,
            if opts.read.swap_xy {
                "they are so with --swap-xy: leave it out"
            } else {
                "pass --swap-xy (or rename the columns)"
            }
        );
    }
    Ok(())
}

/// The placements' CRS and the scene's.
pub(super) fn choose_crs(
    opts: &TreeOptions<'_>,
    source: &PlacementSource,
    sample: &Sample,
    log: &dyn Fn(&str),
) -> Result<(Crs, Crs)> {
    let (src, dst) = match source.kind {
        CoordKind::LonLat => {
            let dst = match opts.crs {
                Some(c) => Crs::parse(c)?,
                None => {
                    let mut lons: Vec<f64> = sample.rows.iter().map(|p| p.0).collect();
                    let mut lats: Vec<f64> = sample.rows.iter().map(|p| p.1).collect();
                    if lons.is_empty() {
                        bail!(
                            "placements {}: no usable rows ({})",
                            opts.placements.display(),
                            sample.report.lines().join("; ")
                        );
                    }
                    Crs::utm_for(median(&mut lons), median(&mut lats))?
                }
            };
            // A file may name a geographic CRS of its own (ETRS89, NAD83).
            // A geographic --input-crs wins over the file's.
            let given = opts.input_crs.map(Crs::parse).transpose()?.filter(Crs::is_geographic);
            let src = match (given, &source.declared_proj4) {
                (Some(given), _) => given,
                (None, Some((name, proj4))) => Crs::from_proj4(name, proj4)?,
                (None, None) => Crs::from_epsg(source.declared_epsg.unwrap_or(4326))?,
            };
            (src, dst)
        }
        CoordKind::Projected if opts.input_crs.is_none() && source.declared_proj4.is_some() => {
            // A .prj without an EPSG code: read with its own definition; the
            // scene in --crs, else in the UTM zone of the placements.
            let (name, proj4) = source.declared_proj4.as_ref().expect("checked");
            log(&format!("placements: the file names its CRS {name:?}, no EPSG code: {proj4}"));
            let src = Crs::from_proj4(name, proj4)?;
            let dst = match opts.crs {
                Some(c) => Crs::parse(c)?,
                None => {
                    let mut xs: Vec<f64> = sample.rows.iter().map(|p| p.0).collect();
                    let mut ys: Vec<f64> = sample.rows.iter().map(|p| p.1).collect();
                    if xs.is_empty() {
                        bail!(
                            "placements {}: no usable rows ({})",
                            opts.placements.display(),
                            sample.report.lines().join("; ")
                        );
                    }
                    let to_lonlat = Reprojector::new(Crs::from_proj4(name, proj4)?, &Crs::from_epsg(4326)?)?;
                    let (lon, lat) = to_lonlat.apply(median(&mut xs), median(&mut ys)).with_context(|| {
                        format!(
                            "placements {}: the middle of the trees is outside CRS {name:?}",
                            opts.placements.display()
                        )
                    })?;
                    Crs::utm_for(lon, lat)?
                }
            };
            (src, dst)
        }
        CoordKind::Projected => {
            let declared = source.declared_epsg.map(|e| format!("EPSG:{e}"));
            let input = opts.input_crs.or(declared.as_deref()).or(opts.crs).context(
                "the placements have projected x/y coordinates: say which CRS they are in with --input-crs EPSG:xxxx",
            )?;
            if opts.input_crs.is_none() && declared.is_some() {
                log(&format!("placements: the file names its CRS: {input}"));
            }
            let src = Crs::parse(input)?;
            let dst = Crs::parse(opts.crs.unwrap_or(input))?;
            (src, dst)
        }
    };
    if dst.is_geographic() {
        bail!("--crs EPSG:{} is geographic; a scene needs a projected CRS in metres (e.g. a UTM zone)", dst.epsg);
    }
    log(&format!("scene CRS EPSG:{}", dst.epsg));
    Ok((src, dst))
}

pub(super) fn median(v: &mut [f64]) -> f64 {
    let n = v.len();
    v.select_nth_unstable_by(n / 2, f64::total_cmp);
    v[n / 2]
}
