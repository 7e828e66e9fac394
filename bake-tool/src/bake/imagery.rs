//! Stage 5 of the bake: ground imagery (`terrain/img/<level>/<x>_<y>.jpg`,
//! see `sylva::format::terrain::ImageryEntry`) from the `--ortho` GeoTIFFs,
//! draped on the terrain tiles.
//!
//! One [`IMAGERY_PX`]² JPEG per terrain tile of the imagery levels that meets
//! the orthophotos' extent. The finest imagery level is the first whose pixels
//! are no larger than the orthophoto's (finer terrain tiles drape a part of an
//! ancestor's image: nothing is gained by upsampling). Its images are sampled
//! from the orthophotos (bilinear, supersampled where an image pixel spans
//! several orthophoto pixels); a coarser image is the 2 × 2 box average of
//! its children's, so every level is filtered like a mipmap.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::input::ortho::Ortho;
use anyhow::{bail, Context, Result};
use rayon::prelude::*;
use sylva::format::terrain::{ImageryEntry, TerrainEntry, TerrainTile};

use crate::input::reproject::{Crs, Reprojector};

/// Pixels per imagery side.
pub const IMAGERY_PX: u32 = sylva::format::terrain::IMAGERY_PX;
/// JPEG quality of the images.
const JPEG_QUALITY: u8 = 85;

/// The opened orthophotos, not yet tied to a scene CRS.
pub struct Orthos {
    orthos: Vec<(PathBuf, Ortho, Crs)>,
}

/// The orthophotos in the scene CRS.
pub struct SceneOrthos {
    orthos: Vec<(PathBuf, Ortho, Option<Reprojector>, Option<Reprojector>)>,
}

impl Orthos {
    /// Reads every orthophoto (before any long work, so a bad file fails
    /// fast). `crs` (`--ortho-crs`) is used for files whose GeoKeys name none,
    /// and overrides them.
    ///
    /// # Errors
    /// A file that does not read as a GeoTIFF orthophoto, or whose CRS is unknown.
    pub fn open(paths: &[PathBuf], crs: Option<&str>, log: &dyn Fn(&str)) -> Result<Self> {
        let mut orthos = Vec::new();
        for path in paths {
            let o = Ortho::open(path)?;
            let epsg = match (crs, o.epsg) {
                (Some(c), _) => Crs::parse(c).with_context(|| format!("--ortho-crs {c}"))?.epsg,
                (None, Some(e)) => e,
                (None, None) => bail!(
                    "ortho {}: its GeoKeys name no EPSG code: say which CRS it is in with --ortho-crs EPSG:xxxx",
                    path.display()
                ),
            };
            let e = o.extent();
            log(&format!(
                "ortho {}: {}×{} pixels of {:.2}, EPSG:{epsg}, {}; x {:.1}–{:.1}, y {:.1}–{:.1}",
                path.display(),
                o.width,
                o.height,
                o.resolution(),
                o.layout,
                e[0],
                e[2],
                e[1],
                e[3]
            ));
            let crs = Crs::from_epsg(epsg).with_context(|| format!("ortho {}", path.display()))?;
            orthos.push((path.clone(), o, crs));
        }
        Ok(Self { orthos })
    }

    /// Whether no orthophoto was given.
    pub fn is_empty(&self) -> bool {
        self.orthos.is_empty()
    }

    /// The orthophotos as seen from the scene CRS.
    ///
    /// # Errors
    /// A CRS proj4rs cannot transform from or to the scene CRS.
    pub fn in_scene(self, scene: &Crs) -> Result<SceneOrthos> {
        let mut out = Vec::new();
        for (path, o, crs) in self.orthos {
            let (to, from) = if crs.epsg == scene.epsg {
                (None, None)
            } else {
                let to = Reprojector::new(Crs::from_epsg(scene.epsg)?, &crs)
                    .with_context(|| format!("ortho {}: from the scene CRS", path.display()))?;
                let from = Reprojector::new(Crs::from_epsg(crs.epsg)?, &Crs::from_epsg(scene.epsg)?)?;
                (Some(to), Some(from))
            };
            out.push((path, o, to, from));
        }
        Ok(SceneOrthos { orthos: out })
    }
}

impl SceneOrthos {
    /// Colour (0–255 RGB) and coverage (0–1) at a scene-CRS point, from the
    /// first orthophoto with data there.
    pub fn colour_at(&self, x: f64, y: f64) -> Option<[f32; 4]> {
        self.orthos.iter().find_map(|(_, o, to, _)| {
            let (ox, oy) = match to {
                Some(r) => r.apply(x, y).ok()?,
                None => (x, y),
            };
            o.sample(ox, oy)
        })
    }

    /// The union of the orthophotos' extents in the scene CRS (corners and
    /// edge midpoints projected), or `None` if a projection fails.
    pub fn scene_extent(&self) -> Option<[f64; 4]> {
        let mut b = [f64::MAX, f64::MAX, f64::MIN, f64::MIN];
        for (_, o, _, from) in &self.orthos {
            let e = o.extent();
            let (cx, cy) = ((e[0] + e[2]) * 0.5, (e[1] + e[3]) * 0.5);
            for (x, y) in
                [(e[0], e[1]), (e[2], e[1]), (e[0], e[3]), (e[2], e[3]), (cx, e[1]), (cx, e[3]), (e[0], cy), (e[2], cy)]
            {
                let (sx, sy) = match from {
                    None => (x, y),
                    Some(r) => r.apply(x, y).ok()?,
                };
                b = [b[0].min(sx), b[1].min(sy), b[2].max(sx), b[3].max(sy)];
            }
        }
        (b[0] <= b[2]).then_some(b)
    }

    /// The finest pixel size in scene metres (from the extent in the scene
    /// CRS over the pixel count, so a geographic image is measured too).
    pub fn resolution_m(&self) -> f64 {
        self.orthos
            .iter()
            .map(|(_, o, _, from)| {
                let e = o.extent();
                let ends = [(e[0], e[1]), (e[2], e[3])].map(|(x, y)| match from {
                    None => Some((x, y)),
                    Some(r) => r.apply(x, y).ok(),
                });
                match ends {
                    [Some(a), Some(b)] => {
                        ((b.0 - a.0).abs() / f64::from(o.width)).min((b.1 - a.1).abs() / f64::from(o.height))
                    }
                    _ => o.resolution(),
                }
            })
            .fold(f64::MAX, f64::min)
    }

    /// The file names, for reports.
    pub fn names(&self) -> String {
        self.orthos
            .iter()
            .map(|(p, ..)| p.file_name().map_or_else(|| p.display().to_string(), |n| n.to_string_lossy().into_owned()))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// Imagery to drape on the terrain.
pub struct ImagerySource<'a> {
    /// Colour (0–255 RGB) and coverage (0–1) at a point in metres relative to
    /// the scene origin, `None` without data.
    pub colour: &'a (dyn Fn(f64, f64) -> Option<[f32; 4]> + Sync),
    /// Where there is imagery, metres relative to the scene origin.
    pub extent_m: [f64; 4],
    /// Pixel size of the source, metres.
    pub resolution_m: f64,
    /// Most samples along a side of an image pixel coarser than the source
    /// (at most 4): photos 4, each texel the mean of what it covers; a
    /// procedural colour fewer (its fine detail averages out anyway, and each
    /// sample costs a dozen noise lookups: 16 a pixel made a few hundred
    /// trees spread over a city take seconds of a bake).
    pub supersample: usize,
    /// Where it came from, for reports.
    pub source: String,
}

/// One image before encoding: RGB 0–255 and coverage per pixel, row 0 north.
type Pixels = Vec<[f32; 4]>;

/// Writes the images for the terrain `terrain` (already written into `dir`)
/// and returns the imagery entry, or `None` when no terrain tile meets the
/// imagery.
///
/// # Errors
/// A terrain tile that cannot be read back, an image that cannot be written.
pub fn write_imagery(
    src: &ImagerySource<'_>,
    terrain: &TerrainEntry,
    dir: &Path,
    log: &dyn Fn(&str),
) -> Result<Option<ImageryEntry>> {
    let started = std::time::Instant::now();
    let px = f64::from(IMAGERY_PX);
    // The finest level: the first whose image pixels are no larger than the source's.
    let mut finest = terrain.levels - 1;
    for l in 0..terrain.levels {
        if terrain.tile_size_m(l) / px <= src.resolution_m * 1.0001 {
            finest = l;
            break;
        }
    }
    let mut entry = ImageryEntry {
        path: format!("{}/img", terrain.path),
        tile_px: IMAGERY_PX,
        levels: finest + 1,
        // Millimetres: short decimals read back exactly (a merge re-reads the manifest).
        extent_m: src.extent_m.map(|v| (v * 1000.0).round() / 1000.0),
        resolution_m: src.resolution_m,
        tiles: 0,
        bytes: 0,
        source: src.source.clone(),
    };
    let mut with = terrain.clone();
    with.imagery = Some(entry.clone());
    let tiles = AtomicU64::new(0);
    let bytes = AtomicU64::new(0);
    let ctx = Ctx { src, terrain: &with, dir, tiles: &tiles, bytes: &bytes };
    if ctx.build(0, 0, 0)?.is_none() {
        log("imagery: no terrain tile meets the orthophotos (no imagery written)");
        return Ok(None);
    }
    entry.tiles = tiles.load(Ordering::Relaxed);
    entry.bytes = bytes.load(Ordering::Relaxed);
    log(&format!(
        "imagery: {} images of {IMAGERY_PX}² in {} levels, finest {:.2} m per pixel (source {:.2} m), {:.2} MB ({:.2} s)",
        entry.tiles,
        entry.levels,
        terrain.tile_size_m(finest) / px,
        src.resolution_m,
        entry.bytes as f64 / 1e6,
        started.elapsed().as_secs_f64()
    ));
    Ok(Some(entry))
}

struct Ctx<'a> {
    src: &'a ImagerySource<'a>,
    terrain: &'a TerrainEntry,
    dir: &'a Path,
    tiles: &'a AtomicU64,
    bytes: &'a AtomicU64,
}

impl Ctx<'_> {
    /// The image of terrain tile `(level, x, y)` (written, and returned for
    /// its parent), or `None` where the tile has no image.
    fn build(&self, level: u8, x: u32, y: u32) -> Result<Option<Pixels>> {
        let t = self.terrain;
        if !t.has_imagery(level, x, y) {
            return Ok(None);
        }
        let rel = t.tile_url(level, x, y);
        let path = self.dir.join(&rel);
        if !path.exists() {
            return Ok(None); // no terrain here
        }
        let file = std::fs::read(&path).with_context(|| format!("cannot read {}", path.display()))?;
        let tile = TerrainTile::decode(&rel, &file)?;
        let n = IMAGERY_PX as usize;
        let kids: Vec<Option<Pixels>> = (0..4u32)
            .into_par_iter()
            .map(|k| {
                if tile.children[k as usize].exists && level + 1 < t.levels {
                    self.build(level + 1, 2 * x + (k & 1), 2 * y + (k >> 1))
                } else {
                    Ok(None)
                }
            })
            .collect::<Result<_>>()?;
        let mut img: Pixels = vec![[0.0; 4]; n * n];
        let size = t.tile_size_m(level);
        let [ox, oy] = t.tile_origin_m(level, x, y);
        let texel = size / n as f64;
        let k_ss = ((texel / self.src.resolution_m).ceil() as usize).clamp(1, self.src.supersample.clamp(1, 4));
        for (q, kid) in kids.iter().enumerate() {
            // Quadrant q (south-west, south-east, north-west, north-east) in image rows (0: north).
            let (qi, qj) = ((q & 1) * n / 2, (1 - (q >> 1)) * n / 2);
            for j in 0..n / 2 {
                for i in 0..n / 2 {
                    let (pi, pj) = (qi + i, qj + j);
                    img[pj * n + pi] = match kid {
                        Some(c) => {
                            // Weighted by coverage, so uncovered pixels do not darken the average.
                            let mut s = [0.0f32; 4];
                            for (di, dj) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                                let p = c[(2 * j + dj) * n + 2 * i + di];
                                for k in 0..3 {
                                    s[k] += p[k] * p[3];
                                }
                                s[3] += p[3];
                            }
                            if s[3] > 0.0 {
                                [s[0] / s[3], s[1] / s[3], s[2] / s[3], s[3] * 0.25]
                            } else {
                                [0.0; 4]
                            }
                        }
                        None => {
                            // Supersampled from the orthophotos.
                            let mut s = [0.0f32; 4];
                            let mut w = 0.0;
                            for sj in 0..k_ss {
                                for si in 0..k_ss {
                                    let fx = (pi as f64 + (si as f64 + 0.5) / k_ss as f64) * texel;
                                    let fy = (pj as f64 + (sj as f64 + 0.5) / k_ss as f64) * texel;
                                    if let Some(c) = (self.src.colour)(ox + fx, oy + size - fy) {
                                        for k in 0..3 {
                                            s[k] += c[k] * c[3];
                                        }
                                        s[3] += c[3];
                                    }
                                    w += 1.0;
                                }
                            }
                            if s[3] > 0.0 {
                                [s[0] / s[3], s[1] / s[3], s[2] / s[3], s[3] / w]
                            } else {
                                [0.0; 4]
                            }
                        }
                    };
                }
            }
        }
        let encoded = encode_jpeg(&img, IMAGERY_PX)?;
        let out = self.dir.join(t.imagery.as_ref().map_or(String::new(), |i| i.tile_url(level, x, y)));
        if let Some(parent) = out.parent() {
            crate::out_dir::create_dir(parent)?;
        }
        crate::out_dir::write_file(&out, &encoded)?;
        self.tiles.fetch_add(1, Ordering::Relaxed);
        self.bytes.fetch_add(encoded.len() as u64, Ordering::Relaxed);
        Ok(Some(img))
    }
}

/// JPEG bytes of an image; pixels without coverage take the mean colour of
/// those with (a viewer shows its own ground there; a flat fill keeps the
/// compression from ringing at the edge).
fn encode_jpeg(img: &[[f32; 4]], px: u32) -> Result<Vec<u8>> {
    let mut mean = [0.0f64; 3];
    let mut covered = 0.0f64;
    for p in img {
        if p[3] > 0.0 {
            for k in 0..3 {
                mean[k] += f64::from(p[k]);
            }
            covered += 1.0;
        }
    }
    let fill = if covered > 0.0 { mean.map(|m| (m / covered) as f32) } else { [96.0, 88.0, 64.0] };
    let rgb: Vec<u8> = img
        .iter()
        .flat_map(|p| {
            let c = if p[3] > 0.0 { [p[0], p[1], p[2]] } else { fill };
            c.map(|v| v.round().clamp(0.0, 255.0) as u8)
        })
        .collect();
    let mut out = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, JPEG_QUALITY)
        .encode(&rgb, px, px, image::ExtendedColorType::Rgb8)
        .context("cannot encode an imagery JPEG")?;
    Ok(out)
}
