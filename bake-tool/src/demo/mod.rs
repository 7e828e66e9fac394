//! `sylva-bake demo`: a complete procedural scene with no input files.
//!
//! Three species (spruce, beech, birch) built from a tapered trunk, branches and
//! alpha-textured leaf cards with procedurally drawn textures; a forest layout
//! with clumps, clearings and species zones from value noise at a density like
//! a managed Central European forest, on gently rolling ground, placed in
//! UTM 33N (EPSG:32633) around the Wachau (E ≈ 540 000, N ≈ 5 360 000), far from
//! the origin so every run exercises the precision path.

pub mod country;

use glam::{DVec3, Quat, Vec2, Vec3};
use sylva::format::pack::MaterialKind;

use crate::bake::batching::SceneTree;
use crate::input::gltf_import::{ImportedMaterial, ImportedModel, ImportedVertex};

/// Demo scene origin in EPSG:32633.
pub const DEMO_ORIGIN: DVec3 = DVec3::new(540_000.0, 5_360_000.0, 0.0);
/// Demo CRS.
pub const DEMO_EPSG: u32 = 32633;

pub use crate::rng::Rng;

use crate::rng::{fbm, value_noise};

/// Crown radius (metres) of a demo tree of species `species` at `scale`.
pub fn crown_radius_m(species: u32, scale: f32) -> f64 {
    let s = &STYLES[(species as usize).min(STYLES.len() - 1)];
    f64::from(s.height * s.crown_radius * scale)
}

/// Signed distance (metres, roughly) from the demo valley's stream: the
/// stream meanders west–east through the origin.
pub fn valley_offset(x: f64, y: f64) -> f64 {
    y - (70.0 * (x / 260.0).sin() + 45.0 * (x / 610.0).sin())
}

/// The demo's ground imagery at `(x, y)`: the forest floor by canopy cover
/// and slope ([`crate::bake::ground_material::forest_floor`]), a stream of a
/// few metres along the valley with gravel banks, and a meadow beside it.
pub fn ground_colour(x: f64, y: f64, cover: f32, slope: f32) -> [f32; 4] {
    let d = valley_offset(x, y).abs() + 2.0 * (fbm(97, x, y, 40.0) - 0.5);
    let mut c = crate::bake::ground_material::forest_floor(x, y, cover, slope);
    let water = [58.0, 66.0, 70.0];
    let gravel = [150.0, 140.0, 120.0];
    let t = |a: f64, b: f64| ((d - a) / (b - a)).clamp(0.0, 1.0) as f32;
    for k in 0..3 {
        let bank = water[k] + (gravel[k] - water[k]) * t(2.0, 3.0);
        c[k] = bank + (c[k] - bank) * t(3.5, 6.0);
    }
    c
}

/// Ground height of the demo terrain (metres above the origin): a valley
/// through the origin whose slopes rise about 60 m to ridges on both sides,
/// cut by side gullies, over rolling hills.
pub fn ground(x: f64, y: f64) -> f64 {
    let d = valley_offset(x, y);
    let across = 1.0 - (-(d / 230.0).powi(2)).exp();
    // Side gullies and spurs running down the slopes, fading out on the valley floor.
    let spurs = 9.0 * (x / 95.0 + d.abs() / 170.0).sin() * (1.0 - (-(d / 110.0).powi(2)).exp());
    // The valley floor falls gently eastwards.
    58.0 * across + spurs - 0.01 * x + 20.0 * fbm(99, x, y, 900.0) + 1.5 * fbm(98, x, y, 150.0)
}

#[derive(Clone, Copy)]
struct SpeciesStyle {
    name: &'static str,
    height: f32,
    conifer: bool,
    bark: [u8; 3],
    leaf: [u8; 3],
    crown_base: f32,
    crown_radius: f32,
}

const STYLES: [SpeciesStyle; 3] = [
    SpeciesStyle {
        name: "spruce",
        height: 28.0,
        conifer: true,
        bark: [92, 66, 48],
        leaf: [34, 74, 38],
        crown_base: 0.15,
        crown_radius: 0.22,
    },
    SpeciesStyle {
        name: "beech",
        height: 24.0,
        conifer: false,
        bark: [128, 124, 116],
        leaf: [78, 128, 46],
        crown_base: 0.35,
        crown_radius: 0.36,
    },
    SpeciesStyle {
        name: "birch",
        height: 19.0,
        conifer: false,
        bark: [222, 218, 206],
        leaf: [118, 152, 58],
        crown_base: 0.4,
        crown_radius: 0.22,
    },
];

/// Builds the three demo tree models.
pub fn demo_models(seed: u64) -> Vec<(String, ImportedModel)> {
    STYLES
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let mut tree = make_tree(s, seed.wrapping_add(i as u64 * 7919));
            // Beech and birch are deciduous: their seasons, as their genera's.
            tree.autumn = crate::library::choose::autumn_of(s.name);
            tree.genus = crate::library::choose::deciduous_genus_of(s.name).map(str::to_string);
            (s.name.to_string(), tree)
        })
        .collect()
}

fn leaf_texture(style: &SpeciesStyle, seed: u64) -> image::RgbaImage {
    let size = 128u32;
    let mut img =
        image::RgbaImage::from_pixel(size, size, image::Rgba([style.leaf[0], style.leaf[1], style.leaf[2], 0]));
    let mut rng = Rng::new(seed);
    let shapes = if style.conifer { 40 } else { 7 };
    for _ in 0..shapes {
        let c = Vec2::new(rng.range(0.2, 0.8), rng.range(0.15, 0.85)) * size as f32;
        let angle = rng.range(0.0, std::f32::consts::TAU);
        let (len, width) =
            if style.conifer { (rng.range(14.0, 22.0), 1.6) } else { (rng.range(20.0, 30.0), rng.range(8.0, 12.0)) };
        let dir = Vec2::from_angle(angle);
        let shade = rng.range(0.75, 1.2);
        for y in 0..size {
            for x in 0..size {
                let p = Vec2::new(x as f32 + 0.5, y as f32 + 0.5) - c;
                let u = p.dot(dir) / len;
                let v = p.perp_dot(dir) / width;
                // Leaf: an ellipse pointed at both ends; needle: a thin line.
                let inside = if style.conifer {
                    u.abs() < 1.0 && v.abs() < 1.0
                } else {
                    u * u + v * v / (1.0 - u * u).max(0.05) < 1.0
                };
                if inside {
                    let vein = if !style.conifer && v.abs() < 0.12 { 1.25 } else { 1.0 };
                    let k = shade * vein * (1.0 - 0.25 * u.abs());
                    let col = style.leaf.map(|ch| (f32::from(ch) * k).clamp(0.0, 255.0) as u8);
                    img.put_pixel(x, y, image::Rgba([col[0], col[1], col[2], 255]));
                }
            }
        }
    }
    img
}

fn bark_texture(style: &SpeciesStyle, seed: u64) -> image::RgbaImage {
    let size = 64u32;
    image::RgbaImage::from_fn(size, size, |x, y| {
        let n = value_noise(seed, f64::from(x) / 3.0, f64::from(y) / 12.0) as f32;
        let stripe =
            if style.name == "birch" && value_noise(seed + 1, 0.0, f64::from(y) / 5.0) > 0.7 { 0.35 } else { 1.0 };
        let k = (0.7 + 0.6 * n) * stripe;
        let c = style.bark.map(|ch| (f32::from(ch) * k).clamp(0.0, 255.0) as u8);
        image::Rgba([c[0], c[1], c[2], 255])
    })
}

struct Builder {
    model: ImportedModel,
}

impl Builder {
    fn vertex(&mut self, position: Vec3, normal: Vec3, uv: Vec2, material: u16) -> u32 {
        self.model.vertices.push(ImportedVertex {
            position,
            normal: normal.normalize_or(Vec3::Z),
            uv,
            color: [1.0; 4],
            material,
        });
        (self.model.vertices.len() - 1) as u32
    }

    /// A tapered cylinder from `a` (radius `ra`) to `b` (radius `rb`).
    fn limb(&mut self, a: Vec3, b: Vec3, ra: f32, rb: f32, sides: u32) {
        let axis = (b - a).normalize_or(Vec3::Z);
        let side = axis.any_orthonormal_vector();
        let other = axis.cross(side);
        let len = (b - a).length();
        let base = self.model.vertices.len() as u32;
        for ring in 0..2 {
            let (c, r) = if ring == 0 { (a, ra) } else { (b, rb) };
            for s in 0..=sides {
                let t = s as f32 / sides as f32 * std::f32::consts::TAU;
                let n = side * t.cos() + other * t.sin();
                self.vertex(c + n * r, n, Vec2::new(s as f32 / sides as f32, ring as f32 * len / 2.0), 0);
            }
        }
        for s in 0..sides {
            let (i0, i1) = (base + s, base + s + 1);
            let (j0, j1) = (i0 + sides + 1, i1 + sides + 1);
            self.model.triangles.push([i0, i1, j1]);
            self.model.triangles.push([i0, j1, j0]);
        }
    }

    /// A leaf card: a quad of half size `half` centred at `c`, facing `normal`.
    fn card(&mut self, c: Vec3, normal: Vec3, up: Vec3, half: Vec2) {
        let right = up.cross(normal).normalize_or(Vec3::X);
        let up = normal.cross(right).normalize_or(Vec3::Z);
        let corners = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)];
        let base = self.model.vertices.len() as u32;
        for (x, y) in corners {
            let p = c + right * (x * half.x) + up * (y * half.y);
            self.vertex(p, normal, Vec2::new((x + 1.0) * 0.5, (1.0 - y) * 0.5), 1);
        }
        self.model.triangles.push([base, base + 1, base + 2]);
        self.model.triangles.push([base, base + 2, base + 3]);
    }
}

/// A broadleaf demo tree with about `leaves` leaf cards (smaller cards for more
/// leaves, so the crown keeps its size): the bake benchmarks' large trees.
#[must_use]
pub fn tree_with_leaves(leaves: usize, seed: u64) -> ImportedModel {
    make_tree_scaled(&STYLES[1], seed, leaves as f32 / (14.0 * 24.0 + 6.0))
}

fn make_tree(style: &SpeciesStyle, seed: u64) -> ImportedModel {
    make_tree_scaled(style, seed, 1.0)
}

fn make_tree_scaled(style: &SpeciesStyle, seed: u64, leaf_scale: f32) -> ImportedModel {
    let mut rng = Rng::new(seed);
    let mut b = Builder {
        model: ImportedModel {
            materials: vec![
                ImportedMaterial {
                    name: format!("{}_bark", style.name),
                    kind: MaterialKind::Branch,
                    base_color: [1.0; 4],
                    alpha_cutoff: 0.0,
                    double_sided: false,
                    texture: Some(bark_texture(style, seed)),
                    blended: false,
                },
                ImportedMaterial {
                    name: format!("{}_leaves", style.name),
                    kind: MaterialKind::Leaf,
                    base_color: [1.0; 4],
                    alpha_cutoff: 0.5,
                    double_sided: true,
                    texture: Some(leaf_texture(style, seed + 1)),
                    blended: false,
                },
            ],
            ..Default::default()
        },
    };
    let h = style.height;
    let trunk_r = h * 0.018;
    // Trunk in two segments with a slight lean.
    let lean = Vec3::new(rng.range(-0.02, 0.02), rng.range(-0.02, 0.02), 1.0);
    let mid = lean * h * 0.5;
    let top = lean * h * 0.97;
    b.limb(Vec3::ZERO, mid, trunk_r, trunk_r * 0.65, 8);
    b.limb(mid, top, trunk_r * 0.65, trunk_r * 0.1, 6);
    let branches = if style.conifer { 26 } else { 14 };
    let crown_h = h * (1.0 - style.crown_base);
    for i in 0..branches {
        let t = style.crown_base + (1.0 - style.crown_base) * (i as f32 + rng.range(0.0, 0.8)) / branches as f32;
        let start = lean * h * t;
        // Crown profile: cone for conifers, ellipsoid for broadleaves.
        let rel = (t - style.crown_base) / (1.0 - style.crown_base);
        let reach = if style.conifer {
            h * style.crown_radius * (1.0 - rel).max(0.08)
        } else {
            h * style.crown_radius * (1.0 - (2.0 * rel - 1.0).powi(2)).max(0.1).sqrt()
        };
        let azimuth = i as f32 * 2.39996 + rng.range(-0.3, 0.3);
        let rise = if style.conifer { -0.15 } else { 0.45 };
        let dir = Vec3::new(azimuth.cos(), azimuth.sin(), rise).normalize();
        let end = start + dir * reach;
        b.limb(start, end, trunk_r * 0.35 * (1.0 - rel * 0.6), trunk_r * 0.06, 5);
        // Leaf cards along and around the branch.
        let cards = ((if style.conifer { 16.0 } else { 24.0 }) * leaf_scale).round() as usize;
        for _ in 0..cards {
            let along = rng.range(0.25, 1.0);
            let jitter = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-0.6, 0.6))
                * (reach * 0.3 + crown_h * 0.02);
            let c = start + (end - start) * along + jitter;
            let normal =
                Quat::from_euler(glam::EulerRot::XYZ, rng.range(-1.2, 1.2), rng.range(-1.2, 1.2), rng.range(0.0, 6.3))
                    * Vec3::Z;
            let size = h * if style.conifer { 0.055 } else { 0.05 } * rng.range(0.8, 1.2) / leaf_scale.max(1.0).sqrt();
            b.card(c, normal, dir, Vec2::new(size, size));
        }
    }
    // A tuft at the top.
    for _ in 0..((6.0 * leaf_scale).round() as usize) {
        let c = top + Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.5, 0.0)) * h * 0.03;
        let normal = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-0.3, 1.0)).normalize_or(Vec3::Z);
        b.card(c, normal, Vec3::Z, Vec2::splat(h * 0.04));
    }
    b.model
}

/// Places `count` trees: species zones, clumps and clearings from noise fields,
/// positions relative to [`DEMO_ORIGIN`] (heights on [`ground`]).
pub fn demo_layout(count: usize, seed: u64) -> Vec<SceneTree> {
    // About 450 trees per hectare where the forest is dense; the area grows with the count.
    let area_m2 = count as f64 / 450.0 * 10_000.0 * 1.8;
    let half = area_m2.sqrt() * 0.5;
    // Noise periods shrink with small scenes so every demo has clearings and all species.
    let k = (half / 1000.0).clamp(0.12, 1.0);
    let mut rng = Rng::new(seed);
    let mut trees = Vec::with_capacity(count);
    let mut attempts = 0u64;
    while trees.len() < count && attempts < count as u64 * 200 {
        attempts += 1;
        let x = f64::from(rng.f32()) * 2.0 * half - half;
        let y = f64::from(rng.f32()) * 2.0 * half - half;
        let density = fbm(seed + 1, x, y, 400.0 * k);
        let clump = fbm(seed + 2, x, y, 60.0 * k.sqrt());
        // Clearings where the density field is low; clumps where both are high;
        // meadows along the stream.
        let meadow = ((valley_offset(x, y).abs() - 18.0) / 40.0).clamp(0.0, 1.0);
        let p = ((density - 0.38) * 3.0).clamp(0.0, 1.0) * (0.55 + 0.45 * clump) * meadow;
        if f64::from(rng.f32()) > p {
            continue;
        }
        let zone = fbm(seed + 3, x, y, 700.0 * k);
        let z = ground(x, y);
        // Spruce higher up, birch in patches, beech elsewhere.
        let birch_patch = fbm(seed + 4, x, y, 120.0 * k.sqrt());
        let species = if zone + z / 300.0 > 0.6 {
            0
        } else if birch_patch > 0.58 {
            2
        } else {
            1
        };
        let id = trees.len() as u64;
        trees.push(SceneTree {
            pos: DVec3::new(x, y, z),
            species,
            scale: rng.range(0.7, 1.15),
            // The demo's trees keep their models' proportions.
            aspect: 1.0,
            yaw_rad: rng.range(0.0, std::f32::consts::TAU),
            variation: (rng.next_u64() % 32) as u8,
            id,
            row: 0,
            dated: false,
        });
    }
    trees
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_is_deterministic_and_has_all_species() {
        let a = demo_layout(20_000, 5);
        let b = demo_layout(20_000, 5);
        assert_eq!(a, b);
        assert_eq!(a.len(), 20_000);
        for s in 0..3 {
            assert!(a.iter().filter(|t| t.species == s).count() > 1000, "species {s} is rare");
        }
    }

    #[test]
    fn models_have_leaves_and_wood() {
        for (name, m) in demo_models(1) {
            let (leaf, wood) = m.triangle_counts();
            assert!(leaf > 200 && wood > 100, "{name}: {leaf} leaf, {wood} wood triangles");
            assert!(m.height() > 10.0);
        }
    }
}
