//! Leaves of an imported model as single ellipsoids (Clasen et al. 2010, §3.1, first step):
//! leaf triangles are grouped into leaves (triangles sharing welded vertices,
//! then groups with the same centre, e.g. crossed cards), sampled uniformly over
//! their surface with the leaf texture's alpha test applied, and summarised by
//! their mean and covariance (the PCA input).

use std::collections::HashMap;

use glam::{DMat3, DVec3, Vec2, Vec3};
use sylva::format::cluster::srgb_to_linear;
use sylva::format::pack::MaterialKind;

use super::em::outer;
use crate::input::gltf_import::ImportedModel;

/// One leaf: its visible surface's moments.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Leaf {
    /// Mean of the visible surface.
    pub center: DVec3,
    /// Covariance of the visible surface.
    pub covariance: DMat3,
    /// Visible area (m² at scale 1).
    pub area: f64,
    /// Mean linear albedo.
    pub color: Vec3,
}

/// Samples per triangle.
const SAMPLES: usize = 64;

struct UnionFind(Vec<u32>);

impl UnionFind {
    fn new(n: usize) -> Self {
        Self((0..n as u32).collect())
    }
    fn find(&mut self, mut i: u32) -> u32 {
        while self.0[i as usize] != i {
            let p = self.0[self.0[i as usize] as usize];
            self.0[i as usize] = p;
            i = p;
        }
        i
    }
    fn union(&mut self, a: u32, b: u32) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            self.0[ra.max(rb) as usize] = ra.min(rb);
        }
    }
}

/// Groups the triangles of `kind` into connected parts: triangles sharing a
/// vertex position (welded at 1e-5 of the model size) are one part. Returns the
/// parts as lists of triangle indices, in order of their first triangle.
#[must_use]
pub fn connected_parts(model: &ImportedModel, kind: MaterialKind) -> Vec<Vec<usize>> {
    let (lo, hi) = model.bounds();
    let weld = ((hi - lo).max_element() * 1e-5).max(1e-9);
    let tris: Vec<usize> = (0..model.triangles.len())
        .filter(|&t| model.materials[usize::from(model.vertices[model.triangles[t][0] as usize].material)].kind == kind)
        .collect();
    let mut uf = UnionFind::new(tris.len());
    let mut first: HashMap<[i64; 3], u32> = HashMap::new();
    for (i, &t) in tris.iter().enumerate() {
        for &v in &model.triangles[t] {
            let p = model.vertices[v as usize].position;
            let key = [p.x, p.y, p.z].map(|c| (c / weld).round() as i64);
            let j = *first.entry(key).or_insert(i as u32);
            uf.union(i as u32, j);
        }
    }
    let mut parts: Vec<Vec<usize>> = Vec::new();
    let mut index: HashMap<u32, usize> = HashMap::new();
    for (i, &t) in tris.iter().enumerate() {
        let r = uf.find(i as u32);
        let k = *index.entry(r).or_insert_with(|| {
            parts.push(Vec::new());
            parts.len() - 1
        });
        parts[k].push(t);
    }
    parts
}

/// Texel of `img` at `uv` (repeat wrap, nearest), as linear RGB and alpha.
pub(crate) fn texel(img: &image::RgbaImage, uv: Vec2) -> ([f32; 3], f32) {
    let (w, h) = img.dimensions();
    let x = ((uv.x.rem_euclid(1.0)) * w as f32) as u32;
    let y = ((uv.y.rem_euclid(1.0)) * h as f32) as u32;
    let p = img.get_pixel(x.min(w - 1), y.min(h - 1)).0;
    ([0, 1, 2].map(|c| srgb_to_linear(f32::from(p[c]) / 255.0)), f32::from(p[3]) / 255.0)
}

/// The leaves of `model`, one per leaf part (crossed cards that share a centre
/// count as one leaf). Fully transparent parts are skipped.
#[must_use]
pub fn extract_leaves(model: &ImportedModel) -> Vec<Leaf> {
    let parts = connected_parts(model, MaterialKind::Leaf);
    let (lo, hi) = model.bounds();
    let size = (hi - lo).max_element().max(1e-6);
    let mut raw: Vec<(DVec3, Leaf)> = Vec::with_capacity(parts.len());
    for part in &parts {
        let (mut w, mut s1, mut s2, mut col) = (0.0f64, DVec3::ZERO, DMat3::ZERO, Vec3::ZERO);
        // Exact geometric centre (vertex mean), to find crossed cards.
        let geo = part
            .iter()
            .flat_map(|&t| model.triangles[t].map(|i| model.vertices[i as usize].position.as_dvec3()))
            .sum::<DVec3>()
            / (part.len() * 3) as f64;
        for &t in part {
            let [a, b, c] = model.triangles[t].map(|i| model.vertices[i as usize]);
            let area = f64::from((b.position - a.position).cross(c.position - a.position).length() * 0.5);
            if area.is_nan() || area <= 0.0 {
                continue;
            }
            let mat = &model.materials[usize::from(a.material)];
            let per = area / SAMPLES as f64;
            for k in 0..SAMPLES {
                // A rank-1 lattice on the unit square folded onto the triangle:
                // evenly spread, deterministic.
                let (mut u, mut v) =
                    (((k as f64) + 0.5) / SAMPLES as f64, (k as f64 * 0.618_033_988_749_895 + 0.31).fract());
                if u + v > 1.0 {
                    (u, v) = (1.0 - u, 1.0 - v);
                }
                let (u32_, v32) = (u as f32, v as f32);
                let bary = |pa: Vec3, pb: Vec3, pc: Vec3| pa + (pb - pa) * u32_ + (pc - pa) * v32;
                let uv = a.uv + (b.uv - a.uv) * u32_ + (c.uv - a.uv) * v32;
                let (mut rgb, mut alpha) = ([1.0f32; 3], 1.0f32);
                if let Some(img) = &mat.texture {
                    (rgb, alpha) = texel(img, uv);
                }
                alpha *= mat.base_color[3] * a.color[3];
                if mat.alpha_cutoff > 0.0 && alpha < mat.alpha_cutoff {
                    continue;
                }
                let p = bary(a.position, b.position, c.position).as_dvec3();
                w += per;
                s1 += p * per;
                s2 += outer(p, p) * per;
                col += Vec3::from(rgb)
                    * Vec3::from_slice(&mat.base_color[..3])
                    * Vec3::from_slice(&a.color[..3])
                    * per as f32;
            }
        }
        if w > 0.0 {
            let m = s1 / w;
            raw.push((
                geo,
                Leaf { center: m, covariance: s2 * (1.0 / w) - outer(m, m), area: w, color: col / w as f32 },
            ));
        }
    }
    // Crossed cards: parts whose centres coincide are one leaf.
    let tol = f64::from(size) * 1e-4;
    let mut by_center: HashMap<[i64; 3], usize> = HashMap::new();
    let mut leaves: Vec<Leaf> = Vec::new();
    for (geo, l) in raw {
        let key = [geo.x, geo.y, geo.z].map(|c| (c / tol).round() as i64);
        match by_center.get(&key) {
            Some(&i) => leaves[i] = merge(&leaves[i], &l),
            None => {
                by_center.insert(key, leaves.len());
                leaves.push(l);
            }
        }
    }
    leaves
}

/// The moments of the union of two surfaces.
#[must_use]
pub fn merge(a: &Leaf, b: &Leaf) -> Leaf {
    let w = a.area + b.area;
    let m = (a.center * a.area + b.center * b.area) / w;
    let second = |l: &Leaf| (l.covariance + outer(l.center, l.center)) * l.area;
    Leaf {
        center: m,
        covariance: (second(a) + second(b)) * (1.0 / w) - outer(m, m),
        area: w,
        color: (a.color * a.area as f32 + b.color * b.area as f32) / w as f32,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::input::gltf_import::{ImportedMaterial, ImportedVertex};

    fn quad(model: &mut ImportedModel, center: Vec3, u: Vec3, v: Vec3) {
        let base = model.vertices.len() as u32;
        for (du, dv) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            model.vertices.push(ImportedVertex {
                position: center + u * du + v * dv,
                normal: u.cross(v).normalize(),
                uv: Vec2::new((du + 1.0) * 0.5, (dv + 1.0) * 0.5),
                color: [1.0; 4],
                material: 0,
            });
        }
        model.triangles.push([base, base + 1, base + 2]);
        model.triangles.push([base, base + 2, base + 3]);
    }

    fn leaf_material() -> ImportedMaterial {
        ImportedMaterial {
            name: "leaf".into(),
            kind: MaterialKind::Leaf,
            base_color: [0.2, 0.5, 0.1, 1.0],
            alpha_cutoff: 0.0,
            double_sided: true,
            texture: None,
            blended: false,
        }
    }

    #[test]
    fn square_cards_become_leaves_with_the_right_moments() {
        let mut model = ImportedModel { materials: vec![leaf_material()], ..Default::default() };
        quad(&mut model, Vec3::new(0.0, 0.0, 5.0), Vec3::X * 0.5, Vec3::Y * 0.5);
        quad(&mut model, Vec3::new(3.0, 0.0, 5.0), Vec3::X * 0.5, Vec3::Z * 0.5);
        // A crossed card: same centre as the second leaf.
        quad(&mut model, Vec3::new(3.0, 0.0, 5.0), Vec3::Y * 0.5, Vec3::Z * 0.5);
        let leaves = extract_leaves(&model);
        assert_eq!(leaves.len(), 2);
        let a = leaves[0];
        assert!((a.center - DVec3::new(0.0, 0.0, 5.0)).length() < 0.02);
        assert!((a.area - 1.0).abs() < 1e-6);
        // A square of side 1: variance 1/12 along each side, 0 across.
        assert!((a.covariance.x_axis.x - 1.0 / 12.0).abs() < 0.015, "{:?}", a.covariance);
        assert!(a.covariance.z_axis.z.abs() < 1e-9);
        assert!((a.color - Vec3::new(0.2, 0.5, 0.1)).length() < 1e-5);
        let b = leaves[1];
        assert!((b.area - 2.0).abs() < 1e-6);
        assert!(b.covariance.x_axis.x > 0.02 && b.covariance.y_axis.y > 0.02 && b.covariance.z_axis.z > 0.06);
    }

    #[test]
    fn alpha_test_removes_transparent_texels() {
        let mut mat = leaf_material();
        mat.alpha_cutoff = 0.5;
        // Left half opaque, right half transparent.
        mat.texture =
            Some(image::RgbaImage::from_fn(8, 8, |x, _| image::Rgba([255, 255, 255, if x < 4 { 255 } else { 0 }])));
        let mut model = ImportedModel { materials: vec![mat], ..Default::default() };
        quad(&mut model, Vec3::ZERO, Vec3::X, Vec3::Y);
        let leaves = extract_leaves(&model);
        assert_eq!(leaves.len(), 1);
        assert!((leaves[0].area - 2.0).abs() < 0.25, "half of the 2×2 card: {}", leaves[0].area);
        assert!(leaves[0].center.x < -0.35, "centre moves to the opaque half: {:?}", leaves[0].center);
    }
}
