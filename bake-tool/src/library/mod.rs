//! The built-in species library: trees generated per genus from botanical
//! form (Weber & Penn 1995, [`weber_penn`]), with their own procedurally drawn
//! leaf and bark textures, as an [`ImportedModel`] like a glTF's — so every
//! tier the bake makes works on them unchanged.
//!
//! `--model NAME=library:GENUS` takes one (`sylva-bake library list` names
//! them). The genera's parameters are in [`genera`]; each says its crown form,
//! leaf shape and colours.

pub mod choose;
pub mod genera;
mod textures;
pub mod weber_penn;

use glam::{Vec2, Vec3};

use crate::input::gltf_import::{ImportedMaterial, ImportedModel, ImportedVertex};
pub use genera::{Genus, LeafShape, ARCHETYPES, GENERA};
use sylva::format::pack::MaterialKind;
use weber_penn::{Params, Skeleton};

/// Sides of a stem's tube per level (trunk first); deeper levels take the last.
const SIDES: [u32; 4] = [10, 6, 4, 3];

/// The genus a `--model` path names as `library:GENUS` (or `library:GENUS:VARIANT`).
#[must_use]
pub fn spec(path: &str) -> Option<&str> {
    path.strip_prefix("library:")
}

/// The model a `library:` spec names: `GENUS` (with its [`VARIANTS`]
/// variants, trees assigned one each) or `GENUS:VARIANT` (that one alone).
///
/// # Errors
/// An unknown genus (the error lists the library's) or variant.
pub fn model_named(spec: &str) -> anyhow::Result<ImportedModel> {
    let (name, variant) = match spec.split_once(':') {
        Some((n, v)) => {
            let v: u64 =
                v.trim().parse().map_err(|_| anyhow::anyhow!("library:{spec}: the variant {v:?} is no number"))?;
            (n, Some(v))
        }
        None => (spec, None),
    };
    let Some(g) = entry(name) else {
        let names: Vec<&str> = GENERA.iter().map(|g| g.name).collect();
        let forms: Vec<&str> = ARCHETYPES.iter().map(|g| g.name).collect();
        anyhow::bail!(
            "library:{spec}: no genus or archetype {name:?} in the library (genera: {}; archetypes: {})",
            names.join(", "),
            forms.join(", ")
        );
    };
    Ok(match variant {
        Some(v) => model(g, v),
        None => model_variants(g, VARIANTS),
    })
}

/// The seed of a genus's variant.
#[must_use]
pub fn variant_seed(g: &Genus, variant: u64) -> u64 {
    crate::rng::hash64(
        g.name.bytes().fold(variant.wrapping_mul(0x9e37_79b9), |h, b| h.wrapping_mul(31).wrapping_add(u64::from(b))),
    )
}

/// The genus named `name` (case-insensitive, Latin), if the library has it.
#[must_use]
pub fn genus(name: &str) -> Option<&'static Genus> {
    let n = name.trim();
    GENERA.iter().find(|g| g.name.eq_ignore_ascii_case(n))
}

/// The genus or archetype named `name` (case-insensitive).
#[must_use]
pub fn entry(name: &str) -> Option<&'static Genus> {
    let n = name.trim();
    genus(n).or_else(|| ARCHETYPES.iter().find(|g| g.name.eq_ignore_ascii_case(n)))
}

/// Variant `variant` of the tree of `genus`: stems as tubes, leaves as
/// alpha-tested cards, with the genus's textures. Metres, Z up, the trunk's
/// base at the origin. Every variant of a genus has variant 0's structure
/// ([`weber_penn::grow_variant`]) and textures: the same vertices and
/// triangles in the same order, only where they are differs.
#[must_use]
pub fn model(genus: &Genus, variant: u64) -> ImportedModel {
    let structure = variant_seed(genus, 0);
    let skeleton = weber_penn::grow_variant(&fitted(genus), structure, variant_seed(genus, variant));
    build(genus, &skeleton, structure)
}

/// The tree of `genus` with its `count` variants (at least 1): variant 0 as
/// the model, the others as its [`ImportedModel::variants`], each stretched
/// to variant 0's height and crown width — its stems' axes and its leaves'
/// places, not their girth or size — so that every variant of a tree stands
/// as tall and as wide as the inventory says.
#[must_use]
pub fn model_variants(genus: &Genus, count: u64) -> ImportedModel {
    let params = fitted(genus);
    let structure = variant_seed(genus, 0);
    let first = weber_penn::grow_variant(&params, structure, structure);
    let (w0, h0) = extent(&first);
    let mut m = build(genus, &first, structure);
    for v in 1..count.max(1) {
        let mut t = weber_penn::grow_variant(&params, structure, variant_seed(genus, v));
        let (w, h) = extent(&t);
        let s = Vec3::new(w0 / w, w0 / w, h0 / h);
        for stem in &mut t.stems {
            for (p, _) in &mut stem.points {
                *p *= s;
            }
        }
        for leaf in &mut t.leaves {
            leaf.centre *= s;
        }
        let other = build(genus, &t, structure);
        m.variants.push(other.vertices.iter().map(|x| [x.position, x.normal]).collect());
    }
    m
}

/// Variants the library fits its genera over (and the bake draws).
pub const VARIANTS: u64 = 3;

/// The genus's parameters fitted so that its variants stand, on average, as
/// tall as the genus's typical height (`params.scale`, the trunk's length)
/// with the genus's `crown_ratio`: the branches' length (level 1, which the
/// deeper levels follow) and the trunk's scaled a few times each, as the
/// crown's width is nearly proportional to the one and the tree's height to
/// the other. Fitted once per genus.
#[must_use]
pub fn fitted(genus: &Genus) -> Params {
    static FITTED: std::sync::LazyLock<std::sync::Mutex<std::collections::HashMap<&'static str, Params>>> =
        std::sync::LazyLock::new(Default::default);
    if let Some(p) = FITTED.lock().ok().and_then(|m| m.get(genus.name).cloned()) {
        return p;
    }
    let mut p = genus.params.clone();
    if p.levels.len() >= 2 && genus.crown_ratio > 0.0 {
        let structure = variant_seed(genus, 0);
        let height = genus.params.scale;
        for _ in 0..8 {
            let (mut w, mut h) = (0.0, 0.0);
            for v in 0..VARIANTS {
                let (vw, vh) = extent(&weber_penn::grow_variant(&p, structure, variant_seed(genus, v)));
                w += vw / VARIANTS as f32;
                h += vh / VARIANTS as f32;
            }
            let (kh, kr) = (height / h, genus.crown_ratio / (w / h));
            if !(kh.is_finite() && kr.is_finite()) || ((kh - 1.0).abs() < 0.01 && (kr - 1.0).abs() < 0.01) {
                break;
            }
            p.scale *= kh.clamp(0.33, 3.0);
            p.scale_v *= kh.clamp(0.33, 3.0);
            p.levels[1].length *= kr.clamp(0.33, 3.0);
        }
    }
    if let Ok(mut m) = FITTED.lock() {
        m.insert(genus.name, p.clone());
    }
    p
}

/// Crown width (the mean of the x and y extents) and height of a grown tree,
/// stems (their tubes across, their axes up) and leaf cards, as the model's
/// bounds measure them.
#[must_use]
pub fn extent(t: &Skeleton) -> (f32, f32) {
    let (mut lo, mut hi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
    for s in &t.stems {
        for &(p, r) in &s.points {
            let r = Vec3::new(r, r, 0.0);
            lo = lo.min(p - r);
            hi = hi.max(p + r);
        }
    }
    for l in &t.leaves {
        let right = l.tip.cross(l.normal).normalize_or(Vec3::X) * (l.size.y * 0.5);
        let up = l.tip * (l.size.x * 0.5);
        for p in [l.centre - right - up, l.centre + right - up, l.centre + right + up, l.centre - right + up] {
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    let size = hi - lo;
    ((size.x + size.y) * 0.5, size.z.max(1e-3))
}

/// The model of a grown skeleton.
fn build(genus: &Genus, t: &Skeleton, seed: u64) -> ImportedModel {
    let material = |part: &str, kind, alpha_cutoff, double_sided, texture| ImportedMaterial {
        name: format!("{}_{part}", genus.name.to_lowercase()),
        kind,
        base_color: [1.0; 4],
        alpha_cutoff,
        double_sided,
        texture: Some(texture),
        blended: false,
    };
    let mut m = ImportedModel {
        materials: vec![
            material("bark", MaterialKind::Branch, 0.0, false, textures::bark(genus, seed)),
            material("leaves", MaterialKind::Leaf, 0.5, true, textures::leaf(genus, seed)),
        ],
        autumn: genus.autumn(),
        // (An archetype is no genus: the default calendar.)
        genus: genus.autumn().filter(|_| !genus.archetype).map(|_| genus.name.to_string()),
        ..Default::default()
    };
    for stem in &t.stems {
        tube(&mut m, &stem.points, stem.bark_repeats, SIDES[usize::from(stem.level).min(SIDES.len() - 1)]);
    }
    for leaf in &t.leaves {
        card(&mut m, leaf);
    }
    m
}

fn vertex(m: &mut ImportedModel, position: Vec3, normal: Vec3, uv: Vec2, material: u16) -> u32 {
    m.vertices.push(ImportedVertex { position, normal: normal.normalize_or(Vec3::Z), uv, color: [1.0; 4], material });
    (m.vertices.len() - 1) as u32
}

/// A tube along `points` (position, radius) with `sides` sides (open: its tip
/// is 2 % of its base); the bark's v runs along it `repeats` times.
fn tube(m: &mut ImportedModel, points: &[(Vec3, f32)], repeats: f32, sides: u32) {
    if points.len() < 2 {
        return;
    }
    let base = m.vertices.len() as u32;
    // A frame carried along the stem (parallel transport: no twist).
    let first_axis = (points[1].0 - points[0].0).normalize_or(Vec3::Z);
    let mut side = first_axis.any_orthonormal_vector();
    for (k, &(c, r)) in points.iter().enumerate() {
        let axis = if k + 1 < points.len() { points[k + 1].0 - c } else { c - points[k - 1].0 }.normalize_or(Vec3::Z);
        side = (side - axis * side.dot(axis)).normalize_or(axis.any_orthonormal_vector());
        let other = axis.cross(side);
        let v = k as f32 / (points.len() - 1) as f32 * repeats;
        for s in 0..=sides {
            let a = s as f32 / sides as f32 * std::f32::consts::TAU;
            let n = side * a.cos() + other * a.sin();
            vertex(m, c + n * r, n, Vec2::new(s as f32 / sides as f32, v), 0);
        }
    }
    let ring = sides + 1;
    for k in 0..points.len() as u32 - 1 {
        for s in 0..sides {
            let i0 = base + k * ring + s;
            let (i1, j0, j1) = (i0 + 1, i0 + ring, i0 + ring + 1);
            m.triangles.push([i0, i1, j1]);
            m.triangles.push([i0, j1, j0]);
        }
    }
}

/// A leaf card: its stalk at one end, its tip at the other.
fn card(m: &mut ImportedModel, leaf: &weber_penn::Leaf) {
    // (right, tip, normal) right-handed: the quad winds counter-clockwise seen
    // from its normal's side, its front face.
    let right = leaf.tip.cross(leaf.normal).normalize_or(Vec3::X) * (leaf.size.y * 0.5);
    let up = leaf.tip * (leaf.size.x * 0.5);
    let base = m.vertices.len() as u32;
    for (x, y) in [(-1.0f32, -1.0f32), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
        let p = leaf.centre + right * x + up * y;
        vertex(m, p, leaf.normal, Vec2::new((x + 1.0) * 0.5, (1.0 - y) * 0.5), 1);
    }
    m.triangles.push([base, base + 1, base + 2]);
    m.triangles.push([base, base + 2, base + 3]);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_genus_grows_a_tree_of_its_form() {
        let mut wrong = Vec::new();
        for g in GENERA.iter().chain(ARCHETYPES.iter()) {
            let (mut mean_ratio, mut mean_height) = (0.0, 0.0);
            for v in 0..VARIANTS {
                let m = model(g, v);
                let (leaf, wood) = m.triangle_counts();
                let h = m.height();
                let ratio = m.crown_width() / h;
                eprintln!(
                    "{:<20} v{v} {ratio:.2} (genus {:.2}) {h:5.1} m, {wood:6} wood {leaf:6} leaf",
                    g.name, g.crown_ratio
                );
                mean_ratio += ratio / VARIANTS as f32;
                mean_height += h / VARIANTS as f32;
                if wood < 200 || leaf < 100 || wood + leaf > 150_000 {
                    wrong.push(format!("{} variant {v}: {wood} wood, {leaf} leaf triangles", g.name));
                }
                // Each variant near the genus's form, as trees of a stand vary.
                if (ratio / g.crown_ratio - 1.0).abs() > 0.35 || (h / g.params.scale - 1.0).abs() > 0.3 {
                    wrong.push(format!(
                        "{} variant {v}: {h:.1} m tall, crown width / height {ratio:.2}; the genus's {:.1} m, {:.2}",
                        g.name, g.params.scale, g.crown_ratio
                    ));
                }
                if !m.vertices.iter().all(|v| v.position.is_finite() && v.normal.is_finite()) {
                    wrong.push(format!("{} variant {v}: a vertex not finite", g.name));
                }
            }
            // Fitted on average to the genus's crown ratio and height.
            if (mean_ratio / g.crown_ratio - 1.0).abs() > 0.06 || (mean_height / g.params.scale - 1.0).abs() > 0.06 {
                wrong.push(format!(
                    "{}: variants {mean_height:.1} m tall, crown width / height {mean_ratio:.2} on average; the genus's {:.1} m, {:.2}",
                    g.name, g.params.scale, g.crown_ratio
                ));
            }
        }
        assert!(wrong.is_empty(), "{}", wrong.join("\n"));
    }

    #[test]
    fn genera_are_found_by_name_and_differ_by_seed() {
        assert_eq!(genus("quercus").map(|g| g.name), Some("Quercus"));
        assert_eq!(genus(" PICEA ").map(|g| g.name), Some("Picea"));
        assert!(genus("Nothofagus").is_none());
        let g = genus("Acer").unwrap();
        let (a, b) = (model(g, 1), model(g, 2));
        assert_ne!(a.vertices.len(), 0);
        assert_ne!(a.vertices, b.vertices);
        assert_eq!(a.vertices, model(g, 1).vertices);
    }

    /// The side-view silhouette of a model on a `n`² grid over `lo..hi` (x, z),
    /// leaf cards whole.
    fn silhouette(m: &ImportedModel, lo: Vec2, hi: Vec2, n: usize) -> Vec<bool> {
        let mut grid = vec![false; n * n];
        let cell = (hi - lo) / n as f32;
        for t in &m.triangles {
            let p = t.map(|i| {
                let v = m.vertices[i as usize].position;
                (Vec2::new(v.x, v.z) - lo) / cell
            });
            let (a, b) = (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
            let edge = |a: Vec2, b: Vec2, c: Vec2| (b - a).perp_dot(c - a);
            let area = edge(p[0], p[1], p[2]);
            for y in (a.y.floor().max(0.0) as usize)..=(b.y.ceil() as usize).min(n - 1) {
                for x in (a.x.floor().max(0.0) as usize)..=(b.x.ceil() as usize).min(n - 1) {
                    let c = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                    let w = [edge(p[1], p[2], c), edge(p[2], p[0], c), edge(p[0], p[1], c)];
                    let inside = if area >= 0.0 { w.iter().all(|&w| w >= 0.0) } else { w.iter().all(|&w| w <= 0.0) };
                    // (Thin triangles that cover no centre still mark their cell.)
                    if inside || (b - a).max_element() < 1.0 {
                        grid[y * n + x] = true;
                    }
                }
            }
        }
        grid
    }

    #[test]
    fn variants_share_their_structure_and_differ_in_shape() {
        // Every variant: variant 0's triangles, uvs and materials, elsewhere;
        // side silhouettes (metres, one frame) overlapping less than 90 %.
        let mut wrong = Vec::new();
        for g in GENERA.iter().chain(ARCHETYPES.iter()) {
            let models: Vec<ImportedModel> = (0..3).map(|v| model(g, v)).collect();
            let first = &models[0];
            let stretched = model_variants(g, 3);
            assert_eq!(stretched.vertices, first.vertices, "{}: variant 0 is the model", g.name);
            for (v, m) in models.iter().enumerate().skip(1) {
                let same = m.triangles == first.triangles
                    && m.vertices.len() == first.vertices.len()
                    && m.vertices.iter().zip(&first.vertices).all(|(a, b)| a.uv == b.uv && a.material == b.material);
                if !same {
                    let uv = m.vertices.iter().zip(&first.vertices).position(|(a, b)| a.uv != b.uv);
                    wrong.push(format!(
                        "{} variant {v}: not variant 0's topology ({} vs {} vertices, {} vs {} triangles, first uv apart at {uv:?})",
                        g.name,
                        m.vertices.len(),
                        first.vertices.len(),
                        m.triangles.len(),
                        first.triangles.len()
                    ));
                    continue;
                }
                // As the bake draws them: stretched to variant 0's height and crown.
                let mut shown = stretched.clone();
                shown.variants.clear();
                for (x, [p, _]) in shown.vertices.iter_mut().zip(&stretched.variants[v - 1]) {
                    x.position = *p;
                }
                let (lo0, hi0) = first.bounds();
                let (lo1, hi1) = shown.bounds();
                let (lo, hi) = (lo0.min(lo1), hi0.max(hi1));
                let (lo, hi) = (Vec2::new(lo.x, lo.z), Vec2::new(hi.x, hi.z));
                let (a, b) = (silhouette(first, lo, hi, 96), silhouette(&shown, lo, hi, 96));
                let both = a.iter().zip(&b).filter(|(a, b)| **a && **b).count();
                let either = a.iter().zip(&b).filter(|(a, b)| **a || **b).count();
                let iou = both as f32 / either.max(1) as f32;
                eprintln!("{:<20} variant {v}: silhouette IoU with variant 0 {iou:.2}", g.name);
                if iou >= 0.9 {
                    wrong.push(format!("{} variant {v}: silhouette IoU with variant 0 {iou:.2}", g.name));
                }
            }
        }
        assert!(wrong.is_empty(), "{}", wrong.join("\n"));
    }
}
