//! Ground heights for the trees (stage 1): the `--dem` GeoTIFFs, each in its
//! own CRS, sampled bilinearly at a tree's position in the scene CRS. The
//! first DEM that has data at a point gives its height.

use std::path::{Path, PathBuf};

use crate::input::dem::Dem;
use anyhow::{bail, Context, Result};

use crate::input::reproject::{Crs, Reprojector};

/// How a given `z` column is meant when there is a DEM.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ZMode {
    /// Ground elevation in the scene's vertical datum: the DEM is not used for rows with a z.
    Absolute,
    /// Height above the DEM's ground (e.g. a tree on a roof or a platform).
    Relative,
}

/// How far from a DEM's valid data (pixels) a tree still takes the nearest
/// valid height (counted and reported) instead of stopping the bake.
pub const NEAR_EDGE_PIXELS: f64 = 2.0;

/// What to do with trees outside every DEM.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum OutsideDem {
    /// Stop the bake and say how many and where.
    Error,
    /// Leave them out (counted in the report).
    Skip,
}

/// The opened DEMs, not yet tied to a scene CRS.
pub struct Dems {
    dems: Vec<(PathBuf, Dem, Crs)>,
}

impl Dems {
    /// Reads every DEM (before any long work, so a bad file fails fast). `crs`
    /// (`--dem-crs`) is used for files whose GeoKeys name none, and overrides them.
    ///
    /// # Errors
    /// A file that does not read as a GeoTIFF DEM, or whose CRS is unknown.
    pub fn open(paths: &[PathBuf], crs: Option<&str>, log: &dyn Fn(&str)) -> Result<Self> {
        let mut dems = Vec::new();
        for path in paths {
            let dem = Dem::open(path)?;
            let epsg = match (crs, dem.epsg) {
                (Some(c), _) => Crs::parse(c).with_context(|| format!("--dem-crs {c}"))?.epsg,
                (None, Some(e)) => e,
                (None, None) => bail!(
                    "DEM {}: its GeoKeys name no EPSG code (a user-defined CRS): say which CRS it is in with \
                     --dem-crs EPSG:xxxx",
                    path.display()
                ),
            };
            let dem_crs = Crs::from_epsg(epsg).with_context(|| format!("DEM {}", path.display()))?;
            let s = dem.summary();
            log(&format!(
                "DEM {}: {}×{} pixels of {:.2} m, EPSG:{epsg}, {}; x {:.1}–{:.1}, y {:.1}–{:.1}; heights {}{}",
                path.display(),
                dem.width,
                dem.height,
                s.resolution[0],
                dem.layout,
                s.extent[0],
                s.extent[2],
                s.extent[1],
                s.extent[3],
                s.range.map_or("none (every pixel is nodata)".to_string(), |(a, b)| format!("{a:.2}–{b:.2} m")),
                if s.holes > 0 { format!("; {} pixels without data", s.holes) } else { String::new() }
            ));
            dems.push((path.clone(), dem, dem_crs));
        }
        Ok(Self { dems })
    }

    /// Whether no DEM was given.
    pub fn is_empty(&self) -> bool {
        self.dems.is_empty()
    }

    /// The DEMs as seen from the scene CRS.
    ///
    /// # Errors
    /// A DEM CRS proj4rs cannot transform from the scene CRS.
    pub fn in_scene(self, scene: &Crs) -> Result<Ground> {
        let mut out = Vec::new();
        for (path, dem, crs) in self.dems {
            let to_dem = if crs.epsg == scene.epsg {
                None
            } else {
                Some(
                    Reprojector::new(Crs::from_epsg(scene.epsg)?, &crs)
                        .with_context(|| format!("DEM {}: from the scene CRS", path.display()))?,
                )
            };
            let from_dem = match to_dem {
                Some(_) => Some(Reprojector::new(Crs::from_epsg(crs.epsg)?, &Crs::from_epsg(scene.epsg)?)?),
                None => None,
            };
            out.push(GroundDem { path, dem, to_dem, from_dem, geographic: crs.is_geographic() });
        }
        Ok(Ground { dems: out })
    }
}

struct GroundDem {
    path: PathBuf,
    dem: Dem,
    to_dem: Option<Reprojector>,
    /// DEM CRS → scene CRS (with `to_dem`).
    from_dem: Option<Reprojector>,
    /// The DEM's CRS is in degrees.
    geographic: bool,
}

/// The DEMs in the scene CRS.
pub struct Ground {
    dems: Vec<GroundDem>,
}

impl Ground {
    /// Ground height at scene-CRS point (`x`, `y`) from the first DEM with data there.
    pub fn height_at(&self, x: f64, y: f64) -> Option<f32> {
        self.dems.iter().find_map(|g| {
            let (dx, dy) = match &g.to_dem {
                Some(r) => r.apply(x, y).ok()?,
                None => (x, y),
            };
            g.dem.sample(dx, dy)
        })
    }

    /// For a point [`Self::height_at`] has no height for: the nearest valid
    /// pixel's height of the first DEM with one within [`NEAR_EDGE_PIXELS`]
    /// pixels (a tree at the edge of the DEM's data, or of a hole).
    pub fn height_near(&self, x: f64, y: f64) -> Option<f32> {
        self.dems.iter().find_map(|g| {
            let (dx, dy) = match &g.to_dem {
                Some(r) => r.apply(x, y).ok()?,
                None => (x, y),
            };
            g.dem.nearest_within(dx, dy, NEAR_EDGE_PIXELS)
        })
    }

    /// The finest DEM pixel size in metres (a geographic DEM's degrees taken
    /// as 111 km, their length along a meridian).
    pub fn resolution_m(&self) -> f64 {
        self.dems
            .iter()
            .map(|g| {
                let r = g.dem.resolution();
                r[0].min(r[1]) * if g.geographic { 111_000.0 } else { 1.0 }
            })
            .fold(f64::MAX, f64::min)
    }

    /// The union of the DEMs' extents in the scene CRS (each DEM's corners and
    /// edge midpoints projected), or `None` if a projection fails.
    pub fn scene_extent(&self) -> Option<[f64; 4]> {
        let mut b = [f64::MAX, f64::MAX, f64::MIN, f64::MIN];
        for g in &self.dems {
            let e = g.dem.extent();
            let (cx, cy) = ((e[0] + e[2]) * 0.5, (e[1] + e[3]) * 0.5);
            for (x, y) in
                [(e[0], e[1]), (e[2], e[1]), (e[0], e[3]), (e[2], e[3]), (cx, e[1]), (cx, e[3]), (e[0], cy), (e[2], cy)]
            {
                let (sx, sy) = match &g.from_dem {
                    None => (x, y),
                    Some(r) => r.apply(x, y).ok()?,
                };
                b = [b[0].min(sx), b[1].min(sy), b[2].max(sx), b[3].max(sy)];
            }
        }
        (b[0] <= b[2]).then_some(b)
    }

    /// The DEM file names, for reports.
    pub fn names(&self) -> String {
        self.dems.iter().map(|g| name(&g.path)).collect::<Vec<_>>().join(", ")
    }

    /// The DEMs' extents in their own CRSs, for errors.
    pub fn describe(&self) -> String {
        self.dems
            .iter()
            .map(|g| {
                let e = g.dem.extent();
                format!("{} covers x {:.1}–{:.1}, y {:.1}–{:.1}", name(&g.path), e[0], e[2], e[1], e[3])
            })
            .collect::<Vec<_>>()
            .join("; ")
    }
}

fn name(p: &Path) -> String {
    p.file_name().map_or_else(|| p.display().to_string(), |n| n.to_string_lossy().into_owned())
}

/// A ground surface fitted to the trees' bases, for scenes without a DEM: the
/// mean base height per grid cell, cells without trees filled from coarser
/// averages (pull–push), sampled bilinearly between cell centres.
#[derive(Debug, Clone)]
pub struct GroundFit {
    x0: f64,
    y0: f64,
    cell: f64,
    nx: usize,
    ny: usize,
    sum: Vec<f64>,
    count: Vec<u32>,
}

impl GroundFit {
    /// A fit over `region` (metres relative to the scene origin: min x, min y,
    /// max x, max y) with cells of `region / 256`, 4–64 m.
    pub fn new(region: [f64; 4]) -> Self {
        let extent = (region[2] - region[0]).max(region[3] - region[1]).max(1.0);
        let cell = (extent / 256.0).clamp(4.0, 64.0);
        let nx = ((region[2] - region[0]) / cell).ceil().max(1.0) as usize + 1;
        let ny = ((region[3] - region[1]) / cell).ceil().max(1.0) as usize + 1;
        Self { x0: region[0], y0: region[1], cell, nx, ny, sum: vec![0.0; nx * ny], count: vec![0; nx * ny] }
    }

    /// Adds a tree base (metres relative to the scene origin); points outside are ignored.
    pub fn add(&mut self, x: f64, y: f64, z: f64) {
        let (i, j) = (((x - self.x0) / self.cell).round(), ((y - self.y0) / self.cell).round());
        if i < 0.0 || j < 0.0 || i >= self.nx as f64 || j >= self.ny as f64 || !z.is_finite() {
            return;
        }
        let k = j as usize * self.nx + i as usize;
        self.sum[k] += z;
        self.count[k] += 1;
    }

    /// The filled surface, or `None` without any tree.
    pub fn finish(self) -> Option<FittedGround> {
        let mut z: Vec<f32> = self
            .sum
            .iter()
            .zip(&self.count)
            .map(|(s, &n)| if n > 0 { (s / f64::from(n)) as f32 } else { f32::NAN })
            .collect();
        if z.iter().all(|v| v.is_nan()) {
            return None;
        }
        fill(&mut z, self.nx, self.ny);
        Some(FittedGround { x0: self.x0, y0: self.y0, cell: self.cell, nx: self.nx, ny: self.ny, z })
    }
}

/// Fills the NaN cells of an `nx`×`ny` grid from a grid half as fine (pull–push).
fn fill(z: &mut [f32], nx: usize, ny: usize) {
    if !z.iter().any(|v| v.is_nan()) || z.iter().all(|v| v.is_nan()) {
        return;
    }
    let (cx, cy) = (nx.div_ceil(2), ny.div_ceil(2));
    let mut coarse = vec![f32::NAN; cx * cy];
    for (k, c) in coarse.iter_mut().enumerate() {
        let (ci, cj) = (k % cx, k / cx);
        let (mut s, mut n) = (0.0, 0);
        for (i, j) in [(2 * ci, 2 * cj), (2 * ci + 1, 2 * cj), (2 * ci, 2 * cj + 1), (2 * ci + 1, 2 * cj + 1)] {
            if i < nx && j < ny && !z[j * nx + i].is_nan() {
                s += z[j * nx + i];
                n += 1;
            }
        }
        if n > 0 {
            *c = s / n as f32;
        }
    }
    fill(&mut coarse, cx, cy);
    for j in 0..ny {
        for i in 0..nx {
            if z[j * nx + i].is_nan() {
                // Bilinear in the coarse grid (its cell centres sit between pairs of fine cells).
                let u = ((i as f32 - 0.5) * 0.5).clamp(0.0, (cx - 1) as f32);
                let v = ((j as f32 - 0.5) * 0.5).clamp(0.0, (cy - 1) as f32);
                z[j * nx + i] = bilinear(&coarse, cx, cy, u, v);
            }
        }
    }
}

fn bilinear(z: &[f32], nx: usize, ny: usize, u: f32, v: f32) -> f32 {
    let (i0, j0) = ((u.floor() as usize).min(nx - 1), (v.floor() as usize).min(ny - 1));
    let (i1, j1) = ((i0 + 1).min(nx - 1), (j0 + 1).min(ny - 1));
    let (a, b) = (u - i0 as f32, v - j0 as f32);
    let row = |j: usize| z[j * nx + i0] * (1.0 - a) + z[j * nx + i1] * a;
    row(j0) * (1.0 - b) + row(j1) * b
}

/// A ground surface fitted to the trees (see [`GroundFit`]).
#[derive(Debug, Clone)]
pub struct FittedGround {
    x0: f64,
    y0: f64,
    cell: f64,
    nx: usize,
    ny: usize,
    z: Vec<f32>,
}

impl FittedGround {
    /// Ground height at a point (metres relative to the scene origin), clamped to the fit's edge.
    pub fn height(&self, x: f64, y: f64) -> f32 {
        let u = (((x - self.x0) / self.cell) as f32).clamp(0.0, (self.nx - 1) as f32);
        let v = (((y - self.y0) / self.cell) as f32).clamp(0.0, (self.ny - 1) as f32);
        bilinear(&self.z, self.nx, self.ny, u, v)
    }

    /// Cell size, metres (the terrain's finest spacing).
    pub fn cell_m(&self) -> f64 {
        self.cell
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fit_follows_the_trees_and_fills_the_gaps_smoothly() {
        // Trees on a slope z = 0.2 x in two clusters far apart; nothing between.
        let mut fit = GroundFit::new([0.0, 0.0, 1024.0, 256.0]);
        assert_eq!(fit.cell, 4.0);
        for k in 0..400 {
            let (x, y) = (f64::from(k % 20) * 3.0, f64::from(k / 20) * 3.0 + 100.0);
            fit.add(x, y, 0.2 * x);
            fit.add(x + 900.0, y, 0.2 * (x + 900.0));
        }
        let g = fit.finish().unwrap();
        // Under the trees: the slope to within a cell's averaging.
        for x in [10.0, 40.0, 920.0, 950.0] {
            assert!((f64::from(g.height(x, 130.0)) - 0.2 * x).abs() < 1.0, "{x}: {}", g.height(x, 130.0));
        }
        // Between the clusters: between their heights, no NaN, no wild values.
        for x in (100..880).step_by(40) {
            let h = g.height(f64::from(x), 130.0);
            assert!(h.is_finite() && (0.0..=200.0).contains(&h), "{x}: {h}");
        }
        assert!(GroundFit::new([0.0, 0.0, 10.0, 10.0]).finish().is_none());
    }
}
