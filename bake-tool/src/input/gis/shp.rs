//! ESRI Shapefiles: the `.shp` geometries (shapefile crate), the `.dbf`
//! attributes (dbase crate; field names cut to 10 bytes; text in the `.cpg`'s
//! code page, else the `.dbf`'s code page mark, else UTF-8), the CRS from the
//! `.prj` (a WKT).

use std::fs::File;
use std::io::{BufReader, Read, Seek};
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use shapefile::{Shape, ShapeReader};

use super::{DeclaredCrs, Feature, Format, Geometry, Layer, Value, MAX_VERTICES};

/// A sidecar of a `.shp` (`dbf`, `prj`, `cpg`, `shx`) in either case.
fn sidecar(path: &Path, ext: &str) -> Option<PathBuf> {
    [ext.to_string(), ext.to_uppercase()].into_iter().map(|e| path.with_extension(e)).find(|p| p.is_file())
}

/// The encoding a `.cpg` names (`UTF-8`, `1252`, `ISO-8859-1`, `CP1250`…;
/// dbase's table), else the `.dbf` header's code page mark, else UTF-8.
fn dbf_reader<D: Read + Seek>(source: D, cpg: Option<&str>) -> Result<dbase::Reader<D>> {
    let mut builder = dbase::ReaderBuilder::new();
    if let Some(enc) = cpg.and_then(dbase::encoding::DynEncoding::from_name) {
        builder = builder.with_encoding(enc);
    }
    builder.build(source).map_err(|e| anyhow!("the .dbf is not a readable dBase file ({e})"))
}

fn cpg_text(shp: &Path) -> Option<String> {
    let text = std::fs::read(sidecar(shp, "cpg")?).ok()?;
    (text.len() < 256).then(|| String::from_utf8_lossy(&text).trim().to_string())
}

/// One row of a `.dbf`, its values in field order.
struct Row(Vec<Value>);

impl dbase::ReadableRecord for Row {
    fn read_using<S: Read + Seek, M: Read + Seek>(
        fields: &mut dbase::FieldIterator<S, M>,
    ) -> Result<Self, dbase::FieldError> {
        let mut values = Vec::new();
        for field in fields {
            values.push(match field?.value {
                dbase::FieldValue::Character(s) => s.map_or(Value::Null, Value::Text),
                dbase::FieldValue::Memo(s) => Value::Text(s),
                dbase::FieldValue::Numeric(n) => n.map_or(Value::Null, Value::Float),
                dbase::FieldValue::Float(n) => n.map_or(Value::Null, |f| Value::Float(f64::from(f))),
                dbase::FieldValue::Double(f) | dbase::FieldValue::Currency(f) => Value::Float(f),
                dbase::FieldValue::Integer(i) => Value::Int(i64::from(i)),
                dbase::FieldValue::Logical(b) => b.map_or(Value::Null, Value::Bool),
                dbase::FieldValue::Date(d) => d.map_or(Value::Null, |d| Value::Text(d.to_string())),
                dbase::FieldValue::DateTime(d) => Value::Text(d.date().to_string()),
            });
        }
        Ok(Row(values))
    }
}

pub(super) fn open(path: &Path) -> Result<Layer> {
    let mut notes = Vec::new();
    let cpg = cpg_text(path);
    if let Some(c) = &cpg {
        match dbase::encoding::DynEncoding::from_name(c) {
            Some(_) => notes.push(format!("text in code page {c:?} (.cpg)")),
            None => notes.push(format!("the .cpg names {c:?}, an unknown code page: text read by the .dbf's own mark")),
        }
    }
    let (fields, count) = match sidecar(path, "dbf") {
        Some(dbf) => {
            let file = File::open(&dbf).with_context(|| format!("cannot open {}", dbf.display()))?;
            let reader =
                dbf_reader(BufReader::new(file), cpg.as_deref()).with_context(|| format!("{}", dbf.display()))?;
            let names = reader.fields().iter().map(|f| f.name().trim().to_string()).collect();
            (names, Some(u64::from(reader.header().num_records)))
        }
        None => {
            notes.push("no .dbf beside it: geometries only, no attributes (no species, heights or ids)".into());
            (Vec::new(), None)
        }
    };
    let crs = match sidecar(path, "prj") {
        Some(prj) => {
            let wkt = std::fs::read(&prj).with_context(|| format!("cannot read {}", prj.display()))?;
            if wkt.len() > 1 << 20 {
                bail!("{}: a .prj of {} bytes is no CRS", prj.display(), wkt.len());
            }
            let wkt = String::from_utf8_lossy(&wkt);
            let crs = DeclaredCrs::from_wkt(&wkt).with_context(|| format!("{}", prj.display()))?;
            notes.push(format!("CRS {} (.prj)", crs.describe()));
            Some(crs)
        }
        None => None,
    };
    // The header is read now, so a file that is no Shapefile fails at once.
    let file = File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
    let shapes = ShapeReader::new(BufReader::new(file)).map_err(|e| anyhow!("not a readable Shapefile ({e})"))?;
    let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    notes.insert(0, format!("{} shapes", shape_type_name(shapes.header().shape_type)));
    Ok(Layer {
        path: path.to_path_buf(),
        format: Format::Shapefile,
        name,
        fields,
        names_cut: true,
        crs,
        count,
        notes,
        geometry_column: None,
    })
}

fn shape_type_name(t: shapefile::ShapeType) -> String {
    format!("{t}")
}

pub(super) fn pass(layer: &Layer, f: &mut dyn FnMut(Feature) -> Result<()>) -> Result<u64> {
    let file = File::open(&layer.path).with_context(|| format!("cannot open {}", layer.path.display()))?;
    let dbf = match sidecar(&layer.path, "dbf") {
        Some(p) => Some(BufReader::new(File::open(&p).with_context(|| format!("cannot open {}", p.display()))?)),
        None => None,
    };
    for_each_shp_feature(BufReader::new(file), dbf, cpg_text(&layer.path).as_deref(), f)
}

/// Streams a Shapefile's features from its `.shp` and `.dbf` bytes (the
/// fuzz target's entry): geometries with their rows, in file order.
///
/// # Errors
/// Unreadable bytes (with the feature where they are), or `f`'s error.
pub fn for_each_shp_feature<S: Read + Seek, D: Read + Seek>(
    shp: S,
    dbf: Option<D>,
    cpg: Option<&str>,
    f: &mut dyn FnMut(Feature) -> Result<()>,
) -> Result<u64> {
    let mut shapes = ShapeReader::new(shp).map_err(|e| anyhow!("not a readable Shapefile ({e})"))?;
    let mut rows = match dbf {
        Some(d) => Some(dbf_reader(d, cpg)?),
        None => None,
    };
    let mut records = rows.as_mut().map(|r| r.iter_records_as::<Row>());
    let mut index = 0u64;
    for shape in shapes.iter_shapes() {
        index += 1;
        let shape = shape.map_err(|e| anyhow!("feature {index}: unreadable shape ({e})"))?;
        let values = match records.as_mut().map(Iterator::next) {
            None => Vec::new(),
            Some(None) => bail!("feature {index}: the .dbf has fewer rows than the .shp has shapes"),
            Some(Some(row)) => row.map_err(|e| anyhow!("feature {index}: unreadable .dbf row ({e})"))?.0,
        };
        f(Feature { index, geometry: geometry(shape), values })?;
    }
    Ok(index)
}

fn points<P>(points: &[P], xyz: impl Fn(&P) -> [f64; 3]) -> Geometry {
    if points.len() > MAX_VERTICES {
        return Geometry::Other("a geometry of more than 4 million vertices");
    }
    Geometry::Points(points.iter().map(xyz).collect())
}

fn rings<P>(rings: &[shapefile::PolygonRing<P>], xy: impl Fn(&P) -> [f64; 2]) -> Geometry {
    if rings.iter().map(|r| r.len()).sum::<usize>() > MAX_VERTICES {
        return Geometry::Other("a geometry of more than 4 million vertices");
    }
    // Shapefile polygons are rings: each outer ring (clockwise) starts a
    // polygon, its inner rings (holes) follow it.
    let mut polygons: Vec<Vec<Vec<[f64; 2]>>> = Vec::new();
    for ring in rings {
        let pts: Vec<[f64; 2]> = ring.points().iter().map(&xy).collect();
        match ring {
            shapefile::PolygonRing::Outer(_) => polygons.push(vec![pts]),
            shapefile::PolygonRing::Inner(_) => match polygons.last_mut() {
                Some(p) => p.push(pts),
                None => polygons.push(vec![pts]),
            },
        }
    }
    Geometry::Polygons(polygons)
}

fn geometry(shape: Shape) -> Geometry {
    let xy = |p: &shapefile::Point| [p.x, p.y, f64::NAN];
    let xym = |p: &shapefile::PointM| [p.x, p.y, f64::NAN];
    let xyz = |p: &shapefile::PointZ| [p.x, p.y, p.z];
    match shape {
        Shape::NullShape => Geometry::Empty,
        Shape::Point(p) => Geometry::Points(vec![xy(&p)]),
        Shape::PointM(p) => Geometry::Points(vec![xym(&p)]),
        Shape::PointZ(p) => Geometry::Points(vec![xyz(&p)]),
        Shape::Multipoint(m) => points(m.points(), xy),
        Shape::MultipointM(m) => points(m.points(), xym),
        Shape::MultipointZ(m) => points(m.points(), xyz),
        Shape::Polygon(p) => rings(p.rings(), |p| [p.x, p.y]),
        Shape::PolygonM(p) => rings(p.rings(), |p| [p.x, p.y]),
        Shape::PolygonZ(p) => rings(p.rings(), |p| [p.x, p.y]),
        Shape::Polyline(_) | Shape::PolylineM(_) | Shape::PolylineZ(_) => Geometry::Other("Polyline"),
        Shape::Multipatch(_) => Geometry::Other("Multipatch"),
    }
}
