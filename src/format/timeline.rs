//! A scene's timeline (`scene.json` `timeline`): the forest at a date, from
//! several censuses of the same trees or from planting and removal dates.
//!
//! The tiles hold every tree ever recorded, each at its latest size; the
//! trees not standing at the scene's `latest` date (dead, removed, planted
//! later) are in batches flagged [`super::tile::BATCH_DATED`], which a view
//! without a date skips, so such a view needs nothing more. At a date, each
//! tree's timeline is read from three kinds of attribute columns (the
//! attribute sidecar, streamed only then):
//!
//! - `from` (a date): when the tree starts standing (planted, or for a tree
//!   first recorded at a later census, the day after the census before);
//!   null: before the first census.
//! - `until` (a date): when it stands no more (removed, or the first census
//!   that found it dead or missing); null: standing at the latest census.
//! - `heights[c]` (a number, metres): its height at census `c` (null: not
//!   recorded alive then).
//!
//! A tree stands at day `d` when `from <= d < until`. Its height then is
//! interpolated linearly in time between its censuses; before the first one,
//! from a tree that grows in at [`GROW_IN_HEIGHT_M`] at `from`, else the first
//! census's; after the last, the last's. It is drawn at that height over its
//! latest (the size its tile holds): [`growth_at`].

use serde::{Deserialize, Serialize};

use super::attributes::{parse_date, AttributeCodes, AttributeSchema, AttributeType, AttributeValue};
use super::Problem;

/// A tree that grows in (planted, or first recorded at a later census) starts
/// at breast height: the height at which an inventory first records a stem.
pub const GROW_IN_HEIGHT_M: f64 = 1.3;
/// Most censuses a timeline may list.
pub const MAX_CENSUSES: usize = 64;

/// The `timeline` block of a manifest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Timeline {
    /// The census dates (`YYYY-MM-DD`), rising; empty for planting and
    /// removal dates alone.
    pub censuses: Vec<String>,
    /// The date a view without one shows (`YYYY-MM-DD`): the last census, or
    /// the day of the bake without censuses.
    pub latest: String,
    /// The date attribute a tree stands from (null: always).
    pub from: String,
    /// The date attribute a tree stands until (null: still standing).
    pub until: String,
    /// Per census, the number attribute of the tree's height then.
    pub heights: Vec<String>,
}

/// A timeline resolved against the scene's attribute columns.
#[derive(Debug, Clone, PartialEq)]
pub struct TimelineColumns {
    /// Census days (days since 1970-01-01), rising.
    pub censuses: Vec<i64>,
    /// The latest day.
    pub latest: i64,
    /// The last day a tree starts or stops standing (planned plantings and removals may be after `latest`).
    pub last_change: i64,
    /// Each column's index (`None`: absent, as the bake leaves out a column
    /// without values: no tree starts, stops, or was measured then).
    from: Option<usize>,
    until: Option<usize>,
    heights: Vec<Option<usize>>,
}

impl Timeline {
    /// Checks the block against the scene's attribute columns.
    ///
    /// # Errors
    /// A [`Problem`] naming what is wrong: dates that do not parse or do not
    /// rise, columns missing or of the wrong type, a height per census.
    pub fn resolve(&self, schema: Option<&AttributeSchema>) -> Result<TimelineColumns, Problem> {
        let bad = |what: String| Problem::Invalid(format!("timeline: {what}"));
        if self.censuses.len() > MAX_CENSUSES {
            return Err(bad(format!("{} censuses, at most {MAX_CENSUSES}", self.censuses.len())));
        }
        let mut censuses = Vec::with_capacity(self.censuses.len());
        for c in &self.censuses {
            let d = parse_date(c).filter(|_| c.len() == 10).ok_or_else(|| bad(format!("census {c:?} is no date")))?;
            if censuses.last().is_some_and(|&p| p >= d) {
                return Err(bad("census dates must rise".into()));
            }
            censuses.push(d);
        }
        let latest = parse_date(&self.latest)
            .filter(|_| self.latest.len() == 10)
            .ok_or_else(|| bad(format!("latest {:?} is no date", self.latest)))?;
        if censuses.last().is_some_and(|&l| l != latest) {
            return Err(bad("latest must be the last census".into()));
        }
        if self.heights.len() != censuses.len() {
            return Err(bad(format!("{} heights for {} censuses", self.heights.len(), censuses.len())));
        }
        let empty = AttributeSchema::default();
        let schema = schema.unwrap_or(&empty);
        // A column that is there must be of its kind; one that is not has no values.
        let column = |name: &str, kinds: &[AttributeType]| match schema.column(name) {
            Some((i, c)) if kinds.contains(&c.kind) => Ok(Some(i)),
            Some(_) => Err(bad(format!("{name:?} is no {} column", if kinds.len() == 1 { "date" } else { "number" }))),
            None => Ok(None),
        };
        let numbers = [AttributeType::Number, AttributeType::Integer];
        let (from, until) = (column(&self.from, &[AttributeType::Date])?, column(&self.until, &[AttributeType::Date])?);
        // (A column without values has no range.)
        let last = |c: Option<usize>| {
            let Some(c) = c.map(|c| &schema.columns[c]) else { return i64::MIN };
            if c.count > 0 && c.max.is_finite() {
                c.max as i64
            } else {
                i64::MIN
            }
        };
        Ok(TimelineColumns {
            last_change: last(from).max(last(until)),
            from,
            until,
            heights: self.heights.iter().map(|h| column(h, &numbers)).collect::<Result<_, _>>()?,
            censuses,
            latest,
        })
    }
}

/// One tree's timeline.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TreeTimeline {
    /// Standing from this day (`None`: always).
    pub from: Option<i64>,
    /// Standing until this day (`None`: still).
    pub until: Option<i64>,
    /// (day, height) of each census it was recorded alive at, rising.
    pub heights: Vec<(i64, f64)>,
}

impl TreeTimeline {
    /// Whether the tree stands on `day`.
    #[must_use]
    pub fn stands(&self, day: i64) -> bool {
        self.from.is_none_or(|f| f <= day) && self.until.is_none_or(|u| day < u)
    }

    /// Its height on `day` (metres; `None` without recorded heights).
    #[must_use]
    pub fn height(&self, day: i64) -> Option<f64> {
        let first = *self.heights.first()?;
        let mut knots = Vec::with_capacity(self.heights.len() + 1);
        if let Some(f) = self.from.filter(|&f| f < first.0) {
            knots.push((f, GROW_IN_HEIGHT_M.min(first.1)));
        }
        knots.extend_from_slice(&self.heights);
        let k = knots.partition_point(|&(d, _)| d <= day);
        Some(match k {
            0 => knots[0].1,
            k if k == knots.len() => knots[k - 1].1,
            k => {
                let ((d0, h0), (d1, h1)) = (knots[k - 1], knots[k]);
                h0 + (h1 - h0) * (day - d0) as f64 / (d1 - d0) as f64
            }
        })
    }

    /// Its height on `day` over its latest (the size its tile holds), at
    /// most 1 (a tree once taller, its top broken since, is drawn at its
    /// latest: the tile's bounds hold that); 1 without recorded heights.
    #[must_use]
    pub fn growth(&self, day: i64) -> f64 {
        match (self.height(day), self.heights.last()) {
            (Some(h), Some(&(_, last))) if last > 0.0 => (h / last).min(1.0),
            _ => 1.0,
        }
    }
}

impl TimelineColumns {
    /// Tree `i`'s timeline from a tile's attribute codes.
    #[must_use]
    pub fn tree(&self, schema: &AttributeSchema, codes: &AttributeCodes, i: usize) -> TreeTimeline {
        let date = |c: Option<usize>| match codes.value(schema, c?, i) {
            Some(AttributeValue::Date(d)) => Some(d),
            _ => None,
        };
        let number = |c: Option<usize>| match codes.value(schema, c?, i) {
            Some(AttributeValue::Number(v)) => Some(v),
            Some(AttributeValue::Integer(v)) => Some(v as f64),
            _ => None,
        };
        TreeTimeline {
            from: date(self.from),
            until: date(self.until),
            heights: self
                .censuses
                .iter()
                .zip(&self.heights)
                .filter_map(|(&d, &c)| number(c).filter(|h| h.is_finite() && *h > 0.0).map(|h| (d, h)))
                .collect(),
        }
    }

    /// The timeline and `day` where a view of that day needs it (see
    /// [`Self::needs_trees`]); `None` otherwise. The style and the query's
    /// filter hold this.
    #[must_use]
    pub fn at(timeline: Option<&Self>, day: Option<i64>) -> Option<(Self, i64)> {
        timeline.zip(day).filter(|(t, d)| t.needs_trees(*d)).map(|(t, d)| (t.clone(), d))
    }

    /// Whether a view of `day` needs the timeline: a day before the latest,
    /// or after it where a tree is planted or removed later.
    #[must_use]
    pub fn needs_trees(&self, day: i64) -> bool {
        day < self.latest || (day > self.latest && self.last_change > self.latest)
    }
}

/// The growth byte of a tree drawn at `growth` of its tile's size: 128 is
/// its own size, in steps of 1/128, at least 1 and at most 255.
#[must_use]
pub fn growth_byte(growth: f64) -> u8 {
    (growth * 128.0).round().clamp(1.0, 255.0) as u8
}

/// The scale a growth byte stands for.
#[must_use]
pub fn growth_of_byte(b: u8) -> f32 {
    f32::from(b) / 128.0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn day(s: &str) -> i64 {
        parse_date(s).unwrap()
    }

    #[test]
    fn a_tree_stands_from_its_start_until_its_end_and_grows_between_censuses() {
        let t = TreeTimeline {
            from: Some(day("2008-11-07")),
            until: Some(day("2018-07-25")),
            heights: vec![(day("2013-07-01"), 5.0)],
        };
        assert!(!t.stands(day("2008-11-06")));
        assert!(t.stands(day("2008-11-07")));
        assert!(t.stands(day("2018-07-24")));
        assert!(!t.stands(day("2018-07-25")));
        // Grows in from breast height to its one census.
        assert!((t.height(day("2008-11-07")).unwrap() - GROW_IN_HEIGHT_M).abs() < 1e-9);
        let mid = day("2008-11-07") + (day("2013-07-01") - day("2008-11-07")) / 2;
        let h = t.height(mid).unwrap();
        assert!((h - (GROW_IN_HEIGHT_M + 5.0) / 2.0).abs() < 0.01, "{h}");
        assert_eq!(t.height(day("2016-01-01")), Some(5.0));
        assert!((t.growth(day("2013-07-01")) - 1.0).abs() < 1e-9);

        let always = TreeTimeline {
            from: None,
            until: None,
            heights: vec![(day("2008-11-07"), 10.0), (day("2013-07-01"), 12.0), (day("2018-07-25"), 16.0)],
        };
        assert!(always.stands(day("1900-01-01")) && always.stands(day("2100-01-01")));
        assert_eq!(always.height(day("2000-01-01")), Some(10.0));
        assert!((always.growth(day("2008-11-07")) - 10.0 / 16.0).abs() < 1e-9);
        let mid = day("2013-07-01") + (day("2018-07-25") - day("2013-07-01")) / 2;
        assert!((always.height(mid).unwrap() - 14.0).abs() < 0.01);
        assert!((always.growth(day("2030-01-01")) - 1.0).abs() < 1e-9);
        assert_eq!(TreeTimeline::default().growth(0), 1.0);
        assert_eq!(growth_byte(1.0), 128);
        assert_eq!(growth_byte(0.0), 1);
        assert_eq!(growth_byte(9.0), 255);
    }

    #[test]
    fn a_timeline_that_does_not_fit_its_columns_is_refused() {
        use crate::format::attributes::AttributeColumn;
        let col = |name: &str, kind| AttributeColumn {
            name: name.into(),
            kind,
            width: 8,
            min: 0.0,
            max: 20_000.0,
            categories: Vec::new(),
            count: 1,
        };
        let schema = AttributeSchema {
            columns: vec![
                col("standing_from", AttributeType::Date),
                col("standing_until", AttributeType::Date),
                col("height_2008-11-07", AttributeType::Number),
            ],
        };
        let good = Timeline {
            censuses: vec!["2008-11-07".into()],
            latest: "2008-11-07".into(),
            from: "standing_from".into(),
            until: "standing_until".into(),
            heights: vec!["height_2008-11-07".into()],
        };
        let r = good.resolve(Some(&schema)).unwrap();
        assert_eq!(r.censuses, vec![day("2008-11-07")]);
        let refused = |t: Timeline, what: &str| {
            let e = t.resolve(Some(&schema)).unwrap_err().to_string();
            assert!(e.contains(what), "{e}");
        };
        refused(Timeline { latest: "2009-01-01".into(), ..good.clone() }, "last census");
        refused(Timeline { censuses: vec!["2008-13-07".into()], ..good.clone() }, "no date");
        refused(Timeline { from: "height_2008-11-07".into(), ..good.clone() }, "is no date column");
        refused(Timeline { heights: vec!["standing_from".into()], ..good.clone() }, "is no number column");
        // A column the bake left out (no values): nobody starts, stops or was measured then.
        let absent = Timeline { until: "gone".into(), heights: vec!["h".into()], ..good.clone() };
        let r = absent.resolve(Some(&schema)).unwrap();
        assert_eq!(r.last_change, 20_000, "standing_from's largest date");
        assert!(absent.resolve(None).is_ok());
        refused(Timeline { heights: Vec::new(), ..good.clone() }, "0 heights");
        refused(
            Timeline {
                censuses: vec!["2008-11-07".into(), "2008-11-07".into()],
                heights: vec!["height_2008-11-07".into(); 2],
                ..good.clone()
            },
            "rise",
        );
    }
}
