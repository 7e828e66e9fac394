//! Styles: colour trees by an attribute or by species, hide those
//! a filter leaves out, highlight a selection. A style compiles, against the
//! scene's attribute columns, into what the GPU reads: a palette of 63
//! colours and one byte per tree (its palette entry, selected, hidden: the
//! layout is `STYLE_*` here), made per resident tile from its ids and
//! attribute sidecars. The cull pass skips hidden trees; the draw passes
//! colour and highlight at every level of detail.
//!
//! The style is JSON, as the browser API takes it:
//!
//! ```json
//! {"color": {"by": "condition", "categories": {"good": "#2e7d32", "poor": "#c62828"}},
//!  "filter": {"dbh": [30, null]}}
//! {"color": {"by": "height", "ramp": ["#440154", "#21918c", "#fde725"], "domain": [5, 30]}}
//! {"color": {"by": "species"}}
//! ```
//!
//! - `color.by`: an attribute, or `species` (the attribute of that name, else
//!   the tree's model species); categories get a palette of their own unless
//!   `categories` maps values (globs) to colours (the rest keep their own
//!   colour); numbers, integers and dates a `ramp` (default viridis) over
//!   `domain` (default the column's range) in 16 steps.
//! - `filter`: as [`super::query::Filter`] (the trees that do not match are hidden).
//! - Colours: `#rrggbb`, `#rgb` or `[r, g, b]` (0–255).

use std::collections::HashSet;

use serde_json::Value;

use super::query::Filter;
use crate::format::attributes::{glob_matches, AttributeCodes, AttributeSchema, AttributeType, AttributeValue};

/// Palette entries (entry 0 is a tree's own colour).
pub const PALETTE: usize = 64;
/// Words of the styles' header: the palette ([`PALETTE`] packed RGBA8
/// colours; entry 0 unused, a tree's own colour), then [`STYLE_FLAGS`], then
/// spare words. The GPU reads it from `render::gpu_data::STYLE_OFFSET_BYTES`
/// in the cull control buffer (`styles.wgsl`).
pub const STYLE_HEADER_WORDS: u32 = 128;
const HEADER_WORDS: usize = STYLE_HEADER_WORDS as usize;
/// Header word: [`STYLE_TREES`] and [`STYLE_BY_SPECIES`] bits.
pub const STYLE_FLAGS: u32 = 64;
/// Flag: one style byte per pool instance follows the header (bits 0–5 the
/// palette entry, 0 the tree's own colour; [`STYLE_SELECTED`]; [`STYLE_HIDDEN`]).
pub const STYLE_TREES: u32 = 1;
/// Flag: a tree's palette entry is its model species + 1 (no per-tree data needed).
pub const STYLE_BY_SPECIES: u32 = 2;
/// Flag: the view has a date (`crate::format::timeline`): the batches of
/// trees not standing at the latest date are drawn too, the style bytes hide
/// the trees not standing at the view's, and a growth byte per pool instance
/// (from header word [`STYLE_GROWTH_AT`]) sizes each tree.
pub const STYLE_DATED: u32 = 4;
/// Header word: where the growth bytes start, in words from the styles' start
/// (`crate::render::gpu_data::growth_words_at`).
pub const STYLE_GROWTH_AT: u32 = 65;
/// Style byte bit: the tree is selected (highlighted at every level of detail).
pub const STYLE_SELECTED: u8 = 64;
/// Style byte bit: the tree is filtered out (the cull pass skips it).
pub const STYLE_HIDDEN: u8 = 128;
/// Steps of a ramp.
const RAMP_STEPS: usize = 16;

/// A qualitative palette for categories and species (Tableau 20-like: distinct
/// hues, then lighter ones), repeated beyond 20.
const QUALITATIVE: [[u8; 3]; 20] = [
    [0x4e, 0x79, 0xa7],
    [0xf2, 0x8e, 0x2b],
    [0xe1, 0x57, 0x59],
    [0x76, 0xb7, 0xb2],
    [0x59, 0xa1, 0x4f],
    [0xed, 0xc9, 0x48],
    [0xb0, 0x7a, 0xa1],
    [0xff, 0x9d, 0xa7],
    [0x9c, 0x75, 0x5f],
    [0xba, 0xb0, 0xac],
    [0x1f, 0x77, 0xb4],
    [0x8c, 0x56, 0x4b],
    [0xae, 0xc7, 0xe8],
    [0xff, 0xbb, 0x78],
    [0x98, 0xdf, 0x8a],
    [0xff, 0x98, 0x96],
    [0xc5, 0xb0, 0xd5],
    [0xc4, 0x9c, 0x94],
    [0xf7, 0xb6, 0xd2],
    [0xdb, 0xdb, 0x8d],
];
/// Viridis in five stops.
const VIRIDIS: [[u8; 3]; 5] =
    [[0x44, 0x01, 0x54], [0x3b, 0x52, 0x8b], [0x21, 0x91, 0x8c], [0x5e, 0xc9, 0x62], [0xfd, 0xe7, 0x25]];

/// How trees are coloured.
#[derive(Debug, Clone, PartialEq)]
enum ColorBy {
    /// By model species: entry = species + 1 (on the GPU, no per-tree data).
    Species,
    /// A category column: entry per code (0: own colour).
    Codes { column: usize, entries: Vec<u8> },
    /// A number, integer or date column: entry by value in `domain`.
    Ramp { column: usize, domain: [f64; 2] },
}

/// One legend line.
#[derive(Debug, Clone, PartialEq)]
pub struct LegendEntry {
    /// The value or range it stands for.
    pub label: String,
    /// sRGB.
    pub color: [u8; 3],
}

/// A tree's id as the API takes it: its number, or the text id an inventory
/// gave it (`"EY17080"`; `.ids` version 2).
#[derive(Debug, Clone, PartialEq, Eq, Hash, serde::Deserialize, serde::Serialize)]
#[serde(untagged)]
pub enum TreeId {
    /// A whole-number id.
    Number(u64),
    /// A text id.
    Text(String),
}

impl From<u64> for TreeId {
    fn from(id: u64) -> Self {
        Self::Number(id)
    }
}

/// A compiled style (see the module docs).
#[derive(Debug, Clone, Default)]
pub struct TreeStyle {
    palette: Vec<[u8; 3]>,
    color: Option<ColorBy>,
    filter: Option<Filter>,
    selected: HashSet<u64>,
    selected_texts: HashSet<String>,
    legend_title: String,
    legend: Vec<LegendEntry>,
    /// The view's date, where the scene has a timeline and the date is not its latest.
    at: Option<(crate::format::timeline::TimelineColumns, i64)>,
}

fn parse_color(v: &Value) -> Result<[u8; 3], String> {
    if let Some(a) = v.as_array() {
        let c: Vec<u8> = a.iter().filter_map(|x| x.as_u64().filter(|&x| x <= 255).map(|x| x as u8)).collect();
        return if c.len() == 3 && a.len() == 3 {
            Ok([c[0], c[1], c[2]])
        } else {
            Err(format!("{v} is not [r, g, b] (0–255)"))
        };
    }
    let s = v.as_str().ok_or_else(|| format!("{v} is not a colour (#rrggbb, #rgb or [r, g, b])"))?;
    let hex = s.strip_prefix('#').unwrap_or(s);
    let digits: Vec<u8> =
        hex.chars().map(|c| c.to_digit(16).map(|d| d as u8)).collect::<Option<_>>().unwrap_or_default();
    match digits.len() {
        6 if hex.len() == 6 => Ok([digits[0] * 16 + digits[1], digits[2] * 16 + digits[3], digits[4] * 16 + digits[5]]),
        3 if hex.len() == 3 => Ok([digits[0] * 17, digits[1] * 17, digits[2] * 17]),
        _ => Err(format!("{s:?} is not a colour (#rrggbb, #rgb or [r, g, b])")),
    }
}

fn hex([r, g, b]: [u8; 3]) -> String {
    format!("#{r:02x}{g:02x}{b:02x}")
}

/// Colour at `t` (0–1) along `stops`.
fn ramp_at(stops: &[[u8; 3]], t: f64) -> [u8; 3] {
    let t = t.clamp(0.0, 1.0) * (stops.len() - 1) as f64;
    let k = (t.floor() as usize).min(stops.len().saturating_sub(2));
    let f = t - k as f64;
    let (a, b) = (stops[k], stops[(k + 1).min(stops.len() - 1)]);
    std::array::from_fn(|c| (f64::from(a[c]) + (f64::from(b[c]) - f64::from(a[c])) * f).round() as u8)
}

impl TreeStyle {
    /// Compiles a JSON style (see the module docs) against `schema` (`None`:
    /// a scene without attributes) and the scene's model `species` names.
    ///
    /// # Errors
    /// Not an object, an unknown key or attribute (the message lists what
    /// there is), or a value of the wrong kind.
    pub fn parse(schema: Option<&AttributeSchema>, species: &[String], style: &Value) -> Result<Self, String> {
        let Some(object) = style.as_object() else {
            return Err(format!("a style is a JSON object with color and/or filter, not {style}"));
        };
        let mut out = Self { palette: vec![[0; 3]], ..Self::default() };
        for key in object.keys() {
            if key != "color" && key != "filter" {
                return Err(format!("{key:?} is not part of a style: use \"color\" and \"filter\""));
            }
        }
        if let Some(f) = object.get("filter").filter(|f| !f.is_null()) {
            out.filter = Some(Filter::parse(schema, f).map_err(|e| format!("filter: {e}"))?);
        }
        if let Some(c) = object.get("color").filter(|c| !c.is_null()) {
            out.compile_color(schema, species, c)?;
        }
        Ok(out)
    }

    fn compile_color(&mut self, schema: Option<&AttributeSchema>, species: &[String], c: &Value) -> Result<(), String> {
        let by =
            c.get("by").and_then(Value::as_str).ok_or("color: say what to colour by, e.g. {\"by\": \"species\"}")?;
        let given = |key: &str| c.get(key).filter(|v| !v.is_null());
        let column = schema.and_then(|s| s.column(by));
        self.legend_title = by.to_string();
        let Some((index, col)) = column else {
            if by.eq_ignore_ascii_case("species") {
                // The model species.
                for (k, name) in species.iter().enumerate().take(PALETTE - 1) {
                    let color = match given("categories").and_then(|m| m.as_object()) {
                        Some(map) => match map.iter().find(|(p, _)| glob_matches(p, name)) {
                            Some((_, v)) => parse_color(v).map_err(|e| format!("color.categories: {e}"))?,
                            None => QUALITATIVE[k % QUALITATIVE.len()],
                        },
                        None => QUALITATIVE[k % QUALITATIVE.len()],
                    };
                    self.palette.push(color);
                    self.legend.push(LegendEntry { label: name.clone(), color });
                }
                self.color = Some(ColorBy::Species);
                return Ok(());
            }
            let names: Vec<&str> = schema.map_or(Vec::new(), |s| s.columns.iter().map(|c| c.name.as_str()).collect());
            return Err(format!("color.by {by:?} is not an attribute of the scene; it has {names:?} and \"species\""));
        };
        if col.kind == AttributeType::Category {
            let mut entries = vec![0u8; col.categories.len()];
            match given("categories") {
                Some(map) => {
                    let map = map.as_object().ok_or("color.categories is {value: colour, …}")?;
                    for (pattern, v) in map {
                        if self.palette.len() >= PALETTE {
                            return Err(format!("color.categories: at most {} colours", PALETTE - 1));
                        }
                        let color = parse_color(v).map_err(|e| format!("color.categories.{pattern}: {e}"))?;
                        let entry = self.palette.len() as u8;
                        let mut any = false;
                        for (k, name) in col.categories.iter().enumerate() {
                            if entries[k] == 0 && glob_matches(pattern, name) {
                                entries[k] = entry;
                                any = true;
                            }
                        }
                        if any {
                            self.palette.push(color);
                            self.legend.push(LegendEntry { label: pattern.clone(), color });
                        }
                    }
                }
                None => {
                    for (k, name) in col.categories.iter().enumerate().take(PALETTE - 1) {
                        let color = QUALITATIVE[k % QUALITATIVE.len()];
                        entries[k] = self.palette.len() as u8;
                        self.palette.push(color);
                        self.legend.push(LegendEntry { label: name.clone(), color });
                    }
                }
            }
            self.color = Some(ColorBy::Codes { column: index, entries });
            return Ok(());
        }
        // A ramp over numbers, integers or dates.
        let stops: Vec<[u8; 3]> = match given("ramp") {
            Some(r) => r
                .as_array()
                .ok_or("color.ramp is a list of colours")?
                .iter()
                .map(|v| parse_color(v).map_err(|e| format!("color.ramp: {e}")))
                .collect::<Result<_, _>>()?,
            None => VIRIDIS.to_vec(),
        };
        if stops.len() < 2 {
            return Err("color.ramp needs two colours or more".into());
        }
        let bound = |v: &Value| -> Result<f64, String> {
            match v {
                Value::String(s) if col.kind == AttributeType::Date => crate::format::attributes::parse_date(s)
                    .map(|d| d as f64)
                    .ok_or_else(|| format!("color.domain: {s:?} is not a date (YYYY-MM-DD)")),
                v => match v.as_f64() {
                    // Beyond ±1e15 the legend's steps would read "inf" or the same number twice.
                    Some(x) if x.is_finite() && x.abs() <= MAX_DOMAIN => Ok(x),
                    Some(_) => Err(format!("color.domain: {v} is beyond ±{MAX_DOMAIN:e}")),
                    None => Err(format!("color.domain: {v} is not a number")),
                },
            }
        };
        const MAX_DOMAIN: f64 = 1e15;
        let domain = match given("domain") {
            Some(Value::Array(a)) if a.len() == 2 => [bound(&a[0])?, bound(&a[1])?],
            Some(_) => return Err("color.domain is [min, max]".into()),
            None => [col.min, col.max],
        };
        let label = |v: f64| match col.kind {
            AttributeType::Date => crate::format::attributes::format_date(v.round() as i64),
            AttributeType::Integer => format!("{}", v.round()),
            _ => format!("{}", (v * 100.0).round() / 100.0),
        };
        for k in 0..RAMP_STEPS {
            let t = (k as f64 + 0.5) / RAMP_STEPS as f64;
            let color = ramp_at(&stops, t);
            self.palette.push(color);
            let a = domain[0] + (domain[1] - domain[0]) * k as f64 / RAMP_STEPS as f64;
            let b = domain[0] + (domain[1] - domain[0]) * (k + 1) as f64 / RAMP_STEPS as f64;
            self.legend.push(LegendEntry { label: format!("{} – {}", label(a), label(b)), color });
        }
        self.color = Some(ColorBy::Ramp { column: index, domain });
        Ok(())
    }

    /// Highlights the trees with these ids (replacing the selection).
    pub fn set_selection<I: Into<TreeId>>(&mut self, ids: impl IntoIterator<Item = I>) {
        self.selected.clear();
        self.selected_texts.clear();
        for id in ids {
            match id.into() {
                TreeId::Number(n) => {
                    self.selected.insert(n);
                }
                // A text that is a whole number as a bake keeps it ("702") is that number.
                TreeId::Text(t) => match crate::format::ids::numeric_id(t.trim()) {
                    Some(n) => {
                        self.selected.insert(n);
                    }
                    None => {
                        self.selected_texts.insert(t.trim().to_string());
                    }
                },
            }
        }
    }

    /// Shows the trees standing on `day` (days since 1970-01-01), sized as
    /// they were then, by the scene's `timeline`; `None` (or the timeline's
    /// latest day): the trees standing at the latest date, as the tiles hold them.
    pub fn set_date(&mut self, timeline: Option<&crate::format::timeline::TimelineColumns>, day: Option<i64>) {
        self.at = crate::format::timeline::TimelineColumns::at(timeline, day);
    }

    /// The day the trees are shown at, if not the latest.
    #[must_use]
    pub fn date(&self) -> Option<i64> {
        self.at.as_ref().map(|a| a.1)
    }

    /// The selected ids.
    #[must_use]
    pub fn selection(&self) -> Vec<TreeId> {
        let mut out: Vec<TreeId> = self.selected.iter().map(|&n| TreeId::Number(n)).collect();
        out.extend(self.selected_texts.iter().cloned().map(TreeId::Text));
        out
    }

    /// Whether the style draws anything differently from no style.
    #[must_use]
    pub fn is_plain(&self) -> bool {
        self.color.is_none()
            && self.filter.is_none()
            && self.selected.is_empty()
            && self.selected_texts.is_empty()
            && self.at.is_none()
    }

    /// Whether it needs a byte per tree (and so each tile's ids and attributes).
    #[must_use]
    pub fn needs_trees(&self) -> bool {
        self.filter.is_some()
            || self.at.is_some()
            || !self.selected.is_empty()
            || !self.selected_texts.is_empty()
            || matches!(self.color, Some(ColorBy::Codes { .. } | ColorBy::Ramp { .. }))
    }

    /// Whether it needs the trees' attributes (not only their ids).
    #[must_use]
    pub fn needs_attributes(&self) -> bool {
        self.filter.as_ref().is_some_and(Filter::needs_attributes)
            || self.at.is_some()
            || matches!(self.color, Some(ColorBy::Codes { .. } | ColorBy::Ramp { .. }))
    }

    /// Whether a filter hides trees (trees whose data has not arrived are hidden too).
    #[must_use]
    pub fn filters(&self) -> bool {
        self.filter.is_some() || self.at.is_some()
    }

    /// The GPU header: the palette (packed RGBA8, alpha 255 for a colour in
    /// use) and the flags word.
    #[must_use]
    pub fn header(&self) -> Vec<u32> {
        let mut h = vec![0u32; HEADER_WORDS];
        for (k, c) in self.palette.iter().enumerate().skip(1).take(PALETTE - 1) {
            h[k] = u32::from_le_bytes([c[0], c[1], c[2], 255]);
        }
        let flags = STYLE_FLAGS as usize;
        let mut f = 0;
        if self.needs_trees() {
            f |= STYLE_TREES;
        }
        if self.color == Some(ColorBy::Species) {
            f |= STYLE_BY_SPECIES;
        }
        if self.at.is_some() {
            f |= STYLE_DATED;
        }
        h[flags] = f;
        h
    }

    /// The style byte of tree `i` of a tile (its id `id`, its tile's codes `codes`).
    #[must_use]
    pub fn tree_byte(
        &self,
        schema: Option<&AttributeSchema>,
        codes: Option<&AttributeCodes>,
        i: usize,
        id: u64,
        text: Option<&str>,
    ) -> u8 {
        let mut b = match (&self.color, schema, codes) {
            (Some(ColorBy::Codes { column, entries }), _, Some(codes)) => codes
                .columns
                .get(*column)
                .and_then(|c| c.get(i))
                .and_then(|&code| entries.get(code as usize))
                .copied()
                .unwrap_or(0),
            (Some(ColorBy::Ramp { column, domain }), Some(schema), Some(codes)) => {
                let value = match codes.value(schema, *column, i) {
                    Some(AttributeValue::Number(v)) => Some(v),
                    Some(AttributeValue::Integer(v) | AttributeValue::Date(v)) => Some(v as f64),
                    _ => None,
                };
                value.map_or(0, |v| {
                    // From domain[0] to domain[1], either way round (as the legend reads).
                    let span = domain[1] - domain[0];
                    let t = if span.abs() < 1e-12 { 0.0 } else { ((v - domain[0]) / span).clamp(0.0, 1.0) };
                    1 + ((t * RAMP_STEPS as f64) as usize).min(RAMP_STEPS - 1) as u8
                })
            }
            _ => 0,
        };
        let selected = match text {
            Some(t) => self.selected_texts.contains(t),
            None => self.selected.contains(&id),
        };
        if selected {
            b |= STYLE_SELECTED;
        }
        if self.filter.as_ref().is_some_and(|f| !f.matches(schema, codes, i, id, text)) {
            b |= STYLE_HIDDEN;
        }
        if let Some((timeline, day)) = &self.at {
            let stands = schema.zip(codes).is_some_and(|(s, c)| timeline.tree(s, c, i).stands(*day));
            if !stands {
                b |= STYLE_HIDDEN;
            }
        }
        b
    }

    /// The growth bytes of a tile's trees `first..` into `out` (at a date: each
    /// tree's size then over its own, `crate::format::timeline::growth_byte`;
    /// else 128, its own size).
    pub fn tile_growth(
        &self,
        schema: Option<&AttributeSchema>,
        codes: Option<&AttributeCodes>,
        first: usize,
        out: &mut [u8],
    ) {
        use crate::format::timeline::growth_byte;
        for (k, g) in out.iter_mut().enumerate() {
            *g = match (&self.at, schema, codes) {
                (Some((timeline, day)), Some(s), Some(c)) => growth_byte(timeline.tree(s, c, first + k).growth(*day)),
                _ => 128,
            };
        }
    }

    /// The style bytes of a tile's trees `first..` (`ids` and `codes` in the
    /// tile's instance order) into `out`, one per tree.
    pub fn tile_bytes(
        &self,
        schema: Option<&AttributeSchema>,
        ids: &crate::format::TreeIds,
        codes: Option<&AttributeCodes>,
        first: usize,
        out: &mut [u8],
    ) {
        for (i, (b, id)) in out.iter_mut().zip(ids.numbers.iter().skip(first)).enumerate() {
            let k = first + i;
            let text = if ids.texts.is_empty() { None } else { ids.text(k as u32) };
            *b = self.tree_byte(schema, codes, k, *id, text);
        }
    }

    /// The legend: `{title, entries: [{label, color}]}` (empty entries without a colouring).
    #[must_use]
    pub fn legend_json(&self) -> Value {
        serde_json::json!({
            "title": self.legend_title,
            "entries": self.legend.iter().map(|e| serde_json::json!({"label": e.label, "color": hex(e.color)})).collect::<Vec<_>>(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::format::attributes::tests::schema as every_kind_schema;
    use crate::format::attributes::{decode_attributes, encode_attributes, AttributeColumn};
    use serde_json::json;

    fn schema() -> AttributeSchema {
        let col = |name: &str, kind, min, max, categories: &[&str]| AttributeColumn {
            name: name.into(),
            kind,
            width: 1,
            min,
            max,
            categories: categories.iter().map(|s| (*s).to_string()).collect(),
            count: 0,
        };
        AttributeSchema {
            columns: vec![
                col("condition", AttributeType::Category, 0.0, 0.0, &["dead", "fair", "good", "poor"]),
                col("height", AttributeType::Integer, 0.0, 40.0, &[]),
            ],
        }
    }

    fn codes() -> AttributeCodes {
        // Trees: good/10 m, poor/30 m, no value/no value.
        AttributeCodes { count: 3, columns: vec![vec![2, 3, 255], vec![10, 30, 255]] }
    }

    #[test]
    fn categories_ramps_filters_and_selections_make_the_bytes() {
        let s = schema();
        let species = vec!["oak".to_string()];
        let style = TreeStyle::parse(
            Some(&s),
            &species,
            &json!({"color": {"by": "Condition", "categories": {"good": "#00ff00", "p*": [255, 0, 0]}}, "filter": {"height": [20, null]}}),
        )
        .unwrap();
        let mut out = [0u8; 3];
        style.tile_bytes(
            Some(&s),
            &crate::format::TreeIds { numbers: vec![7, 8, 9], texts: Vec::new() },
            Some(&codes()),
            0,
            &mut out,
        );
        // good → entry 1 but hidden (10 m); poor → entry 2 shown; no values → own colour, hidden.
        assert_eq!(out, [1 | STYLE_HIDDEN, 2, STYLE_HIDDEN]);
        let h = style.header();
        assert_eq!(h[1], u32::from_le_bytes([0, 255, 0, 255]));
        assert_eq!(h[2], u32::from_le_bytes([255, 0, 0, 255]));
        assert_eq!(h[64], STYLE_TREES);
        assert_eq!(style.legend_json()["entries"][1]["color"], "#ff0000");

        let mut ramp =
            TreeStyle::parse(Some(&s), &species, &json!({"color": {"by": "height", "domain": [0, 40]}})).unwrap();
        ramp.set_selection([8]);
        ramp.tile_bytes(
            Some(&s),
            &crate::format::TreeIds { numbers: vec![7, 8, 9], texts: Vec::new() },
            Some(&codes()),
            0,
            &mut out,
        );
        assert_eq!(out, [1 + 4, (1 + 12) | STYLE_SELECTED, 0]);
        // Text ids: selected by their text; a number by its number only.
        let texts = crate::format::TreeIds {
            numbers: vec![7, (1 << 63) + 2, (1 << 63) + 3],
            texts: vec![(1, "EY17080".into()), (2, "EY17081".into())],
        };
        ramp.set_selection([TreeId::Text(" EY17081".into()), TreeId::Number(7)]);
        ramp.tile_bytes(Some(&s), &texts, Some(&codes()), 0, &mut out);
        assert_eq!(out.map(|b| b & STYLE_SELECTED), [STYLE_SELECTED, 0, STYLE_SELECTED]);
        assert_eq!(ramp.selection().len(), 2);
        // A number given as text ("7", as a popup's data-id or a URL has it) is that number.
        ramp.set_selection([TreeId::Text("7".into())]);
        ramp.tile_bytes(Some(&s), &texts, Some(&codes()), 0, &mut out);
        assert_eq!(out.map(|b| b & STYLE_SELECTED), [STYLE_SELECTED, 0, 0]);
        assert_eq!(ramp.selection(), [TreeId::Number(7)]);
        assert_eq!(ramp.legend_json()["entries"].as_array().unwrap().len(), RAMP_STEPS);
        // A domain no legend can print is refused, saying why.
        let e = TreeStyle::parse(Some(&s), &species, &json!({"color": {"by": "height", "domain": [-1e308, 1e308]}}))
            .unwrap_err();
        assert!(e.contains("beyond ±1e15"), "{e}");
        // A reversed domain runs the ramp from its first value, as the legend reads.
        let reversed =
            TreeStyle::parse(Some(&s), &species, &json!({"color": {"by": "height", "domain": [40, 0]}})).unwrap();
        reversed.tile_bytes(
            Some(&s),
            &crate::format::TreeIds { numbers: vec![7, 8, 9], texts: Vec::new() },
            Some(&codes()),
            0,
            &mut out,
        );
        assert_eq!(out, [1 + 12, 1 + 4, 0]);
        assert!(reversed.legend_json()["entries"][0]["label"].as_str().unwrap().starts_with("40"));

        let by_species = TreeStyle::parse(Some(&s), &species, &json!({"color": {"by": "species"}})).unwrap();
        assert!(!by_species.needs_trees());
        assert_eq!(by_species.header()[64], STYLE_BY_SPECIES);
    }

    #[test]
    fn bad_styles_say_what_is_wrong() {
        let s = schema();
        let err = |v: Value| TreeStyle::parse(Some(&s), &[], &v).unwrap_err();
        assert!(err(json!({"colour": {}})).contains("\"colour\" is not part of a style"));
        assert!(err(json!({"color": {"by": "dbh"}})).contains("not an attribute of the scene"));
        assert!(err(json!({"color": {"by": "height", "ramp": ["#zzz"]}})).contains("not a colour"));
        assert!(err(json!({"filter": {"heigth": 3}})).starts_with("filter:"));
        assert!(err(json!([1])).contains("JSON object"));
    }

    /// A fuzz run in the test suite (the libFuzzer target `decode_attributes`
    /// needs nightly): random multi-byte mutations of a valid sidecar decode to
    /// an error or to codes that re-encode to the same bytes and that values,
    /// filters and styles read without a panic.
    #[test]
    fn random_mutations_never_panic() {
        let s = every_kind_schema();
        let codes =
            AttributeCodes { count: 3, columns: vec![vec![0, 1, 255], vec![0, 2, 1], vec![0, 1, 255], vec![1, 0, 2]] };
        let good = encode_attributes(&s, &codes);
        let any = |c: &AttributeColumn| match c.kind {
            AttributeType::Category => serde_json::json!("*"),
            _ => serde_json::json!([null, null]),
        };
        let filter: serde_json::Value = s.columns.iter().map(|c| (c.name.clone(), any(c))).collect();
        let parsed = crate::scene::query::Filter::parse(Some(&s), &filter).unwrap();
        let style =
            TreeStyle::parse(Some(&s), &[], &serde_json::json!({"color": {"by": s.columns[0].name}, "filter": filter}))
                .unwrap();
        let filter = parsed;
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        let (mut ok, mut refused) = (0, 0);
        for _ in 0..20_000 {
            let mut b = good.clone();
            for _ in 0..1 + next() % 4 {
                let at = (next() % b.len() as u64) as usize;
                b[at] = next() as u8;
            }
            if next() % 8 == 0 {
                b.truncate((next() % b.len() as u64) as usize);
            }
            let instances = if next() % 4 == 0 { (next() % 5) as usize } else { 3 };
            match decode_attributes("fuzz.attr", &b, &s, instances) {
                Ok(c) => {
                    ok += 1;
                    assert_eq!(encode_attributes(&s, &c), b);
                    let mut out = vec![0u8; instances];
                    let ids = crate::format::TreeIds { numbers: (0..instances as u64).collect(), texts: Vec::new() };
                    style.tile_bytes(Some(&s), &ids, Some(&c), 0, &mut out);
                    for i in 0..instances {
                        let _ = c.json(&s, i);
                        let _ = filter.matches(Some(&s), Some(&c), i, i as u64, None);
                    }
                }
                Err(_) => refused += 1,
            }
        }
        assert!(ok > 100 && refused > 100, "{ok} decoded, {refused} refused");
    }
}
