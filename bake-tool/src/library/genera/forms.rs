//! Tree forms as nurseries and field guides name them (round, oval, columnar,
//! spreading, weeping, vase, pyramidal; conifer spire, broad, umbrella,
//! columnar, tiered; palm; shrub; multi-stem), each a Weber & Penn 1995
//! parameter set. Genera without a hand-tuned set start from their form; the
//! library's archetypes are the forms themselves, for names it cannot place.

use super::super::weber_penn::{Level, Params, Shape};
use super::{Bark, Genus, LeafShape};

/// A crown form.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Form {
    /// Broad and rounded: maples, hornbeam, lindens in the open.
    Round,
    /// Taller than wide, rounded: ash, horse chestnut, tulip tree.
    Oval,
    /// Narrow upright: Lombardy poplar, fastigiate cultivars.
    Columnar,
    /// Wide, low-branched: open-grown oak, walnut, chestnut.
    Spreading,
    /// Hanging branches: weeping willow, weeping birch.
    Weeping,
    /// Branches rising from a short trunk: elm, zelkova.
    Vase,
    /// A broadleaf cone: alder, sweetgum, young ginkgo.
    Pyramidal,
    /// Light, irregular, few big limbs: locust, honey locust, eucalyptus.
    Open,
    /// A small tree with a low, wide head: apple, hawthorn, cherry.
    Small,
    /// A conifer cone with level branches: spruce, fir, Douglas fir.
    Spire,
    /// A conifer rounding with age on a long bare trunk: Scots pine.
    BroadConifer,
    /// A flat top on a bare trunk: stone pine.
    Umbrella,
    /// A narrow conifer column: Italian cypress, arborvitae, incense cedar.
    ColumnarConifer,
    /// Level tiers of long branches: cedar.
    Tiered,
    /// A feather palm: a crown of arching fronds on a bare trunk.
    FeatherPalm,
    /// A fan palm: fans on stiff stalks.
    FanPalm,
    /// Several stems from the ground, no trunk: hazel, shrubs.
    Shrub,
    /// A tree of two to four trunks: birch clumps, yew, olive.
    MultiStem,
}

/// A trunk of `curve_res` segments, bending at random by `curve_v`.
pub(super) const fn trunk(curve_res: u32, curve_v: f32) -> Level {
    Level { curve_v, length_v: 0.0, ..Level::new(0, 0.0, 1.0, curve_res) }
}

/// A broadleaf's parameters: crown `shape`, bare trunk share `base_size`,
/// height `scale` (m), the branches (level 1) and twigs (level 2).
pub(super) fn broadleaf(
    shape: Shape,
    base_size: f32,
    scale: f32,
    branches: Level,
    twigs: Level,
    leaf_scale: f32,
) -> Params {
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
pub(super) fn conifer(shape: Shape, base_size: f32, scale: f32, branches: Level, shoots: Level, spray: f32) -> Params {
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

/// A palm: a trunk bare to its top, `fronds` stalks arching from it, with
/// `leaves` cards of `leaf_scale` m along each.
fn palm(scale: f32, fronds: Level, leaves: u32, leaf_scale: f32, leaf_scale_x: f32) -> Params {
    Params {
        shape: Shape::Cylindrical,
        base_size: 0.93,
        scale,
        scale_v: scale * 0.1,
        ratio: 0.016,
        ratio_power: 1.0,
        flare: 0.5,
        base_splits: 0,
        attraction_up: 0.0,
        leaves,
        leaf_scale,
        leaf_scale_x,
        leaf_down_angle: 80.0,
        levels: vec![Level { taper: 0.25, ..trunk(8, 10.0) }, fronds],
    }
}

/// Crown length over crown width of `form` (none for palms and shrubs,
/// whose crowns start where they start).
#[must_use]
pub fn aspect(form: Form) -> Option<f32> {
    Some(match form {
        Form::Round | Form::Vase => 1.1,
        Form::Oval => 1.6,
        Form::Columnar | Form::ColumnarConifer => 4.0,
        Form::Spreading | Form::Small => 0.9,
        Form::Weeping | Form::MultiStem => 1.0,
        Form::Pyramidal => 1.8,
        Form::Open | Form::BroadConifer => 1.2,
        Form::Spire => 2.6,
        Form::Umbrella => 0.5,
        Form::Tiered => 1.6,
        Form::FeatherPalm | Form::FanPalm | Form::Shrub => return None,
    })
}

/// The parameters of `form` for a tree `height` m tall with crown width over
/// height `ratio` (leaf cards sized for the tree): the bare trunk's share is
/// what the crown leaves, the crown as long as `ratio × aspect(form)` of the
/// height — a narrow forest tree has a long clear bole, an open-grown one
/// branches low.
#[must_use]
pub fn params(form: Form, height: f32, ratio: f32) -> Params {
    let mut p = shaped(form, height);
    if let Some(aspect) = aspect(form) {
        p.base_size = (1.0 - ratio * aspect).clamp(0.05, 0.7);
    }
    p
}

/// The parameters of `form` as drawn, before the crown's length is set.
fn shaped(form: Form, height: f32) -> Params {
    // Leaf shoots scale with the tree, within what a shoot can be.
    let leaf = (0.6 * (height / 20.0).sqrt()).clamp(0.3, 0.7);
    let spray = (1.1 * (height / 25.0).sqrt()).clamp(0.6, 1.3);
    let twigs = |n| Level::new(n, 45.0, 0.45, 3);
    match form {
        Form::Round => broadleaf(
            Shape::Spherical,
            0.2,
            height,
            Level { curve: -10.0, seg_splits: 0.1, split_angle: 25.0, ..Level::new(26, 52.0, 0.48, 5) },
            twigs(10),
            leaf,
        ),
        Form::Oval => broadleaf(
            Shape::TendFlame,
            0.2,
            height,
            Level { curve: -10.0, ..Level::new(32, 50.0, 0.36, 5) },
            twigs(11),
            leaf,
        ),
        Form::Columnar => Params {
            attraction_up: 0.9,
            ..broadleaf(
                Shape::Cylindrical,
                0.08,
                height,
                Level { curve: 5.0, curve_v: 15.0, ..Level::new(40, 24.0, 0.2, 4) },
                Level::new(8, 30.0, 0.5, 3),
                leaf,
            )
        },
        Form::Spreading => broadleaf(
            Shape::Hemispherical,
            0.18,
            height,
            Level { curve: -25.0, curve_v: 70.0, seg_splits: 0.15, split_angle: 30.0, ..Level::new(24, 64.0, 0.55, 6) },
            Level { curve_v: 60.0, ..twigs(11) },
            leaf,
        ),
        Form::Weeping => Params {
            attraction_up: -2.5,
            leaves: 22,
            ..broadleaf(
                Shape::Spherical,
                0.25,
                height,
                Level { curve: -20.0, seg_splits: 0.2, split_angle: 30.0, ..Level::new(22, 55.0, 0.55, 6) },
                Level { curve_v: 20.0, ..Level::new(9, 30.0, 0.8, 5) },
                leaf * 0.8,
            )
        },
        Form::Vase => Params {
            attraction_up: 0.3,
            ..broadleaf(
                Shape::InverseConical,
                0.22,
                height,
                Level {
                    curve: 10.0,
                    curve_v: 25.0,
                    seg_splits: 0.25,
                    split_angle: 25.0,
                    ..Level::new(20, 38.0, 0.55, 6)
                },
                twigs(10),
                leaf,
            )
        },
        Form::Pyramidal => broadleaf(
            Shape::Conical,
            0.12,
            height,
            Level { curve: -5.0, ..Level::new(40, 62.0, 0.32, 5) },
            twigs(10),
            leaf,
        ),
        Form::Open => Params {
            leaves: 20,
            ..broadleaf(
                Shape::TendFlame,
                0.3,
                height,
                Level {
                    curve: -10.0,
                    curve_v: 80.0,
                    seg_splits: 0.2,
                    split_angle: 30.0,
                    ..Level::new(14, 50.0, 0.5, 6)
                },
                Level { curve_v: 50.0, ..twigs(8) },
                leaf,
            )
        },
        Form::Small => Params {
            flare: 0.3,
            ..broadleaf(
                Shape::Spherical,
                0.25,
                height,
                Level {
                    curve: -15.0,
                    curve_v: 50.0,
                    seg_splits: 0.2,
                    split_angle: 30.0,
                    ..Level::new(18, 55.0, 0.6, 5)
                },
                Level { curve_v: 40.0, ..twigs(10) },
                leaf,
            )
        },
        Form::Spire => conifer(
            Shape::Conical,
            0.1,
            height,
            Level { curve: -6.0, curve_back: 12.0, ..Level::new(64, 82.0, 0.26, 4) },
            Level { rotate: -90.0, curve_v: 10.0, ..Level::new(9, 58.0, 0.4, 2) },
            spray,
        ),
        Form::BroadConifer => Params {
            attraction_up: 0.8,
            leaves: 12,
            ..conifer(
                Shape::Hemispherical,
                0.45,
                height,
                Level { curve: 25.0, curve_v: 40.0, ..Level::new(26, 65.0, 0.36, 5) },
                Level { curve_v: 30.0, ..Level::new(8, 45.0, 0.45, 3) },
                spray,
            )
        },
        Form::Umbrella => Params {
            attraction_up: 0.4,
            leaves: 12,
            ..conifer(
                Shape::InverseConical,
                0.6,
                height,
                Level {
                    curve: 30.0,
                    curve_v: 20.0,
                    seg_splits: 0.3,
                    split_angle: 25.0,
                    ..Level::new(12, 55.0, 0.6, 6)
                },
                Level { curve_v: 20.0, ..Level::new(10, 50.0, 0.4, 3) },
                spray,
            )
        },
        Form::ColumnarConifer => Params {
            attraction_up: 0.6,
            ..conifer(
                Shape::TaperedCylindrical,
                0.04,
                height,
                Level { curve: 8.0, curve_v: 8.0, ..Level::new(90, 28.0, 0.14, 3) },
                Level { curve_v: 10.0, ..Level::new(8, 35.0, 0.5, 2) },
                spray * 0.8,
            )
        },
        Form::Tiered => conifer(
            Shape::TendFlame,
            0.15,
            height,
            Level { curve: -4.0, curve_back: 8.0, ..Level::new(36, 84.0, 0.42, 5) },
            Level { rotate: -90.0, curve_v: 10.0, ..Level::new(12, 62.0, 0.38, 3) },
            spray,
        ),
        Form::FeatherPalm => palm(
            height,
            Level { curve: -50.0, curve_v: 25.0, rotate: 137.5, ..Level::new(26, 70.0, 0.3, 6) },
            20,
            (height * 0.1).clamp(0.8, 1.8),
            0.5,
        ),
        Form::FanPalm => palm(
            height,
            Level { curve: -25.0, curve_v: 20.0, rotate: 137.5, ..Level::new(30, 55.0, 0.16, 3) },
            2,
            (height * 0.07).clamp(0.6, 1.4),
            1.0,
        ),
        Form::Shrub => Params {
            base_splits: 5,
            flare: 0.0,
            levels: vec![
                Level { split_angle: 35.0, taper: 0.9, ..trunk(5, 30.0) },
                Level { curve: -15.0, curve_v: 40.0, ..Level::new(14, 45.0, 0.55, 4) },
                twigs(8),
            ],
            ..broadleaf(Shape::Spherical, 0.1, height, Level::new(0, 0.0, 0.0, 1), twigs(8), leaf)
        },
        Form::MultiStem => Params {
            base_splits: 3,
            flare: 0.2,
            levels: vec![
                Level { split_angle: 20.0, ..trunk(8, 20.0) },
                Level { curve: -10.0, curve_v: 40.0, ..Level::new(22, 50.0, 0.45, 5) },
                twigs(10),
            ],
            ..broadleaf(Shape::Spherical, 0.25, height, Level::new(0, 0.0, 0.0, 1), twigs(10), leaf)
        },
    }
}

/// The library's archetypes: one tree per form with a plain leaf and bark,
/// for labels whose genus and family it cannot place (chosen by leaf type
/// where the inventory says it).
pub(super) fn archetypes() -> Vec<Genus> {
    let green = [74, 110, 46];
    let needle = [40, 74, 44];
    let bark = [110, 100, 88];
    let conifer_bark = [104, 82, 66];
    let a = |name, form, height, ratio, leaf: LeafShape| {
        let conifer = matches!(leaf, LeafShape::Needles | LeafShape::Scales);
        Genus {
            name,
            family: "",
            archetype: true,
            conifer,
            deciduous: !conifer && !matches!(leaf, LeafShape::Frond | LeafShape::Fan),
            leaf,
            bark: if conifer {
                Bark::Scaly
            } else if matches!(form, Form::FeatherPalm) {
                Bark::Ringed
            } else {
                Bark::Furrowed
            },
            leaf_color: if conifer { needle } else { green },
            bark_color: if conifer { conifer_bark } else { bark },
            crown_ratio: ratio,
            params: params(form, height, ratio),
        }
    };
    vec![
        a("broadleaf-round", Form::Round, 16.0, 0.5, LeafShape::Ovate),
        a("broadleaf-oval", Form::Oval, 18.0, 0.38, LeafShape::Ovate),
        a("broadleaf-columnar", Form::Columnar, 18.0, 0.2, LeafShape::Ovate),
        a("broadleaf-spreading", Form::Spreading, 16.0, 0.75, LeafShape::Ovate),
        a("broadleaf-weeping", Form::Weeping, 12.0, 0.6, LeafShape::Linear),
        a("broadleaf-vase", Form::Vase, 18.0, 0.55, LeafShape::Ovate),
        a("conifer-spire", Form::Spire, 24.0, 0.3, LeafShape::Needles),
        a("conifer-broad", Form::BroadConifer, 20.0, 0.4, LeafShape::Needles),
        a("conifer-umbrella", Form::Umbrella, 15.0, 0.8, LeafShape::Needles),
        a("conifer-columnar", Form::ColumnarConifer, 14.0, 0.22, LeafShape::Scales),
        a("palm", Form::FeatherPalm, 10.0, 0.6, LeafShape::Frond),
        a("shrub", Form::Shrub, 4.0, 1.0, LeafShape::Ovate),
        a("multi-stem", Form::MultiStem, 12.0, 0.6, LeafShape::Ovate),
    ]
}
