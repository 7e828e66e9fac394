//! Tree height and crown diameter from the stem diameter (DBH, at 1.3 m) when
//! an inventory lacks them: per genus where a published equation exists, a
//! broadleaf or conifer default otherwise, every value overridable with
//! `--allometry FILE.csv`. The equations and their sources are listed in
//! `docs/ALLOMETRY.md`.
//!
//! - Height, Curtis–Arney as used by the USDA Forest Vegetation Simulator
//!   (Southern variant, `sn/htdbh.f`): `H_ft = 4.5 + p2·exp(−p3·D_in^p4)` for
//!   D ≥ 3 in; below, linear from 4.51 ft at D = 0 to the value at 3 in (FVS
//!   interpolates from D = 0.3 in; the difference is a few centimetres).
//! - Crown diameter, Bechtold (2003, 2004): `CW_ft = b0 + b1·D_in + b2·D_in²`
//!   for D ≥ 5 in; below, the value at 5 in × 0.509, 0.644, 0.767, 0.885 at
//!   1–4 in (Bragg 2001), interpolated.
//!
//! Both were fitted to stand-grown forest trees: open-grown street trees of the
//! same DBH are usually shorter with wider crowns (docs/ALLOMETRY.md).

use std::path::Path;

use anyhow::{bail, Context, Result};

use super::names::{self, SpeciesTable};

const FT: f64 = 0.3048;
const IN_CM: f64 = 2.54;

/// Curtis–Arney height parameters (feet from inches).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Height {
    /// Asymptote above breast height, ft.
    pub p2: f64,
    /// Rate.
    pub p3: f64,
    /// Shape (negative).
    pub p4: f64,
}

impl Height {
    /// Height in metres of a stem `dbh_cm` across.
    #[must_use]
    pub fn metres(&self, dbh_cm: f64) -> f64 {
        let at = |d_in: f64| 4.5 + self.p2 * (-self.p3 * d_in.powf(self.p4)).exp();
        let d_in = dbh_cm / IN_CM;
        let feet = if d_in >= 3.0 { at(d_in) } else { 4.51 + (at(3.0) - 4.51) * d_in.max(0.0) / 3.0 };
        feet * FT
    }
}

/// Bechtold crown-width parameters (feet from inches).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Crown {
    /// Intercept, ft.
    pub b0: f64,
    /// Slope, ft per inch.
    pub b1: f64,
    /// Curvature, ft per square inch.
    pub b2: f64,
}

impl Crown {
    /// Crown diameter in metres of a stem `dbh_cm` across.
    #[must_use]
    pub fn metres(&self, dbh_cm: f64) -> f64 {
        let at = |d_in: f64| (self.b0 + self.b1 * d_in + self.b2 * d_in * d_in).max(0.0);
        let d_in = dbh_cm / IN_CM;
        let feet = if d_in >= 5.0 {
            at(d_in)
        } else {
            // Bragg (2001): the share of the 5-inch value at 1, 2, 3, 4 inches.
            const SHARE: [f64; 5] = [0.509, 0.644, 0.767, 0.885, 1.0];
            let x = d_in.clamp(1.0, 5.0) - 1.0;
            let i = (x.floor() as usize).min(3);
            let share = SHARE[i] + (SHARE[i + 1] - SHARE[i]) * (x - i as f64);
            at(5.0) * share
        };
        feet * FT
    }
}

/// The equations of one genus (or a default).
#[derive(Debug, Clone, PartialEq)]
pub struct Equations {
    /// Genus (lowercase), or `broadleaf` / `conifer` for the defaults.
    pub genus: String,
    /// Height from DBH.
    pub height: Height,
    /// Crown diameter from DBH.
    pub crown: Crown,
    /// Where the values come from.
    pub source: String,
}

/// Whether `genus` (lowercase) is one of the conifers the table knows.
#[must_use]
pub fn is_conifer(genus: &str) -> bool {
    CONIFERS.contains(&genus)
}

/// Genera treated as conifers when they have no equations of their own.
const CONIFERS: &[&str] = &[
    "pinus",
    "picea",
    "abies",
    "larix",
    "pseudotsuga",
    "taxus",
    "thuja",
    "juniperus",
    "cedrus",
    "calocedrus",
    "sequoia",
    "sequoiadendron",
    "tsuga",
    "cupressus",
    "chamaecyparis",
    "metasequoia",
    "taxodium",
    "cryptomeria",
];

const FVS: &str = "height: USDA FVS Southern variant sn/htdbh.f";
const BECHTOLD: &str = "crown: Bechtold 2003 via FIAstemmap cw_coef";

/// The built-in table: (genus, height p2 p3 p4 with its species, crown b0 b1 b2 with its species).
#[allow(clippy::type_complexity)]
const BUILT_IN: &[(&str, Option<([f64; 3], &str)>, Option<([f64; 3], &str)>)] = &[
    ("acer", Some(([209.8555358, 2.95281334, -0.36787496], "sugar maple")), Some(([9.96, 1.05, 0.0], "sugar maple"))),
    (
        "aesculus",
        Some(([630.9504602, 4.51086779, -0.26826208], "buckeye")),
        Some(([7.34, 1.43, -0.01], "red maple, FIAstemmap's stand-in")),
    ),
    ("betula", Some(([170.5253403, 2.68833651, -0.40080716], "birch")), Some(([5.21, 1.33, 0.0], "paper birch"))),
    (
        "carpinus",
        Some(([628.0209077, 3.88103963, -0.15387585], "American hornbeam")),
        Some(([8.14, 1.85, 0.0], "American hornbeam")),
    ),
    ("castanea", None, Some(([3.57, 2.12, 0.0], "American elm, FIAstemmap's stand-in"))),
    (
        "fagus",
        Some(([526.1392688, 3.89232121, -0.22587084], "American beech")),
        Some(([11.53, 1.13, 0.0], "American beech")),
    ),
    ("fraxinus", Some(([251.4042514, 3.26919806, -0.35905996], "ash")), Some(([6.10, 1.32, 0.0], "white ash"))),
    (
        "gleditsia",
        Some(([778.9356784, 4.20756452, -0.18734197], "honeylocust")),
        Some(([7.74, 1.66, 0.0], "honeylocust")),
    ),
    ("platanus", Some(([644.3567687, 3.92045786, -0.21444786], "sycamore")), Some(([9.36, 1.26, 0.0], "sycamore"))),
    (
        "populus",
        Some(([190.9797059, 3.69278884, -0.52730469], "cottonwood")),
        Some(([4.63, 1.27, 0.0], "quaking aspen")),
    ),
    (
        "prunus",
        Some(([364.0247807, 3.55987361, -0.27263121], "black cherry")),
        Some(([8.72, 0.99, 0.0], "black cherry")),
    ),
    (
        "quercus",
        Some(([700.0636452, 4.10607389, -0.21392785], "northern red oak")),
        Some(([6.21, 1.40, 0.0], "northern red oak")),
    ),
    (
        "robinia",
        Some(([880.2844971, 4.59642097, -0.21824277], "black locust")),
        Some(([7.54, 0.85, 0.0], "black locust")),
    ),
    (
        "salix",
        Some(([408.2772475, 3.81808285, -0.27210505], "willow")),
        Some(([3.43, 1.40, 0.0], "cottonwood, FIAstemmap's stand-in")),
    ),
    ("tilia", Some(([293.5715132, 3.52261899, -0.35122247], "basswood")), Some(([7.19, 1.15, 0.0], "basswood"))),
    ("ulmus", Some(([1005.80672, 4.6473994, -0.20336143], "elm")), Some(([3.57, 2.12, 0.0], "American elm"))),
    (
        "picea",
        Some(([2163.946776, 6.26880851, -0.2161439], "spruce and fir")),
        Some(([4.51, 1.06, 0.0], "Norway spruce")),
    ),
    ("abies", Some(([2163.946776, 6.26880851, -0.2161439], "spruce and fir")), Some(([5.38, 0.89, 0.0], "balsam fir"))),
    (
        "pinus",
        Some(([2108.844224, 5.65948135, -0.18563136], "eastern white pine")),
        Some(([6.37, 0.89, 0.0], "Scots pine")),
    ),
    ("larix", None, Some(([1.95, 1.49, 0.0], "tamarack"))),
    ("pseudotsuga", None, Some(([5.77, 1.06, -0.01], "Douglas-fir, Bechtold 2004"))),
    ("alnus", None, Some(([4.70, 1.35, 0.0], "red alder, Bechtold 2004"))),
];

/// The broadleaf and conifer height defaults (FVS "other hardwoods", "other softwoods").
const BROADLEAF_HEIGHT: [f64; 3] = [109.7324294, 2.25025802, -0.41297463];
const CONIFER_HEIGHT: [f64; 3] = [212.7932729, 3.47154903, -0.32585230];

/// Heights and crowns from DBH, per genus.
#[derive(Debug, Clone)]
pub struct Allometry {
    genera: Vec<Equations>,
    broadleaf: Equations,
    conifer: Equations,
    /// Codes → Latin names (`--species-table`), read before any other name.
    pub species_table: Option<SpeciesTable>,
}

fn mean_crown(rows: &[&Equations]) -> Crown {
    let n = rows.len().max(1) as f64;
    Crown {
        b0: rows.iter().map(|e| e.crown.b0).sum::<f64>() / n,
        b1: rows.iter().map(|e| e.crown.b1).sum::<f64>() / n,
        b2: rows.iter().map(|e| e.crown.b2).sum::<f64>() / n,
    }
}

impl Default for Allometry {
    fn default() -> Self {
        Self::built_in()
    }
}

impl Allometry {
    /// The built-in table (docs/ALLOMETRY.md).
    #[must_use]
    pub fn built_in() -> Self {
        let h = |p: [f64; 3]| Height { p2: p[0], p3: p[1], p4: p[2] };
        let broadleaf_h = h(BROADLEAF_HEIGHT);
        let conifer_h = h(CONIFER_HEIGHT);
        // Crowns first (every built-in genus has one), then the defaults as their means.
        let mut genera: Vec<Equations> = BUILT_IN
            .iter()
            .map(|(genus, height, crown)| {
                let conifer = CONIFERS.contains(genus);
                let (height, hs) = match height {
                    Some((p, species)) => (h(*p), format!("{FVS} ({species})")),
                    None if conifer => (conifer_h, format!("{FVS} (other softwoods: no {genus} equation)")),
                    None => (broadleaf_h, format!("{FVS} (other hardwoods: no {genus} equation)")),
                };
                let ((b0, b1, b2), cs) = match crown {
                    Some(([b0, b1, b2], species)) => ((*b0, *b1, *b2), format!("{BECHTOLD} ({species})")),
                    None => ((0.0, 0.0, 0.0), String::new()),
                };
                Equations {
                    genus: (*genus).to_string(),
                    height,
                    crown: Crown { b0, b1, b2 },
                    source: format!("{hs}; {cs}"),
                }
            })
            .collect();
        genera.sort_by(|a, b| a.genus.cmp(&b.genus));
        let conifers: Vec<&Equations> = genera.iter().filter(|e| CONIFERS.contains(&e.genus.as_str())).collect();
        let broadleaves: Vec<&Equations> = genera.iter().filter(|e| !CONIFERS.contains(&e.genus.as_str())).collect();
        let conifer = Equations {
            genus: "conifer".into(),
            height: conifer_h,
            crown: mean_crown(&conifers),
            source: format!("{FVS} (other softwoods); crown: mean of the built-in conifer genera"),
        };
        let broadleaf = Equations {
            genus: "broadleaf".into(),
            height: broadleaf_h,
            crown: mean_crown(&broadleaves),
            source: format!("{FVS} (other hardwoods); crown: mean of the built-in broadleaf genera"),
        };
        Self { genera, broadleaf, conifer, species_table: None }
    }

    /// The built-in table with the rows of `path` over it (docs/ALLOMETRY.md:
    /// `genus,h_p2,h_p3,h_p4,cw_b0,cw_b1,cw_b2`; empty cells keep the built-in
    /// value; `broadleaf` and `conifer` set the defaults).
    ///
    /// # Errors
    /// An unreadable file, a missing `genus` column, or a value that is no number.
    pub fn with_overrides(path: &Path) -> Result<Self> {
        let mut a = Self::built_in();
        let mut rdr = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .from_path(path)
            .with_context(|| format!("cannot read --allometry {}", path.display()))?;
        let header: Vec<String> = rdr
            .headers()
            .with_context(|| format!("--allometry {}", path.display()))?
            .iter()
            .map(str::to_lowercase)
            .collect();
        let col = |n: &str| header.iter().position(|h| h == n);
        let Some(genus_col) = col("genus") else {
            bail!(
                "--allometry {}: no \"genus\" column (columns: genus,h_p2,h_p3,h_p4,cw_b0,cw_b1,cw_b2)",
                path.display()
            )
        };
        let names = ["h_p2", "h_p3", "h_p4", "cw_b0", "cw_b1", "cw_b2"];
        let cols: Vec<Option<usize>> = names.iter().map(|n| col(n)).collect();
        if cols.iter().all(Option::is_none) {
            bail!("--allometry {}: none of the columns {names:?}", path.display());
        }
        for (i, rec) in rdr.records().enumerate() {
            let rec = rec.with_context(|| format!("--allometry {}: row {}", path.display(), i + 1))?;
            let genus = rec.get(genus_col).unwrap_or("").to_lowercase();
            if genus.is_empty() {
                continue;
            }
            let mut values = [None; 6];
            for (k, c) in cols.iter().enumerate() {
                let Some(text) = c.and_then(|c| rec.get(c)).filter(|t| !t.is_empty()) else { continue };
                let v: f64 = text.parse().ok().filter(|v: &f64| v.is_finite()).with_context(|| {
                    format!(
                        "--allometry {}: row {} ({genus}): {} is {text:?}, not a number",
                        path.display(),
                        i + 1,
                        names[k]
                    )
                })?;
                values[k] = Some(v);
            }
            let base = match genus.as_str() {
                "broadleaf" => a.broadleaf.clone(),
                "conifer" => a.conifer.clone(),
                g => a.equations(g).clone(),
            };
            let e = Equations {
                genus: genus.clone(),
                height: Height {
                    p2: values[0].unwrap_or(base.height.p2),
                    p3: values[1].unwrap_or(base.height.p3),
                    p4: values[2].unwrap_or(base.height.p4),
                },
                crown: Crown {
                    b0: values[3].unwrap_or(base.crown.b0),
                    b1: values[4].unwrap_or(base.crown.b1),
                    b2: values[5].unwrap_or(base.crown.b2),
                },
                source: format!("--allometry {}", path.display()),
            };
            match genus.as_str() {
                "broadleaf" => a.broadleaf = e,
                "conifer" => a.conifer = e,
                _ => match a.genera.iter_mut().find(|g| g.genus == genus) {
                    Some(g) => *g = e,
                    None => a.genera.push(e),
                },
            }
        }
        Ok(a)
    }

    /// The Latin name a label stands for: the species table's where it lists
    /// the label as a code, else the label itself.
    #[must_use]
    pub fn latin<'a>(&'a self, label: &'a str) -> &'a str {
        self.species_table.as_ref().and_then(|t| t.latin(label)).map_or(label, |(name, _)| name)
    }

    /// The genus a species label names (lowercase): through the species
    /// table, the first word of a botanical name that the table knows, or a
    /// common name (`input::names`).
    #[must_use]
    pub fn genus_of(&self, label: &str) -> Option<String> {
        let label = self.latin(label);
        let first = names::first_word(label);
        if self.genera.iter().any(|g| g.genus == first) || CONIFERS.contains(&first.as_str()) {
            return Some(first);
        }
        names::common_genus(label).map(str::to_string)
    }

    /// The equations for `genus` (lowercase): its own, else the conifer or
    /// broadleaf default.
    #[must_use]
    pub fn equations(&self, genus: &str) -> &Equations {
        self.genera.iter().find(|g| g.genus == genus).unwrap_or(if CONIFERS.contains(&genus) {
            &self.conifer
        } else {
            &self.broadleaf
        })
    }

    /// The equations for a species label (see [`Self::genus_of`]).
    #[must_use]
    pub fn for_label(&self, label: &str) -> &Equations {
        match self.genus_of(label) {
            Some(g) => self.equations(&g),
            None => &self.broadleaf,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn documented_values() {
        let a = Allometry::built_in();
        // The checks the sources give: sugar maple and basswood heights at 30 and 60 cm.
        let acer = a.for_label("Acer saccharinum");
        assert!((acer.height.metres(30.0) - 20.8).abs() < 0.1, "{}", acer.height.metres(30.0));
        assert!((acer.height.metres(60.0) - 26.8).abs() < 0.1);
        let tilia = a.for_label("Tilia cordata");
        assert!((tilia.height.metres(30.0) - 21.7).abs() < 0.1);
        assert!((tilia.height.metres(60.0) - 29.4).abs() < 0.1);
        // Bechtold: basswood at 30 cm = 11.811 in → 7.19 + 1.15 × 11.811 ft.
        let expect = (7.19 + 1.15 * 30.0 / 2.54) * 0.3048;
        assert!((tilia.crown.metres(30.0) - expect).abs() < 1e-9);
        // Below 5 in the share of the 5-inch value (Bragg): 0.767 at 3 in.
        let at5 = tilia.crown.metres(5.0 * 2.54);
        assert!((tilia.crown.metres(3.0 * 2.54) - 0.767 * at5).abs() < 1e-9);
        // Below 3 in the height runs linearly down to 4.51 ft.
        assert!((tilia.height.metres(0.0) - 4.51 * 0.3048).abs() < 1e-9);
        // Monotone, finite over the whole range.
        let mut last = 0.0;
        for d in 1..300 {
            let h = tilia.height.metres(f64::from(d));
            assert!(h.is_finite() && h >= last, "{d} cm: {h}");
            last = h;
        }
    }

    #[test]
    fn labels_to_genera() {
        let a = Allometry::built_in();
        for (label, genus) in [
            ("Quercus robur", Some("quercus")),
            ("ulmus minor", Some("ulmus")),
            ("Platanus x hispanica", Some("platanus")),
            ("Red Oak", Some("quercus")),
            ("Horse Chestnut", Some("aesculus")),
            ("Sweet chestnut", Some("castanea")),
            ("Gewone paardenkastanje", Some("aesculus")),
            ("Winterlinde", Some("tilia")),
            ("Chêne vert", Some("quercus")),
            ("Sequoiadendron giganteum", Some("sequoiadendron")),
            ("QURO", None),
        ] {
            assert_eq!(a.genus_of(label).as_deref(), genus, "{label}");
        }
        // Unknown conifer genera take the conifer default, unknown others the broadleaf one.
        assert_eq!(a.for_label("Sequoiadendron giganteum").genus, "conifer");
        assert_eq!(a.for_label("Zelkova serrata").genus, "broadleaf");
        assert_eq!(a.for_label("Larix decidua").genus, "larix");
        assert!(a.for_label("Larix decidua").source.contains("other softwoods"));
    }

    #[test]
    fn overrides_replace_only_what_they_give() {
        let dir = std::env::temp_dir().join(format!("sylva-allometry-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("allometry.csv");
        std::fs::write(
            &path,
            "genus,h_p2,h_p3,h_p4,cw_b0\ntilia,100,3,-0.5,\nzelkova,,,,9\nbroadleaf,,,,1\nconifer,,,,2\n",
        )
        .unwrap();
        let a = Allometry::with_overrides(&path).unwrap();
        let b = Allometry::built_in();
        let t = a.equations("tilia");
        assert_eq!((t.height.p2, t.height.p3, t.height.p4), (100.0, 3.0, -0.5));
        assert_eq!(t.crown, b.equations("tilia").crown, "empty cells keep the built-in crown");
        assert_eq!(a.equations("zelkova").crown.b0, 9.0);
        assert_eq!(a.equations("zelkova").height, b.equations("broadleaf").height);
        assert_eq!(a.equations("broadleaf").crown.b0, 1.0);
        // The conifer row starts from the conifer default, not the broadleaf one.
        assert_eq!(a.for_label("Picea rubens").genus, "picea");
        let conifer = a.equations("sequoiadendron");
        assert_eq!((conifer.crown.b0, conifer.height), (2.0, b.equations("thuja").height));
        std::fs::write(&path, "genus,h_p2\ntilia,tall\n").unwrap();
        let e = Allometry::with_overrides(&path).unwrap_err().to_string();
        assert!(e.contains("h_p2") && e.contains("tall") && e.contains("tilia"), "{e}");
        std::fs::write(&path, "name,h_p2\ntilia,1\n").unwrap();
        assert!(Allometry::with_overrides(&path).unwrap_err().to_string().contains("genus"));
        std::fs::remove_dir_all(&dir).ok();
    }
}
