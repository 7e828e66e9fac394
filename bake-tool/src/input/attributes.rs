//! Per-tree attributes: the inventory's columns typed and coded for
//! the tiles' `.attr` sidecars (`sylva::format::attributes`), in two streamed
//! passes over the placements: the types, ranges and category lists, then
//! every row's codes (held in memory, 4 bytes per column and row).

use std::collections::BTreeSet;

use anyhow::{bail, Result};
use sylva::format::attributes::{
    null_code, parse_date, width_for, AttributeCodes, AttributeColumn, AttributeSchema, AttributeType,
    MAX_ATTRIBUTE_COLUMNS, MAX_CATEGORIES, MAX_TEXT_BYTES,
};

use crate::input::placements::PlacementSource;

/// The attribute columns and every input row's codes.
pub struct AttributeTable {
    /// What the manifest says of the columns.
    pub schema: AttributeSchema,
    /// Per column, the code of each row (index: the 1-based row), at the
    /// column's width.
    codes: Vec<Codes>,
}

/// A column's codes by row, stored at its width (memory: 1, 2 or 4 bytes a row).
enum Codes {
    U8(Vec<u8>),
    U16(Vec<u16>),
    U32(Vec<u32>),
    /// One code over each run of rows (a stand map's stands): `starts` rising,
    /// run `k` the rows `starts[k]..=ends[k]` (memory: a stand's, not a tree's).
    Runs {
        starts: Vec<u64>,
        ends: Vec<u64>,
        codes: Vec<u32>,
    },
}

impl Codes {
    fn new(width: u8, rows: usize) -> Self {
        match width {
            1 => Self::U8(vec![u8::MAX; rows]),
            2 => Self::U16(vec![u16::MAX; rows]),
            _ => Self::U32(vec![u32::MAX; rows]),
        }
    }

    fn set(&mut self, row: usize, code: u32) {
        // (Codes fit their column's width: the column makes them.)
        match self {
            Self::U8(v) => v.get_mut(row).map(|c| *c = code as u8),
            Self::U16(v) => v.get_mut(row).map(|c| *c = code as u16),
            Self::U32(v) => v.get_mut(row).map(|c| *c = code),
            Self::Runs { .. } => None,
        };
    }

    fn get(&self, row: usize) -> Option<u32> {
        match self {
            Self::U8(v) => v.get(row).map(|&c| u32::from(c)),
            Self::U16(v) => v.get(row).map(|&c| u32::from(c)),
            Self::U32(v) => v.get(row).copied(),
            Self::Runs { starts, ends, codes } => {
                let k = starts.partition_point(|&s| s <= row as u64).checked_sub(1)?;
                (row as u64 <= ends[k]).then(|| codes[k])
            }
        }
    }
}

/// Values that mean "none" in inventories: counted as no value, so one `n/a`
/// does not turn a DBH column into text.
const NO_VALUE: [&str; 8] = ["n/a", "na", "-", "--", "null", "none", "nan", "?"];

fn is_no_value(text: &str) -> bool {
    NO_VALUE.iter().any(|n| text.eq_ignore_ascii_case(n))
}

/// Largest whole number kept exact (the schema's bound too).
const MAX_INTEGER: u64 = 9_000_000_000_000_000;

/// A number as the inventory writes it: `12.5`, or with `decimal_comma` (a `;`
/// or tab separated CSV) `12,5` and `1.234,5` as well, as the placements reader does.
fn parse_number(text: &str, decimal_comma: bool) -> Option<f64> {
    let v = if decimal_comma {
        crate::input::placements::parse_decimal_comma(text)
    } else {
        crate::input::placements::parse_f64(text)
    }?;
    v.is_finite().then_some(v)
}

/// What the first pass learns of a column.
struct Seen {
    count: u64,
    integers: bool,
    numbers: bool,
    dates: bool,
    range: [f64; 2],
    date_range: [i64; 2],
    categories: BTreeSet<String>,
    too_many: bool,
}

impl Seen {
    fn new() -> Self {
        Self {
            count: 0,
            integers: true,
            numbers: true,
            dates: true,
            range: [f64::INFINITY, f64::NEG_INFINITY],
            date_range: [i64::MAX, i64::MIN],
            categories: BTreeSet::new(),
            too_many: false,
        }
    }

    fn add(&mut self, text: &str, decimal_comma: bool) {
        self.count += 1;
        let number = parse_number(text, decimal_comma);
        self.numbers &= number.is_some();
        self.integers &= text.parse::<i64>().is_ok_and(|v| v.unsigned_abs() <= MAX_INTEGER);
        if let Some(v) = number {
            self.range = [self.range[0].min(v), self.range[1].max(v)];
        }
        if self.dates {
            match parse_date(text) {
                Some(d) => self.date_range = [self.date_range[0].min(d), self.date_range[1].max(d)],
                None => self.dates = false,
            }
        }
        if !self.too_many && !self.categories.contains(text) {
            if self.categories.len() >= MAX_CATEGORIES || text.len() > MAX_TEXT_BYTES {
                self.too_many = true;
                self.categories.clear();
            } else {
                self.categories.insert(text.to_string());
            }
        }
    }

    /// The column this makes, or why it is left out.
    fn column(self, name: &str) -> Result<AttributeColumn, String> {
        let base = |kind, width, min: f64, max: f64| AttributeColumn {
            name: name.to_string(),
            kind,
            width,
            min,
            max,
            categories: Vec::new(),
            count: self.count,
        };
        if self.count == 0 {
            return Err("no values".into());
        }
        let [lo, hi] = self.range;
        if !(hi - lo).is_finite() && self.numbers {
            return Err(format!("numbers over too wide a range ({lo:e} to {hi:e})"));
        }
        if self.integers && hi - lo < f64::from(u32::MAX - 1) {
            return Ok(base(AttributeType::Integer, width_for((hi - lo) as u64), lo, hi));
        }
        // Whole numbers too far apart for exact codes (10-digit ids or codes):
        // never quantised (a range query would match values outside it); kept
        // as categories when few enough, else left out.
        if self.integers {
            if self.too_many {
                return Err(format!(
                    "whole numbers from {lo} to {hi}, too far apart to keep exactly, and more than \
                     {MAX_CATEGORIES} different ones to keep as categories"
                ));
            }
            let categories: Vec<String> = self.categories.into_iter().collect();
            let mut c = base(AttributeType::Category, width_for(categories.len() as u64), 0.0, 0.0);
            c.categories = categories;
            return Ok(c);
        }
        if self.numbers {
            return Ok(base(AttributeType::Number, 2, lo, hi));
        }
        if self.dates {
            let [lo, hi] = self.date_range;
            return Ok(base(AttributeType::Date, width_for((hi - lo) as u64), lo as f64, hi as f64));
        }
        if self.too_many {
            return Err(format!(
                "more than {MAX_CATEGORIES} different texts (free text, or values over {MAX_TEXT_BYTES} bytes)"
            ));
        }
        let categories: Vec<String> = self.categories.into_iter().collect();
        let mut c = base(AttributeType::Category, width_for(categories.len() as u64), 0.0, 0.0);
        c.categories = categories;
        Ok(c)
    }
}

impl AttributeTable {
    /// Types and codes the attribute columns of `source` (`None` when it has
    /// none to keep). Logs each column, and each one left out and why (a name
    /// repeated or over 256 bytes, past the 256th column, free text, no values).
    ///
    /// # Errors
    /// An unreadable file, or more rows than 32-bit row numbers hold.
    pub fn build(source: &PlacementSource, log: &dyn Fn(&str)) -> Result<Option<Self>> {
        let names = source.attribute_names();
        if names.is_empty() {
            return Ok(None);
        }
        let plans = source.stand_plans();
        if !plans.is_empty() {
            let rows: u64 = plans.last().map_or(0, |p| p.first_row + p.cap);
            if rows >= u64::from(u32::MAX) {
                bail!("{rows} rows: per-tree attributes hold up to {} rows; bake with --no-attributes", u32::MAX - 1);
            }
            return Ok(Self::from_stands(plans, log));
        }
        let decimal_comma = source.decimal_comma();
        let mut seen: Vec<Seen> = names.iter().map(|_| Seen::new()).collect();
        let mut rows = 0u64;
        source.for_each_with_attributes(&mut |p| {
            rows = rows.max(p.row);
            for (s, v) in seen.iter_mut().zip(&p.attrs) {
                if let Some(v) = v.as_deref().filter(|v| !is_no_value(v)) {
                    s.add(v, decimal_comma);
                }
            }
            Ok(())
        })?;
        if rows >= u64::from(u32::MAX) {
            bail!("{rows} rows: per-tree attributes hold up to {} rows; bake with --no-attributes", u32::MAX - 1);
        }
        let mut kept = Vec::new();
        let mut columns = Vec::new();
        for (i, (s, name)) in seen.into_iter().zip(&names).enumerate() {
            let why = if name.len() > MAX_TEXT_BYTES {
                Some(format!("a name over {MAX_TEXT_BYTES} bytes"))
            } else if names[..i].iter().any(|n| n.eq_ignore_ascii_case(name)) {
                Some("a repeated column name (the first is kept)".into())
            } else if columns.len() >= MAX_ATTRIBUTE_COLUMNS {
                Some(format!("past the {MAX_ATTRIBUTE_COLUMNS}th attribute (choose with --attributes)"))
            } else {
                None
            };
            if let Some(why) = why {
                log(&format!("  attribute {name:?} left out: {why}"));
                continue;
            }
            match s.column(name) {
                Ok(c) => {
                    log(&format!("  attribute {:?}: {}", name, describe(&c)));
                    kept.push(i);
                    columns.push(c);
                }
                Err(why) => log(&format!("  attribute {name:?} left out: {why}")),
            }
        }
        if columns.is_empty() {
            return Ok(None);
        }
        let schema = AttributeSchema { columns };
        schema.validate()?;
        let mut codes: Vec<Codes> = schema.columns.iter().map(|c| Codes::new(c.width, rows as usize + 1)).collect();
        source.for_each_with_attributes(&mut |p| {
            let row = p.row as usize;
            for ((column, codes), &i) in schema.columns.iter().zip(codes.iter_mut()).zip(&kept) {
                let Some(Some(text)) = p.attrs.get(i) else { continue };
                if is_no_value(text) {
                    continue;
                }
                codes.set(row, code_of(column, text, decimal_comma));
            }
            Ok(())
        })?;
        let bytes: usize = schema.columns.iter().map(|c| usize::from(c.width)).sum();
        log(&format!("attributes: {} columns, {bytes} bytes per tree", schema.columns.len()));
        Ok(Some(Self { schema, codes }))
    }

    /// The `stand` attribute of a stand map's trees: each stand's id over
    /// its rows (no tree grown; memory per stand). `None` when the ids make
    /// no column (logged).
    #[must_use]
    pub fn from_stands(plans: &[crate::input::stands::StandPlan], log: &dyn Fn(&str)) -> Option<Self> {
        let mut seen = Seen::new();
        for plan in plans.iter().filter(|p| !is_no_value(&p.id)) {
            seen.add(&plan.id, false);
        }
        let mut column = match seen.column("stand") {
            Ok(c) => c,
            Err(why) => {
                log(&format!("  attribute \"stand\" left out: {why}"));
                return None;
            }
        };
        // (Expected stems: the trees are not grown here.)
        column.count = plans.iter().filter(|p| !is_no_value(&p.id)).map(|p| p.expected).sum::<f64>().round() as u64;
        log(&format!("  attribute \"stand\": {} (the stand of each tree)", describe(&column)));
        let codes = Codes::Runs {
            starts: plans.iter().map(|p| p.first_row + 1).collect(),
            ends: plans.iter().map(|p| p.first_row + p.cap).collect(),
            codes: plans
                .iter()
                .map(|p| if is_no_value(&p.id) { null_code(column.width) } else { code_of(&column, &p.id, false) })
                .collect(),
        };
        let schema = AttributeSchema { columns: vec![column] };
        if let Err(e) = schema.validate() {
            log(&format!("  attribute \"stand\" left out: {e}"));
            return None;
        }
        log(&format!("attributes: 1 column, {} bytes per tree", schema.columns[0].width));
        Some(Self { schema, codes: vec![codes] })
    }

    /// The codes of the trees of input rows `rows` (0: no row, no values).
    #[must_use]
    pub fn codes_for(&self, rows: &[u32]) -> AttributeCodes {
        AttributeCodes {
            count: rows.len(),
            columns: self
                .schema
                .columns
                .iter()
                .zip(&self.codes)
                .map(|(c, codes)| {
                    let null = null_code(c.width);
                    rows.iter().map(|&r| if r == 0 { null } else { codes.get(r as usize).unwrap_or(null) }).collect()
                })
                .collect(),
        }
    }
}

/// The code of `text` in `column` (its null code when it is no value of the column's kind).
fn code_of(column: &AttributeColumn, text: &str, decimal_comma: bool) -> u32 {
    match column.kind {
        AttributeType::Category => column.code_of_category(text),
        AttributeType::Date => parse_date(text).map_or(null_code(column.width), |d| column.code_of_number(d as f64)),
        AttributeType::Integer | AttributeType::Number => {
            parse_number(text, decimal_comma).map_or(null_code(column.width), |v| column.code_of_number(v))
        }
    }
}

/// A column for the log: `category, 4 values (fair, good, poor, …)`, `number
/// 5–150`, `date 1990-01-01–2020-12-31`; with how many trees have a value.
fn describe(c: &AttributeColumn) -> String {
    use sylva::format::attributes::format_date;
    let what = match c.kind {
        AttributeType::Category => {
            let shown: Vec<&str> = c.categories.iter().take(5).map(String::as_str).collect();
            let more = if c.categories.len() > 5 { ", …" } else { "" };
            format!("category, {} values ({}{more})", c.categories.len(), shown.join(", "))
        }
        AttributeType::Integer => format!("integer {}–{}", c.min, c.max),
        AttributeType::Number => format!("number {}–{}", c.min, c.max),
        AttributeType::Date => format!("date {}–{}", format_date(c.min as i64), format_date(c.max as i64)),
    };
    format!("{what}; {} rows with a value", c.count)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn columns_are_typed_by_their_values() {
        let typed = |values: &[&str]| {
            let mut s = Seen::new();
            for v in values {
                s.add(v, false);
            }
            s.column("c")
        };
        assert_eq!(typed(&["1", "2", "12"]).unwrap().kind, AttributeType::Integer);
        assert_eq!(typed(&["1", "2.5", "12"]).unwrap().kind, AttributeType::Number);
        assert_eq!(typed(&["2001-02-03", "1999-12-31"]).unwrap().kind, AttributeType::Date);
        let c = typed(&["good", "poor", "good", "fair"]).unwrap();
        assert_eq!(
            (c.kind, c.categories.clone()),
            (AttributeType::Category, vec!["fair".into(), "good".into(), "poor".into()])
        );
        assert_eq!(c.count, 4);
        // Free text is left out; so is an empty column.
        let many: Vec<String> = (0..=MAX_CATEGORIES).map(|i| format!("note {i}")).collect();
        assert!(typed(&many.iter().map(String::as_str).collect::<Vec<_>>()).is_err());
        assert!(typed(&[]).is_err());
        // 10-digit codes are too far apart for exact integer codes: kept as
        // categories (exact), never quantised; too many of them, left out.
        let codes = typed(&["1000000001", "9876543210", "1000000001"]).unwrap();
        assert_eq!(
            (codes.kind, codes.categories.clone()),
            (AttributeType::Category, vec!["1000000001".into(), "9876543210".into()])
        );
        let many: Vec<String> =
            (0..=MAX_CATEGORIES as u64).map(|i| (1_000_000_000 + i * 2_000_000).to_string()).collect();
        let e = typed(&many.iter().map(String::as_str).collect::<Vec<_>>()).unwrap_err();
        assert!(e.contains("too far apart to keep exactly"), "{e}");
        // A year column is an exact integer of one byte.
        let y = typed(&["1950", "2020"]).unwrap();
        assert_eq!((y.width, y.min, y.max), (1, 1950.0, 2020.0));
        assert_eq!(parse_number("12,5", true), Some(12.5));
        assert_eq!(parse_number("12,5", false), None, "a comma CSV's \"12,5\" is no number");
        assert_eq!(parse_number("NaN", false), None);
        assert!(is_no_value("N/A") && is_no_value("-") && !is_no_value("0"));
        // Whole numbers past 9e15 are numbers, not integers (the schema's bound).
        assert_eq!(typed(&["1", "9100000000000000"]).unwrap().kind, AttributeType::Number);
    }

    /// A stand map's `stand` attribute: each stand's id over exactly its rows
    /// (first_row + 1 ..= first_row + cap), none between or beyond, a no-value
    /// id (`NA`) null.
    #[test]
    fn each_stand_codes_exactly_its_rows() {
        let plan = |id: &str, first_row: u64, cap: u64| crate::input::stands::StandPlan {
            first_row,
            cap,
            expected: cap as f64,
            bbox: [0.0; 4],
            area_m2: 1.0,
            id: id.into(),
            mix: vec![("oak".into(), 1.0)],
            height_m: None,
            dbh_cm: None,
        };
        let plans = [plan("A", 0, 3), plan("NA", 3, 2), plan("B", 5, 0), plan("C", 5, 4)];
        let t = AttributeTable::from_stands(&plans, &|_| {}).unwrap();
        let c = &t.schema.columns[0];
        assert_eq!((c.name.as_str(), c.kind), ("stand", AttributeType::Category));
        let codes = t.codes_for(&[0, 1, 3, 4, 5, 6, 9, 10]).columns.remove(0);
        let name = |code: u32| c.categories.get(code as usize).map(String::as_str);
        let names: Vec<Option<&str>> = codes.iter().map(|&k| name(k)).collect();
        assert_eq!(names, [None, Some("A"), Some("A"), None, None, Some("C"), Some("C"), None]);
        assert!(!c.categories.iter().any(|k| k == "NA"), "no value is no category");
    }
}
