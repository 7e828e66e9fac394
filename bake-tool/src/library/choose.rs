//! Which library tree each species label of an inventory gets: its Latin
//! genus (the label's first word: `Quercus robur`, `Platanus x hispanica`,
//! `Acer platanoides 'Crimson King'`), else the genus a common name names
//! (English, Dutch, German: `input::allometry`'s table), else a default by leaf
//! type — a conifer default for known conifer genera, the broadleaf default for
//! everything else — counted and reported.

use std::collections::BTreeMap;

use super::{genus, Genus};
use crate::input::allometry::{is_conifer, Allometry};

/// The library's default for an unknown conifer genus.
pub const CONIFER_DEFAULT: &str = "Abies";
/// The library's default for every other unknown label.
pub const BROADLEAF_DEFAULT: &str = "Acer";

/// Why a label got its genus.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Why {
    /// Its Latin genus is in the library.
    Genus,
    /// A common name of a genus in the library.
    CommonName,
    /// A conifer genus the library lacks (named).
    ConiferDefault(String),
    /// A genus the library lacks, or no genus found (the label's first word).
    BroadleafDefault(String),
}

impl std::fmt::Display for Why {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Why::Genus => write!(f, "genus"),
            Why::CommonName => write!(f, "common name"),
            Why::ConiferDefault(g) => write!(f, "conifer default (no {g} in the library)"),
            Why::BroadleafDefault(g) if g.is_empty() => write!(f, "broadleaf default (no genus in the label)"),
            Why::BroadleafDefault(g) => write!(f, "broadleaf default (no {g} in the library)"),
        }
    }
}

/// The library genus of one species label, and why.
#[must_use]
pub fn choose(label: &str, allometry: &Allometry) -> (&'static Genus, Why) {
    let l = label.trim().to_lowercase();
    let first = l.split(|c: char| !c.is_alphabetic()).find(|w| !w.is_empty()).unwrap_or("");
    if let Some(g) = genus(first) {
        return (g, Why::Genus);
    }
    match allometry.genus_of(label) {
        Some(g) if g != first => match genus(&g) {
            Some(lib) => (lib, Why::CommonName),
            None if is_conifer(&g) => (default(CONIFER_DEFAULT), Why::ConiferDefault(g)),
            None => (default(BROADLEAF_DEFAULT), Why::BroadleafDefault(g)),
        },
        _ if is_conifer(first) => (default(CONIFER_DEFAULT), Why::ConiferDefault(first.to_string())),
        _ => (default(BROADLEAF_DEFAULT), Why::BroadleafDefault(first.to_string())),
    }
}

fn default(name: &str) -> &'static Genus {
    genus(name).expect("the library's defaults are genera of it")
}

/// The library genus of each label of `labels` (label → trees), by genus: the
/// genera used (alphabetical), each with its labels, why and tree counts.
#[must_use]
pub fn choose_all<'a>(
    labels: &'a BTreeMap<String, u64>,
    allometry: &Allometry,
) -> BTreeMap<&'static str, Vec<(&'a str, Why, u64)>> {
    let mut out: BTreeMap<&'static str, Vec<(&'a str, Why, u64)>> = BTreeMap::new();
    for (label, &n) in labels {
        let (g, why) = choose(label, allometry);
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
        ] {
            assert_eq!(name(label), want, "{label}");
            assert_eq!(choose(label, &a).1, Why::Genus, "{label}");
        }
        // A conifer genus the library lacks; an unknown broadleaf; a code.
        assert_eq!(choose("Taxus baccata", &a), (genus(CONIFER_DEFAULT).unwrap(), Why::ConiferDefault("taxus".into())));
        assert_eq!(choose("Ceanothus integerrimus", &a).0.name, BROADLEAF_DEFAULT);
        assert_eq!(choose("QURO", &a).1, Why::BroadleafDefault("quro".into()));
        assert_eq!(choose("", &a).1, Why::BroadleafDefault(String::new()));
    }

    #[test]
    fn common_names_find_their_genus() {
        let a = Allometry::built_in();
        assert_eq!(choose("Red Oak", &a), (genus("Quercus").unwrap(), Why::CommonName));
        // A common name of a genus the library lacks: the default, naming it.
        assert_eq!(choose("Rosskastanie", &a).1, Why::BroadleafDefault("aesculus".into()));
    }
}
