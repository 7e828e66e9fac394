//! The procedural ground material of scenes without an orthophoto: baked as
//! ground imagery ([`super::imagery`]) so the viewer drapes it like a photo.
//!
//! The forest floor follows the canopy: leaf and needle litter under closed
//! canopy, dry grass in clearings and gaps, bare soil on steep slopes, with
//! patchy variation at a few metres so the ground does not read as a flat
//! colour. The canopy cover comes from the trees themselves: every tree's
//! crown disk (its crown width, or a fifth of its height) is splatted into a
//! grid ([`CanopyCover`]) while the trees are placed.
//!
//! Colours never let green dominate (grass is dry and olive), so image tests
//! that count green pixels count foliage only.

use crate::rng::fbm;

/// Pixel size the procedural floor is baked at, metres (its finest images).
pub const FLOOR_RESOLUTION_M: f64 = 2.0;
/// Most cells of a canopy grid (the cell grows beyond).
const MAX_CELLS: f64 = 4.0e6;

/// Crown cover per grid cell (0: open sky, 1: closed canopy).
#[derive(Debug, Clone)]
pub struct CanopyCover {
    x0: f64,
    y0: f64,
    cell: f64,
    nx: usize,
    ny: usize,
    cover: Vec<f32>,
}

impl CanopyCover {
    /// An empty grid over `region` (min x, min y, max x, max y; relative
    /// metres) of `cell_m` cells (coarser if it would exceed 4 M cells).
    #[must_use]
    pub fn new(region: [f64; 4], cell_m: f64) -> Self {
        let (w, h) = ((region[2] - region[0]).max(1.0), (region[3] - region[1]).max(1.0));
        let cell = cell_m.max((w * h / MAX_CELLS).sqrt());
        let (nx, ny) = ((w / cell).ceil() as usize + 1, (h / cell).ceil() as usize + 1);
        Self { x0: region[0], y0: region[1], cell, nx, ny, cover: vec![0.0; nx * ny] }
    }

    /// Adds a crown of radius `r` metres at `(x, y)`: each cell centre within
    /// it is covered (cells more than half covered by a small crown count it
    /// in proportion to its area).
    pub fn add(&mut self, x: f64, y: f64, r: f64) {
        if !(x.is_finite() && y.is_finite() && r.is_finite() && r > 0.0) {
            return;
        }
        let (cx, cy) = ((x - self.x0) / self.cell, (y - self.y0) / self.cell);
        let rc = r / self.cell;
        if rc < 0.7 {
            // Smaller than a cell: its share of the nearest cell.
            let (i, j) = (cx.round(), cy.round());
            if i >= 0.0 && j >= 0.0 && (i as usize) < self.nx && (j as usize) < self.ny {
                let c = &mut self.cover[j as usize * self.nx + i as usize];
                *c += (std::f64::consts::PI * rc * rc) as f32;
            }
            return;
        }
        let (i0, i1) = ((cx - rc).floor().max(0.0) as usize, ((cx + rc).ceil() as usize).min(self.nx - 1));
        let (j0, j1) = ((cy - rc).floor().max(0.0) as usize, ((cy + rc).ceil() as usize).min(self.ny - 1));
        if cx + rc < 0.0 || cy + rc < 0.0 {
            return;
        }
        for j in j0..=j1 {
            for i in i0..=i1 {
                let (dx, dy) = (i as f64 - cx, j as f64 - cy);
                if dx * dx + dy * dy <= rc * rc {
                    self.cover[j * self.nx + i] += 1.0;
                }
            }
        }
    }

    /// Cover at `(x, y)`, bilinear between cell centres, 0–1 (0 outside).
    #[must_use]
    pub fn at(&self, x: f64, y: f64) -> f32 {
        let (fx, fy) = ((x - self.x0) / self.cell, (y - self.y0) / self.cell);
        if !(fx >= 0.0 && fy >= 0.0 && fx <= (self.nx - 1) as f64 && fy <= (self.ny - 1) as f64) {
            return 0.0;
        }
        let (i, j) = ((fx as usize).min(self.nx.saturating_sub(2)), (fy as usize).min(self.ny.saturating_sub(2)));
        let (a, b) = ((fx - i as f64) as f32, (fy - j as f64) as f32);
        let c = |i: usize, j: usize| self.cover[(j.min(self.ny - 1)) * self.nx + i.min(self.nx - 1)].min(1.0);
        let top = c(i, j) * (1.0 - a) + c(i + 1, j) * a;
        let bottom = c(i, j + 1) * (1.0 - a) + c(i + 1, j + 1) * a;
        top * (1.0 - b) + bottom * b
    }
}

/// sRGB colours (0–255) of the forest floor.
const LITTER: [f32; 3] = [88.0, 70.0, 46.0];
const GRASS: [f32; 3] = [134.0, 126.0, 74.0];
const SOIL: [f32; 3] = [132.0, 108.0, 80.0];

fn mix(a: [f32; 3], b: [f32; 3], t: f32) -> [f32; 3] {
    [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t, a[2] + (b[2] - a[2]) * t]
}

fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// The forest floor at `(x, y)` (relative metres) with canopy cover `cover`
/// (0–1) on ground of gradient `slope` (rise over run): sRGB 0–255 and full
/// coverage.
#[must_use]
pub fn forest_floor(x: f64, y: f64, cover: f32, slope: f32) -> [f32; 4] {
    // Gaps read as grass once the canopy opens; litter under closed canopy.
    let patches = fbm(71, x, y, 9.0) as f32;
    let open = smoothstep(0.35, 0.75, cover + 0.25 * (patches - 0.5));
    let mut c = mix(GRASS, LITTER, open);
    // Bare soil where the ground is steep (from about 35°).
    c = mix(c, SOIL, smoothstep(0.55, 0.9, slope));
    // Brightness variation at a few metres and a few decimetres.
    let v = 0.82 + 0.3 * fbm(72, x, y, 4.0) as f32 + 0.08 * fbm(73, x, y, 0.7) as f32;
    [c[0] * v, c[1] * v, c[2] * v, 1.0]
}

/// The gradient (rise over run) of `height` at `(x, y)`, from differences
/// over `h` metres; 0 where there is no height.
pub fn slope_of(height: &dyn Fn(f64, f64) -> Option<f32>, x: f64, y: f64, h: f64) -> f32 {
    match (height(x - h, y), height(x + h, y), height(x, y - h), height(x, y + h)) {
        (Some(a), Some(b), Some(c), Some(d)) => {
            let (gx, gy) = ((b - a) / (2.0 * h as f32), (d - c) / (2.0 * h as f32));
            (gx * gx + gy * gy).sqrt()
        }
        _ => 0.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crowns_cover_their_cells_and_the_floor_follows_the_canopy() {
        let mut c = CanopyCover::new([0.0, 0.0, 100.0, 100.0], 2.0);
        c.add(50.0, 50.0, 6.0);
        assert_eq!(c.at(50.0, 50.0), 1.0);
        assert_eq!(c.at(80.0, 80.0), 0.0);
        assert!(c.at(55.0, 50.0) > 0.5 && c.at(58.0, 50.0) < 0.5);
        c.add(-500.0, 50.0, 6.0); // outside: ignored
        c.add(f64::NAN, 1.0, 2.0);
        // Small crowns add their share.
        for _ in 0..4 {
            c.add(10.0, 10.0, 0.5);
        }
        assert!(c.at(10.0, 10.0) > 0.5);
        // Under the canopy the floor is darker than in the open; never green-dominant.
        let (mut under, mut open) = (0.0, 0.0);
        for k in 0..200 {
            let (x, y) = (f64::from(k) * 1.7, f64::from(k % 13) * 3.1);
            let u = forest_floor(x, y, 1.0, 0.0);
            let o = forest_floor(x, y, 0.0, 0.0);
            under += u[0] + u[1] + u[2];
            open += o[0] + o[1] + o[2];
            for p in [u, o, forest_floor(x, y, 0.5, 1.2)] {
                assert!(p[1] <= p[0] + 1.0, "green dominates: {p:?}");
            }
        }
        assert!(under < open * 0.8, "{under} vs {open}");
        let plane = |x: f64, _y: f64| Some((0.5 * x) as f32);
        assert!((slope_of(&plane, 3.0, 4.0, 1.0) - 0.5).abs() < 1e-6);
    }
}
