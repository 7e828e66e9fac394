//! The genera grown from their crown form: one row each — family, form,
//! typical height, crown width over height at 40 cm DBH, leaf and bark, their
//! colours — with a tweak where the genus departs from its form (a field
//! guide's description: honey locust's fine foliage, the tulip tree's height,
//! the weeping tips of hemlock).

use super::forms::{params, Form};
use super::{Bark, Genus, LeafShape};
use crate::library::weber_penn::Params;

/// One genus of `form`, `height` m tall, crown width over height `ratio`.
#[allow(clippy::too_many_arguments)]
fn g(
    name: &'static str,
    family: &'static str,
    form: Form,
    height: f32,
    ratio: f32,
    leaf: LeafShape,
    bark: Bark,
    leaf_color: [u8; 3],
    bark_color: [u8; 3],
) -> Genus {
    let conifer = matches!(leaf, LeafShape::Needles | LeafShape::Scales);
    Genus {
        name,
        family,
        archetype: false,
        conifer,
        deciduous: !conifer,
        leaf,
        bark,
        leaf_color,
        bark_color,
        crown_ratio: ratio,
        params: params(form, height, ratio),
    }
}

/// The genus with its form's parameters changed by `f`.
fn tweak(mut genus: Genus, f: impl FnOnce(&mut Params)) -> Genus {
    f(&mut genus.params);
    genus
}

/// Evergreen (a broadleaf or palm that keeps its leaves).
fn evergreen(genus: Genus) -> Genus {
    Genus { deciduous: false, ..genus }
}

/// Deciduous (a conifer that sheds its needles).
fn deciduous(genus: Genus) -> Genus {
    Genus { deciduous: true, ..genus }
}

use Bark::{Banded, Fibrous, Furrowed, Patchy, Ringed, Scaly, Smooth};
use Form::{
    ColumnarConifer, FanPalm, FeatherPalm, MultiStem, Open, Oval, Pyramidal, Round, Shrub, Small, Spire, Spreading,
    Tiered, Vase,
};
use LeafShape::{Fan, Frond, Linear, Lobed, Needles, Ovate, Palmate, Pinnate, Scales};

/// The genera from their forms (ratios at 40 cm DBH: docs/ALLOMETRY.md's
/// equations for Aesculus, Alnus, Carpinus, Castanea, Fraxinus, Gleditsia,
/// Prunus, Pseudotsuga, Robinia, Ulmus; the others from their form).
#[allow(clippy::too_many_lines)]
pub(super) fn genera() -> Vec<Genus> {
    vec![
        // Broadleaves.
        g("Fraxinus", "Oleaceae", Oval, 24.0, 0.34, Pinnate, Furrowed, [78, 114, 50], [120, 116, 104]),
        g("Ulmus", "Ulmaceae", Vase, 22.0, 0.49, Ovate, Furrowed, [64, 100, 42], [96, 84, 72]),
        g("Carpinus", "Betulaceae", Round, 15.0, 0.69, Ovate, Smooth, [76, 112, 46], [130, 128, 120]),
        g("Castanea", "Fagaceae", Spreading, 18.0, 0.64, Linear, Furrowed, [70, 104, 40], [92, 80, 66]),
        g("Aesculus", "Sapindaceae", Oval, 20.0, 0.35, Palmate, Scaly, [60, 100, 40], [100, 92, 80]),
        g("Robinia", "Fabaceae", Open, 20.0, 0.28, Pinnate, Furrowed, [92, 126, 56], [104, 90, 74]),
        tweak(g("Gleditsia", "Fabaceae", Open, 18.0, 0.5, Pinnate, Furrowed, [110, 138, 60], [80, 70, 62]), |p| {
            p.leaf_scale *= 0.8;
        }),
        g("Prunus", "Rosaceae", Oval, 12.0, 0.34, Ovate, Banded, [74, 108, 44], [110, 70, 64]),
        g("Malus", "Rosaceae", Small, 7.0, 0.9, Ovate, Scaly, [74, 110, 46], [104, 90, 76]),
        g("Pyrus", "Rosaceae", Oval, 12.0, 0.5, Ovate, Scaly, [66, 104, 44], [90, 80, 70]),
        g("Sorbus", "Rosaceae", Oval, 12.0, 0.5, Pinnate, Smooth, [80, 114, 50], [120, 112, 100]),
        g("Crataegus", "Rosaceae", Small, 7.0, 0.9, Lobed, Scaly, [70, 106, 44], [110, 100, 88]),
        g("Alnus", "Betulaceae", Pyramidal, 18.0, 0.45, Ovate, Furrowed, [52, 88, 40], [80, 74, 66]),
        g("Corylus", "Betulaceae", Shrub, 6.0, 1.0, Ovate, Smooth, [84, 118, 50], [120, 100, 80]),
        g("Juglans", "Juglandaceae", Spreading, 20.0, 0.6, Pinnate, Furrowed, [76, 108, 48], [110, 104, 96]),
        g("Liquidambar", "Altingiaceae", Pyramidal, 20.0, 0.45, Palmate, Furrowed, [60, 98, 44], [98, 88, 76]),
        tweak(
            g("Liriodendron", "Magnoliaceae", Oval, 28.0, 0.4, Lobed, Furrowed, [82, 120, 52], [112, 106, 94]),
            |p| {
                p.base_size = 0.3;
            },
        ),
        tweak(g("Magnolia", "Magnoliaceae", Round, 12.0, 0.7, Ovate, Smooth, [56, 92, 40], [140, 136, 126]), |p| {
            p.leaf_scale *= 1.3;
            p.leaves = 18;
        }),
        tweak(
            g("Catalpa", "Bignoniaceae", Spreading, 12.0, 0.8, Ovate, Furrowed, [96, 130, 58], [110, 100, 86]),
            |p| {
                p.leaf_scale *= 1.4;
                p.leaves = 16;
            },
        ),
        evergreen(tweak(
            g("Eucalyptus", "Myrtaceae", Open, 30.0, 0.45, Linear, Patchy, [98, 120, 92], [190, 180, 160]),
            |p| {
                p.leaf_scale *= 1.3;
                p.leaves = 28;
            },
        )),
        g("Ginkgo", "Ginkgoaceae", Pyramidal, 20.0, 0.45, Fan, Furrowed, [96, 134, 58], [110, 100, 88]),
        g("Ailanthus", "Simaroubaceae", Open, 18.0, 0.5, Pinnate, Smooth, [86, 120, 50], [130, 122, 108]),
        g("Morus", "Moraceae", Round, 10.0, 0.9, Ovate, Furrowed, [70, 110, 44], [120, 100, 76]),
        g("Zelkova", "Ulmaceae", Vase, 18.0, 0.6, Ovate, Patchy, [72, 108, 44], [130, 118, 104]),
        g("Celtis", "Cannabaceae", Round, 16.0, 0.55, Ovate, Smooth, [80, 112, 50], [140, 134, 122]),
        evergreen(g("Olea", "Oleaceae", MultiStem, 8.0, 0.9, Linear, Furrowed, [110, 124, 92], [120, 112, 100])),
        // Palms.
        evergreen(g("Phoenix", "Arecaceae", FeatherPalm, 12.0, 0.6, Frond, Ringed, [72, 104, 52], [130, 110, 84])),
        evergreen(g("Washingtonia", "Arecaceae", FanPalm, 20.0, 0.25, Fan, Ringed, [76, 110, 56], [120, 104, 84])),
        evergreen(g("Trachycarpus", "Arecaceae", FanPalm, 8.0, 0.45, Fan, Fibrous, [60, 94, 48], [80, 64, 50])),
        // Conifers.
        g("Pseudotsuga", "Pinaceae", Spire, 35.0, 0.36, Needles, Furrowed, [44, 78, 46], [104, 80, 64]),
        tweak(g("Tsuga", "Pinaceae", Spire, 25.0, 0.4, Needles, Furrowed, [40, 78, 48], [100, 78, 64]), |p| {
            p.attraction_up = -0.3;
            p.leaf_scale *= 0.8;
        }),
        g("Cedrus", "Pinaceae", Tiered, 25.0, 0.6, Needles, Scaly, [70, 96, 88], [90, 84, 78]),
        g("Thuja", "Cupressaceae", ColumnarConifer, 15.0, 0.3, Scales, Fibrous, [52, 92, 44], [120, 90, 70]),
        g("Chamaecyparis", "Cupressaceae", Spire, 18.0, 0.35, Scales, Fibrous, [52, 86, 60], [116, 88, 70]),
        g("Cupressus", "Cupressaceae", ColumnarConifer, 18.0, 0.18, Scales, Fibrous, [44, 74, 44], [112, 96, 80]),
        g("Juniperus", "Cupressaceae", ColumnarConifer, 8.0, 0.4, Scales, Fibrous, [60, 88, 66], [120, 90, 72]),
        g("Calocedrus", "Cupressaceae", ColumnarConifer, 25.0, 0.25, Scales, Fibrous, [48, 88, 46], [130, 80, 56]),
        g("Sequoia", "Cupressaceae", Spire, 40.0, 0.3, Needles, Fibrous, [46, 80, 44], [130, 74, 50]),
        g("Sequoiadendron", "Cupressaceae", Spire, 45.0, 0.35, Scales, Fibrous, [64, 92, 58], [150, 86, 56]),
        deciduous(g("Metasequoia", "Cupressaceae", Spire, 25.0, 0.35, Needles, Fibrous, [80, 120, 62], [130, 84, 60])),
        deciduous(g("Taxodium", "Cupressaceae", Spire, 25.0, 0.4, Needles, Fibrous, [76, 112, 58], [120, 86, 64])),
        g("Taxus", "Taxaceae", MultiStem, 10.0, 0.8, Needles, Patchy, [30, 58, 34], [120, 70, 52]),
    ]
}
