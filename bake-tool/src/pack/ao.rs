//! A tree's own ambient occlusion, baked once per species and shared by every
//! level of detail: how much of the sky a point inside the crown sees through
//! the tree's leaves and wood.
//!
//! The tree is turned into a grid of extinction coefficients (Beer–Lambert, as
//! in canopy radiative transfer): each triangle adds its area × the fraction of
//! its texture that is opaque, over the cell's volume, times the mean projection
//! of a surface onto a random direction (½ for a thin two-sided leaf, ¼ for a
//! closed surface such as bark — Cauchy's formula). At each cell centre the sky
//! visibility is the mean transmittance along cosine-weighted rays over the
//! upper hemisphere (the sky light of `sky_light` comes from above). A point's
//! occlusion is the visibility trilinearly interpolated there.
//!
//! Every representation samples the same field — mesh vertices, the billboard
//! capture (through the vertices), ellipsoids on their surface, lines at their
//! middle — so a tree is equally dark inside its crown at every level of detail,
//! and the value does not depend on a surface normal a coarser level lacks.

use glam::Vec3;
use rayon::prelude::*;
use sylva::format::pack::MaterialKind;

use crate::input::gltf_import::ImportedModel;

/// Cells along the tree's longest side.
pub const AO_GRID_CELLS: usize = 32;
/// Rays per cell over the upper hemisphere.
pub const AO_RAYS: usize = 48;

/// Sky visibility (0 closed – 1 open) over a grid around one tree.
#[derive(Debug, Clone)]
pub struct AoField {
    /// Centre of cell (0, 0, 0).
    origin: Vec3,
    cell: f32,
    dims: [usize; 3],
    visibility: Vec<f32>,
}

impl AoField {
    /// A field that leaves everything open (a model with no triangles).
    #[must_use]
    pub fn open() -> Self {
        Self { origin: Vec3::ZERO, cell: 1.0, dims: [1, 1, 1], visibility: vec![1.0] }
    }

    /// Bakes the field of `model` (model units, Z up).
    #[must_use]
    pub fn build(model: &ImportedModel) -> Self {
        if model.triangles.is_empty() {
            return Self::open();
        }
        let (lo, hi) = model.bounds();
        let extent = (hi - lo).max(Vec3::splat(1e-3));
        let cell = extent.max_element() / AO_GRID_CELLS as f32;
        // Empty margin cells (one below, at least two above): the field reaches
        // open sky outside the tree.
        let dims = ((extent / cell).ceil().as_uvec3() + 3).to_array().map(|d| d as usize);
        let origin = lo - Vec3::splat(cell) + 0.5 * cell;
        let extinction = extinction_grid(model, origin, cell, dims);
        let dirs = hemisphere_directions(AO_RAYS);
        let n = dims[0] * dims[1] * dims[2];
        let visibility = (0..n)
            .into_par_iter()
            .map(|i| {
                let (x, y, z) = (i % dims[0], (i / dims[0]) % dims[1], i / (dims[0] * dims[1]));
                let p = Vec3::new(x as f32, y as f32, z as f32);
                dirs.iter().map(|d| transmittance(&extinction, dims, cell, p, *d)).sum::<f32>() / dirs.len() as f32
            })
            .collect();
        Self { origin, cell, dims, visibility }
    }

    /// Sky visibility at `p` (model units), trilinear between cell centres;
    /// points outside the grid (an ellipsoid's surface can reach past the
    /// tree's bounds) take the nearest edge's value; 1 for a non-finite point.
    #[must_use]
    pub fn at(&self, p: Vec3) -> f32 {
        let max = Vec3::new(self.dims[0] as f32, self.dims[1] as f32, self.dims[2] as f32) - 1.0;
        if !p.is_finite() {
            return 1.0;
        }
        let g = ((p - self.origin) / self.cell).clamp(Vec3::ZERO, max);
        let base = g.floor().min(max - 1.0).max(Vec3::ZERO);
        let f = g - base;
        let [bx, by, bz] = base.to_array().map(|v| v as usize);
        let mut sum = 0.0;
        for corner in 0..8 {
            let (dx, dy, dz) = (corner & 1, (corner >> 1) & 1, corner >> 2);
            let (x, y, z) =
                ((bx + dx).min(self.dims[0] - 1), (by + dy).min(self.dims[1] - 1), (bz + dz).min(self.dims[2] - 1));
            let w = (if dx == 1 { f.x } else { 1.0 - f.x })
                * (if dy == 1 { f.y } else { 1.0 - f.y })
                * (if dz == 1 { f.z } else { 1.0 - f.z });
            sum += w * self.visibility[x + self.dims[0] * (y + self.dims[1] * z)];
        }
        sum
    }

    /// The pack's `AOFD` section of this field (one byte per cell).
    #[must_use]
    pub fn section_bytes(&self) -> Vec<u8> {
        let cells: Vec<u8> = self.visibility.iter().map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8).collect();
        sylva::format::pack::AoFieldRef::encode(self.dims.map(|d| d as u32), self.origin.to_array(), self.cell, &cells)
    }

    /// Whether this is the field of [`AoField::open`] (nothing baked).
    #[must_use]
    pub fn is_open(&self) -> bool {
        self.visibility.len() == 1
    }
}

/// The fraction of a material that stops light: its texture's texels that
/// survive the alpha test (or its mean alpha when it is not alpha-tested),
/// times the base colour's alpha.
fn opacity(m: &crate::input::gltf_import::ImportedMaterial) -> f32 {
    let base = m.base_color[3].clamp(0.0, 1.0);
    let Some(tex) = &m.texture else {
        return if m.alpha_cutoff > 0.0 { f32::from(u8::from(base >= m.alpha_cutoff)) } else { base };
    };
    let texels = tex.pixels().len().max(1) as f32;
    let covered: f32 = if m.alpha_cutoff > 0.0 {
        tex.pixels().filter(|p| f32::from(p[3]) / 255.0 * base >= m.alpha_cutoff).count() as f32
    } else {
        tex.pixels().map(|p| f32::from(p[3]) / 255.0 * base).sum()
    };
    covered / texels
}

/// Extinction per metre (per model unit) in each cell.
fn extinction_grid(model: &ImportedModel, origin: Vec3, cell: f32, dims: [usize; 3]) -> Vec<f32> {
    let opacities: Vec<f32> = model.materials.iter().map(opacity).collect();
    let mut grid = vec![0.0f32; dims[0] * dims[1] * dims[2]];
    let volume = cell * cell * cell;
    for t in &model.triangles {
        let [a, b, c] = t.map(|i| model.vertices[i as usize].position);
        let area = 0.5 * (b - a).cross(c - a).length();
        if !area.is_finite() || area <= 0.0 {
            continue;
        }
        let material = usize::from(model.vertices[t[0] as usize].material);
        let leaf = model.materials.get(material).is_none_or(|m| m.kind == MaterialKind::Leaf);
        let projection = if leaf { 0.5 } else { 0.25 };
        let weight = projection * opacities.get(material).copied().unwrap_or(1.0) * area / volume;
        // Spread large triangles (a trunk's) over the cells they cross: about
        // one point per quarter cell of area, on a barycentric lattice.
        let k = ((area / (0.25 * cell * cell)).sqrt().ceil() as usize).clamp(1, 16);
        let points = k * (k + 1) / 2;
        for i in 0..k {
            for j in 0..k - i {
                let (u, v) = ((i as f32 + 1.0 / 3.0) / k as f32, (j as f32 + 1.0 / 3.0) / k as f32);
                let p = a + (b - a) * u + (c - a) * v;
                let g = ((p - origin) / cell).round();
                let [x, y, z] = g.to_array().map(|v| v.max(0.0) as usize);
                if x < dims[0] && y < dims[1] && z < dims[2] {
                    grid[x + dims[0] * (y + dims[1] * z)] += weight / points as f32;
                }
            }
        }
    }
    grid
}

/// Transmittance from cell centre `p` (grid units) along `dir` to the grid's edge.
fn transmittance(extinction: &[f32], dims: [usize; 3], cell: f32, p: Vec3, dir: Vec3) -> f32 {
    // Half-cell steps, nearest cell: the own cell counts for its outer half.
    let step = 0.5;
    let mut depth = 0.0;
    let mut at = p + dir * (0.5 * step);
    loop {
        let g = at.round();
        if g.cmplt(Vec3::ZERO).any() {
            break;
        }
        let [x, y, z] = g.to_array().map(|v| v as usize);
        if x >= dims[0] || y >= dims[1] || z >= dims[2] {
            break;
        }
        depth += extinction[x + dims[0] * (y + dims[1] * z)] * step * cell;
        if depth > 12.0 {
            return 0.0;
        }
        at += dir * step;
    }
    (-depth).exp()
}

/// `n` directions over the upper hemisphere with density ∝ cos θ (Malley's
/// method on a Fibonacci spiral over the unit disc).
fn hemisphere_directions(n: usize) -> Vec<Vec3> {
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    (0..n)
        .map(|i| {
            let r = ((i as f32 + 0.5) / n as f32).sqrt();
            let phi = i as f32 * golden;
            let (x, y) = (r * phi.cos(), r * phi.sin());
            Vec3::new(x, y, (1.0 - r * r).max(0.0).sqrt())
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::input::gltf_import::{ImportedMaterial, ImportedVertex};

    fn material(kind: MaterialKind) -> ImportedMaterial {
        ImportedMaterial {
            name: "m".into(),
            kind,
            base_color: [1.0; 4],
            alpha_cutoff: 0.0,
            double_sided: true,
            texture: None,
            blended: false,
        }
    }

    /// A horizontal square of two triangles at height `z`, side `s`, centred on the z axis.
    fn square(model: &mut ImportedModel, z: f32, s: f32, material: u16) {
        let base = model.vertices.len() as u32;
        for (x, y) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            model.vertices.push(ImportedVertex {
                position: Vec3::new(x * s * 0.5, y * s * 0.5, z),
                normal: Vec3::Z,
                uv: glam::Vec2::ZERO,
                color: [1.0; 4],
                material,
            });
        }
        model.triangles.push([base, base + 1, base + 2]);
        model.triangles.push([base, base + 2, base + 3]);
    }

    /// A "crown": many stacked horizontal leaf layers of side 4 from z 2 to 8.
    fn crown(layers: usize) -> ImportedModel {
        let mut m = ImportedModel { materials: vec![material(MaterialKind::Leaf)], ..Default::default() };
        for i in 0..layers {
            square(&mut m, 2.0 + 6.0 * i as f32 / (layers - 1) as f32, 4.0, 0);
        }
        m
    }

    #[test]
    fn a_dense_crown_is_dark_inside_and_open_on_top_and_outside() {
        let field = AoField::build(&crown(12));
        let top = field.at(Vec3::new(0.0, 0.0, 8.3));
        let middle = field.at(Vec3::new(0.0, 0.0, 5.0));
        let bottom = field.at(Vec3::new(0.0, 0.0, 2.2));
        assert!(top > 0.85, "top of the crown sees the sky: {top}");
        assert!(middle < 0.4 && bottom < middle, "deeper is darker: middle {middle}, bottom {bottom}");
        assert!(bottom < 0.15, "12 layers of solid leaves: {bottom}");
        // Beside the crown the sky is partly hidden, far off to the side it is open.
        let beside = field.at(Vec3::new(2.15, 0.0, 2.2));
        assert!(beside > bottom + 0.1 && beside < 0.9, "beside the crown's base: {beside}");
        let far_beside = field.at(Vec3::new(50.0, 0.0, 2.2));
        assert!((far_beside - beside).abs() < 0.05, "clamped to the edge: {far_beside} vs {beside}");
        assert!(field.at(Vec3::new(0.0, 0.0, 50.0)) > 0.99, "high above the crown");
        assert_eq!(field.at(Vec3::splat(f32::NAN)), 1.0);
    }

    #[test]
    fn sparse_leaves_let_light_through() {
        let dense = AoField::build(&crown(12)).at(Vec3::new(0.0, 0.0, 3.0));
        let sparse = AoField::build(&crown(3)).at(Vec3::new(0.0, 0.0, 3.0));
        assert!(sparse > dense + 0.2, "3 layers {sparse} vs 12 layers {dense}");
        // Leaves whose texture is mostly holes shade less than solid ones.
        let mut holey = crown(12);
        let mut tex = image::RgbaImage::new(4, 4);
        for (i, p) in tex.pixels_mut().enumerate() {
            *p = image::Rgba([0, 128, 0, if i % 4 == 0 { 255 } else { 0 }]);
        }
        holey.materials[0].texture = Some(tex);
        holey.materials[0].alpha_cutoff = 0.5;
        assert!((opacity(&holey.materials[0]) - 0.25).abs() < 1e-6);
        let through = AoField::build(&holey).at(Vec3::new(0.0, 0.0, 3.0));
        assert!(through > dense + 0.2, "a quarter-opaque crown {through} vs solid {dense}");
    }

    #[test]
    fn bark_counts_half_as_much_as_a_leaf_of_the_same_area() {
        let mut leaf = crown(6);
        let leafy = AoField::build(&leaf).at(Vec3::new(0.0, 0.0, 2.5));
        leaf.materials[0].kind = MaterialKind::Branch;
        let woody = AoField::build(&leaf).at(Vec3::new(0.0, 0.0, 2.5));
        assert!(woody > leafy, "closed surfaces block a quarter of their area: {woody} vs {leafy}");
    }

    #[test]
    fn the_section_round_trips_through_the_pack_reader() {
        let field = AoField::build(&crown(6));
        let bytes = field.section_bytes();
        let r = sylva::format::pack::AoFieldRef::parse(&bytes).unwrap();
        assert_eq!(r.dims.map(|d| d as usize), field.dims);
        assert_eq!(r.cell, field.cell);
        let mid = field.dims.map(|d| d / 2);
        let i = mid[0] + field.dims[0] * (mid[1] + field.dims[1] * mid[2]);
        assert_eq!(r.cells[i], (field.visibility[i] * 255.0).round() as u8);
        let centre = Vec3::from_array(r.origin) + Vec3::new(mid[0] as f32, mid[1] as f32, mid[2] as f32) * r.cell;
        assert!((field.at(centre) - field.visibility[i]).abs() < 1e-4, "cell centres line up");
        assert!(sylva::format::pack::AoFieldRef::parse(&bytes[..bytes.len() - 1]).is_err());
    }

    #[test]
    fn an_empty_model_is_open() {
        assert!(AoField::build(&ImportedModel::default()).at(Vec3::ZERO) == 1.0);
    }

    #[test]
    fn hemisphere_directions_are_unit_upward_and_cosine_weighted() {
        let d = hemisphere_directions(256);
        assert!(d.iter().all(|v| (v.length() - 1.0).abs() < 1e-4 && v.z >= 0.0));
        // E[cos θ] under a cosine-weighted hemisphere is 2/3.
        let mean = d.iter().map(|v| v.z).sum::<f32>() / d.len() as f32;
        assert!((mean - 2.0 / 3.0).abs() < 0.01, "{mean}");
        let centroid = d.iter().fold(Vec3::ZERO, |a, v| a + *v) / d.len() as f32;
        assert!(centroid.x.abs() < 0.02 && centroid.y.abs() < 0.02);
    }
}
