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
    if let Some((role, name)) = options.columns.iter().find(|(r, _)| coordinate(*r)) {
        bail!(
            "--column {}={name}: a GIS layer's coordinates are its points' geometry, not a field (leave it out; \
             --swap-xy swaps them)",
            role.name()
        );
    }
    for (role, name) in &options.columns {
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

/// The coordinate kind of a layer ([`Layer::lon_lat`]).
pub(super) fn gis_kind(layer: &Layer, options: &ReadOptions) -> Result<(CoordKind, Option<String>)> {
    let given = if options.projected { Some(false) } else { options.geographic_input.then_some(true) };
    let (lon_lat, note) = layer.lon_lat(given)?;
    Ok((if lon_lat { CoordKind::LonLat } else { CoordKind::Projected }, note))
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
            report.skip(&format!("not a point: {o}"), row);
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
            // A z field wins; a geometry's Z only where it is not 0 (PointZ
            // exports fill 0 for "none", which would put trees at sea level).
            z: num(cols.z).or_else(|| Some(p[2]).filter(|z| z.is_finite() && *z != 0.0)),
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
            dated: false,
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
