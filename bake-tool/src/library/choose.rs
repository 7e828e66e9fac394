//! Which library tree each species label of an inventory gets, in order:
//! a code the species table (`--species-table`) lists stands for its Latin
//! name; its Latin genus (the label's first word: `Quercus robur`, `Platanus
//! x hispanica`, `Acer platanoides 'Crimson King'`, `Tilia :: Linde`); a common
//! name in English, Dutch, German, French or Spanish (`input::names`); the
//! family of a genus the library lacks (its family's tree, or the archetype of
//! the family's habit); else an archetype by leaf type — `conifer-spire` for a
//! conifer genus, `broadleaf-round` for everything else — counted and reported.

use std::collections::BTreeMap;

use super::{entry, genus, Genus, GENERA};
use crate::input::allometry::{is_conifer, Allometry};
use crate::input::names;

/// The archetype for an unknown conifer genus.
pub const CONIFER_DEFAULT: &str = "conifer-spire";
/// The archetype for every other label the library cannot place.
pub const BROADLEAF_DEFAULT: &str = "broadleaf-round";

/// Why a label got its tree.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Why {
    /// Its Latin genus is in the library.
    Genus,
    /// A common name of a genus in the library.
    CommonName,
    /// A genus the library lacks (named), of a family it has a tree of.
    Family(String, String),
    /// A genus the library lacks (named), of a family (named) whose habit an archetype draws.
    FamilyArchetype(String, String),
    /// A conifer genus the library lacks (named).
    ConiferDefault(String),
    /// A genus the library lacks, or no genus found (the label's first word).
    BroadleafDefault(String),
    /// A code of the species table, standing for a Latin name; then why that got its tree.
    Code(String, Box<Why>),
    /// Nothing in the label known; the inventory's leaf-type column says this.
    LeafType(String),
}

impl std::fmt::Display for Why {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Why::Genus => write!(f, "genus"),
            Why::CommonName => write!(f, "common name"),
            Why::Family(g, fam) => write!(f, "family {fam} (no {g} in the library)"),
            Why::FamilyArchetype(g, fam) => write!(f, "archetype of family {fam} (no {g} in the library)"),
            Why::ConiferDefault(g) => write!(f, "conifer default (no {g} in the library)"),
            Why::BroadleafDefault(g) if g.is_empty() => write!(f, "broadleaf default (no genus in the label)"),
            Why::BroadleafDefault(g) => write!(f, "broadleaf default (nothing known of {g:?})"),
            Why::Code(latin, then) => write!(f, "species table: {latin}, then {then}"),
            Why::LeafType(t) => write!(f, "archetype of its leaf type {t:?} (nothing known of the name)"),
        }
    }
}

impl Why {
    /// Whether the label's tree is a default (nothing in it was recognised).
    #[must_use]
    pub fn is_default(&self) -> bool {
        match self {
            Why::ConiferDefault(_) | Why::BroadleafDefault(_) => true,
            Why::Code(_, then) => then.is_default(),
            _ => false,
        }
    }
}

/// The library tree (a genus or an archetype) of one species label, and why.
#[must_use]
pub fn choose(label: &str, allometry: &Allometry) -> (&'static Genus, Why) {
    match allometry.species_table.as_ref().and_then(|t| t.latin(label)) {
        Some((latin, family)) => {
            let (g, why) = by_name(latin, family);
            (g, Why::Code(latin.to_string(), Box::new(why)))
        }
        None => by_name(label, None),
    }
}

/// The autumn colour of a deciduous species a model of its own is given for
/// (`--model NAME=FILE`): from the genus its name places (Latin, common name,
/// family) — `None` for an evergreen, and for a name placed by no more than a
/// default (one state, as before seasons).
#[must_use]
pub fn autumn_of(label: &str) -> Option<[u8; 3]> {
    let (g, why) = by_name(label, None);
    if why.is_default() {
        return None;
    }
    g.autumn()
}

/// The Latin genus of a deciduous tree named `label` (its leaf calendar), if
/// the name places one (as [`autumn_of`] does).
#[must_use]
pub fn deciduous_genus_of(label: &str) -> Option<&'static str> {
    let (g, why) = by_name(label, None);
    (!why.is_default() && g.autumn().is_some()).then_some(g.name)
}

/// The library tree of a name (Latin or common), with the family a species table gave.
fn by_name(label: &str, family: Option<&str>) -> (&'static Genus, Why) {
    let mut first = names::first_word(label);
    if let Some(g) = genus(&first) {
        return (g, Why::Genus);
    }
    // A Latin genus the library lacks is its genus before any common name its
    // words might make (`Acacia dealbata` is no "acacia" = locust).
    if names::family_of(&first).is_none() {
        if let Some(g) = names::common_genus(label) {
            match genus(g) {
                Some(lib) => return (lib, Why::CommonName),
                // A common name of a genus the library places by its family.
                None => first = g.to_string(),
            }
        }
    }
    let family = family
        .map(str::to_string)
        .or_else(|| names::family_of(&first).map(str::to_string))
        .or_else(|| first.ends_with("aceae").then(|| capitalised(&first)));
    if let Some(fam) = family {
        if let Some(g) = GENERA.iter().find(|g| g.family.eq_ignore_ascii_case(&fam)) {
            return (g, Why::Family(first, g.family.to_string()));
        }
        if let Some((f, a)) = names::FAMILY_ARCHETYPES.iter().find(|(f, _)| f.eq_ignore_ascii_case(&fam)) {
            return (default(a), Why::FamilyArchetype(first, (*f).to_string()));
        }
    }
    if is_conifer(&first) {
        return (default(CONIFER_DEFAULT), Why::ConiferDefault(first));
    }
    (default(BROADLEAF_DEFAULT), Why::BroadleafDefault(first))
}

fn capitalised(w: &str) -> String {
    let mut c = w.chars();
    c.next().map(|f| f.to_uppercase().chain(c).collect()).unwrap_or_default()
}

fn default(name: &str) -> &'static Genus {
    entry(name).expect("the library's defaults are archetypes of it")
}

/// Header names of a leaf-type column (compared folded, spaces as `_`).
pub const LEAF_TYPE_COLUMNS: &[&str] = &[
    "leaf_type",
    "leaftype",
    "leaf_habit",
    "foliage",
    "foliage_type",
    "tree_type",
    "blatttyp",
    "blattart",
    "bladtype",
    "type_feuillage",
    "tipo_hoja",
];

/// The archetype a leaf-type value names (`conifer`, `needle`, `softwood`,
/// `Nadelbaum`, `naaldboom`, `résineux`, `conífera` …; `broadleaf`,
/// `deciduous`, `hardwood`, `Laubbaum`, `loofboom`, `feuillu`, `frondosa` …;
/// `palm`; `shrub`), if any.
#[must_use]
pub fn leaf_type_archetype(value: &str) -> Option<&'static Genus> {
    let v = names::fold(value);
    let has = |words: &[&str]| words.iter().any(|w| v.contains(w));
    let name = if has(&["palm"]) {
        "palm"
    } else if has(&["shrub", "bush", "strauch", "struik", "arbust", "arbusto"]) {
        "shrub"
    } else if has(&["conif", "needle", "softwood", "nadel", "naald", "resineux"]) {
        CONIFER_DEFAULT
    } else if has(&["broad", "decid", "hardwood", "laub", "loof", "feuillu", "frondos", "latifol"]) {
        BROADLEAF_DEFAULT
    } else {
        return None;
    };
    entry(name)
}

/// The library genus of each label of `labels` (label → trees), by genus: the
/// genera used (alphabetical), each with its labels, why and tree counts. A
/// label nothing is known of takes the archetype of its leaf type where
/// `leaf_types` (label → the inventory's leaf-type value) gives one.
#[must_use]
pub fn choose_all<'a>(
    labels: &'a BTreeMap<String, u64>,
    leaf_types: &BTreeMap<String, String>,
    allometry: &Allometry,
) -> BTreeMap<&'static str, Vec<(&'a str, Why, u64)>> {
    let mut out: BTreeMap<&'static str, Vec<(&'a str, Why, u64)>> = BTreeMap::new();
    for (label, &n) in labels {
        let (mut g, mut why) = choose(label, allometry);
        if why.is_default() {
            if let Some((t, a)) = leaf_types.get(label).and_then(|t| leaf_type_archetype(t).map(|a| (t, a))) {
                (g, why) = (a, Why::LeafType(t.clone()));
            }
        }
        out.entry(g.name).or_default().push((label.as_str(), why, n));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn real_world_labels_find_their_genus() {
        let a = Allometry::built_in();
        let name = |l: &str| choose(l, &a).0.name;
        for (label, want) in [
            ("Quercus robur", "Quercus"),
            ("quercus", "Quercus"),
            ("Platanus x hispanica", "Platanus"),
            ("Acer platanoides 'Crimson King'", "Acer"),
            ("Tilia europaea :: Hollandse linde", "Tilia"),
            ("Betula pendula", "Betula"),
            ("PINUS SYLVESTRIS", "Pinus"),
            ("Picea abies", "Picea"),
            ("Larix decidua", "Larix"),
            ("Salix alba 'Tristis'", "Salix"),
            ("Populus nigra 'Italica'", "Populus"),
            ("Fraxinus excelsior", "Fraxinus"),
            ("Ulmus x hollandica 'Lobel'", "Ulmus"),
            ("Gleditsia triacanthos f. inermis", "Gleditsia"),
            ("Taxus baccata", "Taxus"),
            ("Pseudotsuga menziesii var. glauca", "Pseudotsuga"),
            ("Washingtonia robusta", "Washingtonia"),
        ] {
            assert_eq!(name(label), want, "{label}");
            assert_eq!(choose(label, &a).1, Why::Genus, "{label}");
        }
    }

    #[test]
    fn families_archetypes_and_defaults() {
        let a = Allometry::built_in();
        // An unknown genus of a family the library has: the family's tree.
        assert_eq!(
            choose("Ostrya carpinifolia", &a),
            (genus("Betula").unwrap(), Why::Family("ostrya".into(), "Betulaceae".into()))
        );
        assert_eq!(choose("x Cupressocyparis leylandii", &a).0.name, "Thuja");
        assert_eq!(choose("Amelanchier lamarckii", &a).0.family, "Rosaceae");
        // A Latin genus the library lacks is no common name ("acacia"); a common
        // name of such a genus goes by its family.
        assert_eq!(choose("Acacia dealbata", &a).1, Why::Family("acacia".into(), "Fabaceae".into()));
        assert_eq!(choose("Kornelkirsche", &a).1, Why::FamilyArchetype("cornus".into(), "Cornaceae".into()));
        assert_eq!(choose("Chamaerops humilis", &a).0.name, "Phoenix");
        // A family named outright.
        assert_eq!(choose("Rosaceae", &a).0.family, "Rosaceae");
        // A family without a tree of its own: its habit's archetype.
        let (g, why) = choose("Cornus mas", &a);
        assert_eq!((g.name, why), ("multi-stem", Why::FamilyArchetype("cornus".into(), "Cornaceae".into())));
        assert_eq!(choose("Araucaria araucana", &a).0.name, "conifer-spire");
        // A conifer of a family the library has; a shrub family; unknown: the default, said so.
        assert_eq!(choose("Cryptomeria japonica", &a).0.name, "Thuja");
        assert_eq!(choose("Ceanothus integerrimus", &a).0.name, "shrub");
        let (g, why) = choose("QURO", &a);
        assert_eq!((g.name, why.is_default()), (BROADLEAF_DEFAULT, true));
        assert_eq!(choose("", &a).1, Why::BroadleafDefault(String::new()));
    }

    #[test]
    fn common_names_find_their_genus() {
        let a = Allometry::built_in();
        assert_eq!(choose("Red Oak", &a), (genus("Quercus").unwrap(), Why::CommonName));
        assert_eq!(choose("Rosskastanie", &a).0.name, "Aesculus");
        assert_eq!(choose("Marronnier d'Inde", &a).0.name, "Aesculus");
        assert_eq!(choose("Olmo común", &a).0.name, "Ulmus");
        assert_eq!(choose("Zomereik", &a).0.name, "Quercus");
    }

    #[test]
    fn unknown_labels_take_their_leaf_type() {
        let a = Allometry::built_in();
        let labels: BTreeMap<String, u64> = [("Mystery conifer", 3), ("XY 12", 2), ("Quercus robur", 1), ("Zzz", 1)]
            .map(|(l, n)| (l.to_string(), n))
            .into();
        let types: BTreeMap<String, String> =
            [("Mystery conifer", "Nadelbaum"), ("XY 12", "palm"), ("Quercus robur", "conifer"), ("Zzz", "unbekannt")]
                .map(|(l, t)| (l.to_string(), t.to_string()))
                .into();
        let chosen = choose_all(&labels, &types, &a);
        let of = |label: &str| {
            chosen
                .iter()
                .find(|(_, rows)| rows.iter().any(|r| r.0 == label))
                .map(|(g, rows)| (*g, rows.iter().find(|r| r.0 == label).unwrap().1.clone()))
        };
        assert_eq!(of("Mystery conifer"), Some((CONIFER_DEFAULT, Why::LeafType("Nadelbaum".into()))));
        assert_eq!(of("XY 12"), Some(("palm", Why::LeafType("palm".into()))));
        // A known genus keeps its tree whatever the column says; an unknown value changes nothing.
        assert_eq!(of("Quercus robur"), Some(("Quercus", Why::Genus)));
        assert_eq!(of("Zzz").map(|x| x.0), Some(BROADLEAF_DEFAULT));
        assert_eq!(leaf_type_archetype("Résineux").map(|g| g.name), Some(CONIFER_DEFAULT));
        assert_eq!(leaf_type_archetype("loofboom").map(|g| g.name), Some(BROADLEAF_DEFAULT));
    }

    #[test]
    fn codes_go_through_the_species_table() {
        let dir = std::env::temp_dir().join(format!("sylva-choose-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("spp.csv");
        std::fs::write(&path, "code,latin,family\nQURO,Quercus robur,Fagaceae\nOSCA,Ostrya carpinifolia,Betulaceae\nXYZ,Nothing knownia,Nonaceae\n").unwrap();
        let mut a = Allometry::built_in();
        a.species_table = Some(crate::input::names::SpeciesTable::read(&path).unwrap());
        assert_eq!(
            choose("QURO", &a),
            (genus("Quercus").unwrap(), Why::Code("Quercus robur".into(), Box::new(Why::Genus)))
        );
        assert_eq!(choose("osca", &a).0.name, "Betula");
        assert!(choose("XYZ", &a).1.is_default());
        // The allometry reads the code too.
        assert_eq!(a.genus_of("QURO").as_deref(), Some("quercus"));
        std::fs::remove_dir_all(&dir).ok();
    }
}
