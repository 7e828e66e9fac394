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
            let crs = match DeclaredCrs::read_wkt(&wkt) {
                DeclaredCrs::Unusable(why) => DeclaredCrs::Unusable(format!("{}: {why}", prj.display())),
                crs => crs,
            };
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
        parsed: None,
        text_encoding: None,
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
    let text = cpg_text(&layer.path).or_else(|| layer.text_encoding.clone());
    for_each_shp_feature(BufReader::new(file), dbf, text.as_deref(), f)
}

/// Checks every record's header before the shapefile crate reads it: the
/// crate sizes a record's points from its counts with wrapping arithmetic,
/// so a 150-byte record could make it reserve 4 GiB. A record must hold
/// what its counts say, and lie within the file.
fn check_records<S: Read + Seek>(shp: &mut S) -> Result<()> {
    use std::io::SeekFrom;
    let len = shp.seek(SeekFrom::End(0))?;
    shp.seek(SeekFrom::Start(100))?;
    let mut at = 100u64;
    let mut index = 0u64;
    while at + 8 <= len {
        index += 1;
        let mut head = [0u8; 12];
        if shp.read_exact(&mut head).is_err() {
            break; // a cut record: the crate's read says where
        }
        let content = u64::from(u32::from_be_bytes(head[4..8].try_into().expect("4 bytes"))) * 2;
        if content > len - at - 8 {
            bail!("feature {index}: a record of {content} bytes, past the end of the file");
        }
        let kind = i32::from_le_bytes(head[8..12].try_into().expect("4 bytes"));
        let mut counts = [0u8; 40];
        // The least a record of its counts holds (Z ranges are required, M ranges optional).
        let need = |parts: u64, points: u64, per_part: u64, z: bool| -> u64 {
            let base = 4 + 32 + 8 + per_part * parts + 16 * points;
            base + if z { 16 + 8 * points } else { 0 }
        };
        let required = match kind {
            3 | 5 | 13 | 15 | 23 | 25 | 31 | 8 | 18 | 28 => {
                let n = if matches!(kind, 8 | 18 | 28) { 36 } else { 40 };
                shp.read_exact(&mut counts[..n.min(content.saturating_sub(4) as usize)]).ok();
                let word = |i: usize| u64::from(u32::from_le_bytes(counts[i..i + 4].try_into().expect("4 bytes")));
                match kind {
                    8 | 28 => 4 + 32 + 4 + 16 * word(32),
                    18 => 4 + 32 + 4 + 16 * word(32) + 16 + 8 * word(32),
                    31 => need(word(32), word(36), 8, true),
                    _ => need(word(32), word(36), 4, matches!(kind, 13 | 15)),
                }
            }
            _ => 4,
        };
        if required > content {
            bail!("feature {index}: its counts need {required} bytes, its record holds {content}");
        }
        at += 8 + content;
        shp.seek(SeekFrom::Start(at))?;
    }
    shp.seek(SeekFrom::Start(0))?;
    Ok(())
}

/// The records a `.dbf` marks deleted (`*`), which dBase readers skip: their
/// shapes are skipped with them, so the rows stay paired with their shapes.
fn deleted_rows<D: Read + Seek>(dbf: &mut D) -> Result<Vec<u64>> {
    use std::io::SeekFrom;
    let mut head = [0u8; 32];
    dbf.seek(SeekFrom::Start(0))?;
    if dbf.read_exact(&mut head).is_err() {
        dbf.seek(SeekFrom::Start(0))?;
        return Ok(Vec::new());
    }
    let records = u64::from(u32::from_le_bytes(head[4..8].try_into().expect("4 bytes")));
    let header = u64::from(u16::from_le_bytes(head[8..10].try_into().expect("2 bytes")));
    let record = u64::from(u16::from_le_bytes(head[10..12].try_into().expect("2 bytes")));
    let mut deleted = Vec::new();
    let len = dbf.seek(SeekFrom::End(0))?;
    if let Some(fit) = len.saturating_sub(header).checked_div(record) {
        for i in 0..records.min(fit) {
            dbf.seek(SeekFrom::Start(header + i * record))?;
            let mut flag = [0u8; 1];
            if dbf.read_exact(&mut flag).is_err() {
                break;
            }
            if flag[0] == b'*' {
                deleted.push(i);
            }
        }
    }
    dbf.seek(SeekFrom::Start(0))?;
    Ok(deleted)
}

/// The `.dbf`'s language driver byte: 0 is "not said" (then read as
/// Windows-1252, as GDAL reads it, unless a `.cpg` or `--encoding` says).
fn language_driver<D: Read + Seek>(dbf: &mut D) -> Option<u8> {
    use std::io::SeekFrom;
    let mut head = [0u8; 30];
    dbf.seek(SeekFrom::Start(0)).ok()?;
    let ok = dbf.read_exact(&mut head).is_ok();
    dbf.seek(SeekFrom::Start(0)).ok()?;
    ok.then_some(head[29])
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
    let mut shp = shp;
    check_records(&mut shp).map_err(|e| anyhow!("not a readable Shapefile: {e}"))?;
    let mut shapes = ShapeReader::new(shp).map_err(|e| anyhow!("not a readable Shapefile ({e})"))?;
    let mut deleted = Vec::new();
    let mut rows = match dbf {
        Some(mut d) => {
            deleted = deleted_rows(&mut d)?;
            // No .cpg and no code page in the .dbf: Windows-1252, as GDAL reads it.
            let text = cpg.or_else(|| (language_driver(&mut d) == Some(0)).then_some("1252"));
            Some(dbf_reader(d, text)?)
        }
        None => None,
    };
    let mut records = rows.as_mut().map(|r| r.iter_records_as::<Row>());
    let mut deleted = deleted.into_iter().peekable();
    let mut index = 0u64;
    for shape in shapes.iter_shapes() {
        index += 1;
        let shape = shape.map_err(|e| anyhow!("feature {index}: unreadable shape ({e})"))?;
        if deleted.next_if_eq(&(index - 1)).is_some() {
            f(Feature { index, geometry: Geometry::Other("a record deleted in the .dbf"), values: Vec::new() })?;
            continue;
        }
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
    // Shapefile polygons are rings, outer (clockwise) and inner (holes) in
    // any order: each hole goes to the outer ring that holds its first vertex.
    let mut polygons: Vec<Vec<Vec<[f64; 2]>>> = Vec::new();
    let mut holes: Vec<Vec<[f64; 2]>> = Vec::new();
    for ring in rings {
        let pts: Vec<[f64; 2]> = ring.points().iter().map(&xy).collect();
        match ring {
            shapefile::PolygonRing::Outer(_) => polygons.push(vec![pts]),
            shapefile::PolygonRing::Inner(_) => holes.push(pts),
        }
    }
    for hole in holes {
        let first = hole.first().copied().unwrap_or([f64::NAN; 2]);
        let home = polygons.iter().position(|p| super::ring_holds(&p[0], first));
        match home.or(polygons.len().checked_sub(1)) {
            Some(i) => polygons[i].push(hole),
            None => polygons.push(vec![hole]),
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
