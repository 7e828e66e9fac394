//! The library's own textures, drawn per genus: a leaf card (one blade of
//! the genus's shape, or a spray of needles or scales) and a bark tile.

use glam::Vec2;

use super::genera::{Bark, Genus, LeafShape};
use crate::rng::{value_noise, Rng};

/// Leaf card side (px).
const LEAF_PX: u32 = 64;
/// Bark tile side (px).
const BARK_PX: u32 = 64;

/// Whether `p` (the card in [-1, 1]², the stalk at y = −1, the tip at +1) lies
/// on a blade of `shape`, and its shade there (veins lighter, edges darker).
fn blade(shape: LeafShape, p: Vec2, rng_lobes: f32) -> Option<f32> {
    // u across, v along the blade (0 at the stalk, 1 at the tip).
    let u = p.x;
    let v = (p.y + 1.0) * 0.5;
    let vein = |w: f32| if u.abs() < 0.06 * w { 1.2 } else { 1.0 };
    match shape {
        LeafShape::Ovate => {
            // Widest a third of the way up, pointed at the tip.
            let w = 0.85 * (std::f32::consts::PI * v.powf(0.8)).sin();
            (u.abs() < w && v > 0.04).then(|| vein(1.0) * (1.0 - 0.2 * u.abs() / w.max(1e-3)))
        }
        LeafShape::Lobed => {
            // An oak's blade: rounded lobes along its sides.
            let w = 0.8 * (std::f32::consts::PI * v).sin() * (0.72 + 0.28 * (v * 5.0 * std::f32::consts::TAU).cos());
            (u.abs() < w && v > 0.04).then(|| vein(1.0) * (1.0 - 0.2 * u.abs() / w.max(1e-3)))
        }
        LeafShape::Palmate => {
            // A maple's or plane's: five pointed lobes from the stalk.
            let c = Vec2::new(0.0, -0.45);
            let d = p - c;
            let a = d.y.atan2(d.x);
            let lobes = (0.5 + 0.5 * (5.0 * (a - std::f32::consts::FRAC_PI_2)).cos()).powf(1.5);
            let r = 0.45 + 0.5 * lobes + 0.05 * rng_lobes;
            (d.length() < r && d.y > -0.35).then(|| 1.0 - 0.25 * d.length() / r)
        }
        LeafShape::Linear => {
            // A willow's: long and narrow.
            let w = 0.28 * (std::f32::consts::PI * v).sin();
            (u.abs() < w && v > 0.02).then(|| vein(0.5))
        }
        LeafShape::Pinnate => {
            // Leaflets in pairs along a stalk, one at the tip.
            let rib = u.abs() < 0.05;
            let k = (v * 4.0).floor().min(3.0);
            let centre = Vec2::new(0.5 * u.signum(), (k + 0.55) / 4.0);
            let q = Vec2::new((u.abs() - centre.x.abs()) / 0.42, (v - centre.y - 0.12 * (u.abs() - 0.5)) / 0.1);
            let tip = Vec2::new(u / 0.18, (v - 0.88) / 0.12);
            let leaflet = (q.length_squared() < 1.0 && v < 0.8) || tip.length_squared() < 1.0;
            ((rib && v < 0.9) || leaflet).then(|| if rib { 0.85 } else { 1.0 - 0.2 * q.x.abs().min(1.0) })
        }
        LeafShape::Fan => {
            // A fan from the stalk: ginkgo's notched, a fan palm's split into ribs.
            let d = p - Vec2::new(0.0, -0.9);
            let a = d.x.atan2(d.y);
            let ribs = ((a * 9.0).fract().abs() - 0.5).abs() > 0.08;
            let stalk = d.length() < 0.45 && u.abs() < 0.05;
            (stalk || (a.abs() < 1.2 && d.length() < 1.75 && d.length() > 0.4 && ribs))
                .then(|| 1.0 - 0.25 * (a.abs() / 1.2))
        }
        LeafShape::Needles => {
            // A spray: needles from a twig along the card's middle, leaning forward.
            let twig = u.abs() < 0.04;
            let along = (v * 14.0).fract();
            let needle = (u.abs() - along * 0.9).abs() < 0.07 && u.abs() < 0.92;
            (twig || needle).then_some(if twig { 0.7 } else { 1.0 - 0.3 * u.abs() })
        }
        LeafShape::Scales => {
            // A cypress's or arborvitae's flat spray of scale leaves.
            let w = 0.75 * (std::f32::consts::PI * v).sin();
            let fan = ((u * 6.0).fract() - 0.5).abs() < 0.38 || u.abs() < 0.08;
            (u.abs() < w && fan && v > 0.03).then_some(1.0 - 0.25 * (u / w.max(1e-3)).abs())
        }
        LeafShape::Frond => {
            // A palm's: leaflets from a midrib.
            let rib = u.abs() < 0.05;
            let leaflet = (u.abs() * 0.6 - ((v * 12.0).fract() - 0.2) * 0.3).abs() < 0.06;
            let w = 0.95 * (std::f32::consts::PI * v).sin().sqrt();
            ((rib || leaflet) && u.abs() < w).then_some(if rib { 0.8 } else { 1.0 })
        }
    }
}

/// Blades on a broadleaf's card: a twig along the card's middle with this
/// many leaves on alternate sides (a card stands for a shoot, not one leaf).
const BLADES: usize = 7;

/// The genus's leaf card (sRGB RGBA8, alpha 0 or 255): for broadleaves a shoot
/// of [`BLADES`] leaves of the genus's outline; for conifers and palms one
/// spray or frond filling the card.
#[must_use]
pub fn leaf(g: &Genus, seed: u64) -> image::RgbaImage {
    let mut rng = Rng::new(seed ^ 0x1eaf);
    let jitter = rng.range(-1.0, 1.0);
    let [r, gr, b] = g.leaf_color;
    // Each blade: centre, direction (unit, stalk to tip), half length, shade.
    let spray = matches!(g.leaf, LeafShape::Needles | LeafShape::Scales | LeafShape::Frond) || g.family == "Arecaceae";
    let blades: Vec<(Vec2, Vec2, f32, f32)> = if spray {
        vec![(Vec2::ZERO, Vec2::Y, 1.0, 1.0)]
    } else {
        (0..BLADES)
            .map(|i| {
                let along = -0.75 + 1.55 * (i as f32 + 0.5) / BLADES as f32;
                let side = if i % 2 == 0 { 1.0 } else { -1.0 };
                let tip = i + 1 == BLADES;
                let angle = if tip { 0.0 } else { side * rng.range(0.6, 0.95) };
                let dir = Vec2::new(angle.sin(), angle.cos());
                let half = if tip { 0.34 } else { rng.range(0.3, 0.38) };
                let centre = Vec2::new(0.0, along) + dir * half * 0.95;
                (centre, dir, half, rng.range(0.8, 1.15))
            })
            .collect()
    };
    image::RgbaImage::from_fn(LEAF_PX, LEAF_PX, |x, y| {
        let p = Vec2::new((x as f32 + 0.5) / LEAF_PX as f32 * 2.0 - 1.0, 1.0 - (y as f32 + 0.5) / LEAF_PX as f32 * 2.0);
        // (The blades stay inside the card's margin.)
        let p = p / 0.92;
        if p.abs().max_element() > 1.0 {
            return image::Rgba([r, gr, b, 0]);
        }
        let twig = !spray && p.x.abs() < 0.03 && p.y > -0.95 && p.y < 0.7;
        let hit = blades.iter().rev().find_map(|&(c, dir, half, shade)| {
            // The blade's own frame: its card in [-1, 1]², the stalk at y = −1.
            let d = p - c;
            let q = Vec2::new(-d.perp_dot(dir), d.dot(dir)) / half;
            (q.abs().max_element() <= 1.0).then(|| blade(g.leaf, q, jitter)).flatten().map(|k| k * shade)
        });
        match (hit, twig) {
            (Some(k), _) => {
                let c = [r, gr, b].map(|ch| (f32::from(ch) * k).clamp(0.0, 255.0) as u8);
                image::Rgba([c[0], c[1], c[2], 255])
            }
            (None, true) => image::Rgba([g.bark_color[0], g.bark_color[1], g.bark_color[2], 255]),
            (None, false) => image::Rgba([r, gr, b, 0]),
        }
    })
}

/// The genus's bark tile (sRGB RGBA8, repeating).
#[must_use]
pub fn bark(g: &Genus, seed: u64) -> image::RgbaImage {
    let s = seed ^ 0xba2c;
    let [r, gr, b] = g.bark_color;
    image::RgbaImage::from_fn(BARK_PX, BARK_PX, |x, y| {
        let (fx, fy) = (f64::from(x), f64::from(y));
        // Periodic in x (around the stem): noise on a circle's coordinates.
        let a = fx / f64::from(BARK_PX) * std::f64::consts::TAU;
        let (cx, cy) = (a.cos() * 6.0, a.sin() * 6.0);
        let n = value_noise(s, cx + fy / 9.0, cy) as f32;
        let k = match g.bark {
            // Vertical furrows.
            Bark::Furrowed => {
                0.65 + 0.55 * (value_noise(s + 1, cx * 2.0, cy * 2.0 + fy / 20.0) as f32) * (0.6 + 0.4 * n)
            }
            // Smooth, faintly mottled.
            Bark::Smooth => 0.9 + 0.2 * n,
            // Pale with dark horizontal lenticels (birch).
            Bark::Banded => {
                if value_noise(s + 2, cx * 0.5, fy / 4.0) > 0.72 {
                    0.3
                } else {
                    0.95 + 0.1 * n
                }
            }
            // Flaking patches (plane, some pines).
            Bark::Patchy => {
                if value_noise(s + 3, cx * 0.8, cy * 0.8 + fy / 10.0) > 0.55 {
                    1.25
                } else {
                    0.85 + 0.15 * n
                }
            }
            // Scaly plates.
            Bark::Scaly => 0.7 + 0.45 * (((fy / 7.0 + n as f64 * 2.0).fract() as f32) * 0.8 + 0.2 * n),
            // Long strips (redwood, arborvitae): noise stretched along the stem.
            Bark::Fibrous => 0.55 + 0.7 * (value_noise(s + 4, cx * 3.0, cy * 3.0 + fy / 40.0) as f32).powf(1.5),
            // Rings of old leaf bases (palms).
            Bark::Ringed => {
                if (fy / 8.0 + 0.3 * n as f64).fract() < 0.22 {
                    0.6
                } else {
                    0.95 + 0.15 * n
                }
            }
        };
        let c = [r, gr, b].map(|ch| (f32::from(ch) * k).clamp(0.0, 255.0) as u8);
        image::Rgba([c[0], c[1], c[2], 255])
    })
}

#[cfg(test)]
mod tests {
    use super::super::GENERA;
    use super::*;

    #[test]
    fn every_leaf_card_has_a_blade_and_a_margin() {
        for g in GENERA.iter() {
            let img = leaf(g, 5);
            let opaque = img.pixels().filter(|p| p.0[3] == 255).count();
            let share = opaque as f32 / (LEAF_PX * LEAF_PX) as f32;
            assert!((0.08..0.8).contains(&share), "{}: {share:.2} of the card is leaf", g.name);
            let edge = (0..LEAF_PX).all(|i| img.get_pixel(i, 0).0[3] == 0 && img.get_pixel(0, i).0[3] == 0);
            assert!(edge, "{}: the card's edge must be clear (mips and cut-outs)", g.name);
        }
    }
}
