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
    /// Not standing at the scene's latest date (a census's dead or removed
    /// tree, one planted later): drawn only at a date ([`census`]).
    pub dated: bool,
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
    /// `--input-crs` names a geographic CRS (a GIS layer is read as lon/lat
    /// whatever its own CRS says).
    pub geographic_input: bool,
    /// The GeoPackage table to read (`--layer`; default: the only one, or
    /// the only one of points).
    pub layer: Option<String>,
    /// The file is a stand map whose polygons become trees (`--stands`).
    pub stands: Option<std::sync::Arc<crate::input::stands::StandOptions>>,
    /// The file is a canopy height model whose crowns become trees (`--chm`).
    pub chm: Option<std::sync::Arc<crate::input::chm::ChmOptions>>,
    /// The files are censuses of the same trees, or one inventory with
    /// planting and removal dates (`--census-date`, `--census-date-column`).
    pub census: Option<std::sync::Arc<census::CensusOptions>>,
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

// The names detected before column mapping keep their order (species, species_name,
// genus, taxon, baumart, soort, type, art), so existing files pick the same column.

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
    /// The EPSG code the file names (a GeoJSON's `crs` member, a `.prj`, a
    /// GeoPackage's or FlatGeobuf's CRS), if any.
    pub declared_epsg: Option<u32>,
    /// A CRS the file declares without an EPSG code (a `.prj` whose name is
    /// no EPSG name): its name and proj string.
    pub declared_proj4: Option<(String, String)>,
    /// What was detected, for the log (separator, encoding).
    pub notes: Vec<String>,
    attribute_names: Vec<String>,
    gis: Option<(crate::input::gis::Layer, gis::GisColumns)>,
    stands: Option<(crate::input::gis::Layer, crate::input::stands::StandFields)>,
    /// A stand map's stands, in the order every pass reads them.
    stand_plans: Vec<crate::input::stands::StandPlan>,
    /// The trees' timeline, for censuses (and planting and removal dates).
    pub timeline: Option<sylva::format::timeline::Timeline>,
    /// The timeline's attribute columns that hold values.
    pub timeline_filled: Vec<String>,
}

impl PlacementSource {
    /// Opens `path` (`.csv`, `.tsv`, `.txt`, `.geojson`, `.json`, `.shp`,
    /// `.gpkg`, `.fgb`) and reads its header.
    pub fn open(path: &Path, options: &ReadOptions) -> Result<Self> {
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_lowercase();
        let meta = std::fs::metadata(path).with_context(|| format!("cannot open placements {}", path.display()))?;
        if !meta.is_file() {
            bail!("placements {} is not a regular file", path.display());
        }
        if let Some(stand_options) = &options.stands {
            return Self::open_stands(path, options, stand_options);
        }
        if let Some(chm) = &options.chm {
            return Self::open_chm(path, options, chm);
        }
        if let Some(census) = &options.census {
            let merged = census::merge(options, census)?;
            return Ok(Self {
                path: path.to_path_buf(),
                delimiter: b',',
                options: options.clone(),
                kind: merged.set.kind,
                declared_epsg: merged.declared_epsg,
                declared_proj4: merged.declared_proj4,
                notes: merged.notes,
                attribute_names: merged.set.attribute_names.clone(),
                parsed: Some(merged.set),
                gis: None,
                stands: None,
                stand_plans: Vec::new(),
                timeline: Some(merged.timeline),
                timeline_filled: merged.filled,
            });
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
                    declared_proj4: None,
                    notes,
                    attribute_names: cols.attrs.iter().map(|(_, n)| n.clone()).collect(),
                    gis: None,
                    stands: None,
                    stand_plans: Vec::new(),
                    timeline: None,
                    timeline_filled: Vec::new(),
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
                    declared_proj4: None,
                    notes: Vec::new(),
                    attribute_names,
                    gis: None,
                    stands: None,
                    stand_plans: Vec::new(),
                    timeline: None,
                    timeline_filled: Vec::new(),
                })
            }
            "shp" | "gpkg" | "fgb" => {
                use crate::input::gis::{DeclaredCrs, Layer, Wanted};
                let mut layer = Layer::open(path, options.layer.as_deref(), Wanted::Points)
                    .with_context(|| format!("placements {}", path.display()))?;
                layer.text_encoding = match options.encoding {
                    Encoding::Auto => None,
                    Encoding::Utf8 => Some("UTF-8".into()),
                    Encoding::Latin1 => Some("1252".into()),
                };
                let context = || format!("placements {} ({})", path.display(), layer.format.name());
                gis::check_points(&layer).with_context(context)?;
                let (kind, kind_note) = gis::gis_kind(&layer, options).with_context(context)?;
                let cols = gis::gis_columns(&layer, options).with_context(context)?;
                let mut notes = layer.notes.clone();
                notes.extend(kind_note);
                notes.push(format!("fields: {}", cols.describe()));
                let (declared_epsg, declared_proj4) = match &layer.crs {
                    Some(DeclaredCrs::Epsg(c)) => (Some(*c), None),
                    Some(DeclaredCrs::Proj4 { name, proj4 }) => (None, Some((name.clone(), proj4.clone()))),
                    Some(DeclaredCrs::Unusable(_)) | None => (None, None),
                };
                Ok(Self {
                    path: path.to_path_buf(),
                    delimiter: b',',
                    options: options.clone(),
                    parsed: None,
                    kind,
                    declared_epsg,
                    declared_proj4,
                    notes,
                    attribute_names: cols.attrs.iter().map(|(_, n)| n.clone()).collect(),
                    gis: Some((layer, cols)),
                    stands: None,
                    stand_plans: Vec::new(),
                    timeline: None,
                    timeline_filled: Vec::new(),
                })
            }
            _ => bail!(
                "placements {}: unknown extension {ext:?}; use .csv, .geojson, .shp, .gpkg or .fgb",
                path.display()
            ),
        }
    }

    /// A canopy height model (`--chm`): its trees found once (tops, heights,
    /// crowns) and kept.
    fn open_chm(path: &Path, options: &ReadOptions, chm_options: &crate::input::chm::ChmOptions) -> Result<Self> {
        let mut chm = crate::input::dem::Dem::open(path).with_context(|| format!("CHM {}", path.display()))?;
        let mut ground_note = None;
        if chm.epsg.is_none() && !options.projected {
            bail!("CHM {}: its GeoKeys name no CRS: say which with --input-crs EPSG:xxxx", path.display());
        }
        if !chm_options.ground.is_empty() {
            // A surface model (--dsm): the CHM is it minus the ground.
            let dems = chm_options
                .ground
                .iter()
                .map(|p| {
                    Ok((p.clone(), crate::input::dem::Dem::open(p).with_context(|| format!("DEM {}", p.display()))?))
                })
                .collect::<Result<Vec<_>>>()?;
            let missing = crate::input::chm::subtract_ground(&mut chm, &dems)
                .with_context(|| format!("DSM {}", path.display()))?;
            ground_note = Some(format!(
                "DSM {} minus the --dem ground: a CHM{}",
                path.display(),
                if missing > 0 { format!(" ({missing} pixels without ground left out)") } else { String::new() }
            ));
        }
        // A leaf-type raster (Copernicus HRL Dominant Leaf Type codes: 1
        // broadleaved, 2 coniferous) gives the trees outside every stand theirs.
        let leaf_type = match &chm_options.leaf_type {
            Some(lt) => {
                let raster =
                    crate::input::dem::Dem::open(lt).with_context(|| format!("leaf-type raster {}", lt.display()))?;
                if let (Some(a), Some(b)) = (raster.epsg, chm.epsg) {
                    if a != b {
                        bail!(
                            "leaf-type raster {} is in EPSG:{a}, the CHM in EPSG:{b}: give both in one CRS",
                            lt.display()
                        );
                    }
                }
                Some(raster)
            }
            None => None,
        };
        let started = std::time::Instant::now();
        let trees =
            crate::input::chm::find_trees(&chm, chm_options).with_context(|| format!("CHM {}", path.display()))?;
        let mut report = Report::default();
        let mut rows = Vec::with_capacity(trees.len());
        let stands = match &chm_options.species_stands {
            Some((stand_path, stand_options)) => Some(Self::species_stands(stand_path, stand_options, chm.epsg)?),
            None => None,
        };
        let points = match &chm_options.species_points {
            Some(p) => Some(Self::species_points(p, chm.epsg)?),
            None => None,
        };
        let mut by_point = 0u64;
        let mut by_leaf = [0u64; 2];
        let (mut in_stands, mut outside) = (0u64, 0u64);
        for (i, t) in trees.iter().enumerate() {
            report.rows += 1;
            // The stand a tree stands in gives its species, drawn by the
            // stand's shares from the tree's position (the same on every bake).
            let stand = stands.as_ref().and_then(|s| {
                s.iter().find(|(_, polygons, lo, hi)| {
                    (lo[0]..=hi[0]).contains(&t.xy[0])
                        && (lo[1]..=hi[1]).contains(&t.xy[1])
                        && crate::input::stands::inside(polygons, t.xy[0], t.xy[1])
                })
            });
            // A point of a stem map within the crown names it, before all else.
            let from_point = points.as_ref().and_then(|g| g.nearest(t.xy, 0.5 * f64::from(t.crown_m) + 1.0));
            by_point += u64::from(from_point.is_some());
            let species = match stand {
                _ if from_point.is_some() => from_point.unwrap_or_default().to_string(),
                Some((stand, _, _, _)) => {
                    in_stands += 1;
                    let u = (crate::rng::hash64(t.xy[0].to_bits() ^ t.xy[1].to_bits().rotate_left(17)) >> 11) as f64
                        / (1u64 << 53) as f64;
                    let mut acc = 0.0;
                    stand
                        .mix
                        .iter()
                        .find(|(_, share)| {
                            acc += share;
                            u < acc
                        })
                        .or(stand.mix.last())
                        .map_or(chm_options.species.clone(), |(name, _)| name.clone())
                }
                None => {
                    outside += 1;
                    // (The pixel the top falls in: codes are not interpolated.)
                    let code = leaf_type.as_ref().map(|r| {
                        let (c, row) = r.pixel(t.xy[0], t.xy[1]);
                        r.at(c.round() as i64, row.round() as i64)
                    });
                    match code {
                        Some(1.0) => {
                            by_leaf[0] += 1;
                            "broadleaf".to_string()
                        }
                        Some(2.0) => {
                            by_leaf[1] += 1;
                            "conifer".to_string()
                        }
                        _ => chm_options.species.clone(),
                    }
                }
            };
            let p = Placement {
                x: t.xy[0],
                y: t.xy[1],
                z: None,
                height_m: Some(t.height_m),
                dbh_cm: None,
                crown_m: Some(t.crown_m),
                species: Some(species),
                yaw_deg: None,
                id: None,
                id_text: None,
                attrs: if stands.is_some() { vec![stand.map(|s| s.0.id.clone())] } else { Vec::new() },
                row: i as u64 + 1,
                dated: false,
            };
            if let Some(p) = accept(p, CoordKind::Projected, &mut report) {
                rows.push(p);
            }
        }
        report.kept = rows.len() as u64;
        let s = chm.summary();
        let mut notes = vec![
            format!(
                "CHM {} × {} pixels of {:.2} m ({}), heights {}",
                chm.width,
                chm.height,
                chm.dx.abs(),
                chm.layout,
                s.range.map_or("none".into(), |(a, b)| format!("{a:.1}–{b:.1} m"))
            ),
            format!(
                "{} trees found (tops of at least {} m, window {} + {}·h m; crowns by watershed) in {:.1} s, {:?} unless \
                 said below; trees under the canopy are not seen",
                rows.len(),
                chm_options.min_height,
                chm_options.window_a,
                chm_options.window_b,
                started.elapsed().as_secs_f64(),
                chm_options.species
            ),
        ];
        notes.splice(0..0, ground_note);
        if let (Some(p), Some(g)) = (&chm_options.species_points, &points) {
            notes.push(format!(
                "species points {}: {} points; {by_point} trees named by the nearest within their crown (+1 m)",
                p.display(),
                g.len
            ));
        }
        if let Some(lt) = &chm_options.leaf_type {
            notes.push(format!(
                "leaf types from {}: {} broadleaved (code 1), {} coniferous (code 2), {} other ({:?})",
                lt.display(),
                by_leaf[0],
                by_leaf[1],
                outside - by_leaf[0] - by_leaf[1],
                chm_options.species
            ));
        }
        if stands.is_some() {
            notes.push(format!(
                "{in_stands} trees in stands (species drawn by each stand's shares), {outside} outside every stand ({})",
                if chm_options.leaf_type.is_some() { "by leaf type".to_string() } else { format!("{:?}", chm_options.species) }
            ));
        }
        let attribute_names = if stands.is_some() { vec!["stand".to_string()] } else { Vec::new() };
        Ok(Self {
            path: path.to_path_buf(),
            delimiter: b',',
            options: options.clone(),
            kind: CoordKind::Projected,
            declared_epsg: chm.epsg,
            declared_proj4: None,
            parsed: Some(PlacementSet {
                kind: CoordKind::Projected,
                rows,
                report,
                declared_epsg: chm.epsg,
                attribute_names: attribute_names.clone(),
            }),
            notes,
            attribute_names,
            gis: None,
            stands: None,
            stand_plans: Vec::new(),
            timeline: None,
            timeline_filled: Vec::new(),
        })
    }

    /// Points with a species (any placements file: a stem map, plot centres,
    /// a street-tree register) in a CHM's CRS, gridded by 10 m for the
    /// nearest-point lookup (`--chm-species-points`). Lon/lat points, or points
    /// in another declared CRS, are projected into the CHM's.
    fn species_points(path: &Path, chm_epsg: Option<u32>) -> Result<SpeciesPoints> {
        use crate::input::reproject::{Crs, Reprojector};
        let context = || format!("species points {} (the CHM's species)", path.display());
        let source = Self::open(path, &ReadOptions::default()).with_context(context)?;
        let to_chm = match (source.kind, source.declared_epsg, chm_epsg) {
            (CoordKind::LonLat, declared, Some(chm)) => {
                Some(Reprojector::new(Crs::from_epsg(declared.unwrap_or(4326))?, &Crs::from_epsg(chm)?)?)
            }
            (CoordKind::LonLat, _, None) => {
                bail!("species points {}: lon/lat, and the CHM names no CRS to project them into", path.display())
            }
            (CoordKind::Projected, Some(a), Some(b)) if a != b => {
                Some(Reprojector::new(Crs::from_epsg(a)?, &Crs::from_epsg(b)?)?)
            }
            _ => None,
        };
        let mut grid = SpeciesPoints::default();
        let mut unlabelled = 0u64;
        source
            .for_each(&mut |p| {
                let Some(label) = p.species.filter(|l| !l.trim().is_empty()) else {
                    unlabelled += 1;
                    return Ok(());
                };
                let (x, y) = match &to_chm {
                    Some(r) => match r.apply(p.x, p.y) {
                        Ok(xy) => xy,
                        Err(_) => return Ok(()),
                    },
                    None => (p.x, p.y),
                };
                grid.add([x, y], label);
                Ok(())
            })
            .with_context(context)?;
        if grid.len == 0 {
            bail!(
                "species points {}: no point with a species ({unlabelled} without; name the column with --column species=NAME \
                 on a placements file of its own)",
                path.display()
            );
        }
        Ok(grid)
    }

    /// The stands of a stand map in a CHM's CRS (`--chm` with `--stands`):
    /// each stand, its polygons and their box.
    #[allow(clippy::type_complexity)]
    fn species_stands(
        path: &Path,
        stand_options: &crate::input::stands::StandOptions,
        chm_epsg: Option<u32>,
    ) -> Result<Vec<(crate::input::stands::Stand, crate::input::gis::Polygons, [f64; 2], [f64; 2])>> {
        use crate::input::gis::{DeclaredCrs, Geometry, Layer, Wanted};
        let context = || format!("stands {} (the CHM's species)", path.display());
        let layer = Layer::open(path, None, Wanted::Polygons).with_context(context)?;
        match (&layer.crs, chm_epsg) {
            (Some(DeclaredCrs::Epsg(a)), Some(b)) if *a != b => {
                bail!("stands {}: in EPSG:{a}, the CHM in EPSG:{b}: give both in one CRS", path.display())
            }
            _ => {}
        }
        let fields = crate::input::stands::StandFields::find(&layer, stand_options).with_context(context)?;
        let mut out = Vec::new();
        layer
            .for_each(&mut |feature| {
                if let (Ok((stand, _)), Geometry::Polygons(p)) =
                    (crate::input::stands::read_stand(&feature, &fields, stand_options, false), &feature.geometry)
                {
                    let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
                    for q in p.iter().flatten().flatten() {
                        lo = [lo[0].min(q[0]), lo[1].min(q[1])];
                        hi = [hi[0].max(q[0]), hi[1].max(q[1])];
                    }
                    out.push((stand, p.clone(), lo, hi));
                }
                Ok(())
            })
            .with_context(context)?;
        Ok(out)
    }

    /// A stand map (`--stands`): its polygons and fields, and a report of
    /// what each stand will make (read now, without making a tree).
    fn open_stands(
        path: &Path,
        options: &ReadOptions,
        stand_options: &crate::input::stands::StandOptions,
    ) -> Result<Self> {
        use crate::input::gis::{Layer, Wanted};
        use crate::input::stands::{read_stand, StandFields};
        let context = || format!("stands {}", path.display());
        let layer = Layer::open(path, options.layer.as_deref(), Wanted::Polygons).with_context(context)?;
        let given = if options.projected { Some(false) } else { options.geographic_input.then_some(true) };
        let (lon_lat, kind_note) = layer.lon_lat(given).with_context(context)?;
        let fields = StandFields::find(&layer, stand_options).with_context(context)?;
        let mut notes = layer.notes.clone();
        notes.extend(kind_note);
        notes.push(format!("stand fields: {}", fields.describe(&layer)));
        let (mut stands, mut trees, mut area) = (0u64, 0f64, 0f64);
        let mut skipped: BTreeMap<String, (u64, Vec<u64>)> = BTreeMap::new();
        let mut assumed: BTreeMap<String, u64> = BTreeMap::new();
        let mut ids: std::collections::HashSet<String> = std::collections::HashSet::new();
        let mut shared_ids = 0u64;
        let mut plans: Vec<crate::input::stands::StandPlan> = Vec::new();
        let mut next_row = 0u64;
        layer
            .for_each(&mut |feature| {
                match read_stand(&feature, &fields, stand_options, lon_lat) {
                    Ok((stand, _)) => {
                        if let crate::input::gis::Geometry::Polygons(p) = &feature.geometry {
                            let plan = crate::input::stands::StandPlan::new(&stand, p, next_row);
                            next_row += plan.cap;
                            plans.push(plan);
                        }
                        stands += 1;
                        shared_ids += u64::from(!ids.insert(stand.id.clone()));
                        let n = stand.stems_ha * stand.area_m2 / 1e4;
                        trees += n;
                        area += stand.area_m2;
                        if stands <= 12 {
                            let mix: Vec<String> =
                                stand.mix.iter().map(|(s, p)| format!("{s} {:.0} %", p * 100.0)).collect();
                            notes.push(format!(
                                "stand {}: {:.2} ha, {:.0} stems/ha → {n:.0} trees ({}), {}{}",
                                stand.id,
                                stand.area_m2 / 1e4,
                                stand.stems_ha,
                                mix.join(", "),
                                format!("{:?}", stand.pattern).to_lowercase(),
                                if stand.assumed.is_empty() {
                                    String::new()
                                } else {
                                    let words: Vec<&str> = stand.assumed.iter().map(|a| a.1.as_str()).collect();
                                    format!("; assumed: {}", words.join("; "))
                                }
                            ));
                        }
                        for (kind, _) in stand.assumed {
                            *assumed.entry(kind.to_string()).or_default() += 1;
                        }
                    }
                    Err(reason) => {
                        let e = skipped.entry(reason).or_default();
                        e.0 += 1;
                        if e.1.len() < 5 {
                            e.1.push(feature.index);
                        }
                    }
                }
                Ok(())
            })
            .with_context(context)?;
        if stands > 12 {
            notes.push(format!("… and {} more stands", stands - 12));
        }
        notes.push(format!(
            "{stands} stands, {:.1} ha: about {trees:.0} trees to make{}",
            area / 1e4,
            if skipped.is_empty() {
                String::new()
            } else {
                format!("; {} stands make none", skipped.values().map(|s| s.0).sum::<u64>())
            }
        ));
        for (reason, (n, which)) in &skipped {
            notes.push(format!("{n} stands make no trees: {reason} (e.g. features {which:?})"));
        }
        if shared_ids > 0 {
            notes.push(format!(
                "{shared_ids} stands share their id with an earlier one: their trees' `stand` attribute does not tell them \
                 apart (name a unique field with --stand-column id=FIELD)"
            ));
        }
        for (kind, n) in &assumed {
            notes.push(format!("{n} stands assumed: {kind}"));
        }
        if stands == 0 {
            bail!("stands {}: no stand makes trees ({})", path.display(), notes.join("; "));
        }
        Ok(Self {
            path: path.to_path_buf(),
            delimiter: b',',
            options: options.clone(),
            parsed: None,
            kind: if lon_lat { CoordKind::LonLat } else { CoordKind::Projected },
            declared_epsg: match &layer.crs {
                Some(crate::input::gis::DeclaredCrs::Epsg(c)) => Some(*c),
                _ => None,
            },
            declared_proj4: match &layer.crs {
                Some(crate::input::gis::DeclaredCrs::Proj4 { name, proj4 }) => Some((name.clone(), proj4.clone())),
                _ => None,
            },
            notes,
            // Each tree's stand, unless --attributes leaves it out (or --no-attributes).
            attribute_names: match &options.attributes {
                Some(kept) if !kept.iter().any(|a| a.eq_ignore_ascii_case("stand")) => Vec::new(),
                _ => vec!["stand".into()],
            },
            gis: None,
            stands: Some((layer, fields)),
            stand_plans: plans,
            timeline: None,
            timeline_filled: Vec::new(),
        })
    }

    /// One pass over the usable rows, in file order; returns what was read and skipped.
    pub fn for_each(&self, f: &mut dyn FnMut(Placement) -> Result<()>) -> Result<Report> {
        self.pass(false, None, f)
    }

    /// [`Self::for_each`] with each row's attribute columns ([`Placement::attrs`]).
    pub fn for_each_with_attributes(&self, f: &mut dyn FnMut(Placement) -> Result<()>) -> Result<Report> {
        self.pass(true, None, f)
    }

    /// [`Self::for_each`], growing only the stands of a stand map that `keep`
    /// keeps (a shard's); any other file gives every row.
    pub fn for_each_in(
        &self,
        keep: &dyn Fn(&crate::input::stands::StandPlan) -> bool,
        f: &mut dyn FnMut(Placement) -> Result<()>,
    ) -> Result<Report> {
        self.pass(false, Some(keep), f)
    }

    /// A stand map's stands (empty for any other file), in the order passes read them.
    pub fn stand_plans(&self) -> &[crate::input::stands::StandPlan] {
        &self.stand_plans
    }

    /// A stand map's trees as the cheap passes see them, without growing one:
    /// per stand its share of `per_tree × expected stems` (the fraction carried
    /// to the next stand) or, if more, `per_m2 × area` (at most four a stem)
    /// points uniform over its polygons, each with the stand's height, DBH and
    /// a species drawn by its shares. Nothing for any other file. The report
    /// counts the points and why any were skipped.
    ///
    /// # Errors
    /// The layer cannot be read again, or `f` fails.
    pub fn for_each_preview(
        &self,
        per_tree: f64,
        per_m2: f64,
        f: &mut dyn FnMut(Placement) -> Result<()>,
    ) -> Result<Report> {
        let mut report = Report::default();
        let (Some((layer, fields)), Some(stand_options)) = (&self.stands, &self.options.stands) else {
            return Ok(report);
        };
        let lon_lat = self.kind == CoordKind::LonLat;
        let mut k = 0usize;
        // The stems' share carried from stand to stand, so a small stand is
        // in the sample as often as its stems make it (not rounded away).
        let mut carried = 0.0f64;
        let mut failed = None;
        layer.for_each(&mut |feature| {
            if crate::input::stands::read_stand(&feature, fields, stand_options, lon_lat).is_err() {
                return Ok(());
            }
            let (Some(plan), crate::input::gis::Geometry::Polygons(polygons)) =
                (self.stand_plans.get(k), &feature.geometry)
            else {
                return Ok(());
            };
            k += 1;
            let before = carried.floor();
            carried += per_tree * plan.expected;
            let by_trees = (carried.floor() - before) as u64;
            // Points spread by area (the cells a stand covers) need be no more
            // than its stems (a stand covers no more cells than it has trees).
            let by_area = if per_m2 > 0.0 {
                (per_m2 * plan.area_m2).ceil().min(4.0 * plan.expected + 16.0).max(1.0) as u64
            } else {
                0
            };
            plan.preview(polygons, by_trees.max(by_area), &mut |xy, species| {
                if failed.is_some() {
                    return;
                }
                let p = Placement {
                    x: xy[0],
                    y: xy[1],
                    z: None,
                    height_m: plan.height_m,
                    dbh_cm: plan.dbh_cm,
                    crown_m: None,
                    species: Some(plan.mix[species].0.clone()),
                    yaw_deg: None,
                    id: None,
                    id_text: None,
                    attrs: Vec::new(),
                    row: plan.first_row + 1,
                    dated: false,
                };
                report.rows += 1;
                if let Some(p) = accept(p, self.kind, &mut report) {
                    report.kept += 1;
                    if let Err(e) = f(p) {
                        failed = Some(e);
                    }
                }
            });
            failed.take().map_or(Ok(()), Err)
        })?;
        Ok(report)
    }

    /// Whether numbers may have decimal commas (a CSV separated by `;` or tabs).
    pub fn decimal_comma(&self) -> bool {
        self.parsed.is_none() && self.delimiter != b','
    }

    /// The attribute columns' names (CSV columns or GeoJSON properties).
    pub fn attribute_names(&self) -> Vec<String> {
        self.attribute_names.clone()
    }

    fn pass(
        &self,
        with_attributes: bool,
        keep: Option<&dyn Fn(&crate::input::stands::StandPlan) -> bool>,
        f: &mut dyn FnMut(Placement) -> Result<()>,
    ) -> Result<Report> {
        if let Some(set) = &self.parsed {
            for p in &set.rows {
                f(p.clone())?;
            }
            return Ok(set.report.clone());
        }
        if let (Some((layer, fields)), Some(stand_options)) = (&self.stands, &self.options.stands) {
            use crate::input::stands::{grow_stand, read_stand};
            let mut report = Report::default();
            let lon_lat = self.kind == CoordKind::LonLat;
            let mut k = 0usize;
            layer.for_each(&mut |feature| {
                let Ok((stand, metric)) = read_stand(&feature, fields, stand_options, lon_lat) else {
                    return Ok(()); // said when opened
                };
                // (Plans were made from the same features in the same order.)
                let Some(plan) = self.stand_plans.get(k) else { return Ok(()) };
                k += 1;
                if keep.is_some_and(|keep| !keep(plan)) {
                    return Ok(());
                }
                let lon_lat_polygons = match (&feature.geometry, lon_lat) {
                    (crate::input::gis::Geometry::Polygons(p), true) => Some(&p[..]),
                    _ => None,
                };
                let stems = grow_stand(&stand, &metric, lon_lat_polygons, stand_options);
                for (j, stem) in stems.into_iter().take(plan.cap as usize).enumerate() {
                    report.rows += 1;
                    let p = Placement {
                        x: stem.xy[0],
                        y: stem.xy[1],
                        z: None,
                        height_m: stem.height_m,
                        dbh_cm: stem.dbh_cm,
                        crown_m: None,
                        species: Some(stand.mix[stem.species].0.clone()),
                        yaw_deg: None,
                        id: None,
                        id_text: None,
                        attrs: if with_attributes { vec![Some(stand.id.clone())] } else { Vec::new() },
                        row: plan.first_row + 1 + j as u64,
                        dated: false,
                    };
                    if let Some(p) = accept(p, self.kind, &mut report) {
                        report.kept += 1;
                        f(p)?;
                    }
                }
                Ok(())
            })?;
            return Ok(report);
        }
        if let Some((layer, cols)) = &self.gis {
            let mut report = Report::default();
            layer.for_each(&mut |feature| {
                gis::gis_placements(&feature, cols, self.kind, &self.options, with_attributes, &mut report, f)
            })?;
            return Ok(report);
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

/// A point and its species label.
type LabelledPoint = ([f64; 2], String);

/// Points with a species gridded by 10 m cells (`--chm-species-points`).
#[derive(Default)]
struct SpeciesPoints {
    cells: std::collections::HashMap<(i64, i64), Vec<LabelledPoint>>,
    len: u64,
}

impl SpeciesPoints {
    const CELL_M: f64 = 10.0;

    fn add(&mut self, xy: [f64; 2], label: String) {
        let key = ((xy[0] / Self::CELL_M).floor() as i64, (xy[1] / Self::CELL_M).floor() as i64);
        self.cells.entry(key).or_default().push((xy, label));
        self.len += 1;
    }

    /// The label of the nearest point within `reach` metres of `xy`, if any.
    fn nearest(&self, xy: [f64; 2], reach: f64) -> Option<&str> {
        let reach = reach.clamp(0.0, 50.0);
        let (cx, cy) = ((xy[0] / Self::CELL_M).floor() as i64, (xy[1] / Self::CELL_M).floor() as i64);
        let k = (reach / Self::CELL_M).ceil() as i64;
        let mut best: Option<(f64, &str)> = None;
        for j in cy - k..=cy + k {
            for i in cx - k..=cx + k {
                for (p, label) in self.cells.get(&(i, j)).into_iter().flatten() {
                    let d = (p[0] - xy[0]).hypot(p[1] - xy[1]);
                    if d <= reach && best.is_none_or(|(b, _)| d < b) {
                        best = Some((d, label));
                    }
                }
            }
        }
        best.map(|(_, l)| l)
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

pub mod census;
mod columns;
mod delimited;

pub use crate::input::text::{detect_delimiter, parse_decimal_comma, parse_f64};
pub use columns::*;
pub use delimited::*;

mod geojson;
mod gis;
pub use crate::input::gis::geojson_crs;
pub use geojson::read_geojson;

#[cfg(test)]
mod tests;
