//! The library's genera: each a Weber & Penn 1995 parameter set (the paper's
//! parameter names) read off the genus's botanical form — crown shape, branch angles,
//! how many orders of branching show, leaf size and shape — with its colours.
//!
//! Twelve genera are tuned by hand ([`tuned`]); the others start from their
//! crown [`forms::Form`] ([`table`]); the archetypes are the forms themselves.
//!
//! `crown_ratio` is the crown width over height of the genus's trees at a
//! typical DBH (40 cm): docs/ALLOMETRY.md's crown and height equations where
//! the genus has its own crown equation (a test holds them to it), else its
//! form's as field guides give it. The model grows to it (`library::model`
//! fits its branch length), so the bake, which scales each tree to its
//! inventory's crown, rarely has to squeeze or stretch one far.

use std::sync::LazyLock;

use super::weber_penn::Params;

pub mod forms;
mod table;
mod tuned;

/// A leaf's outline on its card.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LeafShape {
    /// Simple, widest below the middle: beech, lime, birch, poplar.
    Ovate,
    /// With rounded lobes: oak.
    Lobed,
    /// Five pointed lobes from the stalk: maple, plane.
    Palmate,
    /// Long and narrow: willow, chestnut, olive, eucalyptus.
    Linear,
    /// Leaflets in pairs along a stalk: ash, locust, rowan, walnut.
    Pinnate,
    /// A fan: ginkgo, fan palms.
    Fan,
    /// Sprays of needles: spruce, fir, pine, larch, Douglas fir.
    Needles,
    /// Flat sprays of scale leaves: cypress, arborvitae, juniper.
    Scales,
    /// Leaflets from a midrib: palms.
    Frond,
}

/// A bark's pattern.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Bark {
    /// Vertical furrows: oak, ash, lime, poplar.
    Furrowed,
    /// Smooth: beech, hornbeam, young maple.
    Smooth,
    /// Pale with dark bands: birch.
    Banded,
    /// Flaking patches: plane, Scots pine's upper trunk.
    Patchy,
    /// Scaly plates: spruce, pine, larch.
    Scaly,
    /// Long fibrous strips: redwood, arborvitae, cypress, juniper.
    Fibrous,
    /// Rings of old leaf bases: palms.
    Ringed,
}

/// A genus of the library.
#[derive(Debug, Clone, PartialEq)]
pub struct Genus {
    /// Latin name (capitalised).
    pub name: &'static str,
    /// Its family (the fallback for an unknown genus of it; empty for an archetype).
    pub family: &'static str,
    /// An archetype (a form for names the library cannot place), not a genus.
    pub archetype: bool,
    /// A conifer (needles or scales).
    pub conifer: bool,
    /// Sheds its leaves in winter (larch and bald cypress among the conifers).
    pub deciduous: bool,
    /// Leaf outline.
    pub leaf: LeafShape,
    /// Bark pattern.
    pub bark: Bark,
    /// Leaf colour (sRGB).
    pub leaf_color: [u8; 3],
    /// Bark colour (sRGB).
    pub bark_color: [u8; 3],
    /// Crown width over height at a typical DBH (the model grows to it).
    pub crown_ratio: f32,
    /// The tree's form.
    pub params: Params,
}

impl Genus {
    /// A deciduous genus's autumn leaf colour (sRGB), as field guides describe
    /// it: the maples' and sweetgum's reds, the birches', poplars', limes' and
    /// ginkgo's yellows, the oaks' and beech's russet and copper, the larches'
    /// and swamp cypresses' gold to rust; the yellow-brown most genera turn
    /// otherwise. `None` for an evergreen.
    #[must_use]
    pub fn autumn(&self) -> Option<[u8; 3]> {
        if !self.deciduous {
            return None;
        }
        Some(match self.name {
            "Acer" => [196, 70, 34],
            "Liquidambar" => [150, 34, 44],
            "Prunus" | "Sorbus" | "Crataegus" | "Malus" | "Pyrus" => [186, 78, 40],
            "Quercus" => [150, 92, 44],
            "Fagus" | "Carpinus" => [176, 104, 42],
            "Betula" | "Populus" | "Ginkgo" | "Liriodendron" | "Fraxinus" | "Ulmus" | "Tilia" | "Salix" | "Celtis"
            | "Morus" | "Gleditsia" | "Robinia" | "Zelkova" | "Corylus" | "Catalpa" | "Ailanthus" => [214, 172, 48],
            "Larix" => [206, 150, 46],
            "Metasequoia" | "Taxodium" => [176, 88, 40],
            "Castanea" | "Aesculus" | "Juglans" | "Platanus" | "Alnus" | "Magnolia" => [168, 120, 50],
            _ => [190, 140, 50],
        })
    }
}

/// Every genus of the library: the hand-tuned, then those from their forms.
pub static GENERA: LazyLock<Vec<Genus>> = LazyLock::new(|| {
    let mut all = tuned::genera();
    all.extend(table::genera());
    all
});

/// The archetypes: a tree per crown form, for labels the library cannot place.
pub static ARCHETYPES: LazyLock<Vec<Genus>> = LazyLock::new(forms::archetypes);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::input::allometry::Allometry;

    /// The DBH at which a genus's crown ratio is its typical one.
    const TYPICAL_DBH_CM: f64 = 40.0;

    #[test]
    fn crown_ratios_agree_with_the_allometry() {
        // Where docs/ALLOMETRY.md has the genus's own crown equation, its
        // crown width over height at a typical DBH is the genus's (within 10 %).
        let a = Allometry::built_in();
        let mut checked = 0;
        for g in GENERA.iter() {
            let e = a.equations(&g.name.to_lowercase());
            if e.genus != g.name.to_lowercase() {
                continue;
            }
            let want = e.crown.metres(TYPICAL_DBH_CM) / e.height.metres(TYPICAL_DBH_CM);
            let ratio = f64::from(g.crown_ratio);
            assert!((ratio / want - 1.0).abs() <= 0.1, "{}: crown ratio {ratio:.2}, the allometry's {want:.2}", g.name);
            checked += 1;
        }
        assert!(checked >= 20, "{checked} genera with their own equations");
    }

    #[test]
    fn the_library_has_forty_genera_and_every_archetype() {
        assert!(GENERA.len() >= 40, "{} genera", GENERA.len());
        let mut names: Vec<&str> = GENERA.iter().chain(ARCHETYPES.iter()).map(|g| g.name).collect();
        names.sort_unstable();
        let n = names.len();
        names.dedup();
        assert_eq!(names.len(), n, "a name twice");
        assert!(GENERA.iter().all(|g| !g.archetype && !g.family.is_empty()));
        assert!(ARCHETYPES.iter().all(|g| g.archetype));
        // Conifers that shed their needles, broadleaves that keep their leaves.
        for (name, deciduous) in
            [("Larix", true), ("Taxodium", true), ("Picea", false), ("Olea", false), ("Quercus", true)]
        {
            assert_eq!(GENERA.iter().find(|g| g.name == name).map(|g| g.deciduous), Some(deciduous), "{name}");
        }
    }
}
