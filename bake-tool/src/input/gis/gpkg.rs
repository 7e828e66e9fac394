//! OGC GeoPackages (SQLite through rusqlite, the system library): the
//! features tables of `gpkg_contents`, their geometry column
//! (`gpkg_geometry_columns`: GeoPackage binary, a header and WKB, read by
//! geozero), the CRS from `gpkg_spatial_ref_sys`. Opened read-only; only
//! tables are read (a view's SQL could run without end).

use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use rusqlite::{types::ValueRef, Connection, OpenFlags};

use super::{Collect, DeclaredCrs, Feature, Format, Layer, Value, Wanted};

fn connect(path: &Path) -> Result<Connection> {
    let conn = Connection::open_with_flags(path, OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX)
        .map_err(|e| anyhow!("cannot open as SQLite ({e})"))?;
    // No value past 64 MiB (a hostile row cannot make SQLite allocate 1 GB);
    // the schema's functions and views are not trusted.
    conn.set_limit(rusqlite::limits::Limit::SQLITE_LIMIT_LENGTH, 64 << 20)
        .map_err(|e| anyhow!("cannot limit SQLite ({e})"))?;
    conn.execute_batch("PRAGMA trusted_schema = OFF").map_err(|e| anyhow!("cannot set up SQLite ({e})"))?;
    Ok(conn)
}

/// `"name"` quoted as an SQL identifier.
fn quote(name: &str) -> String {
    format!("\"{}\"", name.replace('"', "\"\""))
}

struct Table {
    name: String,
    column: String,
    kind: String,
    srs_id: i64,
}

fn tables(conn: &Connection) -> Result<Vec<Table>> {
    let mut stmt = conn
        .prepare(
            "SELECT g.table_name, g.column_name, g.geometry_type_name, g.srs_id \
             FROM gpkg_geometry_columns g JOIN gpkg_contents c ON c.table_name = g.table_name \
             JOIN sqlite_master m ON m.name = g.table_name AND m.type = 'table' \
             WHERE c.data_type = 'features' ORDER BY g.table_name",
        )
        .map_err(|e| anyhow!("not a GeoPackage: no gpkg_contents/gpkg_geometry_columns tables ({e})"))?;
    let rows = stmt
        .query_map([], |r| {
            Ok(Table {
                name: r.get(0)?,
                column: r.get(1)?,
                kind: r.get::<_, String>(2)?.to_uppercase(),
                srs_id: r.get(3)?,
            })
        })
        .map_err(|e| anyhow!("unreadable gpkg_geometry_columns ({e})"))?;
    rows.collect::<rusqlite::Result<Vec<_>>>().map_err(|e| anyhow!("unreadable gpkg_geometry_columns ({e})"))
}

fn accepts(wanted: Wanted, kind: &str) -> bool {
    match wanted {
        Wanted::Points => matches!(kind, "POINT" | "MULTIPOINT" | "GEOMETRY"),
        Wanted::Polygons => matches!(kind, "POLYGON" | "MULTIPOLYGON" | "CURVEPOLYGON" | "MULTISURFACE" | "GEOMETRY"),
    }
}

fn srs(conn: &Connection, srs_id: i64) -> Result<Option<DeclaredCrs>> {
    // -1 and 0: undefined Cartesian and geographic systems (the specification's).
    if srs_id <= 0 {
        return Ok(None);
    }
    let row: Option<(Option<String>, Option<i64>, Option<String>)> = conn
        .query_row(
            "SELECT organization, organization_coordsys_id, definition FROM gpkg_spatial_ref_sys WHERE srs_id = ?1",
            [srs_id],
            |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)),
        )
        .map(Some)
        .or_else(|e| if e == rusqlite::Error::QueryReturnedNoRows { Ok(None) } else { Err(e) })
        .map_err(|e| anyhow!("unreadable gpkg_spatial_ref_sys ({e})"))?;
    let Some((org, code, definition)) = row else {
        bail!("srs_id {srs_id} is not in gpkg_spatial_ref_sys");
    };
    if org.as_deref().is_some_and(|o| o.eq_ignore_ascii_case("EPSG")) {
        if let Some(c) = code.and_then(|c| u32::try_from(c).ok()).filter(|&c| c > 0) {
            return Ok(Some(DeclaredCrs::Epsg(c)));
        }
    }
    match definition {
        Some(wkt) if !wkt.trim().is_empty() && wkt.trim() != "undefined" => {
            Ok(Some(match DeclaredCrs::read_wkt(&wkt) {
                DeclaredCrs::Unusable(why) => DeclaredCrs::Unusable(format!("srs_id {srs_id}: {why}")),
                crs => crs,
            }))
        }
        _ => Ok(None),
    }
}

pub(super) fn open(path: &Path, layer: Option<&str>, wanted: Wanted) -> Result<Layer> {
    let conn = connect(path)?;
    let all = tables(&conn)?;
    let names = || all.iter().map(|t| format!("{} ({})", t.name, t.kind.to_lowercase())).collect::<Vec<_>>().join(", ");
    let table = match layer {
        Some(l) => all
            .iter()
            .find(|t| t.name.eq_ignore_ascii_case(l))
            .with_context(|| format!("--layer {l}: no such features table; the tables are {}", names()))?,
        None => {
            let fitting: Vec<&Table> = all.iter().filter(|t| accepts(wanted, &t.kind)).collect();
            match (all.len(), fitting.len()) {
                (0, _) => bail!("no features table (gpkg_contents lists none)"),
                (1, _) => &all[0],
                (_, 1) => fitting[0],
                _ => bail!("{} features tables: pick one with --layer NAME; the tables are {}", all.len(), names()),
            }
        }
    };
    let crs = srs(&conn, table.srs_id)?;
    let mut fields = Vec::new();
    {
        let mut stmt = conn
            .prepare(&format!("PRAGMA table_info({})", quote(&table.name)))
            .map_err(|e| anyhow!("table {}: unreadable ({e})", table.name))?;
        let cols = stmt.query_map([], |r| r.get::<_, String>(1)).map_err(|e| anyhow!("table {}: {e}", table.name))?;
        for c in cols {
            let c = c.map_err(|e| anyhow!("table {}: {e}", table.name))?;
            if !c.eq_ignore_ascii_case(&table.column) {
                fields.push(c);
            }
        }
    }
    let count: Option<i64> =
        conn.query_row(&format!("SELECT count(*) FROM {}", quote(&table.name)), [], |r| r.get(0)).ok();
    let mut notes = vec![format!("table {} ({} features)", table.name, table.kind.to_lowercase())];
    if let Some(c) = &crs {
        notes.push(format!("CRS {} (gpkg_spatial_ref_sys)", c.describe()));
    }
    if all.len() > 1 {
        notes.push(format!("{} features tables: {}", all.len(), names()));
    }
    Ok(Layer {
        path: path.to_path_buf(),
        format: Format::GeoPackage,
        name: table.name.clone(),
        fields,
        names_cut: false,
        crs,
        count: count.and_then(|c| u64::try_from(c).ok()),
        notes,
        geometry_column: Some(table.column.clone()),
        parsed: None,
        text_encoding: None,
    })
}

pub(super) fn pass(layer: &Layer, f: &mut dyn FnMut(Feature) -> Result<()>) -> Result<u64> {
    let conn = connect(&layer.path)?;
    let geometry = layer.geometry_column.as_deref().context("no geometry column")?;
    let mut columns = vec![quote(geometry)];
    columns.extend(layer.fields.iter().map(|c| quote(c)));
    let sql = format!("SELECT {} FROM {}", columns.join(", "), quote(&layer.name));
    let mut stmt = conn.prepare(&sql).map_err(|e| anyhow!("table {}: unreadable ({e})", layer.name))?;
    let mut rows = stmt.query([]).map_err(|e| anyhow!("table {}: unreadable ({e})", layer.name))?;
    let mut index = 0u64;
    loop {
        let row = match rows.next() {
            Ok(Some(row)) => row,
            Ok(None) => break,
            Err(e) => bail!("feature {}: unreadable ({e})", index + 1),
        };
        index += 1;
        let mut collect = Collect::default();
        let geometry = match row.get_ref(0) {
            // A geometry that cannot be read is this feature's, counted; the rest go on.
            Ok(ValueRef::Blob(blob)) => match geozero::wkb::process_gpkg_geom(&mut &blob[..], &mut collect) {
                Ok(()) => collect.finish(),
                Err(_) => super::Geometry::Other("unreadable geometry (GeoPackage binary)"),
            },
            _ => super::Geometry::Empty,
        };
        let mut values = Vec::with_capacity(layer.fields.len());
        for i in 0..layer.fields.len() {
            values.push(match row.get_ref(i + 1) {
                Ok(ValueRef::Integer(v)) => Value::Int(v),
                Ok(ValueRef::Real(v)) => Value::Float(v),
                Ok(ValueRef::Text(t)) => Value::Text(String::from_utf8_lossy(t).into_owned()),
                _ => Value::Null,
            });
        }
        f(Feature { index, geometry, values })?;
    }
    Ok(index)
}
