//! What the placements stage says of each species when it is done.

use std::collections::BTreeMap;

use super::*;

/// Per species label: the model used and the ranges a forester can check.
#[derive(Debug, Clone)]
pub(super) struct SpeciesSummary {
    pub(super) model: usize,
    pub(super) trees: u64,
    pub(super) height: (f32, f32),
    pub(super) dbh: Option<(f32, f32)>,
    pub(super) crown: Option<(f32, f32)>,
    /// Range of the crown aspects (trees with a crown width only).
    pub(super) aspect: Option<(f32, f32)>,
    /// Trees whose aspect was clamped.
    pub(super) aspect_clamped: u64,
    /// Trees just off the DEM's data, on the nearest valid height.
    pub(super) ground_near: u64,
    pub(super) from_dbh: u64,
    /// Rows with a DBH, and of them over 150 cm and under 3 cm (unit checks).
    pub(super) dbh_rows: u64,
    pub(super) dbh_big: u64,
    pub(super) dbh_small: u64,
}

pub(super) fn widen(r: Option<(f32, f32)>, v: f32) -> (f32, f32) {
    r.map_or((v, v), |(a, b)| (a.min(v), b.max(v)))
}

/// Logs, per species label, the model used, the count and the height, DBH and
/// crown ranges — what a forester checks first — and a warning when the DBH
/// values look like another unit.
pub(super) fn log_summary(summary: &BTreeMap<String, SpeciesSummary>, species: &SpeciesMap, log: &dyn Fn(&str)) {
    let mut rows: Vec<(&String, &SpeciesSummary)> = summary.iter().collect();
    rows.sort_by(|a, b| b.1.trees.cmp(&a.1.trees).then(a.0.cmp(b.0)));
    let range = |r: Option<(f32, f32)>| r.map_or("-".to_string(), |(a, b)| format!("{a:.1}–{b:.1}"));
    log(&format!("species summary ({} labels):", rows.len()));
    log("  label | model | trees | height m | DBH cm | crown m | crown × model | heights from DBH");
    const SHOWN: usize = 40;
    let ratio = |r: Option<(f32, f32)>| r.map_or("-".to_string(), |(a, b)| format!("{a:.2}–{b:.2}"));
    for (label, s) in rows.iter().take(SHOWN) {
        log(&format!(
            "  {label} | {} | {} | {} | {} | {} | {} | {}",
            species.names[s.model],
            s.trees,
            range(Some(s.height)),
            range(s.dbh),
            range(s.crown),
            ratio(s.aspect),
            s.from_dbh
        ));
    }
    log("  (crown × model: each tree's crown width over height against its model's; 1 keeps the model's shape)");
    let near: u64 = rows.iter().map(|(_, s)| s.ground_near).sum();
    if near > 0 {
        log(&format!(
            "placements: {near} trees lie just off the DEM's data (within {} pixels of it: at its edge or a hole's); \
             they stand on the nearest valid height",
            crate::bake::ground::NEAR_EDGE_PIXELS
        ));
    }
    let clamped: u64 = rows.iter().map(|(_, s)| s.aspect_clamped).sum();
    if clamped > 0 {
        log(&format!(
            "placements: warning: {clamped} trees have crowns more than {MAX_CROWN_ASPECT}× wider or narrower for \
             their height than their model's; they were drawn at {MAX_CROWN_ASPECT}× (or 1/{MAX_CROWN_ASPECT}) (check the crown column's unit: \
             a diameter read as a radius, or centimetres as metres)"
        ));
    }
    if rows.len() > SHOWN {
        let rest: u64 = rows[SHOWN..].iter().map(|(_, s)| s.trees).sum();
        log(&format!("  … {} more labels with {rest} trees", rows.len() - SHOWN));
    }
    let count = |f: fn(&SpeciesSummary) -> u64| rows.iter().map(|(_, s)| f(s)).sum::<u64>();
    let (with_dbh, big, small) = (count(|s| s.dbh_rows), count(|s| s.dbh_big), count(|s| s.dbh_small));
    if with_dbh > 0 && big * 2 > with_dbh {
        log(&format!(
            "placements: warning: {big} of {with_dbh} DBH values are over 150 cm: if the column is in millimetres, \
             pass --dbh-unit mm (or name it dbh_mm)"
        ));
    }
    if with_dbh > 0 && small * 2 > with_dbh {
        log(&format!(
            "placements: warning: {small} of {with_dbh} DBH values are under 3 cm: if the column is in metres, pass \
             --dbh-unit m (or name it dbh_m)"
        ));
    }
}
