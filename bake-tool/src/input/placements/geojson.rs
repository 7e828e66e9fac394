//! GeoJSON placements: a FeatureCollection (or one Feature) of Point or
//! MultiPoint geometries, properties named like the CSV columns, and the
//! 2008 `crs` member GIS exports still write.

use anyhow::Result;

use super::*;

/// The properties kept as attributes: every name any feature has (first seen
/// first), but the id, or the ones `--attributes` names.
fn geojson_attributes(features: &[&serde_json::Value], options: &ReadOptions) -> Result<Vec<String>> {
    let id_names: Vec<String> = match options.columns.iter().find(|(r, _)| *r == ColumnRole::Id) {
        Some((_, n)) => vec![n.to_lowercase()],
        None => ColumnRole::Id.aliases().iter().map(|a| (*a).to_string()).collect(),
    };
    let mut names: Vec<String> = Vec::new();
    for f in features {
        if let Some(p) = f.get("properties").and_then(|p| p.as_object()) {
            // A property without a name is no column (as an empty CSV header cell).
            for k in p.keys().filter(|k| !k.trim().is_empty()) {
                if !names.iter().any(|n| n.eq_ignore_ascii_case(k)) {
                    names.push(k.clone());
                }
            }
        }
    }
    // The id: the first of its names present (the others stay attributes).
    if let Some(id) = id_names.iter().find(|a| names.iter().any(|n| n.to_lowercase() == **a)) {
        names.retain(|n| n.to_lowercase() != *id);
    }
    match &options.attributes {
        None => Ok(names),
        Some(wanted) => wanted
            .iter()
            .map(|w| {
                names.iter().find(|n| n.eq_ignore_ascii_case(w.trim())).cloned().with_context(|| {
                    format!("--attributes {w:?}: no such property (the id is not an attribute); the properties are {names:?}")
                })
            })
            .collect(),
    }
}

/// Reads a GeoJSON FeatureCollection (or a single Feature) of Point/MultiPoint
/// geometries; properties give species, height, yaw and id with the CSV names.
/// Coordinates are lon/lat unless `options.projected` or the file's `crs`
/// member says otherwise.
pub fn read_geojson(bytes: &[u8], options: &ReadOptions) -> Result<PlacementSet> {
    let v: serde_json::Value = serde_json::from_slice(bytes).map_err(|e| anyhow!("not valid JSON: {e}"))?;
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
    let attribute_names = geojson_attributes(&features, options)?;
    let mut report = Report::default();
    let mut rows = Vec::new();
    let mut points_read = Vec::new();
    for (i, f) in features.iter().enumerate() {
        let row = i as u64 + 1;
        report.rows += 1;
        let props = f.get("properties").and_then(|p| p.as_object());
        // Property names lowercased once per feature.
        let keys: Vec<(String, &serde_json::Value)> =
            props.map(|p| p.iter().map(|(k, v)| (k.to_lowercase(), v)).collect()).unwrap_or_default();
        // A property by role: the `--column` name, else the role's aliases; with its key.
        let prop_key = |role: ColumnRole| -> Option<(&str, &serde_json::Value)> {
            let named = options.columns.iter().find(|(r, _)| *r == role).map(|(_, n)| n.to_lowercase());
            let found = match named {
                Some(n) => keys.iter().find(|(k, _)| *k == n),
                None => role.aliases().iter().find_map(|a| keys.iter().find(|(k, _)| k == a)),
            };
            found.map(|(k, v)| (k.as_str(), *v))
        };
        let prop = |role: ColumnRole| prop_key(role).map(|(_, v)| v);
        let num = |v: Option<&serde_json::Value>| v.and_then(|v| v.as_f64().or_else(|| v.as_str().and_then(parse_f64)));
        let geom = f.get("geometry");
        let coordinates = geom.and_then(|g| g.get("coordinates"));
        let points: Vec<&serde_json::Value> = match geom.and_then(|g| g.get("type")).and_then(|t| t.as_str()) {
            Some("Point") => vec![coordinates.unwrap_or(&serde_json::Value::Null)],
            Some("MultiPoint") => match coordinates.and_then(|c| c.as_array()) {
                Some(a) if !a.is_empty() => a.iter().collect(),
                _ => {
                    report.skip("MultiPoint without points", row);
                    continue;
                }
            },
            _ => {
                report.skip("geometry is not a Point or MultiPoint", row);
                continue;
            }
        };
        for c in points {
            let coords: Vec<f64> =
                c.as_array().map(|a| a.iter().filter_map(serde_json::Value::as_f64).collect()).unwrap_or_default();
            if coords.len() < 2 {
                report.skip("point without two numeric coordinates", row);
                continue;
            }
            let (x, y) = if options.swap_xy { (coords[1], coords[0]) } else { (coords[0], coords[1]) };
            let p = Placement {
                x,
                y,
                z: coords.get(2).copied().or_else(|| num(prop(ColumnRole::Z))),
                height_m: num(prop(ColumnRole::Height)).map(|h| h as f32),
                dbh_cm: prop_key(ColumnRole::Dbh).and_then(|(k, v)| {
                    let unit = DbhUnit::from_name(k).or(options.dbh_unit).unwrap_or_default();
                    num(Some(v)).map(|d| (d * unit.to_cm()) as f32)
                }),
                crown_m: num(prop(ColumnRole::CrownDiameter))
                    .or_else(|| num(prop(ColumnRole::CrownRadius)).map(|r| 2.0 * r))
                    .map(|c| c as f32),
                species: prop(ColumnRole::Species).and_then(|s| match s {
                    serde_json::Value::String(s) if !s.trim().is_empty() => Some(s.trim().to_string()),
                    serde_json::Value::Number(n) => Some(n.to_string()),
                    _ => None,
                }),
                yaw_deg: num(prop(ColumnRole::Yaw)).map(|v| v as f32),
                id: prop(ColumnRole::Id).and_then(|v| match v {
                    serde_json::Value::Number(n) => n.as_u64().filter(|n| *n < 1 << 63),
                    serde_json::Value::String(s) => super::number_id(s),
                    _ => None,
                }),
                id_text: prop(ColumnRole::Id).and_then(|v| match v {
                    serde_json::Value::String(s) => super::text_id(s),
                    serde_json::Value::Number(n) if n.as_u64().is_none_or(|n| n >= 1 << 63) => {
                        super::text_id(&n.to_string())
                    }
                    _ => None,
                }),
                attrs: attribute_names
                    .iter()
                    .map(|name| {
                        let v = props.and_then(|p| {
                            p.get(name).or_else(|| p.iter().find(|(k, _)| k.eq_ignore_ascii_case(name)).map(|(_, v)| v))
                        })?;
                        match v {
                            serde_json::Value::String(s) => Some(s.trim().to_string()).filter(|s| !s.is_empty()),
                            serde_json::Value::Number(n) => Some(n.to_string()),
                            serde_json::Value::Bool(b) => Some(b.to_string()),
                            _ => None,
                        }
                    })
                    .collect(),
                row,
                dated: false,
            };
            points_read.push(p);
        }
    }
    let declared_epsg = geojson_crs(&v);
    // A declared geographic CRS (ETRS89, NAD83) is lon/lat too.
    let declared_projected =
        declared_epsg.is_some_and(|e| crate::input::reproject::Crs::from_epsg(e).map_or(true, |c| !c.is_geographic()));
    let kind = if options.projected || declared_projected {
        CoordKind::Projected
    } else {
        // Projected numbers read as degrees would all be "out of range": say why.
        let beyond = points_read.iter().filter(|p| p.x.abs() > 180.0 || p.y.abs() > 90.0).count();
        let swappable =
            points_read.iter().filter(|p| p.y.abs() > 90.0 && p.y.abs() <= 180.0 && p.x.abs() <= 90.0).count();
        if swappable > 0 && swappable * 2 >= points_read.len() && !options.swap_xy {
            bail!(
                "{swappable} of {} points are [latitude, longitude], not GeoJSON's [longitude, latitude]: pass --swap-xy",
                points_read.len()
            );
        }
        if beyond > 0 && beyond * 2 >= points_read.len() {
            let p = points_read.iter().find(|p| p.x.abs() > 180.0 || p.y.abs() > 90.0).expect("counted");
            bail!(
                "{beyond} of {} points are no lon/lat (e.g. feature {}: [{}, {}]): the coordinates are projected; \
                 say which CRS they are in with --input-crs EPSG:xxxx",
                points_read.len(),
                p.row,
                p.x,
                p.y
            );
        }
        CoordKind::LonLat
    };
    for p in points_read {
        if let Some(p) = accept(p, kind, &mut report) {
            if p.id.is_none() && p.id_text.is_some() {
                report.count_text_id(p.row, true, false);
            }
            rows.push(p);
        }
    }
    report.kept = rows.len() as u64;
    Ok(PlacementSet { kind, rows, report, declared_epsg, attribute_names })
}
