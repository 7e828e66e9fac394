//! Per-tree attributes: the columns of the input inventory kept as
//! typed values, described once in the manifest ([`AttributeSchema`]) and
//! stored per tile in a columnar sidecar (`tiles/<x>_<y>.attr`) in the tile's
//! instance order, like the ids (`.ids`).
//!
//! Every value is a code of a fixed width per column (1, 2 or 4 bytes, little
//! endian); the largest code of the width is "no value" ([`null_code`]).
//! - `category`: the index into the column's sorted category list.
//! - `integer`, `date` (days since 1970-01-01): `value − min`, exact.
//! - `number`: `round((value − min) / (max − min) × (null − 1))`, quantised over
//!   the column's range (half a step of error at most).
//!
//! The sidecar: `magic "SYAT"`, `version u32 (1)`, `count u64` (instances),
//! `columns u32`, per column `width u8`, then per column `count × width`
//! bytes. Decoding checks every length, width and code against the schema.

use serde::{Deserialize, Serialize};

use super::Problem;

/// The URL of a tile's attribute sidecar: its own with `.attr` for `.tile`.
#[must_use]
pub fn attributes_url(tile_url: &str) -> String {
    format!("{}.attr", tile_url.strip_suffix(".tile").unwrap_or(tile_url))
}

/// Magic of an attribute sidecar.
pub const ATTRIBUTES_MAGIC: [u8; 4] = *b"SYAT";
/// Version of the attribute sidecar.
pub const ATTRIBUTES_VERSION: u32 = 1;
/// Most attribute columns a scene describes.
pub const MAX_ATTRIBUTE_COLUMNS: usize = 256;
/// Most categories of one column (more: a free-text column, left out by the bake).
pub const MAX_CATEGORIES: usize = 4096;
/// Longest attribute name or category value (bytes).
pub const MAX_TEXT_BYTES: usize = 256;

/// What a column holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AttributeType {
    /// Real numbers, quantised over `[min, max]`.
    Number,
    /// Whole numbers in `[min, max]`, exact.
    Integer,
    /// Text values from a short list (`categories`).
    Category,
    /// Calendar dates (ISO 8601), as days since 1970-01-01 in `[min, max]`.
    Date,
}

/// One attribute column.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AttributeColumn {
    /// The input column's name.
    pub name: String,
    /// The type of its values.
    #[serde(rename = "type")]
    pub kind: AttributeType,
    /// Bytes per value in the sidecars (1, 2 or 4).
    pub width: u8,
    /// Smallest value (numbers, integers, dates in days); 0 for categories.
    #[serde(default)]
    pub min: f64,
    /// Largest value; 0 for categories.
    #[serde(default)]
    pub max: f64,
    /// Category values, sorted (categories only).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub categories: Vec<String>,
    /// Trees with a value in this column.
    #[serde(default)]
    pub count: u64,
}

/// The attribute columns of a scene (`scene.json` `attributes`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct AttributeSchema {
    /// The columns, in sidecar order.
    pub columns: Vec<AttributeColumn>,
}

/// A decoded attribute value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum AttributeValue<'a> {
    /// A number (quantised).
    Number(f64),
    /// A whole number.
    Integer(i64),
    /// A category value.
    Category(&'a str),
    /// A date, days since 1970-01-01.
    Date(i64),
}

impl AttributeValue<'_> {
    /// The value as JSON: numbers and integers as numbers, categories as
    /// strings, dates as `YYYY-MM-DD`.
    #[must_use]
    pub fn to_json(&self) -> serde_json::Value {
        match *self {
            Self::Number(v) => serde_json::json!(v),
            Self::Integer(v) => serde_json::json!(v),
            Self::Category(s) => serde_json::json!(s),
            Self::Date(d) => serde_json::json!(format_date(d)),
        }
    }
}

/// The "no value" code of a width: its largest code.
#[must_use]
pub fn null_code(width: u8) -> u32 {
    match width {
        1 => 0xff,
        2 => 0xffff,
        _ => u32::MAX,
    }
}

/// The narrowest width (1, 2 or 4) whose codes hold `0..=largest` besides "no value".
#[must_use]
pub fn width_for(largest: u64) -> u8 {
    if largest < 0xff {
        1
    } else if largest < 0xffff {
        2
    } else {
        4
    }
}

impl AttributeColumn {
    /// The code of `value` (a number, integer or date in days as f64, or a
    /// category's text); "no value" when it does not fit the column.
    #[must_use]
    pub fn code_of_number(&self, value: f64) -> u32 {
        let null = null_code(self.width);
        if !value.is_finite() || value < self.min || value > self.max {
            return null;
        }
        match self.kind {
            AttributeType::Category => null,
            AttributeType::Integer | AttributeType::Date => {
                let q = (value - self.min).round();
                if q < f64::from(null) {
                    q as u32
                } else {
                    null
                }
            }
            AttributeType::Number => {
                let span = self.max - self.min;
                if span <= 0.0 {
                    0
                } else {
                    ((value - self.min) / span * f64::from(null - 1)).round() as u32
                }
            }
        }
    }

    /// The code of a category value ("no value" when not in the list).
    #[must_use]
    pub fn code_of_category(&self, text: &str) -> u32 {
        match self.categories.binary_search_by(|c| c.as_str().cmp(text)) {
            Ok(i) => i as u32,
            Err(_) => null_code(self.width),
        }
    }

    /// The value of `code` (`None`: no value, or a code outside the column).
    #[must_use]
    pub fn value(&self, code: u32) -> Option<AttributeValue<'_>> {
        let null = null_code(self.width);
        if code >= null {
            return None;
        }
        match self.kind {
            AttributeType::Category => self.categories.get(code as usize).map(|s| AttributeValue::Category(s)),
            AttributeType::Integer => Some(AttributeValue::Integer(self.min as i64 + i64::from(code))),
            AttributeType::Date => Some(AttributeValue::Date(self.min as i64 + i64::from(code))),
            AttributeType::Number => {
                let span = self.max - self.min;
                Some(AttributeValue::Number(if span <= 0.0 {
                    self.min
                } else {
                    self.min + f64::from(code) / f64::from(null - 1) * span
                }))
            }
        }
    }

    /// The largest valid code.
    fn largest_code(&self) -> Option<u64> {
        match self.kind {
            AttributeType::Category => (self.categories.len() as u64).checked_sub(1),
            AttributeType::Integer | AttributeType::Date => Some((self.max - self.min) as u64),
            AttributeType::Number => Some(u64::from(null_code(self.width) - 1)),
        }
    }
}

impl AttributeSchema {
    /// Checks the description: names unique and short, widths 1/2/4, ranges
    /// finite and ordered, whole for integers and dates and within their
    /// width, categories sorted, unique and within their width.
    ///
    /// # Errors
    /// The first problem, naming the column.
    pub fn validate(&self) -> Result<(), Problem> {
        if self.columns.len() > MAX_ATTRIBUTE_COLUMNS {
            return Err(Problem::Invalid(format!(
                "attributes: {} columns (at most {MAX_ATTRIBUTE_COLUMNS})",
                self.columns.len()
            )));
        }
        let mut names = std::collections::HashSet::new();
        for (i, c) in self.columns.iter().enumerate() {
            let what = format!("attributes.columns[{i}] ({:?})", c.name);
            let bad = |why: String| Err(Problem::Invalid(format!("{what}: {why}")));
            if c.name.is_empty() || c.name.len() > MAX_TEXT_BYTES || !names.insert(c.name.as_str()) {
                return bad("empty, too long or repeated name".into());
            }
            if ![1, 2, 4].contains(&c.width) {
                return bad(format!("width {} (1, 2 or 4)", c.width));
            }
            if !c.min.is_finite() || !c.max.is_finite() || c.min > c.max || !(c.max - c.min).is_finite() {
                return bad(format!("range {}..{}", c.min, c.max));
            }
            let null = u64::from(null_code(c.width));
            match c.kind {
                AttributeType::Category => {
                    if c.categories.len() > MAX_CATEGORIES || c.categories.len() as u64 >= null {
                        return bad(format!("{} categories for width {}", c.categories.len(), c.width));
                    }
                    if c.categories.iter().any(|s| s.len() > MAX_TEXT_BYTES)
                        || c.categories.windows(2).any(|w| w[0] >= w[1])
                    {
                        return bad("categories not sorted, repeated or too long".into());
                    }
                }
                AttributeType::Integer | AttributeType::Date => {
                    if c.min.fract() != 0.0 || c.max.fract() != 0.0 || c.min.abs() > 9.0e15 || c.max.abs() > 9.0e15 {
                        return bad(format!("range {}..{} not whole", c.min, c.max));
                    }
                    if (c.max - c.min) >= null as f64 {
                        return bad(format!("range {}..{} too wide for width {}", c.min, c.max, c.width));
                    }
                }
                AttributeType::Number => {
                    if !c.categories.is_empty() {
                        return bad("a number column with categories".into());
                    }
                }
            }
        }
        Ok(())
    }

    /// The column named `name` (exactly, else ignoring ASCII case).
    #[must_use]
    pub fn column(&self, name: &str) -> Option<(usize, &AttributeColumn)> {
        let mut all = self.columns.iter().enumerate();
        all.clone().find(|(_, c)| c.name == name).or_else(|| all.find(|(_, c)| c.name.eq_ignore_ascii_case(name)))
    }
}

/// The codes of a tile's instances, one vector per column.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AttributeCodes {
    /// Instances.
    pub count: usize,
    /// Per column (schema order), `count` codes.
    pub columns: Vec<Vec<u32>>,
}

impl AttributeCodes {
    /// Value of column `column` for instance `i`.
    #[must_use]
    pub fn value<'s>(&self, schema: &'s AttributeSchema, column: usize, i: usize) -> Option<AttributeValue<'s>> {
        let code = *self.columns.get(column)?.get(i)?;
        schema.columns.get(column)?.value(code)
    }

    /// Per column, the smallest and largest code with a value (`None`: no
    /// instance has one): the tile's `attribute_codes` in the manifest or index.
    #[must_use]
    pub fn ranges(&self, schema: &AttributeSchema) -> Vec<Option<[u32; 2]>> {
        schema
            .columns
            .iter()
            .zip(&self.columns)
            .map(|(c, codes)| {
                let null = null_code(c.width);
                codes
                    .iter()
                    .filter(|&&k| k != null)
                    .fold(None, |r: Option<[u32; 2]>, &k| Some(r.map_or([k, k], |[lo, hi]| [lo.min(k), hi.max(k)])))
            })
            .collect()
    }

    /// Every value of instance `i` as a JSON object `{name: value}` (columns
    /// without a value left out).
    #[must_use]
    pub fn json(&self, schema: &AttributeSchema, i: usize) -> serde_json::Map<String, serde_json::Value> {
        schema
            .columns
            .iter()
            .enumerate()
            .filter_map(|(k, c)| Some((c.name.clone(), self.value(schema, k, i)?.to_json())))
            .collect()
    }
}

/// Encodes a tile's attribute sidecar. Codes must fit their column's width
/// (the bake's [`AttributeColumn::code_of_number`] and friends make them so).
///
/// # Panics
/// If `codes` does not match the schema (a bake bug).
#[must_use]
pub fn encode_attributes(schema: &AttributeSchema, codes: &AttributeCodes) -> Vec<u8> {
    assert_eq!(codes.columns.len(), schema.columns.len(), "one code vector per column");
    let mut out = Vec::with_capacity(20 + codes.count * schema.columns.iter().map(|c| c.width as usize).sum::<usize>());
    out.extend_from_slice(&ATTRIBUTES_MAGIC);
    out.extend_from_slice(&ATTRIBUTES_VERSION.to_le_bytes());
    out.extend_from_slice(&(codes.count as u64).to_le_bytes());
    out.extend_from_slice(&(schema.columns.len() as u32).to_le_bytes());
    out.extend(schema.columns.iter().map(|c| c.width));
    for (c, v) in schema.columns.iter().zip(&codes.columns) {
        assert_eq!(v.len(), codes.count, "{}: one code per instance", c.name);
        for &code in v {
            match c.width {
                1 => out.push(code as u8),
                2 => out.extend_from_slice(&(code as u16).to_le_bytes()),
                _ => out.extend_from_slice(&code.to_le_bytes()),
            }
        }
    }
    out
}

/// Decodes and checks a tile's attribute sidecar against `schema`, for a tile
/// of `instances` instances. `file` names it in errors.
///
/// # Errors
/// Wrong magic or version, a count other than the tile's, columns or widths
/// other than the schema's, a length other than they give, or a code outside
/// its column.
pub fn decode_attributes(
    file: &str,
    bytes: &[u8],
    schema: &AttributeSchema,
    instances: usize,
) -> Result<AttributeCodes, Problem> {
    let bad = |why: String| Problem::Invalid(format!("{file}: {why}"));
    if bytes.len() < 20 || bytes[..4] != ATTRIBUTES_MAGIC {
        return Err(bad("not an attribute sidecar (magic \"SYAT\")".into()));
    }
    let version = u32::from_le_bytes(bytes[4..8].try_into().expect("4 bytes"));
    if version != ATTRIBUTES_VERSION {
        return Err(bad(format!("version {version}, this viewer reads {ATTRIBUTES_VERSION}")));
    }
    let count = u64::from_le_bytes(bytes[8..16].try_into().expect("8 bytes"));
    if count != instances as u64 {
        return Err(bad(format!("{count} instances, the tile has {instances}")));
    }
    let columns = u32::from_le_bytes(bytes[16..20].try_into().expect("4 bytes")) as usize;
    if columns != schema.columns.len() {
        return Err(bad(format!("{columns} columns, the scene describes {}", schema.columns.len())));
    }
    let widths = bytes.get(20..20 + columns).ok_or_else(|| bad("truncated column widths".into()))?;
    for (w, c) in widths.iter().zip(&schema.columns) {
        if *w != c.width {
            return Err(bad(format!("column {:?} has width {w}, the scene says {}", c.name, c.width)));
        }
    }
    let per_instance: usize = widths.iter().map(|&w| usize::from(w)).sum();
    let expected = per_instance.checked_mul(instances).and_then(|n| n.checked_add(20 + columns));
    if expected != Some(bytes.len()) {
        return Err(bad(format!("{} bytes, expected {}", bytes.len(), expected.unwrap_or(usize::MAX))));
    }
    let mut at = 20 + columns;
    let mut out = Vec::with_capacity(columns);
    for c in &schema.columns {
        let w = usize::from(c.width);
        let data = &bytes[at..at + w * instances];
        at += w * instances;
        let codes: Vec<u32> = match w {
            1 => data.iter().map(|&b| u32::from(b)).collect(),
            2 => data.chunks_exact(2).map(|b| u32::from(u16::from_le_bytes([b[0], b[1]]))).collect(),
            _ => data.chunks_exact(4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect(),
        };
        let null = null_code(c.width);
        let largest = c.largest_code().map_or(-1, |l| l as i64);
        if let Some(i) = codes.iter().position(|&k| k != null && i64::from(k) > largest) {
            return Err(bad(format!("instance {i}: code {} outside column {:?}", codes[i], c.name)));
        }
        out.push(codes);
    }
    Ok(AttributeCodes { count: instances, columns: out })
}

/// Unicode lower case: in the browser its own (`String.prototype.toLowerCase`,
/// the same mapping without carrying Rust's case tables in the wasm).
fn lowercase(s: &str) -> String {
    #[cfg(target_arch = "wasm32")]
    {
        js_sys::JsString::from(s).to_lower_case().into()
    }
    #[cfg(not(target_arch = "wasm32"))]
    {
        s.to_lowercase()
    }
}

/// Whether `text` matches `pattern`, case-insensitively: `*` matches any run of
/// characters (a glob, anchored at both ends); without one, the whole text.
#[must_use]
pub fn glob_matches(pattern: &str, text: &str) -> bool {
    let p = lowercase(pattern);
    let l = lowercase(text);
    if !p.contains('*') {
        return p == l;
    }
    let parts: Vec<&str> = p.split('*').collect();
    let mut rest = l.as_str();
    for (i, part) in parts.iter().enumerate() {
        if part.is_empty() {
            continue;
        }
        if i == 0 {
            if !rest.starts_with(part) {
                return false;
            }
            rest = &rest[part.len()..];
        } else if let Some(at) = rest.find(part) {
            rest = &rest[at + part.len()..];
        } else {
            return false;
        }
    }
    parts.last().is_none_or(|last| last.is_empty() || l.ends_with(last))
}

/// Days since 1970-01-01 of an ISO 8601 date (`YYYY-MM-DD`, also with a time
/// after it, or `YYYY/MM/DD`); `None` otherwise.
#[must_use]
pub fn parse_date(text: &str) -> Option<i64> {
    let t = text.trim();
    let b = t.as_bytes();
    if b.len() < 10
        || !(b[4] == b'-' || b[4] == b'/')
        || b[7] != b[4]
        || (b.len() > 10 && !matches!(b[10], b'T' | b' '))
    {
        return None;
    }
    let num = |s: &str| -> Option<i64> { s.bytes().all(|c| c.is_ascii_digit()).then(|| s.parse().ok()).flatten() };
    let (y, m, d) = (num(t.get(0..4)?)?, num(t.get(5..7)?)?, num(t.get(8..10)?)?);
    if !(1..=12).contains(&m) || d < 1 || d > i64::from(crate::calendar::days_in_month(y as i32, m as u32)) {
        return None;
    }
    Some(crate::calendar::days_from_civil(y, m, d))
}

/// `YYYY-MM-DD` of days since 1970-01-01.
#[must_use]
pub fn format_date(days: i64) -> String {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!("{y:04}-{m:02}-{d:02}")
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A schema of every column kind (the scene tests' too).
    pub(crate) fn schema() -> AttributeSchema {
        AttributeSchema {
            columns: vec![
                AttributeColumn {
                    name: "dbh".into(),
                    kind: AttributeType::Number,
                    width: 2,
                    min: 5.0,
                    max: 150.0,
                    categories: vec![],
                    count: 3,
                },
                AttributeColumn {
                    name: "year".into(),
                    kind: AttributeType::Integer,
                    width: 1,
                    min: 1900.0,
                    max: 2020.0,
                    categories: vec![],
                    count: 2,
                },
                AttributeColumn {
                    name: "condition".into(),
                    kind: AttributeType::Category,
                    width: 1,
                    min: 0.0,
                    max: 0.0,
                    categories: vec!["fair".into(), "good".into(), "poor".into()],
                    count: 3,
                },
                AttributeColumn {
                    name: "planted".into(),
                    kind: AttributeType::Date,
                    width: 2,
                    min: parse_date("1990-01-01").unwrap() as f64,
                    max: parse_date("2020-12-31").unwrap() as f64,
                    categories: vec![],
                    count: 1,
                },
            ],
        }
    }

    #[test]
    fn values_round_trip_through_their_codes() {
        let s = schema();
        s.validate().unwrap();
        let c = &s.columns;
        let codes = AttributeCodes {
            count: 3,
            columns: vec![
                vec![c[0].code_of_number(5.0), c[0].code_of_number(77.7), c[0].code_of_number(150.0)],
                vec![c[1].code_of_number(1900.0), null_code(1), c[1].code_of_number(2020.0)],
                vec![c[2].code_of_category("good"), c[2].code_of_category("poor"), c[2].code_of_category("fair")],
                vec![null_code(2), null_code(2), c[3].code_of_number(parse_date("2003-07-14").unwrap() as f64)],
            ],
        };
        let bytes = encode_attributes(&s, &codes);
        assert_eq!(bytes.len(), 20 + 4 + 3 * (2 + 1 + 1 + 2));
        let back = decode_attributes("t.attr", &bytes, &s, 3).unwrap();
        assert_eq!(back, codes);
        let Some(AttributeValue::Number(v)) = back.value(&s, 0, 1) else { panic!() };
        assert!((v - 77.7).abs() <= (150.0 - 5.0) / 65534.0, "{v}");
        assert_eq!(back.value(&s, 1, 0), Some(AttributeValue::Integer(1900)));
        assert_eq!(back.value(&s, 1, 1), None);
        assert_eq!(back.value(&s, 2, 1), Some(AttributeValue::Category("poor")));
        let j = back.json(&s, 2);
        assert_eq!(j["planted"], "2003-07-14");
        assert_eq!(j["condition"], "fair");
        assert_eq!(j["year"], 2020);
        assert!(!back.json(&s, 0).contains_key("planted"));
        // Outside the column: no value.
        assert_eq!(c[1].code_of_number(1899.0), null_code(1));
        assert_eq!(c[2].code_of_category("dead"), null_code(1));
    }

    #[test]
    fn hostile_sidecars_are_refused() {
        let s = schema();
        let codes = AttributeCodes { count: 1, columns: vec![vec![0], vec![0], vec![0], vec![0]] };
        let good = encode_attributes(&s, &codes);
        assert!(decode_attributes("t", &good, &s, 1).is_ok());
        let refuse = |bytes: &[u8], instances: usize, want: &str| {
            let e = decode_attributes("t.attr", bytes, &s, instances).unwrap_err().to_string();
            assert!(e.contains(want), "{e}");
        };
        refuse(&good[..10], 1, "magic");
        refuse(&good, 2, "the tile has 2");
        refuse(&good[..good.len() - 1], 1, "bytes, expected");
        let mut b = good.clone();
        b[4] = 9;
        refuse(&b, 1, "version 9");
        let mut b = good.clone();
        b[20] = 4;
        refuse(&b, 1, "width 4");
        let mut b = good.clone();
        b[16] = 3;
        refuse(&b, 1, "3 columns");
        // A category code past the list.
        let mut b = good.clone();
        let at = 20 + 4 + 2 + 1;
        b[at] = 3;
        refuse(&b, 1, "outside column \"condition\"");
        // An integer code past the range.
        let mut b = good;
        b[20 + 4 + 2] = 200;
        refuse(&b, 1, "outside column \"year\"");
        // Every prefix and every single-byte change: an error or a valid decode, never a panic.
        let good = encode_attributes(&s, &codes);
        for n in 0..good.len() {
            let _ = decode_attributes("t", &good[..n], &s, 1);
            for v in [0u8, 1, 0x7f, 0xff] {
                let mut b = good.clone();
                b[n] = v;
                if let Ok(c) = decode_attributes("t", &b, &s, 1) {
                    for k in 0..4 {
                        let _ = c.value(&s, k, 0);
                    }
                }
            }
        }
    }

    #[test]
    fn hostile_schemas_are_refused() {
        let mut s = schema();
        s.columns[2].categories = vec!["b".into(), "a".into()];
        assert!(s.validate().is_err());
        let mut s = schema();
        s.columns[1].max = 1900.0 + 300.0;
        assert!(s.validate().unwrap_err().to_string().contains("too wide"));
        let mut s = schema();
        s.columns[0].min = f64::NAN;
        assert!(s.validate().is_err());
        let mut s = schema();
        s.columns[3].name = "dbh".into();
        assert!(s.validate().is_err());
        let mut s = schema();
        s.columns[0].width = 3;
        assert!(s.validate().is_err());
    }

    #[test]
    fn dates_parse_and_print() {
        assert_eq!(parse_date("1970-01-01"), Some(0));
        assert_eq!(parse_date("2000-03-01"), Some(11_017));
        assert_eq!(parse_date("2024-02-29T10:00:00Z"), Some(19_782));
        assert_eq!(parse_date("2023/02/29"), None);
        assert_eq!(parse_date("2023-13-01"), None);
        assert_eq!(parse_date("12-05-2020"), None);
        assert_eq!(parse_date("2020-1-5"), None);
        for d in [-700_000, -1, 0, 1, 11_017, 19_782, 60_000] {
            assert_eq!(parse_date(&format_date(d)), Some(d), "{d}");
        }
    }
}
