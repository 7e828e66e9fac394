//! The library's genera: each a Weber & Penn 1995 parameter set (the paper's
//! parameter names) read off the genus's botanical form — crown shape, branch angles,
//! how many orders of branching show, leaf size and shape — with its colours.
//!
//! `crown_ratio` is the range of crown width over height the genus's trees
//! take (a test holds variants 0–2 inside it). Open-grown, as a model is; the
//! bake scales each tree to its inventory's crown anyway. (Still to check: that
//! each range holds docs/ALLOMETRY.md's crown equation at a typical DBH.)

use std::sync::LazyLock;

use super::weber_penn::{Level, Params, Shape};

/// A leaf's outline on its card.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LeafShape {
    /// Simple, widest below the middle: beech, lime, birch, poplar.
    Ovate,
    /// With rounded lobes: oak.
    Lobed,
    /// Five pointed lobes from the stalk: maple, plane.
    Palmate,
    /// Long and narrow: willow.
    Linear,
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
}

/// A genus of the library.
#[derive(Debug, Clone, PartialEq)]
pub struct Genus {
    /// Latin name (capitalised).
    pub name: &'static str,
    /// Its family (the fallback for an unknown genus of it).
    pub family: &'static str,
    /// A conifer (needles or scales).
    pub conifer: bool,
    /// Leaf outline.
    pub leaf: LeafShape,
    /// Bark pattern.
    pub bark: Bark,
    /// Leaf colour (sRGB).
    pub leaf_color: [u8; 3],
    /// Bark colour (sRGB).
    pub bark_color: [u8; 3],
    /// Crown width over height its trees take (min, max).
    pub crown_ratio: [f32; 2],
    /// The tree's form.
    pub params: Params,
}

/// A trunk of `curve_res` segments, bending at random by `curve_v`.
const fn trunk(curve_res: u32, curve_v: f32) -> Level {
    Level { curve_v, length_v: 0.0, ..Level::new(0, 0.0, 1.0, curve_res) }
}

/// A broadleaf's parameters: crown `shape`, bare trunk share `base_size`,
/// height `scale` (m), the branches (level 1) and twigs (level 2).
fn broadleaf(shape: Shape, base_size: f32, scale: f32, branches: Level, twigs: Level, leaf_scale: f32) -> Params {
    Params {
        shape,
        base_size,
        scale,
        scale_v: scale * 0.08,
        ratio: 0.022,
        ratio_power: 1.3,
        flare: 0.6,
        base_splits: 0,
        attraction_up: 0.5,
        leaves: 26,
        leaf_scale,
        leaf_scale_x: 0.8,
        leaf_down_angle: 55.0,
        levels: vec![trunk(8, 12.0), branches, twigs],
    }
}

/// A conifer's: a straight leader, whorls of near-level branches, their
/// shoots carrying needle sprays.
fn conifer(shape: Shape, base_size: f32, scale: f32, branches: Level, shoots: Level, spray: f32) -> Params {
    Params {
        shape,
        base_size,
        scale,
        scale_v: scale * 0.06,
        ratio: 0.018,
        ratio_power: 1.1,
        flare: 0.4,
        base_splits: 0,
        attraction_up: 0.25,
        leaves: 10,
        leaf_scale: spray,
        leaf_scale_x: 0.6,
        leaf_down_angle: 40.0,
        levels: vec![trunk(10, 4.0), branches, shoots],
    }
}

/// Every genus of the library.
pub static GENERA: LazyLock<Vec<Genus>> = LazyLock::new(|| {
    vec![
        Genus {
            name: "Quercus",
            family: "Fagaceae",
            conifer: false,
            leaf: LeafShape::Lobed,
            bark: Bark::Furrowed,
            leaf_color: [66, 98, 40],
            bark_color: [96, 86, 74],
            crown_ratio: [0.59, 1.00],
            params: broadleaf(
                Shape::Hemispherical,
                0.22,
                20.0,
                Level {
                    curve: -25.0,
                    curve_v: 70.0,
                    seg_splits: 0.15,
                    split_angle: 30.0,
                    ..Level::new(26, 62.0, 0.5, 6)
                },
                Level { curve_v: 60.0, ..Level::new(11, 45.0, 0.45, 3) },
                0.56,
            ),
        },
        Genus {
            name: "Fagus",
            family: "Fagaceae",
            conifer: false,
            leaf: LeafShape::Ovate,
            bark: Bark::Smooth,
            leaf_color: [70, 112, 42],
            bark_color: [140, 138, 130],
            crown_ratio: [0.45, 0.80],
            params: broadleaf(
                Shape::Spherical,
                0.25,
                24.0,
                Level { curve: -15.0, ..Level::new(32, 55.0, 0.52, 5) },
                Level { rotate: -90.0, ..Level::new(12, 50.0, 0.45, 3) },
                0.60,
            ),
        },
        Genus {
            name: "Acer",
            family: "Sapindaceae",
            conifer: false,
            leaf: LeafShape::Palmate,
            bark: Bark::Smooth,
            leaf_color: [72, 116, 44],
            bark_color: [118, 110, 98],
            crown_ratio: [0.41, 0.71],
            params: broadleaf(
                Shape::Spherical,
                0.2,
                18.0,
                Level { curve: -10.0, seg_splits: 0.1, split_angle: 25.0, ..Level::new(24, 48.0, 0.48, 5) },
                Level { rotate: -90.0, ..Level::new(10, 45.0, 0.45, 3) },
                0.60,
            ),
        },
        Genus {
            name: "Tilia",
            family: "Malvaceae",
            conifer: false,
            leaf: LeafShape::Ovate,
            bark: Bark::Furrowed,
            leaf_color: [74, 118, 46],
            bark_color: [104, 96, 84],
            crown_ratio: [0.35, 0.70],
            params: broadleaf(
                Shape::TendFlame,
                0.2,
                22.0,
                Level { curve: -10.0, ..Level::new(34, 55.0, 0.38, 5) },
                Level { ..Level::new(12, 45.0, 0.45, 3) },
                0.62,
            ),
        },
        Genus {
            name: "Platanus",
            family: "Platanaceae",
            conifer: false,
            leaf: LeafShape::Palmate,
            bark: Bark::Patchy,
            leaf_color: [80, 116, 48],
            bark_color: [150, 142, 118],
            crown_ratio: [0.44, 0.81],
            params: broadleaf(
                Shape::Spherical,
                0.25,
                25.0,
                Level {
                    curve: -20.0,
                    curve_v: 60.0,
                    seg_splits: 0.2,
                    split_angle: 35.0,
                    ..Level::new(22, 58.0, 0.5, 6)
                },
                Level { curve_v: 50.0, ..Level::new(10, 45.0, 0.45, 3) },
                0.70,
            ),
        },
        Genus {
            name: "Betula",
            family: "Betulaceae",
            conifer: false,
            leaf: LeafShape::Ovate,
            bark: Bark::Banded,
            leaf_color: [96, 132, 52],
            bark_color: [226, 222, 210],
            crown_ratio: [0.44, 0.78],
            params: Params {
                attraction_up: -0.4,
                ..broadleaf(
                    Shape::Flame,
                    0.3,
                    18.0,
                    Level { curve: 20.0, ..Level::new(30, 38.0, 0.34, 5) },
                    Level { curve: 30.0, ..Level::new(10, 40.0, 0.5, 4) },
                    0.45,
                )
            },
        },
        Genus {
            name: "Populus",
            family: "Salicaceae",
            conifer: false,
            leaf: LeafShape::Ovate,
            bark: Bark::Furrowed,
            leaf_color: [82, 120, 48],
            bark_color: [120, 116, 104],
            crown_ratio: [0.23, 0.43],
            params: broadleaf(
                Shape::TendFlame,
                0.2,
                26.0,
                Level { curve: -5.0, ..Level::new(30, 35.0, 0.3, 5) },
                Level { ..Level::new(10, 40.0, 0.45, 3) },
                0.58,
            ),
        },
        Genus {
            name: "Salix",
            family: "Salicaceae",
            conifer: false,
            leaf: LeafShape::Linear,
            bark: Bark::Furrowed,
            leaf_color: [110, 140, 66],
            bark_color: [112, 100, 80],
            crown_ratio: [0.42, 0.70],
            params: Params {
                attraction_up: -2.5,
                leaves: 22,
                ..broadleaf(
                    Shape::Spherical,
                    0.25,
                    15.0,
                    Level { curve: -20.0, seg_splits: 0.2, split_angle: 30.0, ..Level::new(22, 55.0, 0.55, 6) },
                    Level { curve_v: 20.0, ..Level::new(9, 30.0, 0.8, 5) },
                    0.42,
                )
            },
        },
        Genus {
            name: "Picea",
            family: "Pinaceae",
            conifer: true,
            leaf: LeafShape::Needles,
            bark: Bark::Scaly,
            leaf_color: [36, 70, 40],
            bark_color: [96, 70, 52],
            crown_ratio: [0.44, 0.76],
            params: conifer(
                Shape::Conical,
                0.08,
                28.0,
                Level { curve: -8.0, curve_back: 20.0, down_angle_v: -10.0, ..Level::new(70, 78.0, 0.26, 4) },
                Level { rotate: -90.0, curve_v: 10.0, ..Level::new(10, 55.0, 0.4, 2) },
                1.12,
            ),
        },
        Genus {
            name: "Abies",
            family: "Pinaceae",
            conifer: true,
            leaf: LeafShape::Needles,
            bark: Bark::Smooth,
            leaf_color: [32, 72, 46],
            bark_color: [122, 118, 108],
            crown_ratio: [0.42, 0.74],
            params: conifer(
                Shape::Conical,
                0.1,
                26.0,
                Level { curve: 8.0, curve_v: 10.0, ..Level::new(64, 86.0, 0.25, 4) },
                Level { rotate: -90.0, curve_v: 8.0, ..Level::new(9, 60.0, 0.4, 2) },
                1.12,
            ),
        },
        Genus {
            name: "Pinus",
            family: "Pinaceae",
            conifer: true,
            leaf: LeafShape::Needles,
            bark: Bark::Patchy,
            leaf_color: [52, 84, 46],
            bark_color: [150, 96, 64],
            crown_ratio: [0.41, 0.78],
            params: Params {
                attraction_up: 0.8,
                leaves: 12,
                ..conifer(
                    Shape::Hemispherical,
                    0.5,
                    22.0,
                    Level { curve: 25.0, curve_v: 40.0, ..Level::new(26, 65.0, 0.36, 5) },
                    Level { curve_v: 30.0, ..Level::new(8, 45.0, 0.45, 3) },
                    1.26,
                )
            },
        },
        Genus {
            name: "Larix",
            family: "Pinaceae",
            conifer: true,
            leaf: LeafShape::Needles,
            bark: Bark::Scaly,
            leaf_color: [88, 124, 56],
            bark_color: [110, 80, 62],
            crown_ratio: [0.48, 0.86],
            params: conifer(
                Shape::Conical,
                0.15,
                26.0,
                Level { curve: 15.0, curve_v: 25.0, ..Level::new(48, 75.0, 0.28, 4) },
                Level { curve: -20.0, curve_v: 20.0, ..Level::new(9, 50.0, 0.45, 3) },
                1.05,
            ),
        },
    ]
});
