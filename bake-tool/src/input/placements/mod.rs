//! Tree placements from CSV (columns auto-detected) or GeoJSON points.
//!
//! Real inventories have missing fields, junk rows, duplicated coordinates and
//! outliers: rows that cannot be used are skipped and counted by reason (with
//! the first few row numbers), never fatal. Only an unreadable file or one
//! with no usable coordinate columns is an error.
//!
//! Files come as spreadsheets export them: UTF-8 or Windows-1252/Latin-1
//! (`--encoding`, detected per field by default), separated by `,`, `;`, tab
//! or `|` (detected from the header), with decimal commas where the separator
//! is not a comma. Lon/lat columns that hold each other's values are caught
//! (`--swap-xy`); GeoJSON in a projected CRS is read with `--input-crs` or its
//! `crs` member.

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
    /// Stem diameter at breast height, centimetres, if given and positive.
    pub dbh_cm: Option<f32>,
    /// Crown diameter, metres, if given (a radius column is doubled).
    pub crown_m: Option<f32>,
    /// Species label, if given.
    pub species: Option<String>,
    /// Yaw in degrees, if given.
    pub yaw_deg: Option<f32>,
    /// Numeric tree id, if given.
    pub id: Option<u64>,
    /// The id as given when it is not a whole number ([`text_id`]): an
    /// inventory's own key (`EY17080`), kept as text.
    pub id_text: Option<String>,
    /// The attribute columns' text ([`Columns::attrs`] order; empty when not
    /// asked for: [`PlacementSource::for_each_with_attributes`]).
    pub attrs: Vec<Option<String>>,
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
    /// Rows without a height (kept; they get one from their DBH or the default height).
    pub missing_height: u64,
    /// Rows sharing their coordinates with an earlier row (kept).
    pub duplicate_coordinates: u64,
    /// Rows with bytes that are no UTF-8, read as Windows-1252 (kept).
    pub not_utf8: u64,
    /// Rows out of lon/lat range that would be in range with x and y swapped.
    pub swappable: u64,
    /// Kept rows whose id is not a whole number (text, or none): such a tree's
    /// number is its row, 2^63 + row (`describe_tree` gives it as `row`), and
    /// a text id is kept as text.
    pub ids_not_numbers: (u64, Vec<u64>),
    /// Of those, rows with a text id (kept, 1–256 bytes) and rows with an id
    /// longer than 256 bytes (not kept).
    pub text_ids: (u64, u64),
}

impl Report {
    /// Counts a kept row whose id is no whole number: `text` kept, or
    /// `too_long` to keep.
    pub fn count_text_id(&mut self, row: u64, text: bool, too_long: bool) {
        self.ids_not_numbers.0 += 1;
        if self.ids_not_numbers.1.len() < 5 {
            self.ids_not_numbers.1.push(row);
        }
        self.text_ids.0 += u64::from(text);
        self.text_ids.1 += u64::from(too_long);
    }

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
            out.push(format!(
                "{} rows have no height: they get one from their DBH, else the default height",
                self.missing_height
            ));
        }
        if self.not_utf8 > 0 {
            out.push(format!(
                "{} rows are not UTF-8: read as Windows-1252/Latin-1 (--encoding utf-8 refuses them)",
                self.not_utf8
            ));
        }
        if self.duplicate_coordinates > 0 {
            out.push(format!("{} rows repeat the coordinates of an earlier row (kept)", self.duplicate_coordinates));
        }
        if self.ids_not_numbers.0 > 0 {
            let (text, long) = self.text_ids;
            let none = self.ids_not_numbers.0 - text - long;
            let mut parts = Vec::new();
            if text > 0 {
                parts.push(format!("{text} are text, kept as the trees' ids"));
            }
            if long > 0 {
                parts.push(format!(
                    "{long} are longer than {MAX_TEXT_ID_BYTES} bytes, not kept: those trees are named by their row"
                ));
            }
            if none > 0 {
                parts.push(format!("{none} are empty: those trees are named by their row (a pick says \"row\")"));
            }
            out.push(format!(
                "{} rows have an id that is not a whole number (e.g. rows {:?}): {}",
                self.ids_not_numbers.0,
                self.ids_not_numbers.1,
                parts.join("; ")
            ));
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
    /// The EPSG code a GeoJSON file names in its `crs` member, if any.
    pub declared_epsg: Option<u32>,
    /// The attribute columns' names ([`Placement::attrs`] order).
    pub attribute_names: Vec<String>,
}

/// Text encoding of a CSV file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Encoding {
    /// UTF-8 where a field is valid UTF-8, else Windows-1252 (Latin-1), counted.
    #[default]
    Auto,
    /// UTF-8 only: rows with other bytes are skipped and counted.
    #[value(name = "utf-8", alias = "utf8")]
    Utf8,
    /// Windows-1252 (a superset of Latin-1 / ISO-8859-1), as older spreadsheets export.
    Latin1,
}

/// How to read a placements file.
#[derive(Debug, Clone, Default)]
pub struct ReadOptions {
    /// Text encoding of CSV files.
    pub encoding: Encoding,
    /// Field separator of CSV files (default: detected from the header line).
    pub delimiter: Option<u8>,
    /// The x/lon and y/lat columns (or GeoJSON coordinates) are swapped.
    pub swap_xy: bool,
    /// Coordinates are projected (the bake was given `--input-crs`): applies to
    /// GeoJSON, whose coordinates are otherwise lon/lat.
    pub projected: bool,
    /// Columns named by the user (`--column ROLE=NAME`), before any detection.
    pub columns: Vec<(ColumnRole, String)>,
    /// Unit of a DBH column whose name does not say (`--dbh-unit`; default cm).
    pub dbh_unit: Option<DbhUnit>,
    /// The columns kept as per-tree attributes (`--attributes`): `None` every
    /// column but the coordinates and the id, `Some` these (none if empty).
    pub attributes: Option<Vec<String>>,
}

/// What a column holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum ColumnRole {
    /// Longitude (degrees).
    Lon,
    /// Latitude (degrees).
    Lat,
    /// Projected x (easting).
    X,
    /// Projected y (northing).
    Y,
    /// Ground height.
    Z,
    /// Tree height, metres.
    Height,
    /// Species label (botanical or common name, or a code).
    Species,
    /// Stem diameter at breast height.
    Dbh,
    /// Crown diameter, metres.
    CrownDiameter,
    /// Crown radius, metres.
    CrownRadius,
    /// Rotation about the vertical, degrees.
    Yaw,
    /// Numeric tree id.
    Id,
}

impl ColumnRole {
    /// Every role, in the order columns are reported.
    pub const ALL: [ColumnRole; 12] = [
        ColumnRole::Lon,
        ColumnRole::Lat,
        ColumnRole::X,
        ColumnRole::Y,
        ColumnRole::Z,
        ColumnRole::Height,
        ColumnRole::Species,
        ColumnRole::Dbh,
        ColumnRole::CrownDiameter,
        ColumnRole::CrownRadius,
        ColumnRole::Yaw,
        ColumnRole::Id,
    ];

    /// The role's name in `--column ROLE=NAME` and in reports.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            ColumnRole::Lon => "lon",
            ColumnRole::Lat => "lat",
            ColumnRole::X => "x",
            ColumnRole::Y => "y",
            ColumnRole::Z => "z",
            ColumnRole::Height => "height",
            ColumnRole::Species => "species",
            ColumnRole::Dbh => "dbh",
            ColumnRole::CrownDiameter => "crown_diameter",
            ColumnRole::CrownRadius => "crown_radius",
            ColumnRole::Yaw => "yaw",
            ColumnRole::Id => "id",
        }
    }

    /// Header names recognised for the role, most specific first (compared
    /// case-insensitively after trimming).
    #[must_use]
    pub fn aliases(self) -> &'static [&'static str] {
        match self {
            ColumnRole::Lon => LON,
            ColumnRole::Lat => LAT,
            ColumnRole::X => X,
            ColumnRole::Y => Y,
            ColumnRole::Z => Z,
            ColumnRole::Height => HEIGHT,
            ColumnRole::Species => SPECIES,
            ColumnRole::Dbh => DBH,
            ColumnRole::CrownDiameter => CROWN_DIAMETER,
            ColumnRole::CrownRadius => CROWN_RADIUS,
            ColumnRole::Yaw => YAW,
            ColumnRole::Id => ID,
        }
    }

    /// Parses `ROLE=NAME` (`--column`).
    ///
    /// # Errors
    /// An unknown role, or no `=`.
    pub fn parse_mapping(s: &str) -> Result<(ColumnRole, String), String> {
        let (role, name) = s.split_once('=').ok_or_else(|| format!("{s:?}: expected ROLE=COLUMN, e.g. dbh=dbh_mm"))?;
        let role = role.trim().to_lowercase().replace('-', "_");
        let found =
            ColumnRole::ALL.iter().find(|r| r.name() == role || (role == "crown" && **r == ColumnRole::CrownDiameter));
        match (found, name.trim()) {
            (Some(r), n) if !n.is_empty() => Ok((*r, n.to_string())),
            (Some(_), _) => Err(format!("{s:?}: the column name is empty")),
            (None, _) => Err(format!(
                "{s:?}: unknown role {role:?}; roles are {}",
                ColumnRole::ALL.map(ColumnRole::name).join(", ")
            )),
        }
    }
}

/// Unit of a DBH column.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum DbhUnit {
    /// Millimetres.
    Mm,
    /// Centimetres (the default).
    #[default]
    Cm,
    /// Inches.
    In,
    /// Metres.
    M,
}

impl DbhUnit {
    /// The unit a column name says (`dbh_mm`, `diameter_cm`, `dbh_in`), if any.
    #[must_use]
    pub fn from_name(name: &str) -> Option<Self> {
        let n = name.trim().to_lowercase();
        let ends =
            |s: &str| n.ends_with(&format!("_{s}")) || n.ends_with(&format!("({s})")) || n.ends_with(&format!(" {s}"));
        if ends("mm") {
            Some(DbhUnit::Mm)
        } else if ends("cm") {
            Some(DbhUnit::Cm)
        } else if ends("in") || ends("inch") || ends("inches") {
            Some(DbhUnit::In)
        } else if ends("m") {
            Some(DbhUnit::M)
        } else {
            None
        }
    }

    /// Centimetres per unit.
    #[must_use]
    pub fn to_cm(self) -> f64 {
        match self {
            DbhUnit::Mm => 0.1,
            DbhUnit::Cm => 1.0,
            DbhUnit::In => 2.54,
            DbhUnit::M => 100.0,
        }
    }

    /// The unit's name.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            DbhUnit::Mm => "mm",
            DbhUnit::Cm => "cm",
            DbhUnit::In => "in",
            DbhUnit::M => "m",
        }
    }
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
            read_csv(std::io::BufReader::new(file), if ext == "tsv" { b'\t' } else { b',' }, &ReadOptions::default())
        }
        "geojson" | "json" => {
            let bytes = std::fs::read(path).with_context(|| format!("cannot read placements {}", path.display()))?;
            read_geojson(&bytes, &ReadOptions::default())
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
const HEIGHT: &[&str] = &[
    "height",
    "height_m",
    "h",
    "h_m",
    "tree_height",
    "treeheight",
    "total_height",
    "hoehe",
    "höhe",
    "baumhöhe",
    "boomhoogte",
    "hoogte",
];
// The names detected before column mapping keep their order (species, species_name,
// genus, taxon, baumart, soort, type, art), so existing files pick the same column.
const SPECIES: &[&str] = &[
    "species",
    "species_name",
    "botanical_name",
    "botanicalname",
    "botanical",
    "scientific_name",
    "scientificname",
    "latin_name",
    "latin",
    "genus",
    "taxon",
    "baumart",
    "soort",
    "type",
    "art",
    "boomsoort",
    "soortnaam",
    "common_name",
    "commonname",
    "species_code",
    "speciescode",
    "spp",
    "sp",
];
const DBH: &[&str] = &[
    "dbh",
    "dbh_cm",
    "dbh_mm",
    "dbh_in",
    "dbh_m",
    "diameter_cm",
    "diameter_mm",
    "stem_diameter",
    "trunk_diameter",
    "d130",
    "d13",
    "bhd",
    "stammdurchmesser",
    "stamdiameter",
];
const CROWN_DIAMETER: &[&str] = &[
    "crown_diameter",
    "crowndiameter",
    "crown_diam",
    "crown_dia",
    "crown_width",
    "crownwidth",
    "canopy_diameter",
    "maxcanopydiam",
    "kronendurchmesser",
    "kroondiameter",
    "kroonbreedte",
];
const CROWN_RADIUS: &[&str] = &["crown_radius", "crownradius", "canopy_radius", "kronenradius"];
const YAW: &[&str] = &["yaw", "rotation", "heading", "azimuth"];
const ID: &[&str] = &["id", "tree_id", "treeid", "objectid", "fid", "gid"];

/// Columns found in a CSV header (or GeoJSON property names).
#[derive(Debug, Clone, PartialEq, Eq)]
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
    /// DBH column.
    pub dbh: Option<usize>,
    /// The DBH column's unit.
    pub dbh_unit: DbhUnit,
    /// Crown column, and whether it holds a radius.
    pub crown: Option<(usize, bool)>,
    /// Yaw column.
    pub yaw: Option<usize>,
    /// Id column.
    pub id: Option<usize>,
    /// What each found column is used for, as `role ← header name`, for the report.
    pub used: Vec<(ColumnRole, String)>,
    /// The columns kept as attributes: index and header name.
    pub attrs: Vec<(usize, String)>,
}

impl Columns {
    /// The columns used, for the log: `species ← species_code, dbh ← dbh_mm (mm), …`.
    #[must_use]
    pub fn describe(&self) -> String {
        self.used
            .iter()
            .map(|(r, n)| {
                let unit = if *r == ColumnRole::Dbh { format!(" ({})", self.dbh_unit.name()) } else { String::new() };
                format!("{} ← {n:?}{unit}", r.name())
            })
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// Detects the columns of a header (names compared case-insensitively):
/// `options.columns` first, then the aliases of each role.
///
/// # Errors
/// No coordinate columns, or a `--column` naming a column the header lacks.
pub fn detect_columns_with(header: &[&str], options: &ReadOptions) -> Result<Columns> {
    let h: Vec<String> = header.iter().map(|s| s.trim().trim_matches('"').to_lowercase()).collect();
    let mut chosen: BTreeMap<ColumnRole, usize> = BTreeMap::new();
    for (role, name) in &options.columns {
        let want = name.trim().to_lowercase();
        let Some(i) = h.iter().position(|c| *c == want) else {
            bail!("--column {}={name}: the header has no column {name:?}; it has {header:?}", role.name());
        };
        chosen.insert(*role, i);
    }
    let taken = |chosen: &BTreeMap<ColumnRole, usize>, i: usize| chosen.values().any(|&c| c == i);
    for role in ColumnRole::ALL {
        if chosen.contains_key(&role) {
            continue;
        }
        // The first alias whose column no other role holds yet.
        let free = role.aliases().iter().find_map(|n| h.iter().position(|c| c == n).filter(|&i| !taken(&chosen, i)));
        if let Some(i) = free {
            chosen.insert(role, i);
        }
    }
    let get = |r: ColumnRole| chosen.get(&r).copied();
    // Coordinates the user named decide the kind, whatever else the header has.
    let named = |r: ColumnRole| options.columns.iter().any(|(c, _)| *c == r);
    let projected_named = named(ColumnRole::X) || named(ColumnRole::Y);
    let (kind, x, y) = match (get(ColumnRole::Lon), get(ColumnRole::Lat), get(ColumnRole::X), get(ColumnRole::Y)) {
        (_, _, Some(x), Some(y)) if projected_named => (CoordKind::Projected, x, y),
        (Some(x), Some(y), _, _) => (CoordKind::LonLat, x, y),
        (_, _, Some(x), Some(y)) => (CoordKind::Projected, x, y),
        _ => bail!(
            "no coordinate columns: expected lon/lat (or lng/lat, longitude/latitude) or x/y (or easting/northing), \
             or name them with --column lon=NAME --column lat=NAME (or x=, y=); the header is {header:?}"
        ),
    };
    let dbh = get(ColumnRole::Dbh);
    let dbh_unit = dbh.and_then(|i| DbhUnit::from_name(&h[i])).or(options.dbh_unit).unwrap_or_default();
    // A crown column the user named wins over a detected one.
    let diameter = get(ColumnRole::CrownDiameter).map(|i| (i, false));
    let radius = get(ColumnRole::CrownRadius).map(|i| (i, true));
    let crown = if named(ColumnRole::CrownRadius) && !named(ColumnRole::CrownDiameter) {
        radius.or(diameter)
    } else {
        diameter.or(radius)
    };
    let coordinate_roles: [ColumnRole; 2] =
        if kind == CoordKind::LonLat { [ColumnRole::Lon, ColumnRole::Lat] } else { [ColumnRole::X, ColumnRole::Y] };
    let used = ColumnRole::ALL
        .iter()
        .filter(|r| {
            !matches!(r, ColumnRole::Lon | ColumnRole::Lat | ColumnRole::X | ColumnRole::Y)
                || coordinate_roles.contains(r)
        })
        .filter(|r| **r != ColumnRole::CrownRadius || crown.is_some_and(|c| c.1))
        .filter(|r| **r != ColumnRole::CrownDiameter || crown.is_some_and(|c| !c.1))
        .filter_map(|r| get(*r).map(|i| (*r, header[i].trim().trim_matches('"').to_string())))
        .collect();
    // Attributes: every named column but the coordinates and the id (which
    // the `.ids` sidecar keeps), or the ones asked for.
    let id = get(ColumnRole::Id);
    let names: Vec<String> = header.iter().map(|s| s.trim().trim_matches('"').to_string()).collect();
    let candidates: Vec<(usize, String)> = names
        .iter()
        .enumerate()
        .filter(|(i, n)| *i != x && *i != y && Some(*i) != id && !n.is_empty())
        .map(|(i, n)| (i, n.clone()))
        .collect();
    let attrs = match &options.attributes {
        None => candidates,
        Some(wanted) => wanted
            .iter()
            .map(|w| {
                candidates.iter().find(|(_, n)| n.eq_ignore_ascii_case(w.trim())).cloned().with_context(|| {
                    format!(
                        "--attributes {w:?}: no such column (the coordinates and the id are not attributes); \
                         the columns are {:?}",
                        candidates.iter().map(|(_, n)| n.as_str()).collect::<Vec<_>>()
                    )
                })
            })
            .collect::<Result<Vec<_>>>()?,
    };
    Ok(Columns {
        kind,
        x,
        y,
        z: get(ColumnRole::Z),
        height: get(ColumnRole::Height),
        species: get(ColumnRole::Species),
        dbh,
        dbh_unit,
        crown,
        yaw: get(ColumnRole::Yaw),
        id,
        used,
        attrs,
    })
}

/// Detects the columns of a header with the default options (tests).
#[cfg(test)]
pub fn detect_columns(header: &[&str]) -> Result<Columns> {
    detect_columns_with(header, &ReadOptions::default())
}

pub fn parse_f64(s: &str) -> Option<f64> {
    let t = s.trim();
    if t.is_empty() {
        return None;
    }
    t.parse::<f64>().ok()
}

/// A number of a CSV whose separator is not a comma: `52.37`, or with a
/// decimal comma as European spreadsheets write it, `52,37` or `1.234,5`.
pub fn parse_decimal_comma(s: &str) -> Option<f64> {
    parse_f64(s).or_else(|| {
        let (int, frac) = s.trim().rsplit_once(',')?;
        if frac.is_empty() || !frac.bytes().all(|b| b.is_ascii_digit()) {
            return None;
        }
        // Thousands separators: groups of three digits after the first.
        let mut groups = int.split('.');
        let first = groups.next()?;
        let rest: Vec<&str> = groups.collect();
        if !rest.iter().all(|g| g.len() == 3 && g.bytes().all(|b| b.is_ascii_digit())) {
            return None;
        }
        format!("{first}{}.{frac}", rest.concat()).parse().ok()
    })
}

/// The field separator of a header line: the most frequent of `,` `;` tab `|`
/// outside quotes (a comma when none occurs).
#[must_use]
pub fn detect_delimiter(header_line: &[u8]) -> u8 {
    let mut counts = [0usize; 4];
    let mut quoted = false;
    for &b in header_line {
        match b {
            b'"' => quoted = !quoted,
            _ if quoted => {}
            b',' => counts[0] += 1,
            b';' => counts[1] += 1,
            b'\t' => counts[2] += 1,
            b'|' => counts[3] += 1,
            _ => {}
        }
    }
    let best = (0..4).max_by_key(|&i| (counts[i], usize::from(i == 0))).unwrap_or(0);
    if counts[best] == 0 {
        b','
    } else {
        [b',', b';', b'\t', b'|'][best]
    }
}

/// One CSV field as text: UTF-8, or Windows-1252 where the options allow it.
/// `None` when the bytes are no UTF-8 and only UTF-8 is accepted.
fn decode_field<'a>(bytes: &'a [u8], encoding: Encoding, fell_back: &mut bool) -> Option<std::borrow::Cow<'a, str>> {
    match (encoding, std::str::from_utf8(bytes)) {
        (Encoding::Latin1, _) => Some(encoding_rs::WINDOWS_1252.decode_without_bom_handling(bytes).0),
        (_, Ok(s)) => Some(std::borrow::Cow::Borrowed(s)),
        (Encoding::Utf8, Err(_)) => None,
        (Encoding::Auto, Err(_)) => {
            *fell_back = true;
            Some(encoding_rs::WINDOWS_1252.decode_without_bom_handling(bytes).0)
        }
    }
}

/// Reads CSV from any reader (the first line is the header).
#[cfg(test)]
pub fn read_csv<R: std::io::Read>(reader: R, delimiter: u8, options: &ReadOptions) -> Result<PlacementSet> {
    let mut report = Report::default();
    let mut rows = Vec::new();
    let kind = stream_csv(reader, delimiter, options, true, &mut report, &mut |p| {
        rows.push(p);
        Ok(())
    })?;
    let attribute_names = Vec::new();
    Ok(PlacementSet { kind, rows, report, declared_epsg: None, attribute_names })
}

/// The CSV reader of every pass over an inventory (the header's and the rows'),
/// so both see the same columns.
fn csv_reader<R: std::io::Read>(reader: R, delimiter: u8) -> csv::Reader<R> {
    csv::ReaderBuilder::new().delimiter(delimiter).flexible(true).trim(csv::Trim::All).from_reader(reader)
}

/// Most bytes of a CSV header record.
pub const MAX_HEADER_BYTES: usize = 1 << 20;

/// The first record of a CSV file, up to its line break outside quotes (a
/// header cell may hold one: what a spreadsheet writes for Alt+Enter), as
/// [`header_record_with`] with the separator not known yet.
///
/// # Errors
/// A header over `limit` bytes, or a read error.
pub fn header_record(reader: impl std::io::Read, limit: usize) -> Result<Vec<u8>> {
    header_record_with(reader, limit, None)
}

/// The first record of a CSV file with quotes as the CSV reader reads them:
/// a `"` opens a quoted field only at the start of a field (after the
/// `separator`, or any of `,`, `;`, a tab or `|` when it is not known yet),
/// `""` inside one is a quote, and elsewhere `"` is a character (`dbh (")`).
/// The record ends at a line feed, a carriage return (with the line feed
/// after it) outside quotes; blank lines before it are skipped.
///
/// # Errors
/// A header over `limit` bytes, or a read error.
pub fn header_record_with(reader: impl std::io::Read, limit: usize, separator: Option<u8>) -> Result<Vec<u8>> {
    use std::io::BufRead;
    #[derive(Clone, Copy, PartialEq)]
    enum State {
        FieldStart,
        Unquoted,
        Quoted,
        QuoteInQuoted,
        /// After a carriage return that ended the record: a line feed may follow.
        Ended,
    }
    let is_separator = |b: u8| match separator {
        Some(d) => b == d,
        None => matches!(b, b',' | b';' | b'\t' | b'|'),
    };
    let mut r = std::io::BufReader::new(reader.take(limit as u64 + 1));
    let mut out = Vec::new();
    let mut state = State::FieldStart;
    let mut content = false;
    loop {
        let buf = r.fill_buf()?;
        if buf.is_empty() {
            break;
        }
        let mut used = buf.len();
        let mut done = false;
        for (i, &b) in buf.iter().enumerate() {
            let at = out.len() + i;
            if state == State::Ended {
                used = i + usize::from(b == b'\n');
                done = true;
                break;
            }
            // A UTF-8 byte-order mark is no part of the first field.
            if at < 3 && b == [0xef, 0xbb, 0xbf][at] && !content {
                continue;
            }
            let terminator = b == b'\n' || b == b'\r';
            if terminator && !content && state == State::FieldStart {
                continue; // a blank line before the header
            }
            content = true;
            state = match (state, b) {
                (State::Quoted, b'"') => State::QuoteInQuoted,
                (State::Quoted, _) => State::Quoted,
                (State::FieldStart | State::QuoteInQuoted, b'"') => State::Quoted,
                (_, b'\n') => {
                    used = i + 1;
                    done = true;
                    break;
                }
                (_, b'\r') => State::Ended,
                (_, b) if is_separator(b) => State::FieldStart,
                _ => State::Unquoted,
            };
        }
        out.extend_from_slice(&buf[..used]);
        r.consume(used);
        if out.len() > limit {
            bail!("the header (the first line) is over {} KiB without its end: is this a CSV file?", limit / 1024);
        }
        if done {
            break;
        }
    }
    Ok(out)
}

/// Reads the header line (UTF-8 or Windows-1252, as the fields) and detects its columns.
fn header_columns<R: std::io::Read>(rdr: &mut csv::Reader<R>, options: &ReadOptions) -> Result<Columns> {
    let mut fell_back = false;
    let header: Vec<String> = rdr
        .byte_headers()
        .map_err(|e| anyhow!("cannot read the CSV header: {e}"))?
        .iter()
        .map(|h| decode_field(h, Encoding::Auto, &mut fell_back).unwrap_or_default().into_owned())
        .collect();
    let refs: Vec<&str> = header.iter().map(String::as_str).collect();
    detect_columns_with(&refs, options)
}

/// Streams CSV rows: each usable row goes to `f` as it is read (memory stays
/// constant whatever the file size); skipped rows are counted in `report`.
/// Returns the coordinate kind of the header.
pub fn stream_csv<R: std::io::Read>(
    reader: R,
    delimiter: u8,
    options: &ReadOptions,
    with_attributes: bool,
    report: &mut Report,
    f: &mut dyn FnMut(Placement) -> Result<()>,
) -> Result<CoordKind> {
    let mut rdr = csv_reader(reader, delimiter);
    let mut cols = header_columns(&mut rdr, options)?;
    if options.swap_xy {
        std::mem::swap(&mut cols.x, &mut cols.y);
    }
    let number = if delimiter == b',' { parse_f64 } else { parse_decimal_comma };
    let mut record = csv::ByteRecord::new();
    let mut row = 0u64;
    loop {
        match rdr.read_byte_record(&mut record) {
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
        let mut row_fell_back = false;
        let mut utf8_error = false;
        let mut get = |c: Option<usize>| {
            let field = record.get(c?)?;
            let text = decode_field(field, options.encoding, &mut row_fell_back);
            utf8_error |= text.is_none();
            text
        };
        let (x, y) = (get(Some(cols.x)), get(Some(cols.y)));
        let (z, height, species, yaw, id) =
            (get(cols.z), get(cols.height), get(cols.species), get(cols.yaw), get(cols.id));
        let (dbh, crown) = (get(cols.dbh), get(cols.crown.map(|c| c.0)));
        let attrs: Vec<Option<String>> = if with_attributes {
            cols.attrs
                .iter()
                .map(|(i, _)| get(Some(*i)).map(|t| t.trim().to_string()).filter(|t| !t.is_empty()))
                .collect()
        } else {
            Vec::new()
        };
        if utf8_error {
            report.skip("not UTF-8 (read it with --encoding latin1)", row);
            continue;
        }
        if row_fell_back {
            report.not_utf8 += 1;
        }
        let (Some(x), Some(y)) = (x.as_deref().and_then(number), y.as_deref().and_then(number)) else {
            report.skip("missing or non-numeric coordinates", row);
            continue;
        };
        let p = Placement {
            x,
            y,
            z: z.as_deref().and_then(number),
            height_m: height.as_deref().and_then(number).map(|h| h as f32),
            dbh_cm: dbh.as_deref().and_then(number).map(|d| (d * cols.dbh_unit.to_cm()) as f32),
            crown_m: crown
                .as_deref()
                .and_then(number)
                .map(|c| if cols.crown.is_some_and(|c| c.1) { 2.0 * c } else { c } as f32),
            species: species.as_deref().map(str::trim).filter(|s| !s.is_empty()).map(str::to_string),
            yaw_deg: yaw.as_deref().and_then(number).map(|v| v as f32),
            id: id.as_deref().and_then(number_id),
            id_text: id.as_deref().and_then(text_id),
            attrs,
            row,
        };
        if let Some(p) = accept(p, cols.kind, report) {
            report.kept += 1;
            if cols.id.is_some() && p.id.is_none() {
                report.count_text_id(p.row, p.id_text.is_some(), id.as_deref().is_some_and(id_too_long));
            }
            f(p)?;
        }
    }
    Ok(cols.kind)
}

pub use sylva::format::ids::MAX_TEXT_ID_BYTES;

/// An id cell's number: a whole number below 2^63 written as that number
/// writes itself ([`sylva::format::ids::numeric_id`]; `0702` is a key, text).
#[must_use]
pub fn number_id(cell: &str) -> Option<u64> {
    sylva::format::ids::numeric_id(cell.trim())
}

/// An id cell that is no such number, trimmed, if it holds 1–256 bytes: the
/// tree's id as text (`EY17080`, a zero-padded `00123`, kept as given).
#[must_use]
pub fn text_id(cell: &str) -> Option<String> {
    let t = cell.trim();
    (!t.is_empty() && t.len() <= MAX_TEXT_ID_BYTES && number_id(t).is_none()).then(|| t.to_string())
}

/// Whether an id cell is text too long to keep.
#[must_use]
pub fn id_too_long(cell: &str) -> bool {
    cell.trim().len() > MAX_TEXT_ID_BYTES
}

/// A placements file that can be read more than once: CSV is streamed from disk
/// on every pass (inputs larger than memory), GeoJSON is parsed once and kept.
pub struct PlacementSource {
    path: std::path::PathBuf,
    delimiter: u8,
    options: ReadOptions,
    parsed: Option<PlacementSet>,
    /// Degrees or metres.
    pub kind: CoordKind,
    /// The EPSG code a GeoJSON file names in its `crs` member, if any.
    pub declared_epsg: Option<u32>,
    /// What was detected, for the log (separator, encoding).
    pub notes: Vec<String>,
    attribute_names: Vec<String>,
}

impl PlacementSource {
    /// Opens `path` (`.csv`, `.tsv`, `.txt`, `.geojson`, `.json`) and reads its header.
    pub fn open(path: &Path, options: &ReadOptions) -> Result<Self> {
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_lowercase();
        let meta = std::fs::metadata(path).with_context(|| format!("cannot open placements {}", path.display()))?;
        if !meta.is_file() {
            bail!("placements {} is not a regular file", path.display());
        }
        match ext.as_str() {
            "csv" | "txt" | "tsv" => {
                let file =
                    std::fs::File::open(path).with_context(|| format!("cannot open placements {}", path.display()))?;
                let known = options.delimiter.or((ext == "tsv").then_some(b'\t'));
                let first_line = header_record_with(file, MAX_HEADER_BYTES, known)
                    .with_context(|| format!("cannot read placements {}", path.display()))?;
                let delimiter =
                    options.delimiter.unwrap_or(if ext == "tsv" { b'\t' } else { detect_delimiter(&first_line) });
                let mut notes = Vec::new();
                if delimiter != b',' {
                    notes.push(format!(
                        "fields separated by {}{}",
                        match delimiter {
                            b'\t' => "tabs".to_string(),
                            d => format!("{:?}", char::from(d)),
                        },
                        if delimiter == b';' { " (decimal commas accepted)" } else { "" }
                    ));
                }
                // The header as the rows' pass reads it (stream_csv): the same reader and settings.
                let mut rdr = csv_reader(&first_line[..], delimiter);
                let cols =
                    header_columns(&mut rdr, options).with_context(|| format!("placements {}", path.display()))?;
                notes.push(format!("columns: {}", cols.describe()));
                Ok(Self {
                    path: path.to_path_buf(),
                    delimiter,
                    options: options.clone(),
                    parsed: None,
                    kind: cols.kind,
                    declared_epsg: None,
                    notes,
                    attribute_names: cols.attrs.iter().map(|(_, n)| n.clone()).collect(),
                })
            }
            "geojson" | "json" => {
                let bytes =
                    std::fs::read(path).with_context(|| format!("cannot read placements {}", path.display()))?;
                let set = read_geojson(&bytes, options).with_context(|| format!("placements {}", path.display()))?;
                let declared_epsg = set.declared_epsg;
                let attribute_names = set.attribute_names.clone();
                Ok(Self {
                    path: path.to_path_buf(),
                    delimiter: b',',
                    options: options.clone(),
                    kind: set.kind,
                    parsed: Some(set),
                    declared_epsg,
                    notes: Vec::new(),
                    attribute_names,
                })
            }
            _ => bail!("placements {}: unknown extension {ext:?}; use .csv or .geojson", path.display()),
        }
    }

    /// One pass over the usable rows, in file order; returns what was read and skipped.
    pub fn for_each(&self, f: &mut dyn FnMut(Placement) -> Result<()>) -> Result<Report> {
        self.pass(false, f)
    }

    /// [`Self::for_each`] with each row's attribute columns ([`Placement::attrs`]).
    pub fn for_each_with_attributes(&self, f: &mut dyn FnMut(Placement) -> Result<()>) -> Result<Report> {
        self.pass(true, f)
    }

    /// Whether numbers may have decimal commas (a CSV separated by `;` or tabs).
    pub fn decimal_comma(&self) -> bool {
        self.parsed.is_none() && self.delimiter != b','
    }

    /// The attribute columns' names (CSV columns or GeoJSON properties).
    pub fn attribute_names(&self) -> Vec<String> {
        self.attribute_names.clone()
    }

    fn pass(&self, with_attributes: bool, f: &mut dyn FnMut(Placement) -> Result<()>) -> Result<Report> {
        if let Some(set) = &self.parsed {
            for p in &set.rows {
                f(p.clone())?;
            }
            return Ok(set.report.clone());
        }
        let file = std::fs::File::open(&self.path)
            .with_context(|| format!("cannot open placements {}", self.path.display()))?;
        let mut report = Report::default();
        let reader = std::io::BufReader::with_capacity(1 << 20, file);
        stream_csv(reader, self.delimiter, &self.options, with_attributes, &mut report, f)
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
            csv::ErrorKind::Utf8 { .. } => "not UTF-8",
            csv::ErrorKind::UnequalLengths { .. } => "wrong number of fields",
            csv::ErrorKind::Io(_) => "I/O error",
            _ => "malformed record",
        }
    }
}

/// Validates one row: finite coordinates in range; height and z sane or dropped.
pub(super) fn accept(mut p: Placement, kind: CoordKind, report: &mut Report) -> Option<Placement> {
    if !p.x.is_finite() || !p.y.is_finite() {
        report.skip("non-finite coordinates (NaN/Inf)", p.row);
        return None;
    }
    if kind == CoordKind::LonLat && (p.x.abs() > 180.0 || p.y.abs() > 90.0) {
        if p.y.abs() <= 180.0 && p.x.abs() <= 90.0 {
            // Valid the other way round: evidence of swapped columns.
            report.swappable += 1;
        }
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
    // The largest known stems are under 15 m across; crowns under 100 m.
    p.dbh_cm = p.dbh_cm.filter(|d| d.is_finite() && *d > 0.0 && *d < 1500.0);
    p.crown_m = p.crown_m.filter(|c| c.is_finite() && *c > 0.0 && *c < 100.0);
    Some(p)
}

mod geojson;
#[cfg(test)]
use geojson::geojson_crs;
pub use geojson::read_geojson;

#[cfg(test)]
mod tests;
