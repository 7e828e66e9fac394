//! Stand polygons → trees (issue 45): a forest district's stand map (species
//! shares, stems/ha or basal area, mean or top height, mean DBH, a pattern)
//! becomes one tree per stem, made again identically on every pass (seeded
//! by the stand's id), so a region of 10^8 trees streams through the bake in
//! the memory of one stand.
//!
//! - **Where stems stand.** Managed stands (`regular`, the default): simple
//!   sequential inhibition (Diggle 2003, *Statistical Analysis of Spatial
//!   Point Patterns*: uniform candidates, each refused within a hard-core
//!   distance of a stem already placed) with the distance 0.7 of the mean
//!   spacing `1/√λ` — a packing fraction of 0.38, under the process's jamming
//!   limit (0.547), so crowns overlap only as much as the density makes them.
//!   Natural regeneration (`clustered`): a Thomas process (Thomas 1949; a
//!   Neyman–Scott process: parents uniform, six stems a parent on average,
//!   offspring displaced by a Gaussian of σ = 0.2 of the parents' spacing),
//!   with a hard core of 0.25 of the mean spacing so stems do not stand in
//!   one another; each cluster one species (mixtures in groups). `random`:
//!   uniform (a binomial process).
//! - **Species**: shares by stems, counts by largest remainder (exact), the
//!   trees in random order (regular, random) or by cluster (clustered).
//! - **DBH**: Weibull with the stand's quadratic mean DBH `dg` (the stem of
//!   mean basal area: `b = dg / √Γ(1 + 2/c)`), shape `c` 3.6 by default — the
//!   unimodal distributions of even-aged stands —
//!   clipped to 1 cm (or 0.3 of a smaller mean) … (3 + 3/c)× the mean.
//! - **Heights**: each stem's along its genus's height curve
//!   (docs/ALLOMETRY.md) flattened (to the power 0.6: within a stand heights
//!   vary less than across a region's trees), scaled so the mean of the
//!   stand's stems is its mean height (or the mean of its 100 tallest a
//!   hectare its top height);
//!   without a DBH ±8 % about the mean; without a height the bake's DBH
//!   allometry gives it; without both, the default height.

use std::collections::HashMap;
use std::sync::Arc;

use anyhow::{bail, Result};

use super::allometry::Allometry;
use super::gis::{ring_holds, Feature, Geometry, Layer, Polygons, Value};
use crate::rng::{hash64, Rng};

/// How a stand's stems are spread.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Pattern {
    /// Inhibition: evenly spaced, as planted and thinned.
    #[default]
    Regular,
    /// Clustered: groups, as natural regeneration.
    Clustered,
    /// Uniform at random.
    Random,
}

impl Pattern {
    fn parse(text: &str) -> Option<Self> {
        let t = text.trim().to_lowercase();
        match t.as_str() {
            "regular" | "managed" | "planted" | "plantation" | "inhibition" | "even" | "regelmäßig"
            | "regelmaessig" => Some(Pattern::Regular),
            "clustered" | "cluster" | "natural" | "regeneration" | "group" | "groups" | "geklumpt" | "gruppen" => {
                Some(Pattern::Clustered)
            }
            "random" | "poisson" | "uniform" | "zufällig" => Some(Pattern::Random),
            _ => None,
        }
    }

    fn name(self) -> &'static str {
        match self {
            Pattern::Regular => "regular",
            Pattern::Clustered => "clustered",
            Pattern::Random => "random",
        }
    }
}

/// What a stand field holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum StandRole {
    /// The stand's id (names its trees' `stand` attribute, seeds its stems).
    Id,
    /// Species: one name, or shares (`Picea abies:60;Fagus sylvatica:40`).
    Species,
    /// Stems per hectare.
    StemsHa,
    /// Basal area, m² per hectare (stems from it and the mean DBH).
    BasalArea,
    /// Mean height, m.
    Height,
    /// Top (dominant) height, m: the mean of the 100 largest stems a hectare.
    TopHeight,
    /// Mean (quadratic) DBH, cm.
    Dbh,
    /// The Weibull shape of the DBH distribution.
    WeibullShape,
    /// Age, years (kept as an attribute).
    Age,
    /// The pattern: regular, clustered or random.
    Pattern,
}

impl StandRole {
    /// Every role, in the order they are reported.
    pub const ALL: [StandRole; 10] = [
        StandRole::Id,
        StandRole::Species,
        StandRole::StemsHa,
        StandRole::BasalArea,
        StandRole::Height,
        StandRole::TopHeight,
        StandRole::Dbh,
        StandRole::WeibullShape,
        StandRole::Age,
        StandRole::Pattern,
    ];

    /// The role's name in `--stand-column ROLE=NAME`.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            StandRole::Id => "id",
            StandRole::Species => "species",
            StandRole::StemsHa => "stems_ha",
            StandRole::BasalArea => "basal_area",
            StandRole::Height => "height",
            StandRole::TopHeight => "top_height",
            StandRole::Dbh => "dbh",
            StandRole::WeibullShape => "weibull_shape",
            StandRole::Age => "age",
            StandRole::Pattern => "pattern",
        }
    }

    /// Field names recognised for the role (case-insensitive), most specific first.
    #[must_use]
    pub fn aliases(self) -> &'static [&'static str] {
        match self {
            StandRole::Id => &["stand_id", "standid", "stand", "bestand", "abteilung", "abt", "afdeling", "id", "fid"],
            StandRole::Species => &[
                "species",
                "species_mix",
                "mix",
                "composition",
                "baumarten",
                "baumart",
                "soorten",
                "soort",
                "essences",
                "especies",
            ],
            StandRole::StemsHa => &[
                "stems_ha",
                "stems_per_ha",
                "stemsha",
                "n_ha",
                "nha",
                "tph",
                "trees_ha",
                "trees_per_ha",
                "density",
                "stammzahl",
                "stammzahl_ha",
                "stems",
            ],
            StandRole::BasalArea => &["basal_area", "basalarea", "ba_ha", "ba", "g_ha", "grundflaeche", "grundfläche"],
            StandRole::Height => &["mean_height", "height", "height_m", "hg", "hm", "h_mean", "mittelhoehe", "hoehe"],
            StandRole::TopHeight => &["top_height", "dominant_height", "h100", "hdom", "h_dom", "oberhoehe", "ho"],
            StandRole::Dbh => &["mean_dbh", "dbh", "dbh_cm", "dg", "qmd", "d_mean", "bhd", "bhd_cm"],
            StandRole::WeibullShape => &["weibull_shape", "weibull_c", "shape"],
            StandRole::Age => &["age", "alter", "leeftijd", "age_years", "stand_age"],
            StandRole::Pattern => &["pattern", "spatial_pattern", "structure"],
        }
    }

    /// Parses `ROLE=NAME` (`--stand-column`).
    ///
    /// # Errors
    /// An unknown role, or no `=`.
    pub fn parse_mapping(s: &str) -> Result<(StandRole, String), String> {
        let (role, name) =
            s.split_once('=').ok_or_else(|| format!("{s:?}: expected ROLE=FIELD, e.g. stems_ha=N_HA"))?;
        let role = role.trim().to_lowercase().replace('-', "_");
        match (StandRole::ALL.iter().find(|r| r.name() == role), name.trim()) {
            (Some(r), n) if !n.is_empty() => Ok((*r, n.to_string())),
            (Some(_), _) => Err(format!("{s:?}: the field name is empty")),
            (None, _) => Err(format!(
                "{s:?}: unknown role {role:?}; roles are {}",
                StandRole::ALL.map(StandRole::name).join(", ")
            )),
        }
    }
}

/// How stands become trees.
#[derive(Debug, Clone)]
pub struct StandOptions {
    /// Fields named by the user (`--stand-column ROLE=NAME`).
    pub columns: Vec<(StandRole, String)>,
    /// Stems a hectare where a stand says neither stems nor basal area.
    pub default_stems_ha: f64,
    /// The pattern where a stand names none.
    pub pattern: Pattern,
    /// The Weibull shape where a stand names none.
    pub weibull_shape: f64,
    /// Height curves per genus (heights along the stand's curve).
    pub allometry: Option<Arc<Allometry>>,
}

impl Default for StandOptions {
    fn default() -> Self {
        Self {
            columns: Vec::new(),
            default_stems_ha: 400.0,
            pattern: Pattern::Regular,
            weibull_shape: 3.6,
            allometry: None,
        }
    }
}

/// The densest stand made (stems a hectare): dense regeneration has ~20,000.
pub const MAX_STEMS_HA: f64 = 50_000.0;
/// The most stems one stand may make (split larger stands).
pub const MAX_STAND_TREES: u64 = 5_000_000;

/// The layer's fields by role.
#[derive(Debug, Clone, Default)]
pub struct StandFields {
    by_role: Vec<(StandRole, usize)>,
    /// `share_<species>` fields: the species and the field.
    share_fields: Vec<(String, usize)>,
}

impl StandFields {
    /// Finds the roles' fields: `--stand-column` first, then the aliases.
    ///
    /// # Errors
    /// A `--stand-column` naming a field the layer lacks.
    pub fn find(layer: &Layer, options: &StandOptions) -> Result<Self> {
        let mut by_role: Vec<(StandRole, usize)> = Vec::new();
        for (role, name) in &options.columns {
            let Some(i) = layer.field(name) else {
                bail!(
                    "--stand-column {}={name}: the layer has no field {name:?}; its fields are {:?}",
                    role.name(),
                    layer.fields
                );
            };
            by_role.push((*role, i));
        }
        for role in StandRole::ALL {
            if by_role.iter().any(|(r, _)| *r == role) {
                continue;
            }
            let free =
                role.aliases().iter().find_map(|a| layer.field(a).filter(|i| !by_role.iter().any(|(_, c)| c == i)));
            if let Some(i) = free {
                by_role.push((role, i));
            }
        }
        let share_fields = layer
            .fields
            .iter()
            .enumerate()
            .filter_map(|(i, f)| {
                let l = f.to_lowercase();
                ["share_", "pct_", "anteil_", "aandeel_"]
                    .iter()
                    .find_map(|p| l.strip_prefix(p))
                    .map(|_| (f[f.find('_').map_or(0, |u| u + 1)..].replace('_', " "), i))
            })
            .collect();
        Ok(Self { by_role, share_fields })
    }

    fn get<'a>(&self, f: &'a Feature, role: StandRole) -> Option<&'a Value> {
        self.by_role.iter().find(|(r, _)| *r == role).and_then(|(_, i)| f.values.get(*i))
    }

    /// For the log: `species ← "BA_MIX", stems_ha ← "N_HA", …`.
    #[must_use]
    pub fn describe(&self, layer: &Layer) -> String {
        let mut parts: Vec<String> =
            self.by_role.iter().map(|(r, i)| format!("{} ← {:?}", r.name(), layer.fields[*i])).collect();
        if !self.share_fields.is_empty() {
            parts.push(format!("shares ← {} share_ fields", self.share_fields.len()));
        }
        parts.join(", ")
    }
}

/// One stand, read from its feature.
#[derive(Debug, Clone, PartialEq)]
pub struct Stand {
    /// Its id (the id field's text, else its feature number).
    pub id: String,
    /// Species and their shares of the stems (summing to 1).
    pub mix: Vec<(String, f64)>,
    /// Stems a hectare.
    pub stems_ha: f64,
    /// Mean height, m, and whether it is a top height.
    pub height: Option<(f64, bool)>,
    /// Mean DBH, cm.
    pub dbh_cm: Option<f64>,
    /// Weibull shape.
    pub shape: f64,
    /// The pattern.
    pub pattern: Pattern,
    /// What was assumed, for the report: the kind (counted over stands) and
    /// this stand's words.
    pub assumed: Vec<(&'static str, String)>,
    /// Area, m² (holes left out).
    pub area_m2: f64,
}

/// A species mix as written: `Picea abies:60;Fagus sylvatica:40`,
/// `Picea abies 60%, Fagus 40%`, `Pinus sylvestris` (all of it), shares
/// normalised; entries without a share split what the others leave.
#[must_use]
pub fn parse_mix(text: &str) -> Vec<(String, f64)> {
    let sep: &[char] = if text.contains(';') { &[';'] } else { &[',', '|', '+'] };
    let mut entries: Vec<(String, Option<f64>)> = Vec::new();
    for part in text.split(sep).map(str::trim).filter(|p| !p.is_empty()) {
        let part = part.trim_end_matches('%').trim();
        let (name, share) = match part.rfind([':', '=']) {
            Some(i) => {
                (part[..i].trim(), part[i + 1..].trim().trim_end_matches('%').trim().replace(',', ".").parse().ok())
            }
            None => match part.rsplit_once(' ') {
                Some((n, s)) if s.trim_end_matches('%').replace(',', ".").parse::<f64>().is_ok() => {
                    (n.trim(), s.trim_end_matches('%').replace(',', ".").parse().ok())
                }
                _ => (part, None),
            },
        };
        if !name.is_empty() {
            entries.push((name.to_string(), share.filter(|s: &f64| s.is_finite() && *s >= 0.0)));
        }
    }
    let given: f64 = entries.iter().filter_map(|e| e.1).sum();
    let scale = if given > 1.5 { 100.0 } else { 1.0 };
    let without = entries.iter().filter(|e| e.1.is_none()).count();
    let left = (1.0 - given / scale).max(0.0);
    let mut mix: Vec<(String, f64)> = entries
        .into_iter()
        .map(|(n, s)| (n, s.map_or(if without > 0 { left / without as f64 } else { 0.0 }, |s| s / scale)))
        .filter(|(_, s)| *s > 0.0)
        .collect();
    let total: f64 = mix.iter().map(|m| m.1).sum();
    if total > 0.0 {
        mix.iter_mut().for_each(|m| m.1 /= total);
    }
    mix
}

/// The area of polygons (rings after the first are holes), m² where the
/// coordinates are metres.
fn area(polygons: &[Vec<Vec<[f64; 2]>>]) -> f64 {
    let ring = |r: &Vec<[f64; 2]>| -> f64 {
        let n = r.len();
        (0..n).map(|i| r[i][0] * r[(i + 1) % n][1] - r[(i + 1) % n][0] * r[i][1]).sum::<f64>().abs() * 0.5
    };
    polygons.iter().map(|p| p.first().map_or(0.0, ring) - p.iter().skip(1).map(ring).sum::<f64>()).sum::<f64>().max(0.0)
}

/// Whether a point lies in the polygons: in an outer ring and in none of its holes.
#[must_use]
pub fn inside(polygons: &[Vec<Vec<[f64; 2]>>], x: f64, y: f64) -> bool {
    polygons.iter().any(|p| {
        p.first().is_some_and(|outer| ring_holds(outer, [x, y])) && !p.iter().skip(1).any(|h| ring_holds(h, [x, y]))
    })
}

/// Local metres about a lon/lat centre, and back (a stand is small enough
/// for an equirectangular frame).
#[derive(Clone, Copy)]
struct Frame {
    lon_lat: bool,
    x0: f64,
    y0: f64,
    kx: f64,
    ky: f64,
}

impl Frame {
    fn new(polygons: &[Vec<Vec<[f64; 2]>>], lon_lat: bool) -> Self {
        let first = polygons.iter().flatten().flatten().next().copied().unwrap_or([0.0, 0.0]);
        if lon_lat {
            Self { lon_lat, x0: first[0], y0: first[1], kx: 111_320.0 * first[1].to_radians().cos(), ky: 110_574.0 }
        } else {
            Self { lon_lat, x0: 0.0, y0: 0.0, kx: 1.0, ky: 1.0 }
        }
    }
    fn to_m(self, p: [f64; 2]) -> [f64; 2] {
        if self.lon_lat {
            [(p[0] - self.x0) * self.kx, (p[1] - self.y0) * self.ky]
        } else {
            p
        }
    }
    fn back(self, p: [f64; 2]) -> [f64; 2] {
        if self.lon_lat {
            [self.x0 + p[0] / self.kx, self.y0 + p[1] / self.ky]
        } else {
            p
        }
    }
}

/// Γ(x) for x in [1, 2] and beyond (Lanczos, g = 7).
fn gamma(x: f64) -> f64 {
    const G: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    let x = x - 1.0;
    let t = x + 7.5;
    let s: f64 = G[0] + (1..9).map(|i| G[i] / (x + i as f64)).sum::<f64>();
    (2.0 * std::f64::consts::PI).sqrt() * t.powf(x + 0.5) * (-t).exp() * s
}

/// Reads a stand from its feature: its mix, density, sizes and what was
/// assumed; `Err` is why it makes no trees.
///
/// # Errors
/// No polygon, no species, a density past [`MAX_STEMS_HA`], too many trees.
pub fn read_stand(
    feature: &Feature,
    fields: &StandFields,
    options: &StandOptions,
    lon_lat: bool,
) -> Result<(Stand, Polygons), String> {
    let Geometry::Polygons(polygons) = &feature.geometry else {
        return Err(match &feature.geometry {
            Geometry::Empty => "no geometry".into(),
            Geometry::Points(_) => "a point, not a polygon".into(),
            Geometry::Other(o) => format!("a {o}, not a polygon"),
            Geometry::Polygons(_) => unreachable!(),
        });
    };
    if polygons.iter().flatten().flatten().any(|p| !p[0].is_finite() || !p[1].is_finite()) {
        return Err("non-finite coordinates".into());
    }
    if polygons.iter().flatten().flatten().any(|p| p[0].abs() > 1e8 || p[1].abs() > 1e8) {
        return Err("coordinates beyond ±100 000 km".into());
    }
    let frame = Frame::new(polygons, lon_lat);
    let metric: Vec<Vec<Vec<[f64; 2]>>> =
        polygons.iter().map(|p| p.iter().map(|r| r.iter().map(|q| frame.to_m(*q)).collect()).collect()).collect();
    let area_m2 = area(&metric);
    if area_m2.is_nan() || area_m2 <= 0.0 {
        return Err("a polygon of no area (degenerate)".into());
    }
    let num = |role| fields.get(feature, role).and_then(Value::as_f64).filter(|v| v.is_finite() && *v > 0.0);
    let text = |role| fields.get(feature, role).and_then(Value::to_text);
    let id = text(StandRole::Id).unwrap_or_else(|| feature.index.to_string());
    let mut assumed = Vec::new();
    let mut mix = text(StandRole::Species).map(|s| parse_mix(&s)).unwrap_or_default();
    if mix.is_empty() && !fields.share_fields.is_empty() {
        let shares: Vec<(String, f64)> = fields
            .share_fields
            .iter()
            .filter_map(|(name, i)| {
                feature
                    .values
                    .get(*i)
                    .and_then(Value::as_f64)
                    .filter(|s| s.is_finite() && *s > 0.0)
                    .map(|s| (name.clone(), s))
            })
            .collect();
        let total: f64 = shares.iter().map(|s| s.1).sum();
        if total.is_finite() && total > 0.0 {
            mix = shares.into_iter().map(|(n, s)| (n, s / total)).collect();
        }
    }
    if mix.is_empty() {
        return Err("no species (name a field with --stand-column species=FIELD)".into());
    }
    let dbh_cm = num(StandRole::Dbh).filter(|d| *d < 500.0);
    let zero = |role| fields.get(feature, role).and_then(Value::as_f64).is_some_and(|v| v == 0.0);
    if zero(StandRole::StemsHa) || (num(StandRole::StemsHa).is_none() && zero(StandRole::BasalArea)) {
        return Err("unstocked (0 stems/ha or no basal area)".into());
    }
    let stems_ha = match (num(StandRole::StemsHa), num(StandRole::BasalArea), dbh_cm) {
        (Some(n), _, _) => n,
        (None, Some(ba), Some(d)) => {
            assumed.push((
                "stems from basal area and mean DBH",
                format!("stems from basal area {ba} m²/ha at mean DBH {d} cm"),
            ));
            ba / (std::f64::consts::PI * (d / 200.0).powi(2))
        }
        _ => {
            assumed.push((
                "the default stems/ha (no stems/ha, or basal area with a DBH)",
                format!("{} stems/ha (no stems/ha, or basal area with a DBH)", options.default_stems_ha),
            ));
            options.default_stems_ha
        }
    };
    if stems_ha > MAX_STEMS_HA {
        return Err(format!("{stems_ha:.0} stems/ha is past {MAX_STEMS_HA:.0}"));
    }
    let expected = stems_ha * area_m2 / 1e4;
    if expected > MAX_STAND_TREES as f64 {
        return Err(format!("{expected:.0} trees in one stand, past {MAX_STAND_TREES}: split it"));
    }
    let height = match (num(StandRole::Height), num(StandRole::TopHeight)) {
        (Some(h), _) if h < 120.0 => Some((h, false)),
        (_, Some(h)) if h < 120.0 => Some((h, true)),
        _ => None,
    };
    if height.is_none() && dbh_cm.is_none() {
        assumed.push(("no height or DBH: the default height", "no height or DBH: the default height".into()));
    } else if height.is_none() {
        assumed.push(("heights from the DBH allometry", "heights from the DBH allometry".into()));
    } else if dbh_cm.is_none() {
        assumed.push(("no DBH: heights ±8 % about the stand's", "no DBH: heights ±8 % about the stand's".into()));
    }
    let shape = num(StandRole::WeibullShape).filter(|c| (0.5..20.0).contains(c)).unwrap_or(options.weibull_shape);
    let pattern = match text(StandRole::Pattern) {
        Some(p) => Pattern::parse(&p).unwrap_or_else(|| {
            assumed.push((
                "an unknown pattern: the default",
                format!("pattern {p:?} unknown: {}", options.pattern.name()),
            ));
            options.pattern
        }),
        None => options.pattern,
    };
    Ok((Stand { id, mix, stems_ha, height, dbh_cm, shape, pattern, assumed, area_m2 }, metric))
}

/// What a stand will make, known when the map is opened without making a
/// tree: the rows its stems take, its box, and what the bake's cheap passes
/// stand in for its trees with (the sample, the density, the ground's cover,
/// the per-tree attribute). A sharded bake grows only the stands whose box
/// touches one of its tiles; every pass numbers a stand's stems from
/// `first_row + 1`, so every shard and every pass agree on each tree's row.
#[derive(Debug, Clone)]
pub struct StandPlan {
    /// The row before the stand's first stem.
    pub first_row: u64,
    /// Most stems it makes (its expected count rounded up; a jammed pattern makes fewer).
    pub cap: u64,
    /// Its expected stems (stems/ha × area).
    pub expected: f64,
    /// Its polygons' box in the layer's coordinates: min x, min y, max x, max y.
    pub bbox: [f64; 4],
    /// Area, m².
    pub area_m2: f64,
    /// Its id (the `stand` attribute).
    pub id: String,
    /// Species and their shares of the stems.
    pub mix: Vec<(String, f64)>,
    /// Mean (or top) height, m, if the map gives one.
    pub height_m: Option<f32>,
    /// Quadratic mean DBH, cm, if the map gives one.
    pub dbh_cm: Option<f32>,
}

impl StandPlan {
    /// The plan of `stand` (read from polygons in the layer's coordinates),
    /// its rows after `first_row`.
    #[must_use]
    pub fn new(stand: &Stand, polygons: &[Vec<Vec<[f64; 2]>>], first_row: u64) -> Self {
        let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
        for p in polygons.iter().flatten().flatten() {
            lo = [lo[0].min(p[0]), lo[1].min(p[1])];
            hi = [hi[0].max(p[0]), hi[1].max(p[1])];
        }
        let expected = stand.stems_ha * stand.area_m2 / 1e4;
        Self {
            first_row,
            cap: expected.ceil() as u64,
            expected,
            bbox: [lo[0], lo[1], hi[0], hi[1]],
            area_m2: stand.area_m2,
            id: stand.id.clone(),
            mix: stand.mix.clone(),
            height_m: stand.height.map(|(h, _)| h as f32),
            dbh_cm: stand.dbh_cm.map(|d| d as f32),
        }
    }

    /// `count` points spread uniformly over the stand's polygons (in the
    /// layer's coordinates), each with a species drawn by the shares, given to
    /// `f` one at a time: the stand's trees as the cheap passes see them (the
    /// same on every call). A part is chosen by its area, the point drawn in
    /// that part's own box (parts kilometres apart waste no tries); tries are
    /// bounded, so a sliver gets fewer points, never an endless loop.
    pub fn preview(&self, polygons: &[Vec<Vec<[f64; 2]>>], count: u64, f: &mut dyn FnMut([f64; 2], usize)) {
        let mut rng = Rng::new(hash64(self.first_row ^ 0x5EED_0F57_A4D0_0001));
        let Some(parts) = Parts::new(polygons) else { return };
        let (mut made, mut tries) = (0u64, 0u64);
        let budget = count.saturating_mul(50).saturating_add(1_000);
        while made < count && tries < budget {
            tries += 1;
            let [x, y] = parts.uniform(&mut rng);
            if inside(polygons, x, y) {
                let mut pick = rng.f64();
                let species = self
                    .mix
                    .iter()
                    .position(|(_, share)| {
                        pick -= share;
                        pick <= 0.0
                    })
                    .unwrap_or(self.mix.len().saturating_sub(1));
                made += 1;
                f([x, y], species);
            }
        }
    }
}

/// A stand's parts (outer rings with their holes) for uniform candidates: a
/// part chosen by its area, a point in that part's own box (a multipart
/// stand's parts kilometres apart waste no tries).
struct Parts {
    boxes: Vec<([f64; 2], [f64; 2], f64)>,
    total: f64,
}

impl Parts {
    /// `None` for no part of any area.
    fn new(polygons: &[Vec<Vec<[f64; 2]>>]) -> Option<Self> {
        let boxes: Vec<([f64; 2], [f64; 2], f64)> = polygons
            .iter()
            .map(|p| {
                let (mut a, mut b) = ([f64::MAX; 2], [f64::MIN; 2]);
                for q in p.iter().flatten() {
                    a = [a[0].min(q[0]), a[1].min(q[1])];
                    b = [b[0].max(q[0]), b[1].max(q[1])];
                }
                (a, b, area(std::slice::from_ref(p)))
            })
            .collect();
        let total: f64 = boxes.iter().map(|p| p.2).sum();
        (!boxes.is_empty() && total > 0.0).then_some(Self { boxes, total })
    }

    /// A candidate: uniform in a part's box, the part chosen by its area.
    fn uniform(&self, rng: &mut Rng) -> [f64; 2] {
        let mut pick = rng.f64() * self.total;
        let (a, b, _) = self
            .boxes
            .iter()
            .find(|p| {
                pick -= p.2;
                pick <= 0.0
            })
            .unwrap_or(&self.boxes[self.boxes.len() - 1]);
        [a[0] + rng.f64() * (b[0] - a[0]), a[1] + rng.f64() * (b[1] - a[1])]
    }
}

/// One generated stem.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stem {
    /// x/lon, y/lat in the layer's coordinates.
    pub xy: [f64; 2],
    /// Index into the stand's mix.
    pub species: usize,
    /// DBH, cm.
    pub dbh_cm: Option<f32>,
    /// Height, m.
    pub height_m: Option<f32>,
}

/// A grid of placed stems for hard-core tests.
struct Grid {
    cell: f64,
    cells: HashMap<(i64, i64), Vec<[f64; 2]>>,
}

impl Grid {
    fn new(cell: f64) -> Self {
        Self { cell: cell.max(1e-3), cells: HashMap::new() }
    }
    fn key(&self, p: [f64; 2]) -> (i64, i64) {
        ((p[0] / self.cell).floor() as i64, (p[1] / self.cell).floor() as i64)
    }
    fn free(&self, p: [f64; 2], r: f64) -> bool {
        let (i, j) = self.key(p);
        let reach = (r / self.cell).ceil() as i64;
        for di in -reach..=reach {
            for dj in -reach..=reach {
                if let Some(v) = self.cells.get(&(i + di, j + dj)) {
                    if v.iter().any(|q| (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2) < r * r) {
                        return false;
                    }
                }
            }
        }
        true
    }
    fn add(&mut self, p: [f64; 2]) {
        let k = self.key(p);
        self.cells.entry(k).or_default().push(p);
    }
}

/// The stand's stems, the same on every call (seeded by its id).
#[must_use]
pub fn grow_stand(
    stand: &Stand,
    metric: &[Vec<Vec<[f64; 2]>>],
    lon_lat_polygons: Option<&[Vec<Vec<[f64; 2]>>]>,
    options: &StandOptions,
) -> Vec<Stem> {
    // Seeded by the id and the stand's area (stands that share an id — a
    // compartment's subcompartments — still differ).
    let key = stand.id.bytes().fold(0xCBF2_9CE4_8422_2325u64, |h, b| (h ^ u64::from(b)).wrapping_mul(0x100_0000_01B3));
    let mut rng = Rng::new(hash64(key ^ stand.area_m2.to_bits()));
    let expected = stand.stems_ha * stand.area_m2 / 1e4;
    let n = (expected.floor() + f64::from(u8::from(rng.f64() < expected.fract()))) as usize;
    if n == 0 {
        return Vec::new();
    }
    let frame =
        lon_lat_polygons.map_or(Frame { lon_lat: false, x0: 0.0, y0: 0.0, kx: 1.0, ky: 1.0 }, |p| Frame::new(p, true));
    let spacing = (stand.area_m2 / n as f64).sqrt();
    let Some(parts) = Parts::new(metric) else { return Vec::new() };
    let uniform = |rng: &mut Rng| parts.uniform(rng);
    let mut points: Vec<[f64; 2]> = Vec::with_capacity(n);
    let mut cluster_of: Vec<usize> = Vec::with_capacity(n);
    let budget = 60 * n + 10_000;
    match stand.pattern {
        Pattern::Regular | Pattern::Random => {
            let mut r = if stand.pattern == Pattern::Regular { 0.7 * spacing } else { 0.0 };
            let mut grid = Grid::new(r.max(spacing * 0.5));
            let (mut tries, mut since) = (0usize, 0usize);
            while points.len() < n && tries < budget {
                tries += 1;
                let p = uniform(&mut rng);
                if !inside(metric, p[0], p[1]) {
                    continue;
                }
                // Jammed (300 refusals inside the stand in a row): pack tighter.
                since += 1;
                if since > 300 {
                    r *= 0.9;
                    since = 0;
                }
                if r == 0.0 || grid.free(p, r) {
                    grid.add(p);
                    points.push(p);
                    cluster_of.push(0);
                    since = 0;
                }
            }
        }
        Pattern::Clustered => {
            let parents_n = (n / 6).max(1);
            let parent_spacing = (stand.area_m2 / parents_n as f64).sqrt();
            let sigma = 0.2 * parent_spacing;
            let mut parents: Vec<[f64; 2]> = Vec::with_capacity(parents_n);
            let mut tries = 0usize;
            while parents.len() < parents_n && tries < budget {
                tries += 1;
                let p = uniform(&mut rng);
                if inside(metric, p[0], p[1]) {
                    parents.push(p);
                }
            }
            if parents.is_empty() {
                return Vec::new();
            }
            let r = 0.25 * spacing;
            let mut grid = Grid::new(r.max(spacing * 0.25));
            let mut tries = 0usize;
            while points.len() < n && tries < budget {
                tries += 1;
                let k = rng.below(parents.len());
                // Box–Muller.
                let (u1, u2) = (rng.f64().max(1e-12), rng.f64());
                let g = (-2.0 * u1.ln()).sqrt();
                let a = std::f64::consts::TAU * u2;
                let p = [parents[k][0] + sigma * g * a.cos(), parents[k][1] + sigma * g * a.sin()];
                if inside(metric, p[0], p[1]) && grid.free(p, r) {
                    grid.add(p);
                    points.push(p);
                    cluster_of.push(k);
                }
            }
        }
    }
    // Species: exact counts by largest remainder, in random order (by cluster
    // where clustered: a cluster is a group of one species).
    let m = points.len();
    let mut counts: Vec<usize> = stand.mix.iter().map(|(_, s)| (s * m as f64).floor() as usize).collect();
    let mut order: Vec<usize> = (0..stand.mix.len()).collect();
    order.sort_by(|&a, &b| {
        let frac = |i: usize| stand.mix[i].1 * m as f64 - counts[i] as f64;
        frac(b).total_cmp(&frac(a))
    });
    let left = m.saturating_sub(counts.iter().sum::<usize>());
    for &i in order.iter().cycle().take(left) {
        counts[i] += 1;
    }
    let mut labels: Vec<usize> = counts.iter().enumerate().flat_map(|(i, &c)| std::iter::repeat_n(i, c)).collect();
    let mut idx: Vec<usize> = (0..m).collect();
    if stand.pattern == Pattern::Clustered {
        // Clusters in a random order, each cluster's stems together.
        let mut cluster_rank: Vec<u64> =
            (0..=cluster_of.iter().copied().max().unwrap_or(0)).map(|_| rng.next_u64()).collect();
        cluster_rank.shrink_to_fit();
        idx.sort_by_key(|&i| (cluster_rank[cluster_of[i]], i));
    } else {
        for i in (1..m).rev() {
            let j = rng.below(i + 1);
            idx.swap(i, j);
        }
    }
    // Assign labels along idx (a shuffle of labels is unnecessary: idx is random).
    let mut species = vec![0usize; m];
    for (k, &i) in idx.iter().enumerate() {
        species[i] = labels[k];
    }
    labels.clear();
    // Sizes.
    let curve = |label: &str, d: f64| -> f64 {
        match &options.allometry {
            Some(a) => a.for_label(label).height.metres(d).max(1.3),
            None => d.sqrt(),
        }
    };
    // The map's mean DBH is the quadratic mean (dg: the stem of mean basal
    // area, as stand tables give it and as basal area ÷ stems implies):
    // E[D²] = b² Γ(1 + 2/c).
    let scale_b = stand.dbh_cm.map(|d| d / gamma(1.0 + 2.0 / stand.shape).sqrt());
    // Clipped to 1 cm (saplings; or 0.3 of a smaller mean) … (3 + 3/c)× the
    // mean (a wide, reverse-J distribution keeps its long tail).
    let (d_lo, d_hi) = stand.dbh_cm.map_or((0.0, 0.0), |d| ((0.3 * d).min(1.0), (3.0 + 3.0 / stand.shape) * d));
    let mut stems: Vec<Stem> = points
        .iter()
        .zip(&species)
        .map(|(p, &s)| {
            let label = &stand.mix[s].0;
            let dbh = scale_b.map(|b| {
                let u = rng.f64().min(1.0 - 1e-12);
                (b * (-(1.0 - u).ln()).powf(1.0 / stand.shape)).clamp(d_lo, d_hi)
            });
            // Relative heights: along the genus's curve, flattened (exponent
            // 0.6: a stand's height curve is flatter than a region's across
            // sizes); without a DBH, ±8 % (a normal deviate, clipped).
            let relative = match (stand.height, dbh) {
                (Some(_), Some(d)) => Some(curve(label, d).powf(0.6)),
                (Some(_), None) => {
                    let (u1, u2) = (rng.f64().max(1e-12), rng.f64());
                    let g = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
                    Some(1.0 + 0.08 * g.clamp(-2.5, 2.5))
                }
                _ => None,
            };
            Stem { xy: frame.back(*p), species: s, dbh_cm: dbh.map(|d| d as f32), height_m: relative.map(|h| h as f32) }
        })
        .collect();
    // Scaled so the stand's height is what the map says: the mean of all its
    // stems (a mean height), or of its 100 tallest a hectare (a top height).
    if let Some((h, top)) = stand.height {
        let mut rel: Vec<f64> = stems.iter().filter_map(|t| t.height_m.map(f64::from)).collect();
        let k =
            if top { ((stand.area_m2 / 1e4 * 100.0).round() as usize).clamp(1, rel.len().max(1)) } else { rel.len() };
        if k > 0 && !rel.is_empty() {
            rel.sort_by(|a, b| b.total_cmp(a));
            let reference = rel[..k].iter().sum::<f64>() / k as f64;
            let scale = h / reference.max(1e-9);
            for t in &mut stems {
                t.height_m = t.height_m.map(|r| (f64::from(r) * scale) as f32);
            }
        }
    }
    stems
}

#[cfg(test)]
mod tests;
