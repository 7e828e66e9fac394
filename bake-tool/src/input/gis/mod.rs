//! GIS vector files as GIS exports write them: Shapefile (`.shp` with its
//! `.dbf`, `.prj`, `.cpg`), GeoPackage (`.gpkg`, SQLite) and FlatGeobuf
//! (`.fgb`), read through their crates (shapefile and dbase, rusqlite with
//! geozero's WKB, flatgeobuf) into one model: a layer of features, each a
//! geometry (points or polygons) and the values of the layer's fields, with
//! the layer's CRS.
//!
//! Features are streamed: a pass holds one feature at a time, so a file of
//! 10^8 points reads in constant memory. Hostile files get errors, never a
//! panic or an unbounded allocation: a feature's vertices are capped
//! ([`MAX_VERTICES`]); SQLite opens read-only and reads tables only (no views,
//! whose SQL could run without end).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

mod crs;
mod fgb;
mod geojson;
mod gpkg;
mod shp;

pub use crs::{epsg_of_wkt, geojson_crs, DeclaredCrs};
pub use fgb::for_each_fgb_feature;
pub use shp::for_each_shp_feature;

/// The most vertices one feature may have (a stand polygon of a million
/// vertices is already absurd); a feature with more is refused.
pub const MAX_VERTICES: usize = 1 << 22;

/// A field's value in one feature.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// Empty (NULL, a blank dBase field).
    Null,
    /// A logical field.
    Bool(bool),
    /// A whole number.
    Int(i64),
    /// A number.
    Float(f64),
    /// Text.
    Text(String),
}

impl Value {
    /// The value as a number: numbers, and text that reads as one.
    #[must_use]
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            Value::Int(i) => Some(*i as f64),
            Value::Float(f) => Some(*f).filter(|f| f.is_finite()),
            Value::Text(t) => crate::input::text::parse_f64(t),
            Value::Null | Value::Bool(_) => None,
        }
    }

    /// The value as text, trimmed, if not empty: numbers as they write
    /// themselves (`12`, `0.5`).
    #[must_use]
    pub fn to_text(&self) -> Option<String> {
        match self {
            Value::Null => None,
            Value::Bool(b) => Some(b.to_string()),
            Value::Int(i) => Some(i.to_string()),
            Value::Float(f) => f.is_finite().then(|| f.to_string()),
            Value::Text(t) => Some(t.trim().to_string()).filter(|t| !t.is_empty()),
        }
    }
}

/// Polygons: each its rings (the first the outer), each ring its vertices.
pub type Polygons = Vec<Vec<Vec<[f64; 2]>>>;

/// A feature's geometry.
#[derive(Debug, Clone, PartialEq)]
pub enum Geometry {
    /// None (a null shape, an empty geometry).
    Empty,
    /// A point or a multipoint: x, y and z (NaN where the file has none).
    Points(Vec<[f64; 3]>),
    /// A polygon or multipolygon: polygons, each its rings (the first the
    /// outer), each ring its vertices.
    Polygons(Vec<Vec<Vec<[f64; 2]>>>),
    /// Anything else (lines, curves, collections), by its type's name.
    Other(&'static str),
}

/// One feature.
#[derive(Debug, Clone, PartialEq)]
pub struct Feature {
    /// 1-based feature number in the layer.
    pub index: u64,
    /// Its geometry.
    pub geometry: Geometry,
    /// Its values, in the layer's field order ([`Layer::fields`]).
    pub values: Vec<Value>,
}

/// The vector formats read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// ESRI Shapefile.
    Shapefile,
    /// OGC GeoPackage.
    GeoPackage,
    /// FlatGeobuf.
    FlatGeobuf,
    /// GeoJSON (parsed whole).
    GeoJson,
}

impl Format {
    /// The format of a path by its extension (`.shp`, `.gpkg`, `.fgb`).
    #[must_use]
    pub fn of(path: &Path) -> Option<Self> {
        match path.extension()?.to_str()?.to_ascii_lowercase().as_str() {
            "shp" => Some(Format::Shapefile),
            "gpkg" => Some(Format::GeoPackage),
            "fgb" => Some(Format::FlatGeobuf),
            "geojson" | "json" => Some(Format::GeoJson),
            _ => None,
        }
    }

    /// Its name in messages.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Format::Shapefile => "Shapefile",
            Format::GeoPackage => "GeoPackage",
            Format::FlatGeobuf => "FlatGeobuf",
            Format::GeoJson => "GeoJSON",
        }
    }
}

/// An opened layer: its schema and CRS, read again on every pass.
#[derive(Debug, Clone)]
pub struct Layer {
    /// The file.
    pub path: PathBuf,
    /// Its format.
    pub format: Format,
    /// The layer's name (a GeoPackage table; the file stem otherwise).
    pub name: String,
    /// Field names, in the order of [`Feature::values`].
    pub fields: Vec<String>,
    /// Whether field names may be cut (dBase: 10 bytes).
    pub names_cut: bool,
    /// The CRS the file declares, if any.
    pub crs: Option<DeclaredCrs>,
    /// Features the file says it holds, where it says.
    pub count: Option<u64>,
    /// What was found, for the log (sidecars, encoding, the CRS's source).
    pub notes: Vec<String>,
    /// GeoPackage: the geometry column.
    geometry_column: Option<String>,
    /// GeoJSON: the features, parsed once.
    parsed: Option<std::sync::Arc<Vec<Feature>>>,
    /// The `.dbf`'s text encoding where no `.cpg` says (`--encoding`).
    pub text_encoding: Option<String>,
}

impl Layer {
    /// Opens `path` by its extension; `layer` picks a GeoPackage table
    /// (default: the only features table, else the only one whose geometry
    /// `wanted` accepts).
    pub fn open(path: &Path, layer: Option<&str>, wanted: Wanted) -> Result<Self> {
        let format =
            Format::of(path).with_context(|| format!("{}: not a .shp, .gpkg, .fgb or .geojson", path.display()))?;
        let meta = std::fs::metadata(path).with_context(|| format!("cannot open {}", path.display()))?;
        if !meta.is_file() {
            bail!("{} is not a regular file", path.display());
        }
        let mut l = match format {
            Format::Shapefile => shp::open(path),
            Format::GeoPackage => gpkg::open(path, layer, wanted),
            Format::FlatGeobuf => fgb::open(path),
            Format::GeoJson => geojson::open(path),
        }
        .with_context(|| format!("{} {}", format.name(), path.display()))?;
        if layer.is_some() && format != Format::GeoPackage {
            l.notes.push(format!("--layer is for GeoPackages; a {} has one layer", format.name()));
        }
        Ok(l)
    }

    /// One pass over the features in file order; returns how many were read.
    pub fn for_each(&self, f: &mut dyn FnMut(Feature) -> Result<()>) -> Result<u64> {
        match self.format {
            Format::Shapefile => shp::pass(self, f),
            Format::GeoPackage => gpkg::pass(self, f),
            Format::FlatGeobuf => fgb::pass(self, f),
            Format::GeoJson => {
                let features = self.parsed.as_deref().map_or(&[][..], |v| &v[..]);
                for feature in features {
                    f(feature.clone())?;
                }
                Ok(features.len() as u64)
            }
        }
        .with_context(|| format!("{} {}", self.format.name(), self.path.display()))
    }

    /// The first `n` features (fewer if the layer has fewer), to look at.
    pub fn first(&self, n: u64, f: &mut dyn FnMut(&Feature)) -> Result<()> {
        #[derive(Debug)]
        struct Enough;
        impl std::fmt::Display for Enough {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("enough features seen")
            }
        }
        impl std::error::Error for Enough {}
        let r = self.for_each(&mut |feature| {
            f(&feature);
            if feature.index >= n {
                return Err(Enough.into());
            }
            Ok(())
        });
        match r {
            Err(e) if !e.chain().any(|c| c.is::<Enough>()) => Err(e),
            _ => Ok(()),
        }
    }

    /// Whether the coordinates are lon/lat: as its CRS says, projected where
    /// `--input-crs` names a projected CRS, else as its first thousand
    /// vertices look (lon/lat where they can be, said in the note); an error
    /// where they cannot be lon/lat and nothing says what they are.
    pub fn lon_lat(&self, input_crs: Option<bool>) -> Result<(bool, Option<String>)> {
        // --input-crs wins over the file's (it is there for files whose CRS is wrong or unusable).
        if let Some(geographic) = input_crs {
            return Ok((geographic, None));
        }
        if let Some(crs) = &self.crs {
            return match crs.is_geographic() {
                Some(g) => Ok((g, None)),
                None => bail!("its CRS is {}: say which CRS it is with --input-crs EPSG:xxxx", crs.describe()),
            };
        }
        let (mut seen, mut beyond, mut beyond_count) = (0usize, None::<(u64, [f64; 2])>, 0usize);
        let mut look = |index: u64, x: f64, y: f64| {
            if seen < 1000 {
                seen += 1;
                if x.abs() > 180.0 || y.abs() > 90.0 {
                    beyond_count += 1;
                    beyond.get_or_insert((index, [x, y]));
                }
            }
        };
        self.first(1000, &mut |feature| match &feature.geometry {
            Geometry::Points(points) => points.iter().for_each(|p| look(feature.index, p[0], p[1])),
            Geometry::Polygons(polygons) => {
                polygons.iter().flatten().flatten().for_each(|p| look(feature.index, p[0], p[1]));
            }
            _ => {}
        })?;
        let what = match self.format {
            Format::Shapefile => "no .prj beside it",
            _ => "no CRS in it",
        };
        match beyond {
            Some((index, p)) if beyond_count * 2 >= seen.max(1) => bail!(
                "{what}, and its coordinates are no lon/lat (e.g. feature {index}: [{}, {}]): say which CRS they \
                 are in with --input-crs EPSG:xxxx",
                p[0],
                p[1]
            ),
            _ => Ok((true, Some(format!("{what}: coordinates read as lon/lat (WGS 84)")))),
        }
    }

    /// A layer of these fields and nothing else (tests of field roles).
    #[cfg(test)]
    #[must_use]
    pub fn for_tests(fields: &[&str]) -> Self {
        Self {
            path: PathBuf::new(),
            format: Format::GeoJson,
            name: "test".into(),
            fields: fields.iter().map(|f| (*f).to_string()).collect(),
            names_cut: false,
            crs: None,
            count: None,
            notes: Vec::new(),
            geometry_column: None,
            parsed: None,
            text_encoding: None,
        }
    }

    /// The index of a field by name (case-insensitive), or of a name the
    /// format cut: a dBase field `species_co` answers to `species_code`.
    #[must_use]
    pub fn field(&self, name: &str) -> Option<usize> {
        let want = name.trim().to_lowercase();
        self.fields.iter().position(|f| f.to_lowercase() == want).or_else(|| {
            let cut = cut_name(&want);
            (self.names_cut && cut.len() < want.len())
                .then(|| self.fields.iter().position(|f| f.to_lowercase() == cut))?
        })
    }
}

/// Whether a ring holds a point (even-odd).
#[must_use]
pub fn ring_holds(ring: &[[f64; 2]], p: [f64; 2]) -> bool {
    let n = ring.len();
    let mut inside = false;
    for i in 0..n {
        let (a, b) = (ring[i], ring[(i + n - 1) % n]);
        if (a[1] > p[1]) != (b[1] > p[1]) && p[0] < (b[0] - a[0]) * (p[1] - a[1]) / (b[1] - a[1]) + a[0] {
            inside = !inside;
        }
    }
    inside
}

/// A name as dBase keeps it: its first 10 bytes (at a character boundary).
#[must_use]
pub fn cut_name(name: &str) -> String {
    let mut end = name.len().min(10);
    while !name.is_char_boundary(end) {
        end -= 1;
    }
    name[..end].to_string()
}

/// Which geometries a reader wants (a GeoPackage with several tables picks
/// the one that has them).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wanted {
    /// Points (placements).
    Points,
    /// Polygons (stands).
    Polygons,
}

/// Collects a geozero geometry into a [`Geometry`], bounded by [`MAX_VERTICES`].
#[derive(Default)]
pub(crate) struct Collect {
    points: Vec<[f64; 3]>,
    polygons: Vec<Vec<Vec<[f64; 2]>>>,
    depth_polygon: u32,
    other: Option<&'static str>,
    vertices: usize,
}

impl Collect {
    pub(crate) fn finish(self) -> Geometry {
        if let Some(o) = self.other {
            Geometry::Other(o)
        } else if !self.polygons.is_empty() {
            Geometry::Polygons(self.polygons)
        } else if !self.points.is_empty() {
            Geometry::Points(self.points)
        } else {
            Geometry::Empty
        }
    }

    fn vertex(&mut self, x: f64, y: f64, z: Option<f64>) -> geozero::error::Result<()> {
        self.vertices += 1;
        if self.vertices > MAX_VERTICES {
            return Err(geozero::error::GeozeroError::Geometry(format!(
                "more than {MAX_VERTICES} vertices in one feature"
            )));
        }
        if self.other.is_some() {
            return Ok(());
        }
        if self.depth_polygon > 0 {
            if let Some(ring) = self.polygons.last_mut().and_then(|p| p.last_mut()) {
                ring.push([x, y]);
            }
        } else {
            self.points.push([x, y, z.unwrap_or(f64::NAN)]);
        }
        Ok(())
    }

    fn other(&mut self, name: &'static str) -> geozero::error::Result<()> {
        self.other.get_or_insert(name);
        Ok(())
    }
}

impl geozero::GeomProcessor for Collect {
    fn dimensions(&self) -> geozero::CoordDimensions {
        geozero::CoordDimensions::xyz()
    }
    fn multi_dim(&self) -> bool {
        true
    }
    fn xy(&mut self, x: f64, y: f64, _idx: usize) -> geozero::error::Result<()> {
        self.vertex(x, y, None)
    }
    fn coordinate(
        &mut self,
        x: f64,
        y: f64,
        z: Option<f64>,
        _m: Option<f64>,
        _t: Option<f64>,
        _tm: Option<u64>,
        _idx: usize,
    ) -> geozero::error::Result<()> {
        self.vertex(x, y, z)
    }
    fn linestring_begin(&mut self, tagged: bool, _size: usize, _idx: usize) -> geozero::error::Result<()> {
        if tagged || self.depth_polygon == 0 {
            return self.other("LineString");
        }
        if let Some(p) = self.polygons.last_mut() {
            p.push(Vec::new());
        }
        Ok(())
    }
    fn polygon_begin(&mut self, _tagged: bool, _size: usize, _idx: usize) -> geozero::error::Result<()> {
        self.depth_polygon += 1;
        self.polygons.push(Vec::new());
        Ok(())
    }
    fn polygon_end(&mut self, _tagged: bool, _idx: usize) -> geozero::error::Result<()> {
        self.depth_polygon = self.depth_polygon.saturating_sub(1);
        Ok(())
    }
    fn multilinestring_begin(&mut self, _size: usize, _idx: usize) -> geozero::error::Result<()> {
        self.other("MultiLineString")
    }
    fn circularstring_begin(&mut self, _size: usize, _idx: usize) -> geozero::error::Result<()> {
        self.other("CircularString")
    }
    fn compoundcurve_begin(&mut self, _size: usize, _idx: usize) -> geozero::error::Result<()> {
        self.other("CompoundCurve")
    }
    fn curvepolygon_begin(&mut self, _size: usize, _idx: usize) -> geozero::error::Result<()> {
        self.other("CurvePolygon")
    }
    fn multicurve_begin(&mut self, _size: usize, _idx: usize) -> geozero::error::Result<()> {
        self.other("MultiCurve")
    }
    fn multisurface_begin(&mut self, _size: usize, _idx: usize) -> geozero::error::Result<()> {
        self.other("MultiSurface")
    }
    fn geometrycollection_begin(&mut self, _size: usize, _idx: usize) -> geozero::error::Result<()> {
        // An error, not a note: collections nest, and the WKB reader recurses
        // once a level (a deep one would overflow the stack).
        Err(geozero::error::GeozeroError::Geometry("a GeometryCollection".into()))
    }
    fn triangle_begin(&mut self, _tagged: bool, _size: usize, _idx: usize) -> geozero::error::Result<()> {
        self.other("Triangle")
    }
    fn polyhedralsurface_begin(&mut self, _size: usize, _idx: usize) -> geozero::error::Result<()> {
        self.other("PolyhedralSurface")
    }
    fn tin_begin(&mut self, _size: usize, _idx: usize) -> geozero::error::Result<()> {
        self.other("TIN")
    }
}

#[cfg(test)]
mod tests;
