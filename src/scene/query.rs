//! Search by attributes: a filter over the per-tree attribute
//! columns (`format::attributes`) and the tree ids, matched tile by tile
//! against the sidecars. The filter is JSON, as the browser API takes it:
//!
//! ```json
//! {"species": "quercus*", "dbh": [30, null], "condition": ["good", "fair"],
//!  "planted": ["1990-01-01", null], "id": [113001, 113054]}
//! ```
//!
//! - a category column: a text (a `*` glob, case-insensitive; without `*` the
//!   whole value) or a list of them;
//! - a number, integer or date column: `[min, max]` (either `null`: open;
//!   dates as `YYYY-MM-DD`), or one value (a number's within half its
//!   quantisation step);
//! - `id`: an id or a list of ids: numbers, or the texts of an inventory
//!   whose ids are text (`"EY17080"`).
//!
//! Every condition must hold; a tree without a value in a column never
//! matches a condition on it.

use std::collections::HashSet;

use serde_json::Value;

use crate::format::attributes::{
    glob_matches, null_code, parse_date, AttributeCodes, AttributeColumn, AttributeSchema, AttributeType,
};

/// One column's condition, compiled against its column.
#[derive(Debug, Clone)]
enum Condition {
    /// The category codes that match.
    Codes(Vec<bool>),
    /// A closed range of values (numbers, integers, dates in days).
    Range(f64, f64),
}

/// A compiled filter.
#[derive(Debug, Clone, Default)]
pub struct Filter {
    conditions: Vec<(usize, Condition)>,
    /// `id`: the numbers and texts asked for.
    ids: Option<(HashSet<u64>, HashSet<String>)>,
    /// The trees standing on a day (a scene's timeline, [`Self::at_date`]).
    at: Option<(crate::format::timeline::TimelineColumns, i64)>,
}

impl Filter {
    /// Compiles a JSON filter against `schema` (`None`: a scene without
    /// attributes, where only `id` can be asked for).
    ///
    /// # Errors
    /// Not an object, an unknown attribute (the message lists them), or a value
    /// of the wrong kind for its column.
    pub fn parse(schema: Option<&AttributeSchema>, filter: &Value) -> Result<Self, String> {
        let Some(object) = filter.as_object() else {
            return Err(format!("a filter is a JSON object of attribute names, not {filter}"));
        };
        let mut out = Self::default();
        for (name, want) in object {
            if name == "id" {
                let (mut numbers, mut texts) = (HashSet::new(), HashSet::new());
                for v in as_list(want) {
                    match v {
                        Value::Number(n) => {
                            numbers.insert(
                                n.as_u64().ok_or_else(|| format!("id: {v} is not a tree id (a whole number)"))?,
                            );
                        }
                        Value::String(t) => {
                            texts.insert(t.trim().to_string());
                        }
                        _ => return Err(format!("id: {v} is not a tree id (a whole number or a text)")),
                    }
                }
                out.ids = Some((numbers, texts));
                continue;
            }
            let Some((index, column)) = schema.and_then(|s| s.column(name)) else {
                let names: Vec<&str> =
                    schema.map_or(Vec::new(), |s| s.columns.iter().map(|c| c.name.as_str()).collect());
                return Err(if names.is_empty() {
                    format!("{name:?}: the scene has no attributes (bake it with its inventory's columns)")
                } else {
                    format!("{name:?} is not an attribute of the scene; it has {names:?} and \"id\"")
                });
            };
            out.conditions.push((index, compile(column, want).map_err(|e| format!("{name}: {e}"))?));
        }
        Ok(out)
    }

    /// Whether the filter needs the attribute sidecars (not only the ids).
    #[must_use]
    pub fn needs_attributes(&self) -> bool {
        !self.conditions.is_empty() || self.at.is_some()
    }

    /// Matches only the trees standing on `day` (days since 1970-01-01) by
    /// the scene's `timeline`; `None` (or its latest day): those standing at
    /// the latest date, as a view without a date shows them.
    pub fn at_date(&mut self, timeline: Option<&crate::format::timeline::TimelineColumns>, day: Option<i64>) {
        self.at = crate::format::timeline::TimelineColumns::at(timeline, day);
    }

    /// Whether it matches at a date (the trees not standing at the latest one included).
    #[must_use]
    pub fn dated(&self) -> bool {
        self.at.is_some()
    }

    /// Whether a tile whose codes span `ranges` (its `attribute_codes`) may
    /// hold a match; `None` (no summary): it may.
    #[must_use]
    pub fn may_match(&self, schema: Option<&AttributeSchema>, ranges: Option<&[Option<[u32; 2]>]>) -> bool {
        let (Some(schema), Some(ranges)) = (schema, ranges) else { return true };
        self.conditions.iter().all(|(c, condition)| {
            let (Some(range), Some(column)) = (ranges.get(*c), schema.columns.get(*c)) else { return true };
            // No value in the tile: nothing there can match this condition.
            let Some([lo, hi]) = *range else { return false };
            match condition {
                Condition::Codes(ok) => (lo..=hi).any(|k| ok.get(k as usize).copied().unwrap_or(false)),
                Condition::Range(a, b) => {
                    // Codes are monotonic in value: the tile's values span value(lo)..value(hi).
                    let (Some(vlo), Some(vhi)) = (number_of(column, lo), number_of(column, hi)) else { return true };
                    vhi >= *a && vlo <= *b
                }
            }
        })
    }

    /// Whether instance `i` (id `id`, text id `text`, codes `codes` of its tile) matches.
    #[must_use]
    pub fn matches(
        &self,
        schema: Option<&AttributeSchema>,
        codes: Option<&AttributeCodes>,
        i: usize,
        id: u64,
        text: Option<&str>,
    ) -> bool {
        if let Some((timeline, day)) = &self.at {
            if !schema.zip(codes).is_some_and(|(s, c)| timeline.tree(s, c, i).stands(*day)) {
                return false;
            }
        }
        if let Some((numbers, texts)) = &self.ids {
            // A text id is matched as text; a number also as its digits ("113001").
            let named = match text {
                Some(t) => texts.contains(t),
                None => numbers.contains(&id) || (!texts.is_empty() && texts.contains(&id.to_string())),
            };
            if !named {
                return false;
            }
        }
        self.conditions.iter().all(|(c, condition)| {
            let (Some(schema), Some(codes)) = (schema, codes) else { return false };
            let Some(&code) = codes.columns.get(*c).and_then(|v| v.get(i)) else { return false };
            let column = &schema.columns[*c];
            if code == null_code(column.width) {
                return false;
            }
            match condition {
                Condition::Codes(ok) => ok.get(code as usize).copied().unwrap_or(false),
                Condition::Range(lo, hi) => number_of(column, code).is_some_and(|v| v >= *lo && v <= *hi),
            }
        })
    }
}

fn as_list(v: &Value) -> Vec<&Value> {
    match v {
        Value::Array(a) => a.iter().collect(),
        other => vec![other],
    }
}

/// A code's value as a number (dates in days).
fn number_of(column: &AttributeColumn, code: u32) -> Option<f64> {
    use crate::format::attributes::AttributeValue as V;
    match column.value(code)? {
        V::Number(v) => Some(v),
        V::Integer(v) | V::Date(v) => Some(v as f64),
        V::Category(_) => None,
    }
}

fn compile(column: &AttributeColumn, want: &Value) -> Result<Condition, String> {
    if column.kind == AttributeType::Category {
        let patterns: Vec<&str> = as_list(want)
            .into_iter()
            .map(|v| v.as_str().ok_or_else(|| format!("{v} is not a text (the column is a category)")))
            .collect::<Result<_, _>>()?;
        return Ok(Condition::Codes(
            column.categories.iter().map(|c| patterns.iter().any(|p| glob_matches(p, c))).collect(),
        ));
    }
    // Numbers, integers, dates: a value or [min, max].
    let value = |v: &Value| -> Result<Option<f64>, String> {
        match (v, column.kind) {
            (Value::Null, _) => Ok(None),
            (Value::String(s), AttributeType::Date) => {
                parse_date(s).map(|d| Some(d as f64)).ok_or_else(|| format!("{s:?} is not a date (YYYY-MM-DD)"))
            }
            (Value::Number(n), AttributeType::Number | AttributeType::Integer) => {
                n.as_f64().filter(|v| v.is_finite()).map(Some).ok_or_else(|| format!("{n} is not a finite number"))
            }
            (v, kind) => Err(format!("{v} does not fit a {} column", serde_json::json!(kind).as_str().unwrap_or("?"))),
        }
    };
    // Half a quantisation step of slack for numbers.
    let slack = if column.kind == AttributeType::Number {
        (column.max - column.min) / f64::from(null_code(column.width) - 1) * 0.5
    } else {
        0.0
    };
    match want {
        Value::Array(a) if a.len() == 2 => {
            let lo = value(&a[0])?.unwrap_or(f64::NEG_INFINITY);
            let hi = value(&a[1])?.unwrap_or(f64::INFINITY);
            Ok(Condition::Range(lo - slack, hi + slack))
        }
        Value::Array(_) => Err("a range is [min, max] (null for an open end)".into()),
        v => {
            let x = value(v)?.ok_or("null matches nothing; leave the attribute out")?;
            Ok(Condition::Range(x - slack, x + slack))
        }
    }
}

/// What a search found.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct QueryResult {
    /// Trees that match.
    pub count: u64,
    /// Their ids, in tile and instance order, up to the limit asked for: a
    /// number, or the text id of a tree that has one.
    pub ids: Vec<Value>,
    /// Bounds of their trunk bases, metres relative to the scene origin
    /// (`None`: no match).
    pub bounds: Option<([f32; 3], [f32; 3])>,
    /// Tiles read.
    pub tiles: u64,
    /// Tiles skipped: their codes' ranges (the index's `attribute_codes`) say
    /// nothing in them can match.
    pub skipped: u64,
}

impl QueryResult {
    /// Adds a matching tree.
    pub fn add(&mut self, id: u64, text: Option<&str>, position_m: [f32; 3], limit: usize) {
        self.count += 1;
        if self.ids.len() < limit {
            self.ids.push(text.map_or_else(|| Value::from(id), Value::from));
        }
        let (lo, hi) = self.bounds.get_or_insert((position_m, position_m));
        for k in 0..3 {
            lo[k] = lo[k].min(position_m[k]);
            hi[k] = hi[k].max(position_m[k]);
        }
    }

    /// The result as JSON: `{count, ids, bounds: {min, max} | null, tiles, skipped}`.
    #[must_use]
    pub fn to_json(&self) -> Value {
        serde_json::json!({
            "count": self.count,
            "ids": self.ids,
            "bounds": self.bounds.map(|(min, max)| serde_json::json!({"min": min, "max": max})),
            "tiles": self.tiles,
            "skipped": self.skipped,
        })
    }
}

/// Matches one tile: its bytes, its ids' and (when the filter needs them) its
/// attribute sidecar's, `files` naming the three in errors; adds the matches to
/// `result` (ids up to `limit` in all). Shared by [`query_dir`] and the
/// browser's `query`.
///
/// # Errors
/// A file that does not decode, or ids that do not match the tile.
#[allow(clippy::too_many_arguments)]
pub fn query_tile(
    schema: Option<&AttributeSchema>,
    filter: &Filter,
    species: u32,
    [tile, ids]: [&[u8]; 2],
    attr: Option<&[u8]>,
    files: [&str; 3],
    limit: usize,
    result: &mut QueryResult,
) -> Result<(), String> {
    use crate::format::attributes::decode_attributes;
    use crate::format::{decode_tree_ids, Tile};
    let tile = Tile::decode(files[0], tile, species).map_err(|e| e.to_string())?;
    let tree_ids = decode_tree_ids(files[1], ids).map_err(|e| e.to_string())?;
    let ids = &tree_ids.numbers;
    if ids.len() != tile.instances.len() {
        return Err(format!("{}: {} ids for {} trees", files[1], ids.len(), tile.instances.len()));
    }
    let codes = match (schema.filter(|_| filter.needs_attributes()), attr) {
        (Some(s), Some(bytes)) => {
            Some(decode_attributes(files[2], bytes, s, tile.instances.len()).map_err(|e| e.to_string())?)
        }
        (Some(_), None) => return Err(format!("{}: the filter needs the attribute sidecar", files[2])),
        _ => None,
    };
    result.tiles += 1;
    // The trees not standing at the latest date are seen only at a date.
    for batch in tile.batches.iter().filter(|b| filter.dated() || b.flags & crate::format::tile::BATCH_DATED == 0) {
        let run = batch.instance_offset as usize..(batch.instance_offset + batch.instance_count) as usize;
        for i in run {
            let text = tree_ids.text(i as u32);
            if filter.matches(schema, codes.as_ref(), i, ids[i], text) {
                result.add(ids[i], text, tile.instances[i].decode(batch).position_m, limit);
            }
        }
    }
    Ok(())
}

/// What a pick says of one tree, the `index`th of a tile: its bytes, its ids'
/// and (scenes with attributes) its attribute sidecar's, `files` naming the
/// three in errors. `{id, row, species, attributes, lon, lat, height, position}`:
/// `id` the tree's number, or its text id (with `row`, the input row), or null
/// with `row` for a tree without an id (else `row` null),
/// `height` the tree's (m), `position` its trunk base in the
/// scene CRS (m), `lon`/`lat` where `geo` can say (else null).
///
/// # Errors
/// A file that does not decode, ids that do not match the tile, or an index
/// outside it.
pub fn describe_tree(
    manifest: &crate::format::Manifest,
    geo: Option<&crate::geo::GeoFrame>,
    [tile, ids]: [&[u8]; 2],
    attr: Option<&[u8]>,
    files: [&str; 3],
    index: u32,
) -> Result<Value, String> {
    use crate::format::attributes::decode_attributes;
    use crate::format::{decode_tree_ids, Tile};
    let tile = Tile::decode(files[0], tile, manifest.species.len() as u32).map_err(|e| e.to_string())?;
    let tree_ids = decode_tree_ids(files[1], ids).map_err(|e| e.to_string())?;
    let ids = &tree_ids.numbers;
    let i = index as usize;
    if ids.len() != tile.instances.len() {
        return Err(format!("{}: {} ids for {} trees", files[1], ids.len(), tile.instances.len()));
    }
    let batch = tile
        .batches
        .iter()
        .find(|b| (b.instance_offset..b.instance_offset + b.instance_count).contains(&index))
        .ok_or_else(|| format!("{}: no tree {index} (the tile has {})", files[0], tile.instances.len()))?;
    let tree = tile.instances[i].decode(batch);
    let species = manifest.species.get(batch.species as usize);
    let codes = match (manifest.attributes.as_ref(), attr) {
        (Some(schema), Some(bytes)) => {
            Some(decode_attributes(files[2], bytes, schema, tile.instances.len()).map_err(|e| e.to_string())?)
        }
        _ => None,
    };
    let attributes = match (manifest.attributes.as_ref(), &codes) {
        (Some(schema), Some(codes)) => Value::Object(codes.json(schema, i)),
        _ => Value::Object(serde_json::Map::new()),
    };
    let timeline = match (manifest.timeline.as_ref(), manifest.attributes.as_ref(), &codes) {
        (Some(t), Some(schema), Some(codes)) => timeline_json(t, schema, codes, i),
        _ => Value::Null,
    };
    let local = glam::DVec3::from(tree.position_m.map(f64::from));
    let at = geo.and_then(|g| g.to_geo(local).ok());
    let o = manifest.origin_m;
    let round = |v: f64, k: f64| (v * k).round() / k;
    // A tree whose inventory row had no numeric id is numbered by its row
    // (2^63 + row, past what a JS number holds exactly): say the row instead.
    // A text id (the inventory's own key) is the id, as text, and the row is said too.
    let (id, row) = match (ids[i] >= 1 << 63, tree_ids.text(index)) {
        (true, Some(text)) => (Value::from(text), Some(ids[i] - (1 << 63))),
        (true, None) => (Value::Null, Some(ids[i] - (1 << 63))),
        (false, _) => (Value::from(ids[i]), None),
    };
    Ok(serde_json::json!({
        "id": id,
        "row": row,
        "species": species.map(|s| s.name.as_str()),
        "attributes": attributes,
        "lon": at.map(|a| round(a.0, 1e7)),
        "lat": at.map(|a| round(a.1, 1e7)),
        "height": species.map(|s| round(f64::from(tree.scale * s.height_m), 100.0)),
        "position": [round(o[0] + local.x, 100.0), round(o[1] + local.y, 100.0), round(o[2] + local.z, 100.0)],
        "timeline": timeline,
    }))
}

/// A tree's timeline for a pick: `{from, until, censuses: [{date, height, dbh,
/// crown}]}` (dates `YYYY-MM-DD`, `from`/`until` null where open; a census's
/// height, DBH and crown width null where it was not recorded alive then, or
/// not given); null where the block does not fit the columns.
fn timeline_json(
    t: &crate::format::timeline::Timeline,
    schema: &AttributeSchema,
    codes: &AttributeCodes,
    i: usize,
) -> Value {
    use crate::format::attributes::{format_date, AttributeValue};
    let Ok(columns) = t.resolve(Some(schema)) else { return Value::Null };
    let tree = columns.tree(schema, codes, i);
    let number = |name: &str| match schema.column(name).and_then(|(c, _)| codes.value(schema, c, i)) {
        Some(AttributeValue::Number(v)) => Some((v * 100.0).round() / 100.0),
        Some(AttributeValue::Integer(v)) => Some(v as f64),
        _ => None,
    };
    let censuses: Vec<Value> = t
        .censuses
        .iter()
        .zip(&t.heights)
        .map(|(date, height)| {
            serde_json::json!({
                "date": date,
                "height": number(height),
                "dbh": number(&format!("dbh_{date}")),
                "crown": number(&format!("crown_{date}")),
            })
        })
        .collect();
    serde_json::json!({
        "from": tree.from.map(format_date),
        "until": tree.until.map(format_date),
        "censuses": censuses,
    })
}

/// Searches a baked scene in a local folder: every tile's ids and (when the
/// filter needs them) attributes, up to `limit` ids listed.
///
/// # Errors
/// An unreadable or invalid manifest, tile or sidecar (named), or a filter that
/// does not fit the scene.
#[cfg(not(target_arch = "wasm32"))]
pub fn query_dir(dir: &std::path::Path, filter: &Value, limit: usize) -> Result<QueryResult, String> {
    query_dir_at(dir, filter, limit, None)
}

/// [`query_dir`] at a date (`YYYY-MM-DD`): the trees standing then, by the
/// scene's timeline (a scene without one: the date changes nothing).
///
/// # Errors
/// As [`query_dir`], or a date that is no date.
#[cfg(not(target_arch = "wasm32"))]
pub fn query_dir_at(
    dir: &std::path::Path,
    filter: &Value,
    limit: usize,
    date: Option<&str>,
) -> Result<QueryResult, String> {
    use crate::format::attributes::attributes_url;
    use crate::format::Manifest;
    let read = |url: &str| {
        crate::paths::read_regular(&dir.join(url), None, crate::paths::MAX_SCENE_FILE_BYTES)
            .map_err(|e| format!("cannot read {}: {e}", dir.join(url).display()))
    };
    let m = Manifest::decode("scene.json", &read("scene.json")?).map_err(|e| e.to_string())?;
    let schema = m.attributes.as_ref();
    let mut filter = Filter::parse(schema, filter)?;
    if let Some(text) = date {
        let day = parse_date(text).ok_or_else(|| format!("date {text:?}: expected YYYY-MM-DD, e.g. 2019-06-01"))?;
        let timeline = m.timeline.as_ref().map(|t| t.resolve(schema)).transpose().map_err(|e| e.to_string())?;
        filter.at_date(timeline.as_ref(), Some(day));
    }
    let mut result = QueryResult::default();
    for t in crate::format::index::read_all_tiles(dir, &m)? {
        if !filter.may_match(schema, t.attribute_codes.as_deref()) {
            result.skipped += 1;
            continue;
        }
        let attr_url = attributes_url(&t.url);
        let attr = match schema.filter(|_| filter.needs_attributes()) {
            Some(_) => Some(read(&attr_url)?),
            None => None,
        };
        let files = [t.url.as_str(), t.ids_url.as_str(), attr_url.as_str()];
        let (tile, ids) = (read(&t.url)?, read(&t.ids_url)?);
        query_tile(schema, &filter, m.species.len() as u32, [&tile, &ids], attr.as_deref(), files, limit, &mut result)?;
    }
    Ok(result)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::format::attributes::AttributeColumn;
    use serde_json::json;

    fn schema() -> AttributeSchema {
        let column = |name: &str, kind, width, min, max, categories: &[&str]| AttributeColumn {
            name: name.into(),
            kind,
            width,
            min,
            max,
            categories: categories.iter().map(|s| (*s).to_string()).collect(),
            count: 0,
        };
        AttributeSchema {
            columns: vec![
                column(
                    "species",
                    AttributeType::Category,
                    1,
                    0.0,
                    0.0,
                    &["acer campestre", "quercus robur", "quercus rubra"],
                ),
                column("dbh", AttributeType::Number, 2, 0.0, 100.0, &[]),
                column("planted", AttributeType::Date, 2, 0.0, 20000.0, &[]),
            ],
        }
    }

    #[test]
    fn filters_match_what_they_say() {
        let s = schema();
        let c = &s.columns;
        // Three trees: (quercus robur, 50, 2000-01-01), (acer, 20, none), (quercus rubra, 80, 1990-06-01).
        let codes = AttributeCodes {
            count: 3,
            columns: vec![
                vec![1, 0, 2],
                vec![c[1].code_of_number(50.0), c[1].code_of_number(20.0), c[1].code_of_number(80.0)],
                vec![
                    c[2].code_of_number(parse_date("2000-01-01").unwrap() as f64),
                    null_code(2),
                    c[2].code_of_number(parse_date("1990-06-01").unwrap() as f64),
                ],
            ],
        };
        let hits = |f: Value| -> Vec<usize> {
            let f = Filter::parse(Some(&s), &f).unwrap();
            (0..3).filter(|&i| f.matches(Some(&s), Some(&codes), i, 100 + i as u64, None)).collect()
        };
        assert_eq!(hits(json!({"species": "Quercus*"})), [0, 2]);
        assert_eq!(hits(json!({"species": "quercus robur"})), [0]);
        assert_eq!(hits(json!({"species": ["acer*", "*rubra"]})), [1, 2]);
        assert_eq!(hits(json!({"dbh": [30, null]})), [0, 2]);
        assert_eq!(hits(json!({"dbh": [null, 50]})), [0, 1]);
        assert_eq!(hits(json!({"dbh": 20})), [1]);
        assert_eq!(hits(json!({"planted": ["1995-01-01", null]})), [0]);
        assert_eq!(hits(json!({"planted": [null, null]})), [0, 2], "no value: no match");
        assert_eq!(hits(json!({"species": "quercus*", "dbh": [60, 90]})), [2]);
        assert_eq!(hits(json!({"id": [101, 102]})), [1, 2]);
        assert_eq!(hits(json!({})), [0, 1, 2]);
        let err = |f: Value| Filter::parse(Some(&s), &f).unwrap_err();
        assert!(err(json!({"height": 3})).contains("\"species\""));
        assert!(err(json!({"species": 3})).contains("not a text"));
        assert!(err(json!({"dbh": "big"})).contains("does not fit"));
        assert!(err(json!({"planted": ["2000-13-01", null]})).contains("not a date"));
        assert!(err(json!({"dbh": [1, 2, 3]})).contains("[min, max]"));
        assert!(err(json!([1])).contains("JSON object"));
        assert!(Filter::parse(None, &json!({"dbh": 1})).unwrap_err().contains("no attributes"));
        // Tiles: the codes' ranges say which can match.
        let ranges = codes.ranges(&s);
        assert_eq!(ranges[0], Some([0, 2]));
        assert_eq!(ranges[2].map(|r| r[0] <= r[1]), Some(true));
        let may = |f: Value, r: &[Option<[u32; 2]>]| Filter::parse(Some(&s), &f).unwrap().may_match(Some(&s), Some(r));
        assert!(may(json!({"dbh": [70, 90]}), &ranges));
        assert!(!may(json!({"dbh": [90, null]}), &ranges), "all dbh below 90");
        assert!(!may(json!({"species": "quercus*"}), &[Some([0, 0]), ranges[1], ranges[2]]), "only acer");
        assert!(may(json!({"species": "quercus*"}), &[Some([0, 1]), ranges[1], ranges[2]]));
        assert!(!may(json!({"planted": [null, null]}), &[ranges[0], ranges[1], None]), "no dates in the tile");
        assert!(may(json!({"id": [5]}), &[None, None, None]), "ids are not summarised");
        assert!(Filter::parse(Some(&s), &json!({})).unwrap().may_match(Some(&s), None));
    }
}
