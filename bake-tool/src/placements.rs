//! Tree placements from CSV (columns auto-detected) or GeoJSON points.
//!
//! Real inventories have missing fields, junk rows, duplicated coordinates and
//! outliers: rows that cannot be used are skipped and counted by reason (with
//! the first few row numbers), never fatal. Only an unreadable file or one
//! with no usable coordinate columns is an error.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};

/// Whether input coordinates are degrees or metres.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CoordKind {
    /// Longitude/latitude in degrees (WGS 84).
    LonLat,
    /// Projected x/y in the input CRS.
    Projected,
}

/// One usable input row.
#[derive(Debug, Clone, PartialEq)]
pub struct Placement {
    /// Longitude or x.
    pub x: f64,
    /// Latitude or y.
    pub y: f64,
    /// Ground height, metres, if given.
    pub z: Option<f64>,
    /// Tree height, metres, if given and positive.
    pub height_m: Option<f32>,
    /// Species label, if given.
    pub species: Option<String>,
    /// Yaw in degrees, if given.
    pub yaw_deg: Option<f32>,
    /// Numeric tree id, if given.
    pub id: Option<u64>,
    /// 1-based data row (CSV line minus the header) or feature index.
    pub row: u64,
}

/// What was read and what was skipped.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Report {
    /// Data rows seen.
    pub rows: u64,
    /// Rows kept.
    pub kept: u64,
    /// Skipped rows per reason: count and the first few row numbers.
    pub skipped: BTreeMap<String, (u64, Vec<u64>)>,
    /// Rows without a height (kept; they get the default height).
    pub missing_height: u64,
    /// Rows sharing their coordinates with an earlier row (kept).
    pub duplicate_coordinates: u64,
}

impl Report {
    /// Records a skipped row.
    pub fn skip(&mut self, reason: &str, row: u64) {
        let e = self.skipped.entry(reason.to_string()).or_insert((0, Vec::new()));
        e.0 += 1;
        if e.1.len() < 5 {
            e.1.push(row);
        }
    }

    /// Skipped rows in total.
    #[cfg(test)]
    pub fn skipped_total(&self) -> u64 {
        self.skipped.values().map(|(n, _)| n).sum()
    }

    /// A human-readable summary, one line per item.
    pub fn lines(&self) -> Vec<String> {
        let mut out = vec![format!("{} rows read, {} kept", self.rows, self.kept)];
        for (reason, (n, rows)) in &self.skipped {
            out.push(format!("skipped {n} rows: {reason} (e.g. rows {rows:?})"));
        }
        if self.missing_height > 0 {
            out.push(format!("{} rows have no height: they get the default height", self.missing_height));
        }
        if self.duplicate_coordinates > 0 {
            out.push(format!("{} rows repeat the coordinates of an earlier row (kept)", self.duplicate_coordinates));
        }
        out
    }
}

/// Placements read from one file.
#[derive(Debug, Clone)]
pub struct PlacementSet {
    /// Degrees or metres.
    pub kind: CoordKind,
    /// Usable rows.
    pub rows: Vec<Placement>,
    /// What happened.
    pub report: Report,
}

/// Reads a `.csv` or `.geojson`/`.json` file whole (tests; the bake streams
/// with [`PlacementSource`]).
#[cfg(test)]
pub fn read_placements(path: &Path) -> Result<PlacementSet> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_lowercase();
    let mut set = match ext.as_str() {
        "csv" | "txt" | "tsv" => {
            let file =
                std::fs::File::open(path).with_context(|| format!("cannot open placements {}", path.display()))?;
            read_csv(std::io::BufReader::new(file), if ext == "tsv" { b'\t' } else { b',' })
        }
        "geojson" | "json" => {
            let bytes = std::fs::read(path).with_context(|| format!("cannot read placements {}", path.display()))?;
            read_geojson(&bytes)
        }
        _ => bail!("placements {}: unknown extension {ext:?}; use .csv or .geojson", path.display()),
    }
    .with_context(|| format!("placements {}", path.display()))?;
    mark_duplicates(&mut set);
    Ok(set)
}

#[cfg(test)]
fn mark_duplicates(set: &mut PlacementSet) {
    let mut seen = std::collections::HashSet::with_capacity(set.rows.len());
    for p in &set.rows {
        if !seen.insert((p.x.to_bits(), p.y.to_bits())) {
            set.report.duplicate_coordinates += 1;
        }
    }
}

const LON: &[&str] = &["lon", "lng", "long", "longitude"];
const LAT: &[&str] = &["lat", "latitude"];
const X: &[&str] = &["x", "easting", "east", "e", "x_coord", "xcoord"];
const Y: &[&str] = &["y", "northing", "north", "n", "y_coord", "ycoord"];
const Z: &[&str] = &["z", "elevation", "elev", "altitude", "ground", "ground_z"];
const HEIGHT: &[&str] = &["height", "height_m", "h", "tree_height", "treeheight", "hoehe", "boomhoogte"];
const SPECIES: &[&str] = &["species", "species_name", "genus", "taxon", "baumart", "soort", "type", "art"];
const YAW: &[&str] = &["yaw", "rotation", "heading", "azimuth"];
const ID: &[&str] = &["id", "tree_id", "treeid", "objectid", "fid", "gid"];

fn find_col(header: &[String], names: &[&str]) -> Option<usize> {
    names.iter().find_map(|n| header.iter().position(|h| h == n))
}

/// Columns found in a CSV header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Columns {
    /// Coordinate kind.
    pub kind: CoordKind,
    /// x (or longitude) column.
    pub x: usize,
    /// y (or latitude) column.
    pub y: usize,
    /// Optional columns.
    pub z: Option<usize>,
    /// Height column.
    pub height: Option<usize>,
    /// Species column.
    pub species: Option<usize>,
    /// Yaw column.
    pub yaw: Option<usize>,
    /// Id column.
    pub id: Option<usize>,
}

/// Detects the columns of a header (names compared case-insensitively).
pub fn detect_columns(header: &[&str]) -> Result<Columns> {
    let h: Vec<String> = header.iter().map(|s| s.trim().trim_matches('"').to_lowercase()).collect();
    let (kind, x, y) = match (find_col(&h, LON), find_col(&h, LAT), find_col(&h, X), find_col(&h, Y)) {
        (Some(x), Some(y), _, _) => (CoordKind::LonLat, x, y),
        (_, _, Some(x), Some(y)) => (CoordKind::Projected, x, y),
        _ => bail!(
            "no coordinate columns: expected lon/lat (or lng/lat, longitude/latitude) or x/y (or easting/northing); the header is {header:?}"
        ),
    };
    Ok(Columns {
        kind,
        x,
        y,
        z: find_col(&h, Z),
        height: find_col(&h, HEIGHT),
        species: find_col(&h, SPECIES),
        yaw: find_col(&h, YAW),
        id: find_col(&h, ID),
    })
}

fn parse_f64(s: &str) -> Option<f64> {
    let t = s.trim();
    if t.is_empty() {
        return None;
    }
    t.parse::<f64>().ok()
}

/// Reads CSV from any reader (the first line is the header).
#[cfg(test)]
pub fn read_csv<R: std::io::Read>(reader: R, delimiter: u8) -> Result<PlacementSet> {
    let mut report = Report::default();
    let mut rows = Vec::new();
    let kind = stream_csv(reader, delimiter, &mut report, &mut |p| {
        rows.push(p);
        Ok(())
    })?;
    Ok(PlacementSet { kind, rows, report })
}

/// Streams CSV rows: each usable row goes to `f` as it is read (memory stays
/// constant whatever the file size); skipped rows are counted in `report`.
/// Returns the coordinate kind of the header.
pub fn stream_csv<R: std::io::Read>(
    reader: R,
    delimiter: u8,
    report: &mut Report,
    f: &mut dyn FnMut(Placement) -> Result<()>,
) -> Result<CoordKind> {
    let mut rdr =
        csv::ReaderBuilder::new().delimiter(delimiter).flexible(true).trim(csv::Trim::All).from_reader(reader);
    let header: Vec<String> =
        rdr.headers().map_err(|e| anyhow!("cannot read the CSV header: {e}"))?.iter().map(str::to_string).collect();
    let header_refs: Vec<&str> = header.iter().map(String::as_str).collect();
    let cols = detect_columns(&header_refs)?;
    let mut record = csv::StringRecord::new();
    let mut row = 0u64;
    loop {
        match rdr.read_record(&mut record) {
            Ok(false) => break,
            Ok(true) => {}
            Err(e) => {
                row += 1;
                report.rows += 1;
                report.skip(&format!("unreadable CSV ({})", e.kind_name()), row);
                continue;
            }
        }
        row += 1;
        report.rows += 1;
        let get = |c: Option<usize>| c.and_then(|c| record.get(c));
        let (Some(x), Some(y)) = (get(Some(cols.x)).and_then(parse_f64), get(Some(cols.y)).and_then(parse_f64)) else {
            report.skip("missing or non-numeric coordinates", row);
            continue;
        };
        let p = Placement {
            x,
            y,
            z: get(cols.z).and_then(parse_f64),
            height_m: get(cols.height).and_then(parse_f64).map(|h| h as f32),
            species: get(cols.species).map(str::trim).filter(|s| !s.is_empty()).map(str::to_string),
            yaw_deg: get(cols.yaw).and_then(parse_f64).map(|v| v as f32),
            id: get(cols.id).and_then(|s| s.trim().parse::<u64>().ok()),
            row,
        };
        if let Some(p) = accept(p, cols.kind, report) {
            report.kept += 1;
            f(p)?;
        }
    }
    Ok(cols.kind)
}

/// A placements file that can be read more than once: CSV is streamed from disk
/// on every pass (inputs larger than memory), GeoJSON is parsed once and kept.
pub struct PlacementSource {
    path: std::path::PathBuf,
    delimiter: u8,
    parsed: Option<PlacementSet>,
    /// Degrees or metres.
    pub kind: CoordKind,
}

impl PlacementSource {
    /// Opens `path` (`.csv`, `.tsv`, `.txt`, `.geojson`, `.json`) and reads its header.
    pub fn open(path: &Path) -> Result<Self> {
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_lowercase();
        match ext.as_str() {
            "csv" | "txt" | "tsv" => {
                let delimiter = if ext == "tsv" { b'\t' } else { b',' };
                let file =
                    std::fs::File::open(path).with_context(|| format!("cannot open placements {}", path.display()))?;
                let mut rdr = csv::ReaderBuilder::new().delimiter(delimiter).flexible(true).from_reader(file);
                let header: Vec<String> = rdr
                    .headers()
                    .map_err(|e| anyhow!("placements {}: cannot read the CSV header: {e}", path.display()))?
                    .iter()
                    .map(str::to_string)
                    .collect();
                let refs: Vec<&str> = header.iter().map(String::as_str).collect();
                let cols = detect_columns(&refs).with_context(|| format!("placements {}", path.display()))?;
                Ok(Self { path: path.to_path_buf(), delimiter, parsed: None, kind: cols.kind })
            }
            "geojson" | "json" => {
                let bytes =
                    std::fs::read(path).with_context(|| format!("cannot read placements {}", path.display()))?;
                let set = read_geojson(&bytes).with_context(|| format!("placements {}", path.display()))?;
                Ok(Self { path: path.to_path_buf(), delimiter: b',', kind: set.kind, parsed: Some(set) })
            }
            _ => bail!("placements {}: unknown extension {ext:?}; use .csv or .geojson", path.display()),
        }
    }

    /// One pass over the usable rows, in file order; returns what was read and skipped.
    pub fn for_each(&self, f: &mut dyn FnMut(Placement) -> Result<()>) -> Result<Report> {
        if let Some(set) = &self.parsed {
            for p in &set.rows {
                f(p.clone())?;
            }
            return Ok(set.report.clone());
        }
        let file = std::fs::File::open(&self.path)
            .with_context(|| format!("cannot open placements {}", self.path.display()))?;
        let mut report = Report::default();
        stream_csv(std::io::BufReader::with_capacity(1 << 20, file), self.delimiter, &mut report, f)
            .with_context(|| format!("placements {}", self.path.display()))?;
        Ok(report)
    }
}

trait CsvErrorKind {
    fn kind_name(&self) -> &'static str;
}

impl CsvErrorKind for csv::Error {
    fn kind_name(&self) -> &'static str {
        match self.kind() {
            csv::ErrorKind::Utf8 { .. } => "invalid UTF-8",
            csv::ErrorKind::UnequalLengths { .. } => "wrong number of fields",
            csv::ErrorKind::Io(_) => "I/O error",
            _ => "malformed record",
        }
    }
}

/// Validates one row: finite coordinates in range; height and z sane or dropped.
fn accept(mut p: Placement, kind: CoordKind, report: &mut Report) -> Option<Placement> {
    if !p.x.is_finite() || !p.y.is_finite() {
        report.skip("non-finite coordinates (NaN/Inf)", p.row);
        return None;
    }
    if kind == CoordKind::LonLat && (p.x.abs() > 180.0 || p.y.abs() > 90.0) {
        report.skip("longitude/latitude out of range", p.row);
        return None;
    }
    if kind == CoordKind::Projected && (p.x.abs() > 1e8 || p.y.abs() > 1e8) {
        report.skip("projected coordinates beyond ±100 000 km", p.row);
        return None;
    }
    if p.z.is_some_and(|z| !z.is_finite() || z.abs() > 20_000.0) {
        report.skip("ground height not finite or beyond ±20 km", p.row);
        return None;
    }
    p.height_m = p.height_m.filter(|h| h.is_finite() && *h > 0.0 && *h < 200.0);
    if p.height_m.is_none() {
        report.missing_height += 1;
    }
    p.yaw_deg = p.yaw_deg.filter(|y| y.is_finite());
    Some(p)
}

/// Reads a GeoJSON FeatureCollection (or a single Feature) of Point/MultiPoint
/// geometries; properties give species, height, yaw and id with the CSV names.
pub fn read_geojson(bytes: &[u8]) -> Result<PlacementSet> {
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
    let mut report = Report::default();
    let mut rows = Vec::new();
    for (i, f) in features.iter().enumerate() {
        let row = i as u64 + 1;
        report.rows += 1;
        let props = f.get("properties").and_then(|p| p.as_object());
        let prop = |names: &[&str]| {
            props.and_then(|p| p.iter().find(|(k, _)| names.contains(&k.to_lowercase().as_str())).map(|(_, v)| v))
        };
        let num = |v: Option<&serde_json::Value>| v.and_then(|v| v.as_f64().or_else(|| v.as_str().and_then(parse_f64)));
        let geom = f.get("geometry");
        let points: Vec<&serde_json::Value> = match geom.and_then(|g| g.get("type")).and_then(|t| t.as_str()) {
            Some("Point") => geom.and_then(|g| g.get("coordinates")).into_iter().collect(),
            Some("MultiPoint") => geom
                .and_then(|g| g.get("coordinates"))
                .and_then(|c| c.as_array())
                .map(|a| a.iter().collect())
                .unwrap_or_default(),
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
            let p = Placement {
                x: coords[0],
                y: coords[1],
                z: coords.get(2).copied().or_else(|| num(prop(Z))),
                height_m: num(prop(HEIGHT)).map(|h| h as f32),
                species: prop(SPECIES).and_then(|s| match s {
                    serde_json::Value::String(s) if !s.trim().is_empty() => Some(s.trim().to_string()),
                    serde_json::Value::Number(n) => Some(n.to_string()),
                    _ => None,
                }),
                yaw_deg: num(prop(YAW)).map(|v| v as f32),
                id: prop(ID).and_then(|v| v.as_u64().or_else(|| v.as_str().and_then(|s| s.parse().ok()))),
                row,
            };
            if let Some(p) = accept(p, CoordKind::LonLat, &mut report) {
                rows.push(p);
            }
        }
    }
    report.kept = rows.len() as u64;
    Ok(PlacementSet { kind: CoordKind::LonLat, rows, report })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn detects_lng_lat_columns_like_amsterdam() {
        let c = detect_columns(&["id", "species", "height", "dbh", "lat", "lng", "condition"]).unwrap();
        assert_eq!(c.kind, CoordKind::LonLat);
        assert_eq!((c.x, c.y), (5, 4));
        assert_eq!((c.id, c.species, c.height), (Some(0), Some(1), Some(2)));
    }

    #[test]
    fn detects_projected_columns() {
        let c = detect_columns(&["X", "Y", "Z", "Species", "Height_m", "Yaw"]).unwrap();
        assert_eq!(c.kind, CoordKind::Projected);
        assert_eq!((c.z, c.species, c.height, c.yaw), (Some(2), Some(3), Some(4), Some(5)));
    }

    #[test]
    fn header_without_coordinates_is_an_error_naming_the_header() {
        let e = detect_columns(&["name", "value"]).unwrap_err().to_string();
        assert!(e.contains("no coordinate columns") && e.contains("name"), "{e}");
    }

    #[test]
    fn bad_rows_are_counted_not_fatal() {
        let csv = "id,lat,lng,height,species\n\
                   1,52.37,4.90,15,Oak\n\
                   2,NaN,4.90,15,Oak\n\
                   3,,4.91,9,Pine\n\
                   4,95.0,4.90,9,Pine\n\
                   5,52.37,4.90,,Oak\n\
                   6,52.38,abc,9,Oak\n\
                   7,52.36,4.92,-3,Oak,extra\n";
        let set = read_csv(csv.as_bytes(), b',').unwrap();
        assert_eq!(set.report.rows, 7);
        assert_eq!(set.rows.len(), 3, "{:?}", set.report);
        assert_eq!(set.report.skipped_total(), 4);
        assert_eq!(set.report.missing_height, 2); // row 5 empty, row 7 negative
        assert_eq!(set.rows[0].species.as_deref(), Some("Oak"));
        assert_eq!(set.rows[0].id, Some(1));
        assert_eq!(set.rows[0].height_m, Some(15.0));
        let lines = set.report.lines().join("\n");
        assert!(lines.contains("non-finite") && lines.contains("out of range"), "{lines}");
    }

    #[test]
    fn geojson_points_and_properties() {
        let gj = br#"{"type":"FeatureCollection","features":[
            {"type":"Feature","geometry":{"type":"Point","coordinates":[15.4,48.4,210.5]},"properties":{"species":"pine","height":"21.5","id":42}},
            {"type":"Feature","geometry":{"type":"MultiPoint","coordinates":[[15.41,48.41],[15.42,48.42]]},"properties":{"Species":"oak"}},
            {"type":"Feature","geometry":{"type":"LineString","coordinates":[[0,0],[1,1]]},"properties":{}},
            {"type":"Feature","geometry":null,"properties":{}}
        ]}"#;
        let set = read_geojson(gj).unwrap();
        assert_eq!(set.rows.len(), 3);
        assert_eq!(set.rows[0].z, Some(210.5));
        assert_eq!(set.rows[0].height_m, Some(21.5));
        assert_eq!(set.rows[0].id, Some(42));
        assert_eq!(set.rows[2].species.as_deref(), Some("oak"));
        assert_eq!(set.report.skipped_total(), 2);
        assert!(read_geojson(b"{\"type\":\"Topology\"}").is_err());
        assert!(read_geojson(b"not json").is_err());
    }

    #[test]
    fn duplicates_are_counted() {
        let dir = std::env::temp_dir().join(format!("sylva-dup-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("d.csv");
        std::fs::write(&p, "x,y\n1,2\n1,2\n3,4\n").unwrap();
        let set = read_placements(&p).unwrap();
        assert_eq!(set.report.duplicate_coordinates, 1);
        assert_eq!(set.kind, CoordKind::Projected);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
