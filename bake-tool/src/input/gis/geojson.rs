//! GeoJSON as a layer (stand polygons): parsed whole (GeoJSON is one JSON
//! value), its features' properties as fields (every name any feature has,
//! first seen first), the 2008 `crs` member as its CRS.

use std::path::Path;
use std::sync::Arc;

use anyhow::{anyhow, bail, Context, Result};

use super::{DeclaredCrs, Feature, Format, Geometry, Layer, Value, MAX_VERTICES};

fn coords(v: &serde_json::Value) -> Option<[f64; 2]> {
    let a = v.as_array()?;
    Some([a.first()?.as_f64()?, a.get(1)?.as_f64()?])
}

fn ring(v: &serde_json::Value, budget: &mut usize) -> Option<Vec<[f64; 2]>> {
    let a = v.as_array()?;
    *budget = budget.checked_sub(a.len())?;
    a.iter().map(coords).collect()
}

fn polygon(v: &serde_json::Value, budget: &mut usize) -> Option<Vec<Vec<[f64; 2]>>> {
    v.as_array()?.iter().map(|r| ring(r, budget)).collect()
}

fn geometry(g: Option<&serde_json::Value>) -> Geometry {
    let Some(g) = g.filter(|g| !g.is_null()) else { return Geometry::Empty };
    let c = g.get("coordinates").unwrap_or(&serde_json::Value::Null);
    let mut budget = MAX_VERTICES;
    let bad = Geometry::Other("malformed geometry (or more than 4 million vertices)");
    match g.get("type").and_then(|t| t.as_str()) {
        Some("Point") => coords(c).map_or(bad, |p| Geometry::Points(vec![[p[0], p[1], f64::NAN]])),
        Some("MultiPoint") => ring(c, &mut budget)
            .map_or(bad, |ps| Geometry::Points(ps.into_iter().map(|p| [p[0], p[1], f64::NAN]).collect())),
        Some("Polygon") => polygon(c, &mut budget).map_or(bad, |p| Geometry::Polygons(vec![p])),
        Some("MultiPolygon") => c
            .as_array()
            .and_then(|ps| ps.iter().map(|p| polygon(p, &mut budget)).collect::<Option<Vec<_>>>())
            .map_or(bad, Geometry::Polygons),
        Some("LineString" | "MultiLineString") => Geometry::Other("LineString"),
        _ => Geometry::Other("GeometryCollection or unknown"),
    }
}

fn value(v: &serde_json::Value) -> Value {
    match v {
        serde_json::Value::Bool(b) => Value::Bool(*b),
        serde_json::Value::Number(n) => {
            n.as_i64().map_or_else(|| n.as_f64().map_or(Value::Null, Value::Float), Value::Int)
        }
        serde_json::Value::String(s) => Value::Text(s.clone()),
        _ => Value::Null,
    }
}

pub(super) fn open(path: &Path) -> Result<Layer> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let v: serde_json::Value = serde_json::from_slice(&bytes).map_err(|e| anyhow!("not valid JSON: {e}"))?;
    drop(bytes);
    let features: Vec<&serde_json::Value> = match v.get("type").and_then(|t| t.as_str()) {
        Some("FeatureCollection") => v
            .get("features")
            .and_then(|f| f.as_array())
            .ok_or_else(|| anyhow!("$.features is missing or not an array"))?
            .iter()
            .collect(),
        Some("Feature") => vec![&v],
        other => bail!("$.type is {other:?}, expected \"FeatureCollection\" or \"Feature\""),
    };
    let mut fields: Vec<String> = Vec::new();
    for f in &features {
        if let Some(p) = f.get("properties").and_then(|p| p.as_object()) {
            for k in p.keys().filter(|k| !k.trim().is_empty()) {
                if !fields.iter().any(|n| n == k) {
                    fields.push(k.clone());
                }
            }
        }
    }
    let parsed: Vec<Feature> = features
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let props = f.get("properties").and_then(|p| p.as_object());
            Feature {
                index: i as u64 + 1,
                geometry: geometry(f.get("geometry")),
                values: fields.iter().map(|k| props.and_then(|p| p.get(k)).map_or(Value::Null, value)).collect(),
            }
        })
        .collect();
    let crs = super::geojson_crs(&v).map(DeclaredCrs::Epsg);
    let mut notes = vec![format!("{} features", parsed.len())];
    if let Some(c) = &crs {
        notes.push(format!("CRS {} (crs member)", c.describe()));
    }
    Ok(Layer {
        path: path.to_path_buf(),
        format: Format::GeoJson,
        name: path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
        fields,
        names_cut: false,
        crs,
        count: Some(parsed.len() as u64),
        notes,
        geometry_column: None,
        parsed: Some(Arc::new(parsed)),
        text_encoding: None,
    })
}
