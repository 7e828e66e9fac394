//! The columns of an inventory: which header names mean what (a role each,
//! in the names foresters and GIS exports use), the DBH unit, and the
//! numbers as written (a decimal point or a decimal comma).

use anyhow::{bail, Context, Result};
use std::collections::BTreeMap;

use super::*;

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

pub(super) const LON: &[&str] = &["lon", "lng", "long", "longitude"];

pub(super) const LAT: &[&str] = &["lat", "latitude"];

pub(super) const X: &[&str] = &["x", "easting", "east", "e", "x_coord", "xcoord"];

pub(super) const Y: &[&str] = &["y", "northing", "north", "n", "y_coord", "ycoord"];

pub(super) const Z: &[&str] = &["z", "elevation", "elev", "altitude", "ground", "ground_z"];

pub(super) const HEIGHT: &[&str] = &[
    "height",
    "height_m",
    "h",
    "h_m",
    "tree_height",
    "treeheight",
    "total_height",
    "hoehe",
    "hoehe_m",
    "höhe",
    "höhe_m",
    "baumhöhe",
    "boomhoogte",
    "hoogte",
];

pub(super) const SPECIES: &[&str] = &[
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

pub(super) const DBH: &[&str] = &[
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
    "bhd_cm",
    "bhd_mm",
    "stammdurchmesser",
    "stamdiameter",
];

pub(super) const CROWN_DIAMETER: &[&str] = &[
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

pub(super) const CROWN_RADIUS: &[&str] = &["crown_radius", "crownradius", "canopy_radius", "kronenradius"];

pub(super) const YAW: &[&str] = &["yaw", "rotation", "heading", "azimuth"];

pub(super) const ID: &[&str] = &["id", "tree_id", "treeid", "objectid", "fid", "gid"];

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
