//! Per-tree attributes (issue 19): the inventory's columns typed and coded for
//! the tiles' `.attr` sidecars (`sylva::format::attributes`), in two streamed
//! passes over the placements: the types, ranges and category lists, then
//! every row's codes (held in memory, 4 bytes per column and row).

use std::collections::BTreeSet;

use anyhow::{bail, Result};
use sylva::format::attributes::{
    null_code, parse_date, width_for, AttributeCodes, AttributeColumn, AttributeSchema, AttributeType, MAX_CATEGORIES,
    MAX_TEXT_BYTES,
};

use crate::placements::PlacementSource;

/// The attribute columns and every input row's codes.
pub struct AttributeTable {
    /// What the manifest says of the columns.
    pub schema: AttributeSchema,
    /// Per column, the code of each row (index: the 1-based row).
    codes: Vec<Vec<u32>>,
}

/// A number as an inventory writes it: `12.5`, or `12,5` (a decimal comma).
fn parse_number(text: &str) -> Option<f64> {
    let v = text.parse::<f64>().ok().or_else(|| {
        (text.matches(',').count() == 1 && !text.contains('.')).then(|| text.replace(',', ".").parse().ok()).flatten()
    })?;
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

    fn add(&mut self, text: &str) {
        self.count += 1;
        let number = parse_number(text);
        self.numbers &= number.is_some();
        self.integers &= text.parse::<i64>().is_ok_and(|v| v.unsigned_abs() < 1 << 53);
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
        if self.integers && hi - lo < f64::from(u32::MAX - 1) {
            return Ok(base(AttributeType::Integer, width_for((hi - lo) as u64), lo, hi));
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
    /// none to keep). Logs each column, and each one left out and why.
    ///
    /// # Errors
    /// An unreadable file, or more rows than 32-bit row numbers hold.
    pub fn build(source: &PlacementSource, log: &dyn Fn(&str)) -> Result<Option<Self>> {
        let names = source.attribute_names();
        if names.is_empty() {
            return Ok(None);
        }
        let mut seen: Vec<Seen> = names.iter().map(|_| Seen::new()).collect();
        let mut rows = 0u64;
        source.for_each_with_attributes(&mut |p| {
            rows = rows.max(p.row);
            for (s, v) in seen.iter_mut().zip(&p.attrs) {
                if let Some(v) = v {
                    s.add(v);
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
        let mut codes: Vec<Vec<u32>> =
            schema.columns.iter().map(|c| vec![null_code(c.width); rows as usize + 1]).collect();
        source.for_each_with_attributes(&mut |p| {
            let row = p.row as usize;
            for ((column, codes), &i) in schema.columns.iter().zip(codes.iter_mut()).zip(&kept) {
                let Some(Some(text)) = p.attrs.get(i) else { continue };
                let code = match column.kind {
                    AttributeType::Category => column.code_of_category(text),
                    AttributeType::Date => {
                        parse_date(text).map_or(null_code(column.width), |d| column.code_of_number(d as f64))
                    }
                    AttributeType::Integer | AttributeType::Number => {
                        parse_number(text).map_or(null_code(column.width), |v| column.code_of_number(v))
                    }
                };
                if let Some(slot) = codes.get_mut(row) {
                    *slot = code;
                }
            }
            Ok(())
        })?;
        let bytes: usize = schema.columns.iter().map(|c| usize::from(c.width)).sum();
        log(&format!("attributes: {} columns, {bytes} bytes per tree", schema.columns.len()));
        Ok(Some(Self { schema, codes }))
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
                    rows.iter()
                        .map(|&r| if r == 0 { null } else { codes.get(r as usize).copied().unwrap_or(null) })
                        .collect()
                })
                .collect(),
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
                s.add(v);
            }
            s.column("c")
        };
        assert_eq!(typed(&["1", "2", "12"]).unwrap().kind, AttributeType::Integer);
        assert_eq!(typed(&["1", "2.5", "12,5"]).unwrap().kind, AttributeType::Number);
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
        // A year column is an exact integer of one byte.
        let y = typed(&["1950", "2020"]).unwrap();
        assert_eq!((y.width, y.min, y.max), (1, 1950.0, 2020.0));
        assert_eq!(parse_number("12,5"), Some(12.5));
        assert_eq!(parse_number("1,234,5"), None);
        assert_eq!(parse_number("NaN"), None);
    }
}
