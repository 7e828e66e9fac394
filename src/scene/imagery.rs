//! Ground imagery on the terrain (CPU side; the terrain pass samples what this
//! attaches to each drawn tile, `src/render/terrain.rs`).
//!
//! Every image covers one terrain tile's square ([`IMAGE_PX`]², row 0 at the
//! north edge, RGBA8 sRGB, alpha = coverage). It comes from one of two
//! sources ([`ImageryChoice`]):
//! - the scene's baked imagery (`terrain.imagery` in the manifest): one JPEG
//!   per terrain tile of its imagery levels;
//! - an XYZ or WMTS raster source in Web Mercator (a URL template): the tiles
//!   of the zoom whose pixels match the image's are fetched and resampled into
//!   the terrain tile's square, through the scene CRS (the [`GeoFrame`]: a 9 × 9 grid of
//!   exactly projected points, bilinear between them).
//!
//! Each frame [`Imagery::attach`] gives every drawn terrain tile the image of
//! the finest tile at or above it that is resident (finer tiles drape a part
//! of it: an offset and scale in the tile's uv), and asks for the image the
//! tile should have. At most 96 images are kept (least
//! recently used dropped; images drawn this frame and the root's are kept
//! even beyond it). One image of an XYZ source may start several source
//! fetches at once (up to 16, usually 1–4), beyond the stream's in-flight
//! limit; baked images that fail with a server error are retried with backoff
//! like tiles.

use std::collections::HashMap;
use std::sync::Arc;

use glam::DVec3;

use super::quadtree::{ancestor, uv_in, QuadKey as TerrainKey, QuadResidency, RetryPolicy};
use crate::format::imagery::{decode_image, Rgba8};
use crate::format::terrain::TerrainEntry;
use crate::geo::GeoFrame;

/// Pixels per image side.
pub const IMAGE_PX: u32 = crate::format::terrain::IMAGERY_PX;
/// Largest side of an XYZ/WMTS tile accepted.
pub const MAX_SOURCE_TILE_PX: u32 = 1024;
/// Points per side of the grid projected exactly for an XYZ image.
const GRID: usize = 9;
/// Most source tiles composed into one image (the zoom is lowered beyond).
const MAX_SOURCE_TILES: usize = 16;

/// One image: [`IMAGE_PX`]² RGBA8 (sRGB) pixels, row 0 north; alpha is coverage.
#[derive(Debug, Clone, PartialEq)]
pub struct ImageryTile {
    /// Pixels per side.
    pub px: u32,
    /// `px² · 4` bytes.
    pub rgba: Vec<u8>,
}

/// Which image a drawn terrain tile drapes.
#[derive(Debug, Clone)]
pub struct DrawImagery {
    /// Identifies the image (source generation, terrain tile it covers).
    pub key: (u32, TerrainKey),
    /// The image.
    pub tile: Arc<ImageryTile>,
    /// Where the drawn tile lies in the image's tile: uv offset (x, y) and
    /// scale (z, w), uv running east and north from the south-west corner.
    pub uv: [f32; 4],
}

/// An XYZ (or WMTS, GoogleMapsCompatible) raster source in Web Mercator.
#[derive(Debug, Clone, PartialEq)]
pub struct XyzSource {
    template: String,
    /// Finest zoom level the source serves.
    pub max_zoom: u8,
}

impl XyzSource {
    /// A source from a URL template: `{z}`, `{x}`, `{y}` (`{-y}`: TMS rows
    /// counted from the south), or the WMTS names `{TileMatrix}`, `{TileCol}`,
    /// `{TileRow}`.
    ///
    /// # Errors
    /// A template without a zoom, column and row placeholder, or a zoom beyond 24.
    pub fn new(template: &str, max_zoom: u8) -> Result<Self, String> {
        let has = |names: &[&str]| names.iter().any(|n| template.contains(n));
        if !(has(&["{z}", "{TileMatrix}"]) && has(&["{x}", "{TileCol}"]) && has(&["{y}", "{-y}", "{TileRow}"])) {
            return Err(format!(
                "imagery URL {template:?} has no {{z}}/{{x}}/{{y}} (or WMTS {{TileMatrix}}/{{TileCol}}/{{TileRow}}) placeholders"
            ));
        }
        if max_zoom > 24 {
            return Err(format!("imagery max zoom {max_zoom} is beyond 24"));
        }
        Ok(Self { template: template.to_string(), max_zoom })
    }

    /// The URL of tile `(z, x, y)` (XYZ rows: 0 at the north).
    #[must_use]
    pub fn url(&self, z: u8, x: u32, y: u32) -> String {
        let tms = (1u32 << z) - 1 - y;
        self.template
            .replace("{z}", &z.to_string())
            .replace("{TileMatrix}", &z.to_string())
            .replace("{x}", &x.to_string())
            .replace("{TileCol}", &x.to_string())
            .replace("{-y}", &tms.to_string())
            .replace("{y}", &y.to_string())
            .replace("{TileRow}", &y.to_string())
    }
}

/// Where ground imagery comes from.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum ImageryChoice {
    /// The scene's baked imagery, if it has some.
    #[default]
    Scene,
    /// None: the terrain's own ground material.
    Off,
    /// An XYZ/WMTS raster source.
    Xyz(XyzSource),
}

/// A fetch the imagery wants started.
#[derive(Debug, Clone, PartialEq)]
pub enum ImageryFetch {
    /// A baked image: its URL relative to the manifest.
    Baked(TerrainKey, String),
    /// A source tile `(z, x, y)`: its URL as the template gives it.
    Source((u8, u32, u32), String),
}

#[derive(Debug)]
enum SourceSlot {
    Loading,
    Failed,
    Ready(Arc<Rgba8>),
}

/// A source tile's address `(z, x, y)`.
type SourceKey = (u8, u32, u32);
/// The source tiles an image is composed from (`None`: failed).
type SourceTiles = [(SourceKey, Option<Arc<Rgba8>>)];

/// An XYZ image waiting for its source tiles.
#[derive(Debug)]
struct Compose {
    zoom: u8,
    /// Web Mercator world coordinates (0–1, y south) of a GRID² point grid over
    /// the tile, row-major from the south-west.
    grid: Vec<[f64; 2]>,
    tiles: Vec<(u8, u32, u32)>,
}

/// The imagery of one scene: what is resident and which images the drawn tiles drape.
#[derive(Debug)]
pub struct Imagery {
    choice: ImageryChoice,
    generation: u32,
    /// The images resident, asked for and waited for (at most 96 kept, 256 KB each).
    res: QuadResidency<ImageryTile>,
    pending: HashMap<TerrainKey, Compose>,
    source: HashMap<(u8, u32, u32), SourceSlot>,
    /// The image each drawn tile should drape (for an XYZ source: worked out
    /// once per tile, as it takes projections).
    targets: HashMap<TerrainKey, Option<TerrainKey>>,
    /// A drawn tile's image (or the root image it starts with) waits for a
    /// retry: set by [`Self::attach`].
    waiting_needed: bool,
}

impl Default for Imagery {
    fn default() -> Self {
        Self::new()
    }
}

impl Imagery {
    /// No imagery yet, the scene's own as the source.
    #[must_use]
    pub fn new() -> Self {
        Self {
            choice: ImageryChoice::default(),
            generation: 0,
            res: QuadResidency::new(96),
            pending: HashMap::new(),
            source: HashMap::new(),
            targets: HashMap::new(),
            waiting_needed: false,
        }
    }

    /// The source.
    #[must_use]
    pub fn choice(&self) -> &ImageryChoice {
        &self.choice
    }

    /// Changes the source (everything held is dropped; answers to requests of
    /// the former source are ignored).
    pub fn set_choice(&mut self, choice: ImageryChoice) {
        if choice != self.choice {
            self.choice = choice;
            self.generation = self.generation.wrapping_add(1);
            self.res.clear();
            self.pending.clear();
            self.source.clear();
            self.targets.clear();
        }
    }

    /// The current source generation (requests carry it).
    #[must_use]
    pub fn generation(&self) -> u32 {
        self.generation
    }

    /// Images decoded and kept.
    #[must_use]
    pub fn resident(&self) -> usize {
        self.res.resident()
    }

    /// The resident image of `key`, if any (for tests and tools).
    #[must_use]
    pub fn image(&self, key: TerrainKey) -> Option<Arc<ImageryTile>> {
        self.res.get(key).cloned()
    }

    /// The tile whose image `key` should drape: itself, or the ancestor at the
    /// finest level with images (`None`: no image for it).
    fn target(&mut self, entry: &TerrainEntry, geo: Option<&GeoFrame>, key: TerrainKey) -> Option<TerrainKey> {
        match &self.choice {
            ImageryChoice::Off => None,
            ImageryChoice::Scene => {
                let levels = entry.imagery.as_ref()?.levels;
                let k = ancestor(key, key.0.min(levels - 1));
                entry.has_imagery(k.0, k.1, k.2).then_some(k)
            }
            ImageryChoice::Xyz(src) => {
                if let Some(t) = self.targets.get(&key) {
                    return *t;
                }
                let geo = geo?;
                let mut k = key;
                // Up while the image would be more than twice as sharp as the source.
                while k.0 > 0 && zoom_for(entry, geo, k).is_some_and(|z| z > u32::from(src.max_zoom) + 1) {
                    k = ancestor(k, k.0 - 1);
                }
                if self.targets.len() > 16_384 {
                    self.targets.clear();
                }
                self.targets.insert(key, Some(k));
                Some(k)
            }
        }
    }

    /// Attaches to each drawn tile (its key and its image slot) the finest
    /// resident image at or above it, and appends the images to fetch to
    /// `wanted` (in draw order, no repeats).
    pub fn attach<'a>(
        &mut self,
        entry: &TerrainEntry,
        geo: Option<&GeoFrame>,
        draws: impl IntoIterator<Item = (TerrainKey, &'a mut Option<DrawImagery>)>,
        wanted: &mut Vec<TerrainKey>,
    ) {
        self.res.next_frame();
        self.waiting_needed = false;
        for (key, imagery) in draws {
            *imagery = None;
            let Some(target) = self.target(entry, geo, key) else { continue };
            if self.askable(target) && !wanted.contains(&target) {
                wanted.push(target);
            }
            self.waiting_needed |= self.res.waiting(target);
            let mut k = target;
            loop {
                if let Some(tile) = self.res.use_now(k) {
                    *imagery = Some(DrawImagery { key: (self.generation, k), tile, uv: uv_in(k, key) });
                    break;
                }
                if k.0 == 0 {
                    break;
                }
                k = ancestor(k, k.0 - 1);
            }
            // Nothing yet: the coarsest image first, so the ground shows something soon.
            if imagery.is_none() {
                let root = ancestor(target, 0);
                if root != target && self.askable(root) && !wanted.contains(&root) {
                    wanted.insert(0, root);
                }
            }
        }
    }

    /// Starts loading the image of `key`: the fetches it needs (none when it
    /// is composed from source tiles already held, or cannot be made).
    pub fn start(&mut self, entry: &TerrainEntry, geo: Option<&GeoFrame>, key: TerrainKey) -> Vec<ImageryFetch> {
        let mut out = Vec::new();
        if !self.askable(key) {
            return out;
        }
        match &self.choice {
            ImageryChoice::Off => {}
            ImageryChoice::Scene => {
                if let Some(i) = &entry.imagery {
                    // (A retry keeps its attempt count.)
                    self.res.mark_loading(key);
                    out.push(ImageryFetch::Baked(key, i.tile_url(key.0, key.1, key.2)));
                }
            }
            ImageryChoice::Xyz(src) => {
                let Some(geo) = geo else { return out };
                let Some(c) = plan(entry, geo, key, src.max_zoom) else {
                    self.res.mark_broken(key);
                    return out;
                };
                for &t in &c.tiles {
                    if let std::collections::hash_map::Entry::Vacant(e) = self.source.entry(t) {
                        e.insert(SourceSlot::Loading);
                        out.push(ImageryFetch::Source(t, src.url(t.0, t.1, t.2)));
                    }
                }
                self.res.mark_loading(key);
                self.pending.insert(key, c);
            }
        }
        out
    }

    /// A baked image arrived (or failed for good: the tile drapes its ancestor's).
    ///
    /// # Errors
    /// The bytes are no image of [`IMAGE_PX`]² (the message names `url`).
    pub fn on_baked(
        &mut self,
        entry: &TerrainEntry,
        key: TerrainKey,
        url: &str,
        bytes: Option<&[u8]>,
    ) -> Result<(), String> {
        let Some(bytes) = bytes else {
            self.res.mark_broken(key);
            return Ok(());
        };
        let decoded = decode_image(url, bytes, IMAGE_PX).map_err(|e| e.to_string()).and_then(|img| {
            if img.width != IMAGE_PX || img.height != IMAGE_PX {
                Err(format!("{url}: a {}×{} image where {IMAGE_PX}² was expected", img.width, img.height))
            } else {
                Ok(img)
            }
        });
        match decoded {
            Ok(mut img) => {
                // Coverage from the imagery extent.
                if let Some(i) = &entry.imagery {
                    let [ox, oy] = entry.tile_origin_m(key.0, key.1, key.2);
                    let s = entry.tile_size_m(key.0);
                    let n = IMAGE_PX as usize;
                    let [x0, y0, x1, y1] = i.extent_m;
                    for j in 0..n {
                        let y = oy + s * (1.0 - (j as f64 + 0.5) / n as f64);
                        for ii in 0..n {
                            let x = ox + s * (ii as f64 + 0.5) / n as f64;
                            let inside = x >= x0 && x <= x1 && y >= y0 && y <= y1;
                            img.pixels[(j * n + ii) * 4 + 3] = if inside { 255 } else { 0 };
                        }
                    }
                }
                self.insert(key, ImageryTile { px: IMAGE_PX, rgba: img.pixels });
                Ok(())
            }
            Err(e) => {
                self.res.mark_broken(key);
                Err(e)
            }
        }
    }

    /// A baked image failed in a way a retry may mend: it waits `base_s ·
    /// 2^(attempts − 1)` seconds and is asked for again, up to `max_attempts`
    /// attempts. Returns whether it will be retried (else it is given up on).
    pub fn retry_later(&mut self, key: TerrainKey, now_s: f64, policy: RetryPolicy) -> bool {
        self.res.failed(key, true, policy, now_s)
    }

    /// Whether an image the drawn terrain needs waits for its retry: the view
    /// is not settled before it arrived or was given up on (then listed among
    /// the failures, as tiles and terrain are). Images no longer drawn do not count.
    #[must_use]
    pub fn retries_pending(&self) -> bool {
        self.waiting_needed
    }

    /// Failed images whose retry is due become wanted again.
    pub fn retry_due(&mut self, now_s: f64) {
        self.res.retry_due(now_s);
    }

    /// Whether the image of `key` is to be asked for (never asked, or a retry is due).
    fn askable(&self, key: TerrainKey) -> bool {
        self.res.is_unknown(key)
    }

    /// A source tile arrived (`None`: failed; its part of the images stays
    /// without imagery). Images whose tiles are all in are composed.
    ///
    /// # Errors
    /// The bytes are no image (the message names `url`); the tile counts as failed.
    pub fn on_source(&mut self, tile: (u8, u32, u32), url: &str, bytes: Option<&[u8]>) -> Result<(), String> {
        let mut result = Ok(());
        let slot = match bytes.map(|b| decode_image(url, b, MAX_SOURCE_TILE_PX)) {
            Some(Ok(img)) => SourceSlot::Ready(Arc::new(img)),
            Some(Err(e)) => {
                result = Err(e.to_string());
                SourceSlot::Failed
            }
            None => SourceSlot::Failed,
        };
        self.source.insert(tile, slot);
        self.compose_ready();
        result
    }

    /// Composes every pending image whose source tiles are all in, then drops
    /// source tiles no pending image needs.
    fn compose_ready(&mut self) {
        let ready: Vec<TerrainKey> = self
            .pending
            .iter()
            .filter(|(_, c)| c.tiles.iter().all(|t| !matches!(self.source.get(t), Some(SourceSlot::Loading) | None)))
            .map(|(k, _)| *k)
            .collect();
        for key in ready {
            let Some(c) = self.pending.remove(&key) else { continue };
            let tiles: Vec<(SourceKey, Option<Arc<Rgba8>>)> = c
                .tiles
                .iter()
                .map(|t| {
                    (
                        *t,
                        match self.source.get(t) {
                            Some(SourceSlot::Ready(img)) => Some(Arc::clone(img)),
                            _ => None,
                        },
                    )
                })
                .collect();
            let image = compose(&c, &tiles);
            self.insert(key, image);
        }
        let needed: Vec<(u8, u32, u32)> = self.pending.values().flat_map(|c| c.tiles.iter().copied()).collect();
        self.source.retain(|t, s| matches!(s, SourceSlot::Loading) || needed.contains(t));
    }

    fn insert(&mut self, key: TerrainKey, tile: ImageryTile) {
        self.res.insert(key, tile);
    }
}

/// Web Mercator world coordinates (0–1 east, 0–1 south) of lon/lat degrees.
fn mercator(lon: f64, lat: f64) -> [f64; 2] {
    let lat = lat.clamp(-85.051_128_78, 85.051_128_78).to_radians();
    let y = (1.0 - (lat.tan() + 1.0 / lat.cos()).ln() / std::f64::consts::PI) * 0.5;
    [(lon + 180.0) / 360.0, y]
}

/// The exact grid of a tile's points in Web Mercator.
fn mercator_grid(entry: &TerrainEntry, geo: &GeoFrame, key: TerrainKey) -> Option<Vec<[f64; 2]>> {
    let [ox, oy] = entry.tile_origin_m(key.0, key.1, key.2);
    let s = entry.tile_size_m(key.0);
    let mut grid = Vec::with_capacity(GRID * GRID);
    for j in 0..GRID {
        for i in 0..GRID {
            let (x, y) = (ox + s * i as f64 / (GRID - 1) as f64, oy + s * j as f64 / (GRID - 1) as f64);
            let (lon, lat, _) = geo.to_geo(DVec3::new(x, y, 0.0)).ok()?;
            if !(lon.is_finite() && lat.is_finite()) {
                return None;
            }
            grid.push(mercator(lon, lat));
        }
    }
    Some(grid)
}

/// The zoom whose pixels match an image of tile `key` (unclamped), from its
/// corners and centre.
fn zoom_for(entry: &TerrainEntry, geo: &GeoFrame, key: TerrainKey) -> Option<u32> {
    let [ox, oy] = entry.tile_origin_m(key.0, key.1, key.2);
    let s = entry.tile_size_m(key.0);
    let mut points = [[0.0; 2]; 5];
    for (p, (u, v)) in points.iter_mut().zip([(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0), (0.5, 0.5)]) {
        let (lon, lat, _) = geo.to_geo(DVec3::new(ox + s * u, oy + s * v, 0.0)).ok()?;
        if !(lon.is_finite() && lat.is_finite()) {
            return None;
        }
        *p = mercator(lon, lat);
    }
    Some(zoom_of(&points))
}

fn zoom_of(grid: &[[f64; 2]]) -> u32 {
    let (lo, hi) = bounds(grid);
    let span = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1e-12);
    (1.0 / span).log2().ceil().clamp(0.0, 30.0) as u32
}

fn bounds(grid: &[[f64; 2]]) -> ([f64; 2], [f64; 2]) {
    grid.iter().fold(([f64::MAX; 2], [f64::MIN; 2]), |(lo, hi), p| {
        ([lo[0].min(p[0]), lo[1].min(p[1])], [hi[0].max(p[0]), hi[1].max(p[1])])
    })
}

/// The zoom and source tiles of tile `key`'s image.
fn plan(entry: &TerrainEntry, geo: &GeoFrame, key: TerrainKey, max_zoom: u8) -> Option<Compose> {
    let grid = mercator_grid(entry, geo, key)?;
    let (lo, hi) = bounds(&grid);
    let mut zoom = zoom_of(&grid).min(u32::from(max_zoom));
    loop {
        let n = f64::from(1u32 << zoom);
        let t = |v: f64| (v * n).floor().clamp(0.0, n - 1.0) as u32;
        let (x0, x1, y0, y1) = (t(lo[0]), t(hi[0]), t(lo[1]), t(hi[1]));
        let count = (x1 - x0 + 1) as usize * (y1 - y0 + 1) as usize;
        if count <= MAX_SOURCE_TILES || zoom == 0 {
            let z = zoom as u8;
            let tiles = (y0..=y1).flat_map(|y| (x0..=x1).map(move |x| (z, x, y))).collect();
            return Some(Compose { zoom: z, grid, tiles });
        }
        zoom -= 1;
    }
}

/// Resamples the source tiles into the image of one terrain tile (bilinear;
/// pixels over failed tiles have alpha 0).
fn compose(c: &Compose, tiles: &SourceTiles) -> ImageryTile {
    let n = IMAGE_PX as usize;
    let world_px = f64::from(1u32 << c.zoom) * 256.0;
    let mut rgba = vec![0u8; n * n * 4];
    // The tiles form a rectangle (row-major from its north-west tile): index it.
    let x0 = tiles.iter().map(|(t, _)| i64::from(t.1)).min().unwrap_or(0);
    let y0 = tiles.iter().map(|(t, _)| i64::from(t.2)).min().unwrap_or(0);
    let w = tiles.iter().map(|(t, _)| i64::from(t.1)).max().unwrap_or(0) - x0 + 1;
    let texel = |gx: i64, gy: i64| -> Option<[f32; 4]> {
        // Global pixel (256 per tile at this zoom) → tile and pixel in it.
        let (tx, ty) = (gx.div_euclid(256) - x0, gy.div_euclid(256) - y0);
        if tx < 0 || ty < 0 || tx >= w {
            return None;
        }
        let (t, img) = tiles.get((ty * w + tx) as usize)?;
        debug_assert_eq!((i64::from(t.1) - x0, i64::from(t.2) - y0), (tx, ty));
        let img = img.as_ref()?;
        let (px, py) = (gx.rem_euclid(256), gy.rem_euclid(256));
        // Tiles of another size (e.g. 512 "retina" tiles) are scaled.
        let sx = (px as u64 * u64::from(img.width) / 256) as usize;
        let sy = (py as u64 * u64::from(img.height) / 256) as usize;
        let at = (sy * img.width as usize + sx) * 4;
        let p = &img.pixels[at..at + 4];
        Some([f32::from(p[0]), f32::from(p[1]), f32::from(p[2]), f32::from(p[3])])
    };
    for j in 0..n {
        let v = 1.0 - (j as f64 + 0.5) / n as f64; // north at row 0
        for i in 0..n {
            let u = (i as f64 + 0.5) / n as f64;
            // Bilinear in the projected grid.
            let (fu, fv) = (u * (GRID - 1) as f64, v * (GRID - 1) as f64);
            let (a, b) = ((fu.floor() as usize).min(GRID - 2), (fv.floor() as usize).min(GRID - 2));
            let (wu, wv) = (fu - a as f64, fv - b as f64);
            let g = |a: usize, b: usize| c.grid[b * GRID + a];
            let lerp = |p: [f64; 2], q: [f64; 2], w: f64| [p[0] + (q[0] - p[0]) * w, p[1] + (q[1] - p[1]) * w];
            let m = lerp(lerp(g(a, b), g(a + 1, b), wu), lerp(g(a, b + 1), g(a + 1, b + 1), wu), wv);
            let (x, y) = (m[0] * world_px - 0.5, m[1] * world_px - 0.5);
            let (x0, y0) = (x.floor() as i64, y.floor() as i64);
            let (fx, fy) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
            let mut sum = [0.0f32; 4];
            for (dx, dy, w) in
                [(0, 0, (1.0 - fx) * (1.0 - fy)), (1, 0, fx * (1.0 - fy)), (0, 1, (1.0 - fx) * fy), (1, 1, fx * fy)]
            {
                if let Some(p) = texel(x0 + dx, y0 + dy) {
                    for k in 0..4 {
                        sum[k] += p[k] * w;
                    }
                }
            }
            let at = (j * n + i) * 4;
            for k in 0..4 {
                rgba[at + k] = sum[k].round().clamp(0.0, 255.0) as u8;
            }
        }
    }
    ImageryTile { px: IMAGE_PX, rgba }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn templates_fill_in_xyz_tms_and_wmts_names() {
        let s = XyzSource::new("http://127.0.0.1:9/t/{z}/{x}/{y}.png", 19).unwrap();
        assert_eq!(s.url(3, 5, 1), "http://127.0.0.1:9/t/3/5/1.png");
        let s = XyzSource::new("t/{z}/{x}/{-y}.png", 19).unwrap();
        assert_eq!(s.url(3, 5, 1), "t/3/5/6.png");
        let s = XyzSource::new("w?TileMatrix={TileMatrix}&TileCol={TileCol}&TileRow={TileRow}", 19).unwrap();
        assert_eq!(s.url(3, 5, 1), "w?TileMatrix=3&TileCol=5&TileRow=1");
        let e = XyzSource::new("http://x/tiles.png", 19).unwrap_err();
        assert!(e.contains("placeholders"), "{e}");
        assert!(XyzSource::new("{z}/{x}/{y}", 30).is_err());
    }

    #[test]
    fn a_finer_tile_drapes_its_part_of_an_ancestors_image() {
        assert_eq!(ancestor((3, 5, 6), 1), (1, 1, 1));
        assert_eq!(uv_in((1, 1, 1), (3, 5, 6)), [0.25, 0.5, 0.25, 0.25]);
        assert_eq!(uv_in((2, 3, 1), (2, 3, 1)), [0.0, 0.0, 1.0, 1.0]);
    }

    #[test]
    fn mercator_matches_the_tile_scheme() {
        // Tile 0/0/0 is the world; zoom 1 splits it at lon 0 and lat 0.
        assert_eq!(mercator(-180.0, 0.0), [0.0, 0.5]);
        let m = mercator(13.4, 52.5);
        // Berlin at zoom 10: tile 550/335 (as every web map has it).
        assert_eq!(((m[0] * 1024.0) as u32, (m[1] * 1024.0) as u32), (550, 335));
    }
}
