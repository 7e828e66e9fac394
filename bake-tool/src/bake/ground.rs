//! Ground heights for the trees (stage 1): the `--dem` GeoTIFFs, each in its
//! own CRS, sampled bilinearly at a tree's position in the scene CRS. The
//! first DEM that has data at a point gives its height.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use sylva_bake::dem::Dem;

use crate::reproject::{Crs, Reprojector};

/// How a given `z` column is meant when there is a DEM.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ZMode {
    /// Ground elevation in the scene's vertical datum: the DEM is not used for rows with a z.
    Absolute,
    /// Height above the DEM's ground (e.g. a tree on a roof or a platform).
    Relative,
}

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
            out.push(GroundDem { path, dem, to_dem, geographic: crs.is_geographic() });
        }
        Ok(Ground { dems: out })
    }
}

struct GroundDem {
    path: PathBuf,
    dem: Dem,
    to_dem: Option<Reprojector>,
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

    /// The finest DEM pixel size in metres (a geographic DEM's degrees taken
    /// as 111 km, their length along a meridian).
    pub fn resolution_m(&self) -> f64 {
        self.dems
            .iter()
            .map(|g| {
                let r = g.dem.summary().resolution;
                r[0].min(r[1]) * if g.geographic { 111_000.0 } else { 1.0 }
            })
            .fold(f64::MAX, f64::min)
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
                let e = g.dem.summary().extent;
                format!("{} covers x {:.1}–{:.1}, y {:.1}–{:.1}", name(&g.path), e[0], e[2], e[1], e[3])
            })
            .collect::<Vec<_>>()
            .join("; ")
    }
}

fn name(p: &Path) -> String {
    p.file_name().map_or_else(|| p.display().to_string(), |n| n.to_string_lossy().into_owned())
}
