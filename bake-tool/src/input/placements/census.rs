//! Censuses: several inventories of the same trees (one file per census date,
//! `--placements 2008.csv --census-date 2008-11-07 …`, or one file with a date
//! column per row), or one inventory with planting and removal dates, made
//! into one row per tree with its timeline (`sylva::format::timeline`).
//!
//! Trees are matched by id across censuses. A tree is drawn where and as its
//! last record alive has it; it stands from its planting date, or for a tree
//! first recorded at a later census (ingrowth) from the day after the census
//! before (so on each census date the trees standing are that census's), and
//! until its removal date, or the first census that records it dead or no
//! longer lists it. Its height at each census it was recorded alive at (given,
//! or from its DBH by the allometry) goes into `height_<date>`, its DBH and
//! crown width (where given) into `dbh_<date>` and `crown_<date>`: the viewer
//! sizes the tree between its heights and shows them all in a pick's popup.
//! Trees not standing at the latest date are marked [`Placement::dated`]:
//! only a view at a date draws them.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use sylva::format::attributes::{format_date, parse_date};
use sylva::format::timeline::{Timeline, MAX_CENSUSES};

use super::{CoordKind, Placement, PlacementSet, PlacementSource, ReadOptions, Report};
use crate::input::allometry::Allometry;

/// The attribute a tree stands from.
pub const FROM_COLUMN: &str = "standing_from";
/// The attribute a tree stands until.
pub const UNTIL_COLUMN: &str = "standing_until";

/// Column names read as a row's census date, planting date and removal date
/// (lower case, compared without case), unless named with the options.
const DATE_NAMES: &[&str] = &["census_date", "census", "survey_date", "inventory_date", "measured", "date"];
const PLANTED_NAMES: &[&str] =
    &["planted", "planting_date", "plant_date", "date_planted", "plantdatum", "pflanzdatum", "plantation"];
const REMOVED_NAMES: &[&str] =
    &["removed", "removal_date", "date_removed", "felled", "rooidatum", "faelldatum", "fälldatum", "abattage"];
/// A status column, and the words (in any case, anywhere in it) of a tree
/// recorded dead or gone.
const STATUS_NAMES: &[&str] = &["status", "stemstatus", "tree_status", "plantstatus", "state", "vitality"];
const DEAD_WORDS: &[&str] = &[
    "dead",
    "died",
    "removed",
    "felled",
    "stump",
    "snag",
    "cut",
    "dood",
    "gerooid",
    "tot",
    "abgestorben",
    "gefällt",
    "mort",
    "abattu",
    "muerto",
];

/// How the censuses come.
#[derive(Debug, Clone, Default)]
pub struct CensusOptions {
    /// Every placements file, in the order given.
    pub files: Vec<PathBuf>,
    /// One census date per file (days since 1970-01-01), or none: the date column.
    pub dates: Vec<i64>,
    /// A date column per row (`--census-date-column`; default a column named so).
    pub date_column: Option<String>,
    /// Heights from DBH where a census gives no height.
    pub allometry: Option<Arc<Allometry>>,
    /// The date a view without one shows when there are no censuses (planting
    /// and removal dates alone): the day of the bake.
    pub today: i64,
}

impl CensusOptions {
    /// Parses `--census-date` values, one per file.
    ///
    /// # Errors
    /// A date that is no `YYYY-MM-DD`, or a count that does not match the files.
    pub fn parse_dates(files: usize, dates: &[String]) -> Result<Vec<i64>> {
        let parsed = dates
            .iter()
            .map(|d| {
                parse_date(d)
                    .filter(|_| d.trim().len() == 10)
                    .with_context(|| format!("--census-date {d:?}: expected a date as YYYY-MM-DD (e.g. 2013-07-01)"))
            })
            .collect::<Result<Vec<_>>>()?;
        if !parsed.is_empty() && parsed.len() != files {
            bail!(
                "{} --census-date for {} --placements: give one date per file, in the files' order",
                parsed.len(),
                files
            );
        }
        Ok(parsed)
    }
}

/// Whether one file's columns could make a timeline: planting or removal
/// dates (not a census date column alone: many inventories have a survey
/// date). The bake makes one only when asked (`--timeline`); it says so
/// where it could.
#[must_use]
pub fn has_timeline_columns(names: &[String]) -> bool {
    let found = |list: &[&str]| names.iter().any(|n| list.contains(&n.trim().to_lowercase().as_str()));
    found(PLANTED_NAMES) || found(REMOVED_NAMES)
}

/// The merged rows: one per tree, its attributes, its timeline.
pub struct Merged {
    /// The rows, with the timeline columns last among their attributes.
    pub set: PlacementSet,
    /// The timeline block of the manifest.
    pub timeline: Timeline,
    /// The timeline's columns that hold values (the bake checks they are kept).
    pub filled: Vec<String>,
    /// The CRS the files declare (the first file's).
    pub declared_epsg: Option<u32>,
    /// A declared CRS without an EPSG code.
    pub declared_proj4: Option<(String, String)>,
    /// For the log.
    pub notes: Vec<String>,
}

/// A tree's record at one census.
struct Record {
    day: i64,
    alive: bool,
    placement: Placement,
}

fn column_index(names: &[String], wanted: Option<&str>, defaults: &[&str]) -> Option<usize> {
    match wanted {
        Some(w) => names.iter().position(|n| n.eq_ignore_ascii_case(w)),
        None => names.iter().position(|n| defaults.contains(&n.trim().to_lowercase().as_str())),
    }
}

/// Whether a status records the tree dead or gone: a word for it (not of a
/// part: "dead top", "dead branch" are a live tree's), or ForestGEO's codes
/// `D` (dead), `M` (missing) and `P` (prior: not yet recruited).
fn is_dead(status: &str) -> bool {
    let s = status.trim().to_lowercase();
    if matches!(s.as_str(), "d" | "m" | "p") {
        return true;
    }
    let words: Vec<&str> = s.split(|c: char| !c.is_alphanumeric()).filter(|w| !w.is_empty()).collect();
    let part = words.iter().any(|w| matches!(*w, "top" | "branch" | "branches" | "limb" | "limbs" | "wood" | "crown"));
    !part && DEAD_WORDS.iter().any(|w| words.contains(w))
}

/// Whether an input column's name is one the timeline writes (it would shadow it).
fn is_timeline_name(name: &str) -> bool {
    let n = name.trim().to_lowercase();
    n == FROM_COLUMN
        || n == UNTIL_COLUMN
        || ["height_", "dbh_", "crown_"].iter().any(|p| n.strip_prefix(p).is_some_and(|d| parse_date(d).is_some()))
}

/// Reads every census file and merges their rows by tree id.
///
/// # Errors
/// A file that cannot be read, files in different coordinate kinds, a
/// census date column with no date, rows of several censuses without ids.
pub fn merge(read: &ReadOptions, census: &CensusOptions) -> Result<Merged> {
    let mut options = read.clone();
    options.census = None;
    // Every column is read (the timeline's among them); those kept as
    // attributes are chosen below.
    let kept_names = options.attributes.take();
    let several = census.files.len() > 1;
    let mut kind = None;
    let mut declared = (None, None);
    let mut notes = Vec::new();
    let mut report = Report::default();
    // Per tree (by id, or by file and row without one), its records.
    let mut order: Vec<String> = Vec::new();
    let mut trees: HashMap<String, Vec<Record>> = HashMap::new();
    let mut attribute_names: Vec<String> = Vec::new();
    let mut planted: HashMap<String, i64> = HashMap::new();
    let mut removed: HashMap<String, i64> = HashMap::new();
    let mut days_seen = std::collections::BTreeSet::new();
    let mut too_many_dates = false;
    let mut dated_columns = false;
    for (f, path) in census.files.iter().enumerate() {
        let source = PlacementSource::open(path, &options)?;
        let this = (source.declared_epsg, source.declared_proj4.clone());
        if f > 0 && this != declared && (this.0.is_some() || this.1.is_some()) {
            let name = |d: &(Option<u32>, Option<(String, String)>)| match d {
                (Some(e), _) => format!("EPSG:{e}"),
                (None, Some((n, _))) => n.clone(),
                (None, None) => "none".into(),
            };
            bail!(
                "census {} ({}) declares the CRS {}, the first {}: give every census in one CRS",
                f + 1,
                path.display(),
                name(&this),
                name(&declared)
            );
        }
        // Numbers with decimal commas (a `;`-separated file's) are written with points.
        let decimal_comma = source.decimal_comma();
        match kind {
            None => {
                kind = Some(source.kind);
                declared = this;
            }
            Some(k) if k != source.kind => bail!(
                "census {} ({}) has {} coordinates, the first has {}: give every census in one CRS",
                f + 1,
                path.display(),
                if source.kind == CoordKind::LonLat { "lon/lat" } else { "projected" },
                if k == CoordKind::LonLat { "lon/lat" } else { "projected" }
            ),
            Some(_) => {}
        }
        for n in &source.notes {
            notes.push(format!("census {} ({}): {n}", f + 1, path.display()));
        }
        let names = source.attribute_names();
        // A date column per row where named, or found among several files without --census-date.
        let date_at = match &census.date_column {
            Some(c) => column_index(&names, Some(c), DATE_NAMES),
            None if census.dates.is_empty() && several => column_index(&names, None, DATE_NAMES),
            None => None,
        };
        if census.dates.is_empty() && several && date_at.is_none() {
            bail!("census {} ({}) has no date column: give --census-date, one per file", f + 1, path.display());
        }
        if let Some(c) = &census.date_column {
            if date_at.is_none() {
                bail!("{}: no column {c:?} (--census-date-column); its columns: {}", path.display(), names.join(", "));
            }
        }
        let planted_at = column_index(&names, None, PLANTED_NAMES);
        let removed_at = column_index(&names, None, REMOVED_NAMES);
        dated_columns |= planted_at.is_some() || removed_at.is_some();
        let status_at = column_index(&names, None, STATUS_NAMES);
        // (Planting and removal dates stay attributes too: a search by them.)
        let timeline_columns = [date_at];
        // Attribute columns of this file, by name, into the union.
        let mut slot = Vec::with_capacity(names.len());
        for (i, n) in names.iter().enumerate() {
            let kept = kept_names.as_ref().is_none_or(|k| k.iter().any(|k| k.eq_ignore_ascii_case(n)));
            if timeline_columns.contains(&Some(i)) || !kept {
                slot.push(None);
                continue;
            }
            if is_timeline_name(n) {
                notes.push(format!(
                    "census {} ({}): column {n:?} left out: the timeline writes a column of that name",
                    f + 1,
                    path.display()
                ));
                slot.push(None);
                continue;
            }
            let at = attribute_names.iter().position(|a| a == n).unwrap_or_else(|| {
                attribute_names.push(n.clone());
                attribute_names.len() - 1
            });
            slot.push(Some(at));
        }
        let file_day = census.dates.get(f).copied();
        days_seen.extend(file_day);
        let file_report = source.for_each_with_attributes(&mut |mut p: Placement| {
            let cell = |i: Option<usize>| i.and_then(|i| p.attrs.get(i).cloned().flatten());
            let day = match (date_at.and_then(|i| p.attrs.get(i).cloned().flatten()), file_day) {
                (Some(text), _) => match parse_date(&text) {
                    Some(d) => Some(d),
                    None => {
                        report.skip(&format!("census {}: census date is no date (YYYY-MM-DD)", f + 1), p.row);
                        return Ok(());
                    }
                },
                (None, Some(d)) => Some(d),
                (None, None) if date_at.is_some() => {
                    report.skip(&format!("census {}: no census date", f + 1), p.row);
                    return Ok(());
                }
                (None, None) => None,
            };
            let key = match (&p.id, &p.id_text) {
                (Some(id), _) => id.to_string(),
                (None, Some(t)) => t.clone(),
                (None, None) if several || date_at.is_some() => {
                    report.skip(&format!("census {}: no id to match the tree across censuses", f + 1), p.row);
                    return Ok(());
                }
                (None, None) => format!("\u{0}{f}:{}", p.row),
            };
            // A status says who died at a census; a register's (no census dates)
            // says nothing of when: its removal date does.
            let alive = day.is_none() || !cell(status_at).is_some_and(|s| is_dead(&s));
            for (at, target) in [(planted_at, &mut planted), (removed_at, &mut removed)] {
                if let Some(text) = cell(at).filter(|t| !t.trim().is_empty()) {
                    match parse_date(&text).or_else(|| year_only(&text)) {
                        Some(d) => {
                            target.insert(key.clone(), d);
                        }
                        None => report.skip(
                            &format!("census {}: a planting or removal date is no date (kept without it)", f + 1),
                            p.row,
                        ),
                    }
                }
            }
            let mut attrs = vec![None; attribute_names.len()];
            for (i, v) in p.attrs.drain(..).enumerate() {
                if let Some(Some(at)) = slot.get(i) {
                    if let Some(a) = attrs.get_mut(*at) {
                        *a = match v {
                            Some(text) if decimal_comma && text.contains(',') => {
                                Some(match crate::input::text::parse_decimal_comma(&text) {
                                    Some(n) => n.to_string(),
                                    None => text,
                                })
                            }
                            v => v,
                        };
                    }
                }
            }
            p.attrs = attrs;
            let day = day.unwrap_or(i64::MIN);
            if day != i64::MIN && days_seen.insert(day) && days_seen.len() > MAX_CENSUSES {
                too_many_dates = true;
                return Err(anyhow::anyhow!("more than {MAX_CENSUSES} census dates"));
            }
            let records = trees.entry(key.clone()).or_insert_with(|| {
                order.push(key);
                Vec::new()
            });
            records.push(Record { day, alive, placement: p });
            Ok(())
        });
        let file_report = match file_report {
            Err(_) if too_many_dates => bail!(
                "{}: more than {MAX_CENSUSES} different census dates (a census is one date: is the date column right?)",
                path.display()
            ),
            r => r?,
        };
        report.rows += file_report.rows;
        report.missing_height += file_report.missing_height;
        report.not_utf8 += file_report.not_utf8;
        report.swappable += file_report.swappable;
        report.ids_not_numbers.0 += file_report.ids_not_numbers.0;
        for r in file_report.ids_not_numbers.1 {
            if report.ids_not_numbers.1.len() < 5 {
                report.ids_not_numbers.1.push(r);
            }
        }
        report.text_ids.0 += file_report.text_ids.0;
        report.text_ids.1 += file_report.text_ids.1;
        for (reason, (n, rows)) in file_report.skipped {
            let e = report.skipped.entry(format!("census {}: {reason}", f + 1)).or_insert((0, Vec::new()));
            e.0 += n;
            e.1.extend(rows.into_iter().take(5 - e.1.len().min(5)));
        }
    }
    let censuses: Vec<i64> = days_seen.into_iter().collect();
    if censuses.is_empty() && !dated_columns {
        bail!(
            "no census dates and no planting or removal date column ({} or {}): nothing says when a tree stands",
            PLANTED_NAMES.join(", "),
            REMOVED_NAMES.join(", ")
        );
    }
    if censuses.len() > MAX_CENSUSES {
        bail!("{} census dates: at most {MAX_CENSUSES}", censuses.len());
    }
    let latest = censuses.last().copied().unwrap_or(census.today);
    let heights: Vec<String> = censuses.iter().map(|&d| format!("height_{}", format_date(d))).collect();
    let dbhs: Vec<String> = censuses.iter().map(|&d| format!("dbh_{}", format_date(d))).collect();
    let crowns: Vec<String> = censuses.iter().map(|&d| format!("crown_{}", format_date(d))).collect();
    let base = attribute_names.len();
    // The timeline's columns first (within the attribute columns' cap whatever the files hold).
    let mut names: Vec<String> = vec![FROM_COLUMN.into(), UNTIL_COLUMN.into()];
    names.extend(heights.iter().cloned());
    names.extend(dbhs.iter().cloned());
    names.extend(crowns.iter().cloned());
    let timeline_count = names.len();
    names.extend(attribute_names);
    let mut filled = vec![false; timeline_count];
    // Rows are renumbered where a tree is made of several records; a register keeps its own.
    let renumber = !censuses.is_empty();
    let mut rows = Vec::with_capacity(order.len());
    let (mut never_alive, mut dated) = (0u64, 0u64);
    for key in order {
        let mut records = trees.remove(&key).unwrap_or_default();
        // In census order; a census listing a tree twice keeps the later row.
        records.sort_by_key(|r| r.day);
        records.dedup_by(|later, earlier| {
            let same = later.day == earlier.day;
            if same {
                std::mem::swap(later, earlier);
            }
            same
        });
        let Some(last_alive) = records.iter().rposition(|r| r.alive) else {
            never_alive += 1;
            if let Some(r) = records.first() {
                report.skip("recorded dead at every census (no size to draw)", r.placement.row);
            }
            continue;
        };
        let first_alive = records.iter().position(|r| r.alive).unwrap_or(last_alive);
        let at = |day: i64| censuses.binary_search(&day).ok();
        let first_day = records[first_alive].day;
        let last_day = records[last_alive].day;
        // Ingrowth: first recorded alive at a later census grows in from the
        // day after the one before (which did not record it).
        let from = planted.get(&key).copied().or_else(|| at(first_day).filter(|&c| c > 0).map(|c| censuses[c - 1] + 1));
        // Gone at the first census after its last record alive (dead there, or not listed).
        let until = removed.get(&key).copied().or_else(|| at(last_day).and_then(|c| censuses.get(c + 1).copied()));
        let mut cells: Vec<Option<String>> = vec![None; 2 + 3 * censuses.len()];
        cells[0] = from.map(format_date);
        cells[1] = until.map(format_date);
        for r in records.iter().filter(|r| r.alive) {
            let Some(c) = at(r.day) else { continue };
            let p = &r.placement;
            let from_dbh = || {
                let (a, d) = (census.allometry.as_ref()?, p.dbh_cm?);
                let h = a.for_label(p.species.as_deref().unwrap_or("")).height.metres(f64::from(d));
                (h.is_finite() && h > 0.0).then_some(h as f32)
            };
            cells[2 + c] = p.height_m.or_else(from_dbh).map(|h| format!("{h:.2}"));
            cells[2 + censuses.len() + c] = p.dbh_cm.map(|d| format!("{d:.1}"));
            cells[2 + 2 * censuses.len() + c] = p.crown_m.map(|w| format!("{w:.1}"));
        }
        let mut p = records.swap_remove(last_alive).placement;
        for (f, c) in filled.iter_mut().zip(&cells) {
            *f |= c.is_some();
        }
        let mut own = std::mem::take(&mut p.attrs);
        own.resize(base, None);
        p.attrs = cells;
        p.attrs.extend(own);
        p.dated = !(from.is_none_or(|f| f <= latest) && until.is_none_or(|u| latest < u));
        dated += u64::from(p.dated);
        if renumber {
            p.row = rows.len() as u64 + 1;
        }
        rows.push(p);
    }
    report.kept = rows.len() as u64;
    notes.push(format!(
        "censuses: {} trees from {} rows of {} file(s){}; {} not standing at {} (drawn at a date){}",
        rows.len(),
        report.rows,
        census.files.len(),
        if censuses.is_empty() {
            String::new()
        } else {
            format!(", census dates {}", censuses.iter().map(|&d| format_date(d)).collect::<Vec<_>>().join(", "))
        },
        dated,
        format_date(latest),
        if never_alive > 0 { format!("; {never_alive} only ever recorded dead, left out") } else { String::new() }
    ));
    if rows.is_empty() {
        bail!("the censuses hold no tree recorded alive");
    }
    let filled: Vec<String> = names.iter().zip(&filled).filter(|(_, f)| **f).map(|(n, _)| n.clone()).collect();
    Ok(Merged {
        filled,
        set: PlacementSet {
            kind: kind.unwrap_or(CoordKind::Projected),
            rows,
            report,
            declared_epsg: declared.0,
            attribute_names: names,
        },
        timeline: Timeline {
            censuses: censuses.iter().map(|&d| format_date(d)).collect(),
            latest: format_date(latest),
            from: FROM_COLUMN.into(),
            until: UNTIL_COLUMN.into(),
            heights,
        },
        declared_epsg: declared.0,
        declared_proj4: declared.1,
        notes,
    })
}

/// A planting year alone (`1987`, as many registers keep it): its 1 January.
fn year_only(text: &str) -> Option<i64> {
    let t = text.trim();
    let t = t.strip_suffix(".0").unwrap_or(t);
    (t.len() == 4 && t.bytes().all(|b| b.is_ascii_digit()))
        .then(|| t.parse::<i64>().ok())
        .flatten()
        .filter(|y| (1000..=2999).contains(y))
        .map(|y| sylva::calendar::days_from_civil(y, 1, 1))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("sylva-census-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    fn day(s: &str) -> i64 {
        parse_date(s).unwrap()
    }

    /// A row's attribute by name.
    fn cell<'a>(set: &'a PlacementSet, p: &'a Placement, name: &str) -> Option<&'a str> {
        let i = set.attribute_names.iter().position(|n| n == name)?;
        p.attrs.get(i)?.as_deref()
    }

    #[test]
    fn three_censuses_become_one_tree_each_with_its_timeline() {
        let dir = tmp("three");
        // 1: in all three, growing; 2: dead at the second; 3: not listed at the third;
        // 4: new at the second (ingrowth); 5: only ever dead; 6: a DBH and no height.
        let files = [
            ("2008.csv", "id,x,y,species,height,dbh,status\n1,500000,5700000,oak,10,,alive\n2,500010,5700000,oak,12,,alive\n3,500020,5700000,pine,8,,\n5,500040,5700000,oak,3,,dead\n6,500050,5700000,oak,,30,\n"),
            ("2013.csv", "id,x,y,species,height,dbh,status\n1,500000,5700000,oak,11,,alive\n2,500010,5700000,oak,12,,Dead (standing)\n3,500020,5700000,pine,9,,\n4,500030,5700000,oak,4,,\n6,500050,5700000,oak,,32,\n"),
            ("2018.csv", "id,x,y,species,height,dbh,status\n1,500001,5700000,oak,13,,alive\n4,500030,5700000,oak,6,,\n6,500050,5700000,oak,,35,\n"),
        ];
        for (name, text) in files {
            std::fs::write(dir.join(name), text).unwrap();
        }
        let census = CensusOptions {
            files: files.iter().map(|(n, _)| dir.join(n)).collect(),
            dates: ["2008-11-07", "2013-07-01", "2018-07-25"].iter().map(|d| day(d)).collect(),
            date_column: None,
            allometry: Some(Arc::new(Allometry::built_in())),
            today: day("2026-12-06"),
        };
        let m = merge(&ReadOptions::default(), &census).unwrap();
        let set = &m.set;
        let ids: Vec<u64> = set.rows.iter().map(|p| p.id.unwrap()).collect();
        assert_eq!(ids, [1, 2, 3, 6, 4], "in order of first appearance; 5 only ever dead");
        assert_eq!(m.timeline.censuses, ["2008-11-07", "2013-07-01", "2018-07-25"]);
        assert_eq!(m.timeline.latest, "2018-07-25");
        assert_eq!(set.report.skipped.len(), 1, "{:?}", set.report.skipped);
        let row = |id: u64| set.rows.iter().find(|p| p.id == Some(id)).unwrap();
        let get = |id: u64, name: &str| cell(set, row(id), name).map(str::to_string);
        // 1: always there, drawn where and as its last census has it.
        assert_eq!((get(1, FROM_COLUMN), get(1, UNTIL_COLUMN)), (None, None));
        assert_eq!(row(1).x, 500_001.0);
        assert_eq!(row(1).height_m, Some(13.0));
        assert!(!row(1).dated);
        let heights: Vec<Option<String>> = m.timeline.heights.iter().map(|h| get(1, h)).collect();
        assert_eq!(heights, [Some("10.00".into()), Some("11.00".into()), Some("13.00".into())]);
        // 2: recorded dead at the second census: gone from then, at its 2008 size.
        assert_eq!(get(2, UNTIL_COLUMN).as_deref(), Some("2013-07-01"));
        assert!(row(2).dated);
        assert_eq!(get(2, "height_2013-07-01"), None);
        // 3: not listed at the third.
        assert_eq!(get(3, UNTIL_COLUMN).as_deref(), Some("2018-07-25"));
        assert!(row(3).dated);
        // 4: grows in from the day after the first census.
        assert_eq!(get(4, FROM_COLUMN).as_deref(), Some("2008-11-08"));
        assert_eq!(get(4, UNTIL_COLUMN), None);
        assert!(!row(4).dated);
        // 6: heights from its DBH by the allometry, its DBH kept per census.
        assert_eq!(get(6, "dbh_2013-07-01").as_deref(), Some("32.0"));
        let h: Vec<f64> = m.timeline.heights.iter().map(|c| get(6, c).unwrap().parse().unwrap()).collect();
        assert!(h[0] > 5.0 && h[0] < h[1] && h[1] < h[2], "{h:?}");
        // The attributes: the timeline's columns, then the files' (the status too).
        assert_eq!(set.attribute_names[..2], [FROM_COLUMN.to_string(), UNTIL_COLUMN.to_string()]);
        assert!(set.attribute_names.ends_with(&["species".into(), "height".into(), "dbh".into(), "status".into()]));
        assert!(m.filled.contains(&UNTIL_COLUMN.to_string()) && m.filled.contains(&"dbh_2013-07-01".to_string()));
        assert!(!m.filled.contains(&"crown_2013-07-01".to_string()), "no crown widths given");
        assert!(m
            .notes
            .iter()
            .any(|n| n.contains("5 trees from 13 rows of 3 file(s)") && n.contains("2 not standing")));
    }

    #[test]
    fn one_file_with_a_date_column_or_planting_dates_makes_a_timeline() {
        let dir = tmp("columns");
        // Every census's rows in one file, a date per row.
        let path = dir.join("all.csv");
        std::fs::write(
            &path,
            "tree,x,y,height,surveyed\nA,0,0,5,2010-05-01\nA,0,0,7,2015-05-01\nB,5,0,4,2015-05-01\nC,9,0,4,2010-05-01\n,1,1,3,2010-05-01\nD,2,2,3,2010-13-01\n",
        )
        .unwrap();
        let census = CensusOptions {
            files: vec![path.clone()],
            date_column: Some("surveyed".into()),
            today: day("2026-12-06"),
            ..CensusOptions::default()
        };
        let read = ReadOptions { columns: vec![(super::super::ColumnRole::Id, "tree".into())], ..Default::default() };
        let m = merge(&read, &census).unwrap();
        assert_eq!(m.timeline.censuses, ["2010-05-01", "2015-05-01"]);
        let texts: Vec<&str> = m.set.rows.iter().map(|p| p.id_text.as_deref().unwrap()).collect();
        assert_eq!(texts, ["A", "B", "C"]);
        let reasons: Vec<&String> = m.set.report.skipped.keys().collect();
        assert!(reasons.iter().any(|r| r.contains("no id to match")), "{reasons:?}");
        assert!(reasons.iter().any(|r| r.contains("census date is no date")), "{reasons:?}");
        assert!(!m.set.attribute_names.iter().any(|n| n == "surveyed"), "the census date is no attribute");
        // C: not at the second census.
        let c = &m.set.rows[2];
        assert_eq!(cell(&m.set, c, UNTIL_COLUMN), Some("2015-05-01"));
        assert!(c.dated);

        // A street-tree register: planting years and removal dates, no censuses, no ids needed.
        let path = dir.join("register.csv");
        std::fs::write(
            &path,
            "x,y,height,planted,removed\n0,0,8,1987,\n5,0,9,2001-03-15,2019-02-01\n9,0,3,2031,\n1,1,3,soon,\n",
        )
        .unwrap();
        let census = CensusOptions { files: vec![path], today: day("2026-12-06"), ..CensusOptions::default() };
        let m = merge(&ReadOptions::default(), &census).unwrap();
        assert!(m.timeline.censuses.is_empty());
        assert_eq!(m.timeline.latest, "2026-12-06");
        let from: Vec<Option<&str>> = m.set.rows.iter().map(|p| cell(&m.set, p, FROM_COLUMN)).collect();
        assert_eq!(from, [Some("1987-01-01"), Some("2001-03-15"), Some("2031-01-01"), None]);
        let dated: Vec<bool> = m.set.rows.iter().map(|p| p.dated).collect();
        assert_eq!(dated, [false, true, true, false], "removed in 2019; planted in 2031");
        assert!(m.set.report.skipped.keys().any(|r| r.contains("planting or removal date is no date")));
        assert!(has_timeline_columns(&["x".into(), "Planted".into()]));
        assert!(!has_timeline_columns(&["x".into(), "date".into()]), "a survey date alone is no timeline");
    }

    #[test]
    fn census_options_that_do_not_fit_are_refused() {
        let e = CensusOptions::parse_dates(3, &["2008-11-07".into(), "2013-07-01".into()]).unwrap_err().to_string();
        assert!(e.contains("2 --census-date for 3 --placements"), "{e}");
        let e = CensusOptions::parse_dates(1, &["2008-11-7".into()]).unwrap_err().to_string();
        assert!(e.contains("YYYY-MM-DD"), "{e}");
        let dir = tmp("refused");
        std::fs::write(dir.join("a.csv"), "x,y\n0,0\n").unwrap();
        std::fs::write(dir.join("b.csv"), "lon,lat\n5,52\n").unwrap();
        let census = CensusOptions {
            files: vec![dir.join("a.csv"), dir.join("b.csv")],
            dates: vec![day("2008-01-01"), day("2009-01-01")],
            ..CensusOptions::default()
        };
        // Projected and lon/lat censuses.
        let e = merge(&ReadOptions::default(), &census).err().unwrap().to_string();
        assert!(e.contains("census 2 (") && e.contains("lon/lat coordinates, the first has projected"), "{e}");
        // No ids to match: every row skipped, then nothing to draw.
        std::fs::write(dir.join("b.csv"), "x,y\n1,1\n").unwrap();
        let e = merge(&ReadOptions::default(), &census).err().unwrap().to_string();
        assert!(e.contains("no tree recorded alive"), "{e}");
        let census = CensusOptions { dates: Vec::new(), ..census };
        let e = merge(&ReadOptions::default(), &census).err().unwrap().to_string();
        assert!(e.contains("no date column: give --census-date"), "{e}");
        // A date column with more dates than censuses can be.
        let mut csv = String::from("id,x,y,date\n");
        for k in 0..70 {
            csv += &format!("{k},0,0,{}\n", format_date(day("2000-01-01") + k));
        }
        std::fs::write(dir.join("c.csv"), csv).unwrap();
        let census = CensusOptions {
            files: vec![dir.join("c.csv")],
            date_column: Some("date".into()),
            ..CensusOptions::default()
        };
        let e = merge(&ReadOptions::default(), &census).err().unwrap().to_string();
        assert!(e.contains("more than 64 different census dates"), "{e}");
    }

    #[test]
    fn statuses_decimal_commas_and_clashing_names_are_read_as_meant() {
        assert!(is_dead("dead") && is_dead("Dead (standing)") && is_dead("D") && is_dead("gefällt") && is_dead("M"));
        assert!(
            !is_dead("alive") && !is_dead("dead top") && !is_dead("Dead branches") && !is_dead("A") && !is_dead("")
        );
        let dir = tmp("commas");
        std::fs::write(dir.join("a.csv"), "id;x;y;height;girth;standing_from\n1;0;0;10,5;101,5;x\n").unwrap();
        std::fs::write(dir.join("b.csv"), "id;x;y;height;girth\n1;0;0;11,5;120,25\n").unwrap();
        let census = CensusOptions {
            files: vec![dir.join("a.csv"), dir.join("b.csv")],
            dates: vec![day("2010-01-01"), day("2015-01-01")],
            ..CensusOptions::default()
        };
        let m = merge(&ReadOptions::default(), &census).unwrap();
        let p = &m.set.rows[0];
        assert_eq!(cell(&m.set, p, "girth"), Some("120.25"), "decimal commas written with points");
        assert_eq!(cell(&m.set, p, "height_2010-01-01"), Some("10.50"));
        assert_eq!(m.set.attribute_names.iter().filter(|n| *n == FROM_COLUMN).count(), 1);
        assert!(m.notes.iter().any(|n| n.contains("\"standing_from\" left out")), "{:?}", m.notes);
        // A register's dead status says nothing of when: its removal date does.
        std::fs::write(dir.join("r.csv"), "x,y,status,removed\n0,0,gefällt,2019-02-01\n1,1,dead,\n").unwrap();
        let census =
            CensusOptions { files: vec![dir.join("r.csv")], today: day("2026-12-06"), ..CensusOptions::default() };
        let m = merge(&ReadOptions::default(), &census).unwrap();
        assert_eq!(m.set.rows.len(), 2);
        assert_eq!(m.set.rows.iter().map(|p| p.row).collect::<Vec<_>>(), [1, 2], "a register keeps its rows");
        assert!(m.set.rows[0].dated && !m.set.rows[1].dated);
    }
}
