//! Canopy rasters (`canopy/<level>/<x>_<y>.cnpy`): what the forest
//! looks like from far away, for views where its trees are a pixel or two.
//!
//! A quadtree like the terrain's ([`CanopyEntry`] in the manifest): the root
//! raster covers the scene's square of tiles, each level halves the side, the
//! finest has cells of about [`FINEST_CELL_M`] (or a tile's side / 64 where tiles
//! are larger); only squares with trees exist, and each raster says which of
//! its four children do. A raster is a square of `cells`×`cells` cells over its
//! square. Each cell holds the share of its
//! ground that crowns cover seen from above (overlap counted as random:
//! `1 − exp(−Σ crown area / cell area)`), how much more the trees cover seen
//! from the side (their side silhouettes' area over their crowns' area from
//! above: a view at elevation θ sees `1 − exp(−Λ (1 + side · cot θ))`, Λ the
//! exponent above), the crowns' mean albedo (their species' top-view colour,
//! weighted by crown area), their mean height and the mean ground height under
//! them. Built by the bake from the tiles and the
//! species packs' billboards (`sylva-bake`'s `canopy.rs`). A viewer draws it
//! over the ground where trees are too small to draw, cross-faded with them.
//!
//! Layout (little endian): a 52-byte header (version 3; version 2: 48 bytes,
//! without `flags`; version 1: 44 bytes, without `tallest_ratio` either, read
//! as 1), then the cells row by row (row 0 at the square's lowest y), 8 bytes
//! each, then — with flag bit 0 — the cells' seasons, 8 bytes each, in the same order:
//!
//! ```text
//! header  magic "SYCN" | version u16 | header_bytes u16 (52) | cells u32
//!         | x0 f32 | y0 f32 | size_m f32 | z_min f32 | z_max f32 | height_max f32
//!         | height_min f32 (the shortest tree in the square)
//!         | children u32 (bit i: child (2x + (i & 1), 2y + (i >> 1)) exists; bits 4–31 0)
//!         | tallest_ratio f32 (1–64) | flags u32 (bit 0: seasons follow; bits 1–31 0)
//! cell    r u8 | g u8 | b u8 (sRGB albedo) | cover u8 (0–255) | height u8 (× height_max / 255)
//!         | side u8 (/ 32) | ground u16 (z_min + q / 65535 × (z_max − z_min))
//! season  autumn r u8 | g u8 | b u8 (sRGB albedo in autumn) | bare cover u8 (leaf-off)
//!         | bare r u8 | g u8 | b u8 (sRGB albedo in leaf-off) | bare side u8 (/ 32)
//! ```
//!
//! The seasons (a scene with deciduous species, their packs' `season`): the
//! cells as the crowns look in autumn (their leaves in their autumn colour)
//! and in leaf-off (the bare wood's cover, albedo and side from its far-tier
//! captures; evergreens as in leaf-on). Without them a cell is the same in
//! every season.
//!
//! `x0`, `y0`, `size_m`: the square in metres relative to the scene origin;
//! `z_*`: the ground heights' range; `height_max`: the tallest tree's height;
//! `tallest_ratio`: the crowns' batches' tallest trees over the crowns' own
//! heights, both weighted by crown area (Σ area · batch tallest / Σ area ·
//! height, ≥ 1): the cull's cross-fade drops a share of each batch by its
//! tallest tree, so a viewer sizes a cell's trees as `height × tallest_ratio`
//! to know what share of them the canopy stands in for.

use serde::{Deserialize, Serialize};

use super::entries::check_url;
use super::error::{finite, DecodeError, Problem, Reader};

/// File magic.
pub const CANOPY_MAGIC: [u8; 4] = *b"SYCN";
/// Version written by this build (it reads 1, 2 and 3).
pub const CANOPY_VERSION: u16 = 3;
/// Header bytes (version 3).
pub const CANOPY_HEADER_BYTES: usize = 52;
/// Header bytes of version 2 (no `flags`).
pub const CANOPY_HEADER_BYTES_V2: usize = 48;
/// Header flag: the cells' seasons follow the cells.
pub const CANOPY_FLAG_SEASONS: u32 = 1;
/// Header bytes of version 1 (no `tallest_ratio`).
pub const CANOPY_HEADER_BYTES_V1: usize = 44;
/// Largest `tallest_ratio` a raster may carry.
pub const MAX_TALLEST_RATIO: f32 = 64.0;
/// Bytes per cell.
pub const CANOPY_CELL_BYTES: usize = 8;
/// Cells per side the bake writes.
pub const CANOPY_CELLS: u32 = 64;
/// Most cells per side a file may have.
pub const MAX_CANOPY_CELLS: u32 = 1024;
/// The finest level's cells are about this wide (metres); where tiles are wider
/// than 64 of them the levels go on below a tile.
pub const FINEST_CELL_M: f64 = 15.0;
/// Most levels of the quadtree.
pub const MAX_CANOPY_LEVELS: u8 = 24;

/// The manifest's `canopy` (scene version 8): the quadtree of rasters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CanopyEntry {
    /// Folder of the rasters, relative to the manifest.
    pub path: String,
    /// The root square's lowest corner, metres relative to the scene origin.
    pub origin_m: [f64; 2],
    /// The root square's side, metres.
    pub root_size_m: f64,
    /// Levels (1: the root alone).
    pub levels: u8,
    /// Cells per raster side.
    pub cells: u32,
    /// Rasters in all.
    pub rasters: u64,
    /// Their bytes in all.
    pub bytes: u64,
}

/// A raster's key: (level, x, y).
pub type CanopyKey = (u8, u32, u32);

impl CanopyEntry {
    /// URL of raster `(level, x, y)` relative to the manifest.
    #[must_use]
    pub fn raster_url(&self, level: u8, x: u32, y: u32) -> String {
        format!("{}/{level}/{x}_{y}.cnpy", self.path)
    }

    /// Side of a raster of `level`, metres.
    #[must_use]
    pub fn size_m(&self, level: u8) -> f64 {
        self.root_size_m / f64::from(1u32 << level.min(31))
    }

    /// Lowest corner of raster `(level, x, y)`, metres relative to the scene origin.
    #[must_use]
    pub fn origin_of(&self, level: u8, x: u32, y: u32) -> [f64; 2] {
        let s = self.size_m(level);
        [self.origin_m[0] + f64::from(x) * s, self.origin_m[1] + f64::from(y) * s]
    }

    /// Checks the entry (called by the manifest's validation).
    pub(crate) fn validate(&self) -> Result<(), Problem> {
        check_url("canopy.path", &self.path)?;
        finite("canopy.origin_m[0]", self.origin_m[0])?;
        finite("canopy.origin_m[1]", self.origin_m[1])?;
        finite("canopy.root_size_m", self.root_size_m)?;
        if self.root_size_m <= 0.0 {
            return Err(Problem::Invalid(format!("canopy.root_size_m is {}: must be positive", self.root_size_m)));
        }
        if self.levels == 0 || self.levels > MAX_CANOPY_LEVELS {
            return Err(Problem::OutOfRange {
                what: "canopy.levels".into(),
                value: self.levels.into(),
                allowed: format!("1–{MAX_CANOPY_LEVELS}"),
            });
        }
        // Viewers draw rasters of CANOPY_CELLS per side; other sizes are for later versions.
        if self.cells != CANOPY_CELLS {
            return Err(Problem::OutOfRange {
                what: "canopy.cells".into(),
                value: self.cells.into(),
                allowed: format!("{CANOPY_CELLS}"),
            });
        }
        Ok(())
    }
}

/// One cell of a [`Canopy`], decoded.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CanopyCell {
    /// The crowns' mean albedo, sRGB.
    pub color: [u8; 3],
    /// Share of the cell's ground covered by crowns seen from above, 0–1.
    pub cover: f32,
    /// The crowns' mean tree height in metres (0 where none).
    pub height_m: f32,
    /// The trees' side silhouettes' area over their crowns' area from above (0–7.97).
    pub side: f32,
    /// Mean ground height under them, metres relative to the scene origin.
    pub ground_m: f32,
}

/// A canopy raster.
#[derive(Debug, Clone, PartialEq)]
pub struct Canopy {
    /// Cells per side.
    pub cells: u32,
    /// The square's lowest corner, metres relative to the scene origin.
    pub origin_m: [f32; 2],
    /// The square's side in metres.
    pub size_m: f32,
    /// Ground heights' range (metres relative to the scene origin).
    pub z_range_m: [f32; 2],
    /// The tallest tree's height in metres: the height quantisation's top.
    pub height_max_m: f32,
    /// The shortest tree's height in metres (the whole square's, not a cell mean).
    pub height_min_m: f32,
    /// Which children exist: bit `i` for child `(2x + (i & 1), 2y + (i >> 1))`.
    pub children: u8,
    /// The crowns' batches' tallest trees over their own heights (Σ area ·
    /// batch tallest / Σ area · height; 1 in version 1 rasters): a cell's
    /// trees are sized `height_m × tallest_ratio` for the cross-fade, as the
    /// cull sizes each batch by its tallest tree.
    pub tallest_ratio: f32,
    /// Raw cells, `cells²` × 8 bytes, row by row.
    pub data: Vec<u8>,
    /// The cells' seasons (autumn, leaf-off), `cells²` × 8 bytes in the same
    /// order; `None`: every season alike (no deciduous trees, or an older raster).
    pub seasons: Option<Vec<u8>>,
}

impl Canopy {
    /// The cell at column `x`, row `y` (both `< cells`).
    #[must_use]
    pub fn cell(&self, x: u32, y: u32) -> CanopyCell {
        let at = (y as usize * self.cells as usize + x as usize) * CANOPY_CELL_BYTES;
        let c = &self.data[at..at + CANOPY_CELL_BYTES];
        let q = u16::from_le_bytes([c[6], c[7]]);
        CanopyCell {
            color: [c[0], c[1], c[2]],
            cover: f32::from(c[3]) / 255.0,
            height_m: f32::from(c[4]) / 255.0 * self.height_max_m,
            side: f32::from(c[5]) / 32.0,
            ground_m: self.z_range_m[0] + f32::from(q) / 65535.0 * (self.z_range_m[1] - self.z_range_m[0]),
        }
    }

    /// The raw cells as they look in `season` (`cells²` × 8 bytes, the
    /// layout of [`Self::data`]): autumn's albedo, leaf-off's cover, albedo
    /// and side where the raster has its seasons; else the cells themselves.
    #[must_use]
    pub fn cells_in(&self, season: crate::format::pack::Season) -> std::borrow::Cow<'_, [u8]> {
        use crate::format::pack::Season;
        let Some(seasons) = &self.seasons else { return std::borrow::Cow::Borrowed(&self.data) };
        if season == Season::LeafOn {
            return std::borrow::Cow::Borrowed(&self.data);
        }
        let mut out = self.data.clone();
        for (c, s) in out.chunks_exact_mut(CANOPY_CELL_BYTES).zip(seasons.chunks_exact(CANOPY_CELL_BYTES)) {
            if season == Season::Autumn {
                c[..3].copy_from_slice(&s[..3]);
            } else {
                c[3] = s[3];
                c[..3].copy_from_slice(&s[4..7]);
                c[5] = s[7];
            }
        }
        std::borrow::Cow::Owned(out)
    }

    /// Side of one cell in metres.
    #[must_use]
    pub fn cell_m(&self) -> f32 {
        self.size_m / self.cells as f32
    }

    /// Mean cover over all cells (0–1).
    #[must_use]
    pub fn mean_cover(&self) -> f32 {
        let n = (self.cells * self.cells).max(1);
        let sum: u64 = self.data.chunks_exact(CANOPY_CELL_BYTES).map(|c| u64::from(c[3])).sum();
        sum as f32 / 255.0 / n as f32
    }

    /// Packs one cell (values clamped to what the file holds).
    #[must_use]
    pub fn pack_cell(&self, cell: &CanopyCell) -> [u8; CANOPY_CELL_BYTES] {
        let unit = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
        let h = if self.height_max_m > 0.0 { unit(cell.height_m / self.height_max_m) } else { 0 };
        let span = self.z_range_m[1] - self.z_range_m[0];
        let g = if span > 0.0 {
            ((cell.ground_m - self.z_range_m[0]) / span * 65535.0).round().clamp(0.0, 65535.0) as u16
        } else {
            0
        };
        let g = g.to_le_bytes();
        let side = (cell.side * 32.0).round().clamp(0.0, 255.0) as u8;
        [cell.color[0], cell.color[1], cell.color[2], unit(cell.cover), h, side, g[0], g[1]]
    }

    /// The file bytes.
    #[must_use]
    pub fn encode(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(CANOPY_HEADER_BYTES + self.data.len());
        out.extend_from_slice(&CANOPY_MAGIC);
        out.extend_from_slice(&CANOPY_VERSION.to_le_bytes());
        out.extend_from_slice(&(CANOPY_HEADER_BYTES as u16).to_le_bytes());
        out.extend_from_slice(&self.cells.to_le_bytes());
        for v in [
            self.origin_m[0],
            self.origin_m[1],
            self.size_m,
            self.z_range_m[0],
            self.z_range_m[1],
            self.height_max_m,
            self.height_min_m,
        ] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&u32::from(self.children).to_le_bytes());
        out.extend_from_slice(&self.tallest_ratio.to_le_bytes());
        let flags = if self.seasons.is_some() { CANOPY_FLAG_SEASONS } else { 0 };
        out.extend_from_slice(&flags.to_le_bytes());
        out.extend_from_slice(&self.data);
        if let Some(seasons) = &self.seasons {
            out.extend_from_slice(seasons);
        }
        out
    }

    /// Decodes and validates a raster. `file` names it in errors.
    ///
    /// # Errors
    /// A [`DecodeError`] for a wrong magic, version or header size, a cell count
    /// of 0 or above [`MAX_CANOPY_CELLS`], a length that is not the header plus
    /// `cells²` cells, non-finite or inverted ranges (heights: 0 ≤ min ≤ max), a
    /// non-positive size, child bits above bit 3, or a `tallest_ratio` outside
    /// 1–[`MAX_TALLEST_RATIO`].
    pub fn decode(file: &str, bytes: &[u8]) -> Result<Self, DecodeError> {
        decode_canopy(bytes).map_err(|p| DecodeError::new(file, p))
    }
}

fn decode_canopy(bytes: &[u8]) -> Result<Canopy, Problem> {
    let r = Reader::new(bytes);
    r.magic("Sylva canopy raster", &CANOPY_MAGIC)?;
    let version = r.u16("header.version", 4)?;
    let expected = match version {
        1 => CANOPY_HEADER_BYTES_V1,
        2 => CANOPY_HEADER_BYTES_V2,
        CANOPY_VERSION => CANOPY_HEADER_BYTES,
        _ => return Err(Problem::UnsupportedVersion { found: version.into(), supported: CANOPY_VERSION.into() }),
    };
    let header = r.u16("header.header_bytes", 6)?;
    if usize::from(header) != expected {
        return Err(Problem::Invalid(format!(
            "header.header_bytes is {header}, expected {expected} for version {version}"
        )));
    }
    let cells = r.u32("header.cells", 8)?;
    if cells == 0 || cells > MAX_CANOPY_CELLS {
        return Err(Problem::OutOfRange {
            what: "header.cells".into(),
            value: cells.into(),
            allowed: format!("1–{MAX_CANOPY_CELLS} per side"),
        });
    }
    let f = |what: &str, at: u64| -> Result<f32, Problem> {
        let v = f32::from_bits(r.u32(what, at)?);
        finite(what, f64::from(v))?;
        Ok(v)
    };
    let (x0, y0, size) = (f("header.x0", 12)?, f("header.y0", 16)?, f("header.size_m", 20)?);
    let (z_min, z_max, h_max) = (f("header.z_min", 24)?, f("header.z_max", 28)?, f("header.height_max", 32)?);
    let h_min = f("header.height_min", 36)?;
    if size <= 0.0 {
        return Err(Problem::Invalid(format!("header.size_m is {size}: the square needs a positive side")));
    }
    if z_max < z_min || !(z_max - z_min).is_finite() {
        return Err(Problem::Invalid(format!("header.z_max {z_max} is below z_min {z_min}, or too far above")));
    }
    if !(0.0..=h_max).contains(&h_min) {
        return Err(Problem::Invalid(format!("header heights {h_min}–{h_max} m: not 0 ≤ height_min ≤ height_max")));
    }
    let children = r.u32("header.children", 40)?;
    if children > 0xf {
        return Err(Problem::Invalid(format!("header.children is {children:#x}: only bits 0–3 (four children) exist")));
    }
    let tallest_ratio = if version == 1 { 1.0 } else { f("header.tallest_ratio", 44)? };
    if !(1.0..=MAX_TALLEST_RATIO).contains(&tallest_ratio) {
        return Err(Problem::Invalid(format!(
            "header.tallest_ratio is {tallest_ratio}: must be 1–{MAX_TALLEST_RATIO} \
             (a batch's tallest tree is at least as tall as each of its trees)"
        )));
    }
    let flags = if version >= 3 { r.u32("header.flags", 48)? } else { 0 };
    if flags & !CANOPY_FLAG_SEASONS != 0 {
        return Err(Problem::Invalid(format!("header.flags is {flags:#x}: only bit 0 (seasons) exists")));
    }
    let n = u64::from(cells) * u64::from(cells) * CANOPY_CELL_BYTES as u64;
    let data = r.slice("cells", expected as u64, n)?;
    let seasons = if flags & CANOPY_FLAG_SEASONS != 0 {
        Some(r.slice("seasons", expected as u64 + n, n)?.to_vec())
    } else {
        None
    };
    let end = expected as u64 + n * if seasons.is_some() { 2 } else { 1 };
    if bytes.len() as u64 != end {
        return Err(Problem::Invalid(format!(
            "{} bytes after the {cells}×{cells} cells{} end at byte {end}",
            bytes.len() as u64 - end.min(bytes.len() as u64),
            if seasons.is_some() { " and their seasons" } else { "" }
        )));
    }
    Ok(Canopy {
        cells,
        origin_m: [x0, y0],
        size_m: size,
        z_range_m: [z_min, z_max],
        height_max_m: h_max,
        height_min_m: h_min,
        children: children as u8,
        tallest_ratio,
        data: data.to_vec(),
        seasons,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Canopy {
        let mut c = Canopy {
            cells: 4,
            origin_m: [-100.0, 50.0],
            size_m: 400.0,
            z_range_m: [10.0, 90.0],
            height_max_m: 30.0,
            height_min_m: 2.0,
            children: 0b1010,
            tallest_ratio: 1.25,
            data: vec![0; 16 * CANOPY_CELL_BYTES],
            seasons: None,
        };
        for i in 0..16u32 {
            let cell = CanopyCell {
                color: [i as u8 * 10, 100, 50],
                cover: i as f32 / 15.0,
                height_m: i as f32 * 2.0,
                side: i as f32 * 0.25,
                ground_m: 10.0 + i as f32 * 5.0,
            };
            let packed = c.pack_cell(&cell);
            c.data[i as usize * 8..i as usize * 8 + 8].copy_from_slice(&packed);
        }
        c
    }

    #[test]
    fn round_trip_and_quantisation() {
        let c = sample();
        let bytes = c.encode();
        assert_eq!(bytes.len(), CANOPY_HEADER_BYTES + 16 * 8);
        let d = Canopy::decode("c.cnpy", &bytes).unwrap();
        assert_eq!(d, c);
        let cell = d.cell(3, 2); // i = 11
        assert_eq!(cell.color, [110, 100, 50]);
        assert!((cell.cover - 11.0 / 15.0).abs() < 0.5 / 255.0);
        assert!((cell.height_m - 22.0).abs() <= 30.0 / 255.0);
        assert_eq!(cell.side, 2.75);
        assert!((cell.ground_m - 65.0).abs() <= 80.0 / 65535.0);
        assert!((d.cell_m() - 100.0).abs() < 1e-6);
        assert!((d.mean_cover() - 0.5).abs() < 0.01);
        let e = CanopyEntry {
            path: "canopy".into(),
            origin_m: [-512.0, 0.0],
            root_size_m: 2048.0,
            levels: 3,
            cells: 64,
            rasters: 5,
            bytes: 5 * 32_816,
        };
        assert_eq!(e.raster_url(2, 3, 1), "canopy/2/3_1.cnpy");
        assert_eq!(e.origin_of(2, 3, 1), [-512.0 + 1536.0, 512.0]);
        assert!(e.validate().is_ok());
        for bad in [
            CanopyEntry { path: "../x".into(), ..e.clone() },
            CanopyEntry { root_size_m: 0.0, ..e.clone() },
            CanopyEntry { levels: 0, ..e.clone() },
            CanopyEntry { levels: 99, ..e.clone() },
            CanopyEntry { cells: 0, ..e.clone() },
            CanopyEntry { cells: 1024, ..e.clone() },
            CanopyEntry { origin_m: [f64::NAN, 0.0], ..e.clone() },
        ] {
            assert!(bad.validate().is_err(), "{bad:?}");
        }
    }

    #[test]
    fn versions_1_and_2_read_without_seasons() {
        let c = sample();
        let v3 = c.encode();
        // Version 2: the 48-byte header without `flags`.
        let mut v2 = v3[..CANOPY_HEADER_BYTES_V2].to_vec();
        v2[4..6].copy_from_slice(&2u16.to_le_bytes());
        v2[6..8].copy_from_slice(&(CANOPY_HEADER_BYTES_V2 as u16).to_le_bytes());
        v2.extend_from_slice(&v3[CANOPY_HEADER_BYTES..]);
        assert_eq!(Canopy::decode("v2.cnpy", &v2).unwrap(), c);
        // Version 1: the 44-byte header without `tallest_ratio` either.
        let mut v1 = v3[..CANOPY_HEADER_BYTES_V1].to_vec();
        v1[4..6].copy_from_slice(&1u16.to_le_bytes());
        v1[6..8].copy_from_slice(&(CANOPY_HEADER_BYTES_V1 as u16).to_le_bytes());
        v1.extend_from_slice(&v3[CANOPY_HEADER_BYTES..]);
        let d = Canopy::decode("old.cnpy", &v1).unwrap();
        assert_eq!(d, Canopy { tallest_ratio: 1.0, ..c });
        v1[6..8].copy_from_slice(&48u16.to_le_bytes());
        assert!(Canopy::decode("old.cnpy", &v1).unwrap_err().to_string().contains("expected 44 for version 1"));
    }

    #[test]
    fn seasons_round_trip_and_replace_the_cells_they_change() {
        use crate::format::pack::Season;
        let mut c = sample();
        let mut seasons = vec![0u8; 16 * CANOPY_CELL_BYTES];
        for (i, s) in seasons.chunks_exact_mut(CANOPY_CELL_BYTES).enumerate() {
            s.copy_from_slice(&[200, 90, i as u8, 30, 90, 80, 70, 8]);
        }
        c.seasons = Some(seasons);
        let bytes = c.encode();
        assert_eq!(bytes.len(), CANOPY_HEADER_BYTES + 2 * 16 * 8);
        let d = Canopy::decode("s.cnpy", &bytes).unwrap();
        assert_eq!(d, c);
        assert_eq!(&*d.cells_in(Season::LeafOn), &d.data[..]);
        let autumn = d.cells_in(Season::Autumn);
        let off = d.cells_in(Season::LeafOff);
        let i = 11 * CANOPY_CELL_BYTES;
        assert_eq!(
            autumn[i..i + 8],
            [200, 90, 11, d.data[i + 3], d.data[i + 4], d.data[i + 5], d.data[i + 6], d.data[i + 7]]
        );
        assert_eq!(off[i..i + 8], [90, 80, 70, 30, d.data[i + 4], 8, d.data[i + 6], d.data[i + 7]]);
        // Without seasons every season is the leaf-on cells.
        assert_eq!(&*sample().cells_in(Season::LeafOff), &sample().data[..]);
        // A seasons flag without the block, or unknown flags: refused.
        let mut short = bytes.clone();
        short.truncate(bytes.len() - 1);
        assert!(Canopy::decode("s", &short).is_err());
        let mut flags = bytes.clone();
        flags[48] = 3;
        assert!(Canopy::decode("s", &flags).unwrap_err().to_string().contains("header.flags"));
    }

    #[test]
    fn hostile_rasters_are_refused_without_panics() {
        let good = sample().encode();
        for n in 0..good.len() {
            assert!(Canopy::decode("c", &good[..n]).is_err(), "truncated at {n}");
        }
        let mut longer = good.clone();
        longer.push(0);
        assert!(Canopy::decode("c", &longer).unwrap_err().to_string().contains("after the 4×4 cells"));
        let set = |at: usize, v: &[u8]| {
            let mut b = good.clone();
            b[at..at + v.len()].copy_from_slice(v);
            Canopy::decode("c.cnpy", &b).unwrap_err().to_string()
        };
        assert!(set(0, b"XXXX").contains("not a Sylva canopy raster"));
        assert!(set(4, &9u16.to_le_bytes()).contains("version 9"));
        assert!(set(8, &0u32.to_le_bytes()).contains("header.cells"));
        assert!(set(8, &5000u32.to_le_bytes()).contains("header.cells"));
        assert!(set(8, &u32::MAX.to_le_bytes()).contains("header.cells"));
        assert!(set(20, &f32::NAN.to_le_bytes()).contains("size_m"));
        assert!(set(20, &(-1f32).to_le_bytes()).contains("positive"));
        assert!(set(28, &0f32.to_le_bytes()).contains("below z_min"));
        assert!(set(32, &f32::INFINITY.to_le_bytes()).contains("height_max"));
        assert!(set(36, &40f32.to_le_bytes()).contains("height_min"));
        assert!(set(36, &(-1f32).to_le_bytes()).contains("height_min"));
        let mut wide = good.clone();
        wide[24..28].copy_from_slice(&(-3e38f32).to_le_bytes());
        wide[28..32].copy_from_slice(&3e38f32.to_le_bytes());
        assert!(Canopy::decode("c", &wide).unwrap_err().to_string().contains("too far"));
        assert!(set(40, &[0x10]).contains("children"));
        assert!(set(44, &0.5f32.to_le_bytes()).contains("tallest_ratio"));
        assert!(set(44, &f32::NAN.to_le_bytes()).contains("tallest_ratio"));
        assert!(set(44, &100f32.to_le_bytes()).contains("tallest_ratio"));
        assert!(set(6, &48u16.to_le_bytes()).contains("expected 52 for version 3"));
        // Every single-byte change decodes or fails cleanly.
        for at in 0..good.len() {
            for v in [0u8, 1, 0x7f, 0xff] {
                let mut b = good.clone();
                b[at] = v;
                let _ = Canopy::decode("c", &b);
            }
        }
    }
}
