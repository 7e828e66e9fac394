//! Placements from a GIS layer (Shapefile, GeoPackage, FlatGeobuf): the
//! points are the trees, the fields are found as CSV columns are (the same
//! names, `--column`, DBH units; a dBase field cut to 10 bytes answers to its
//! whole name: `species_co` is `species_code`), the CRS is the file's.

use anyhow::Result;

use super::*;
use crate::input::gis::{Feature, Geometry, Layer, Value};

/// The layer's fields by role.
#[derive(Debug, Clone, Default)]
pub(super) struct GisColumns {
    z: Option<usize>,
    height: Option<usize>,
    species: Option<usize>,
    dbh: Option<(usize, DbhUnit)>,
    crown: Option<(usize, bool)>,
    yaw: Option<usize>,
    id: Option<usize>,
    /// Attribute fields: index and name.
    pub(super) attrs: Vec<(usize, String)>,
    /// For the log.
    used: Vec<(ColumnRole, String)>,
}

impl GisColumns {
    pub(super) fn describe(&self) -> String {
        self.used.iter().map(|(r, n)| format!("{} ← {n:?}", r.name())).collect::<Vec<_>>().join(", ")
    }
}

pub(super) fn gis_columns(layer: &Layer, options: &ReadOptions) -> Result<GisColumns> {
    let mut chosen: BTreeMap<ColumnRole, usize> = BTreeMap::new();
    let coordinate = |r: ColumnRole| matches!(r, ColumnRole::Lon | ColumnRole::Lat | ColumnRole::X | ColumnRole::Y);
    for (role, name) in options.columns.iter().filter(|(r, _)| !coordinate(*r)) {
        let Some(i) = layer.field(name) else {
            bail!(
                "--column {}={name}: the layer has no field {name:?}; its fields are {:?}",
                role.name(),
                layer.fields
            );
        };
        chosen.insert(*role, i);
    }
    for role in ColumnRole::ALL.into_iter().filter(|r| !coordinate(*r)) {
        if chosen.contains_key(&role) {
            continue;
        }
        let free = role.aliases().iter().find_map(|a| layer.field(a).filter(|i| !chosen.values().any(|c| c == i)));
        if let Some(i) = free {
            chosen.insert(role, i);
        }
    }
    let get = |r: ColumnRole| chosen.get(&r).copied();
    let named = |r: ColumnRole| options.columns.iter().any(|(c, _)| *c == r);
    let diameter = get(ColumnRole::CrownDiameter).map(|i| (i, false));
    let radius = get(ColumnRole::CrownRadius).map(|i| (i, true));
    let crown = if named(ColumnRole::CrownRadius) && !named(ColumnRole::CrownDiameter) {
        radius.or(diameter)
    } else {
        diameter.or(radius)
    };
    let dbh = get(ColumnRole::Dbh)
        .map(|i| (i, DbhUnit::from_name(&layer.fields[i].to_lowercase()).or(options.dbh_unit).unwrap_or_default()));
    let mut used: Vec<(ColumnRole, String)> = Vec::new();
    for (role, i) in &chosen {
        let keep = match role {
            ColumnRole::CrownDiameter => crown == Some((*i, false)),
            ColumnRole::CrownRadius => crown == Some((*i, true)),
            _ => true,
        };
        if keep {
            let unit = match (role, dbh) {
                (ColumnRole::Dbh, Some((_, u))) => format!(" ({})", u.name()),
                _ => String::new(),
            };
            used.push((*role, format!("{}{unit}", layer.fields[*i])));
        }
    }
    let id = get(ColumnRole::Id);
    let candidates: Vec<(usize, String)> = layer
        .fields
        .iter()
        .enumerate()
        .filter(|(i, n)| Some(*i) != id && !n.trim().is_empty())
        .map(|(i, n)| (i, n.clone()))
        .collect();
    let attrs = match &options.attributes {
        None => candidates,
        Some(wanted) => wanted
            .iter()
            .map(|w| {
                layer.field(w).and_then(|i| candidates.iter().find(|(c, _)| *c == i).cloned()).with_context(|| {
                    format!(
                        "--attributes {w:?}: no such field (the id is not an attribute); the fields are {:?}",
                        candidates.iter().map(|(_, n)| n.as_str()).collect::<Vec<_>>()
                    )
                })
            })
            .collect::<Result<Vec<_>>>()?,
    };
    Ok(GisColumns {
        z: get(ColumnRole::Z),
        height: get(ColumnRole::Height),
        species: get(ColumnRole::Species),
        dbh,
        crown,
        yaw: get(ColumnRole::Yaw),
        id,
        attrs,
        used,
    })
}

/// The coordinate kind of a layer: its CRS's, `--input-crs`'s (projected),
/// else what its first points look like (lon/lat where they can be).
pub(super) fn gis_kind(layer: &Layer, options: &ReadOptions) -> Result<(CoordKind, Option<String>)> {
    if options.projected {
        return Ok((CoordKind::Projected, None));
    }
    if let Some(crs) = &layer.crs {
        return match crs.is_geographic() {
            Some(true) => Ok((CoordKind::LonLat, None)),
            Some(false) => Ok((CoordKind::Projected, None)),
            None => bail!("its CRS {} cannot be used: say which CRS it is with --input-crs EPSG:xxxx", crs.describe()),
        };
    }
    // No CRS: look at the first thousand points.
    let (mut seen, mut beyond, mut beyond_count) = (0usize, None::<(u64, [f64; 3])>, 0usize);
    layer.first(1000, &mut |feature| {
        if let Geometry::Points(points) = &feature.geometry {
            for p in points {
                seen += 1;
                if p[0].abs() > 180.0 || p[1].abs() > 90.0 {
                    beyond_count += 1;
                    beyond.get_or_insert((feature.index, *p));
                }
            }
        }
    })?;
    let what = match layer.format {
        crate::input::gis::Format::Shapefile => "no .prj beside it",
        _ => "no CRS in it",
    };
    match beyond {
        Some((index, p)) if beyond_count * 2 >= seen.max(1) => bail!(
            "{what}, and its coordinates are no lon/lat (e.g. feature {index}: [{}, {}]): say which CRS they are in \
             with --input-crs EPSG:xxxx",
            p[0],
            p[1]
        ),
        _ => Ok((CoordKind::LonLat, Some(format!("{what}: coordinates read as lon/lat (WGS 84)")))),
    }
}

/// Whether a layer holds points: an error naming what it holds otherwise.
pub(super) fn check_points(layer: &Layer) -> Result<()> {
    let (mut points, mut other) = (0usize, None::<String>);
    layer.first(100, &mut |feature| match &feature.geometry {
        Geometry::Points(_) => points += 1,
        Geometry::Polygons(_) => {
            other.get_or_insert("polygons".into());
        }
        Geometry::Other(o) => {
            other.get_or_insert(format!("{o} geometries"));
        }
        Geometry::Empty => {}
    })?;
    match (points, other) {
        (0, Some(o)) => bail!(
            "it holds {o}, not points: placements are one point per tree (a stand map of polygons is no stem map)"
        ),
        _ => Ok(()),
    }
}

fn text(v: Option<&Value>) -> Option<String> {
    v.and_then(Value::to_text)
}

/// A feature's trees (one per point), validated into `out`; skipped ones counted.
pub(super) fn gis_placements(
    feature: &Feature,
    cols: &GisColumns,
    kind: CoordKind,
    options: &ReadOptions,
    with_attributes: bool,
    report: &mut Report,
    out: &mut dyn FnMut(Placement) -> Result<()>,
) -> Result<()> {
    let row = feature.index;
    report.rows += 1;
    let points = match &feature.geometry {
        Geometry::Points(p) => p,
        Geometry::Empty => {
            report.skip("no geometry", row);
            return Ok(());
        }
        Geometry::Polygons(_) => {
            report.skip("geometry is a polygon, not a point", row);
            return Ok(());
        }
        Geometry::Other(o) => {
            report.skip(&format!("geometry is a {o}, not a point"), row);
            return Ok(());
        }
    };
    let get = |i: Option<usize>| i.and_then(|i| feature.values.get(i));
    let num = |i: Option<usize>| get(i).and_then(Value::as_f64);
    let id_value = get(cols.id);
    let id = id_value.and_then(|v| match v {
        Value::Int(i) => u64::try_from(*i).ok().filter(|i| *i < 1 << 63),
        Value::Float(f) if f.fract() == 0.0 && *f >= 0.0 && *f < 9.0e15 => Some(*f as u64),
        Value::Text(t) => number_id(t),
        _ => None,
    });
    let id_text = if id.is_none() { text(id_value).and_then(|t| text_id(&t)) } else { None };
    let too_long = id.is_none() && text(id_value).is_some_and(|t| id_too_long(&t));
    for p in points {
        let (x, y) = if options.swap_xy { (p[1], p[0]) } else { (p[0], p[1]) };
        let placement = Placement {
            x,
            y,
            z: Some(p[2]).filter(|z| !z.is_nan()).or_else(|| num(cols.z)),
            height_m: num(cols.height).map(|h| h as f32),
            dbh_cm: cols.dbh.and_then(|(i, unit)| num(Some(i)).map(|d| (d * unit.to_cm()) as f32)),
            crown_m: cols.crown.and_then(|(i, radius)| num(Some(i)).map(|c| if radius { 2.0 * c } else { c } as f32)),
            species: text(get(cols.species)),
            yaw_deg: num(cols.yaw).map(|v| v as f32),
            id,
            id_text: id_text.clone(),
            attrs: if with_attributes {
                cols.attrs.iter().map(|(i, _)| text(feature.values.get(*i))).collect()
            } else {
                Vec::new()
            },
            row,
        };
        if let Some(p) = accept(placement, kind, report) {
            if cols.id.is_some() && p.id.is_none() {
                report.count_text_id(p.row, p.id_text.is_some(), too_long);
            }
            report.kept += 1;
            out(p)?;
        }
    }
    Ok(())
}
