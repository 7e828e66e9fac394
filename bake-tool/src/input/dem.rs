//! Elevation models (`--dem FILE.tif`): GeoTIFF height grids read with the
//! `tiff` crate (strips or tiles, uncompressed, deflate or LZW; float32/64,
//! int8–32 or uint8–32 samples), georeferenced from their GeoTIFF tags, and
//! sampled bilinearly between pixel centres.
//!
//! Georeferencing: `ModelPixelScale` + `ModelTiepoint`, or
//! `ModelTransformation` (no rotation). The CRS comes from the GeoKeys
//! (`ProjectedCSTypeGeoKey`, else `GeographicTypeGeoKey`) unless the caller
//! names it; a user-defined CRS (32767) needs `--dem-crs`. `GDAL_NODATA` and
//! non-finite samples are holes: a point whose four surrounding pixels are not
//! all valid has no height (the nearest valid of them is used when some are).

use std::io::{Read, Seek};
use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use tiff::decoder::{Decoder, DecodingResult, Limits};
use tiff::tags::Tag;

/// Most pixels of one DEM (a 32,768² grid: 4 GiB of f32 heights).
pub const MAX_DEM_PIXELS: u64 = 1 << 30;

/// Most decoded bytes per byte of file (see [`Dem::read`]).
const MAX_EXPANSION: u64 = 2048;

/// GeoKey ids (GeoTIFF 1.1, §7).
const GT_MODEL_TYPE: u16 = 1024;
const GT_RASTER_TYPE: u16 = 1025;
const GEOGRAPHIC_TYPE: u16 = 2048;
const PROJECTED_CS_TYPE: u16 = 3072;
/// A user-defined CRS code in a GeoKey.
const USER_DEFINED: u16 = 32767;

/// A georeferenced height grid.
#[derive(Debug, Clone)]
pub struct Dem {
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Map x of the centre of pixel (0, 0) and the step per column.
    pub x0: f64,
    /// Map x step per column.
    pub dx: f64,
    /// Map y of the centre of pixel (0, 0).
    pub y0: f64,
    /// Map y step per row (negative for north-up grids).
    pub dy: f64,
    /// EPSG code of the grid's CRS from its GeoKeys, if it names one.
    pub epsg: Option<u32>,
    /// Heights, row-major; NaN where there is no data.
    pub heights: Vec<f32>,
    /// The nodata value declared (`GDAL_NODATA`), if any.
    pub nodata: Option<f64>,
    /// Compression and layout, for reports (e.g. "float32, deflate, tiles 256×256").
    pub layout: String,
}

/// What [`Dem::summary`] reports.
#[derive(Debug, Clone, PartialEq)]
pub struct DemSummary {
    /// Map bounds of the pixel areas (min x, min y, max x, max y).
    pub extent: [f64; 4],
    /// Pixel size (x, y), map units.
    pub resolution: [f64; 2],
    /// Lowest and highest valid height.
    pub range: Option<(f32, f32)>,
    /// Pixels without data.
    pub holes: u64,
}

impl Dem {
    /// Reads a GeoTIFF DEM file.
    ///
    /// # Errors
    /// A file that cannot be opened, is no TIFF, has several samples per pixel,
    /// an unsupported sample format, no georeferencing, a rotated grid or more
    /// than [`MAX_DEM_PIXELS`] pixels; the message names the file.
    pub fn open(path: &Path) -> Result<Self> {
        let file = std::fs::File::open(path).with_context(|| format!("DEM {}: cannot open", path.display()))?;
        Self::read(std::io::BufReader::new(file)).with_context(|| format!("DEM {}", path.display()))
    }

    /// Reads a GeoTIFF DEM from `reader` (errors do not name a file).
    ///
    /// # Errors
    /// See [`Dem::open`].
    pub fn read<R: Read + Seek>(reader: R) -> Result<Self> {
        let (mut d, width, height, budget, file_len) = bounded_decoder(reader, "--dem")?;
        if u64::from(width) * u64::from(height) > budget {
            bail!(
                "the header declares {width}×{height} pixels, more than {MAX_EXPANSION} per byte of this {file_len}-byte file: \
                 it is corrupt or truncated"
            );
        }
        let samples = d.find_tag_unsigned::<u16>(Tag::SamplesPerPixel).ok().flatten().unwrap_or(1);
        if samples != 1 {
            bail!("{samples} samples per pixel: a DEM has one (heights); is this an image (use --ortho for imagery)?");
        }
        let Grid { x0, dx, y0, dy, epsg, nodata } = grid_of(&mut d)?;
        let compression = match d.find_tag_unsigned::<u16>(Tag::Compression).ok().flatten().unwrap_or(1) {
            1 => "uncompressed",
            5 => "LZW",
            8 | 32946 => "deflate",
            7 => "JPEG",
            32773 => "PackBits",
            _ => "compressed",
        };
        let chunks = match d.get_chunk_type() {
            tiff::decoder::ChunkType::Strip => "strips".to_string(),
            tiff::decoder::ChunkType::Tile => {
                let (w, h) = d.chunk_dimensions();
                format!("tiles {w}×{h}")
            }
        };
        let image = d.read_image().map_err(|e| anyhow!("cannot decode the heights: {e}"))?;
        let (kind, values): (&str, Vec<f32>) = match image {
            DecodingResult::F32(v) => ("float32", v),
            DecodingResult::F64(v) => ("float64", v.into_iter().map(|h| h as f32).collect()),
            DecodingResult::I16(v) => ("int16", v.into_iter().map(f32::from).collect()),
            DecodingResult::U16(v) => ("uint16", v.into_iter().map(f32::from).collect()),
            DecodingResult::I32(v) => ("int32", v.into_iter().map(|h| h as f32).collect()),
            DecodingResult::U32(v) => ("uint32", v.into_iter().map(|h| h as f32).collect()),
            DecodingResult::I8(v) => ("int8", v.into_iter().map(f32::from).collect()),
            DecodingResult::U8(v) => ("uint8", v.into_iter().map(f32::from).collect()),
            other => bail!("unsupported sample format {:?}: use float32, int16 or uint16 heights", kind_name(&other)),
        };
        if values.len() as u64 != u64::from(width) * u64::from(height) {
            bail!("decoded {} heights for a {width}×{height} grid", values.len());
        }
        let heights: Vec<f32> = values
            .into_iter()
            .map(|h| {
                if !h.is_finite() || nodata.is_some_and(|n| f64::from(h) == n || h == n as f32) {
                    f32::NAN
                } else {
                    h
                }
            })
            .collect();
        // No ground lies 100 km above or below the datum: such a value is a
        // no-data marker the file does not declare (3.4e38, -1e10, …).
        if let Some(i) = heights.iter().position(|h| h.abs() > MAX_HEIGHT_M) {
            let h = heights[i];
            bail!(
                "a height of {h} m at pixel (column {}, row {}): no ground lies so high or low. If it marks \
                 missing data, declare it in the file (GDAL_NODATA; `gdal_edit.py -a_nodata {h} DEM.tif`)",
                i % width as usize,
                i / width as usize
            );
        }
        Ok(Self {
            width,
            height,
            x0,
            dx,
            y0,
            dy,
            epsg,
            heights,
            nodata,
            layout: format!("{kind}, {compression}, {chunks}"),
        })
    }

    /// Whether the map point lies within the grid's pixel areas.
    #[must_use]
    pub fn contains(&self, x: f64, y: f64) -> bool {
        let (c, r) = self.pixel(x, y);
        (-0.5..=f64::from(self.width) - 0.5).contains(&c) && (-0.5..=f64::from(self.height) - 0.5).contains(&r)
    }

    /// Fractional (column, row) of a map point, pixel centres at whole numbers.
    #[must_use]
    pub fn pixel(&self, x: f64, y: f64) -> (f64, f64) {
        ((x - self.x0) / self.dx, (y - self.y0) / self.dy)
    }

    /// The height at pixel `(c, r)`, NaN for a hole or outside.
    #[must_use]
    pub fn at(&self, c: i64, r: i64) -> f32 {
        if c < 0 || r < 0 || c >= i64::from(self.width) || r >= i64::from(self.height) {
            return f32::NAN;
        }
        self.heights[r as usize * self.width as usize + c as usize]
    }

    /// Bilinear height at a map point (clamped to the outer pixel centres
    /// within the grid), or `None` outside the grid or where the four
    /// surrounding pixels are all holes (some holes: the valid ones' mean
    /// weighted as bilinear).
    #[must_use]
    pub fn sample(&self, x: f64, y: f64) -> Option<f32> {
        if !self.contains(x, y) {
            return None;
        }
        let (c, r) = self.pixel(x, y);
        let c = c.clamp(0.0, f64::from(self.width - 1));
        let r = r.clamp(0.0, f64::from(self.height - 1));
        let (c0, r0) = (c.floor() as i64, r.floor() as i64);
        let (fc, fr) = (c - c0 as f64, r - r0 as f64);
        let mut sum = 0.0;
        let mut weight = 0.0;
        for (dc, dr, w) in
            [(0, 0, (1.0 - fc) * (1.0 - fr)), (1, 0, fc * (1.0 - fr)), (0, 1, (1.0 - fc) * fr), (1, 1, fc * fr)]
        {
            let h = self.at(c0 + dc, r0 + dr);
            if h.is_finite() && w > 0.0 {
                sum += f64::from(h) * w;
                weight += w;
            }
        }
        if weight > 0.0 {
            return Some((sum / weight) as f32);
        }
        // Exactly on a pixel centre whose neighbours beyond have no weight.
        let h = self.at(c.round() as i64, r.round() as i64);
        h.is_finite().then_some(h)
    }

    /// The height of the valid pixel nearest to a map point within `reach`
    /// pixels of it (centre to point, inside the grid or beyond its edge), for
    /// a point that [`Self::sample`] has no height for: a tree at the edge of
    /// a DEM's data. `None` farther out.
    #[must_use]
    pub fn nearest_within(&self, x: f64, y: f64, reach: f64) -> Option<f32> {
        let (c, r) = self.pixel(x, y);
        // Farther than `reach` from the grid (or not a number): nothing near.
        let (w, h) = (f64::from(self.width), f64::from(self.height));
        let near = c > -1.0 - reach && r > -1.0 - reach && c < w + reach && r < h + reach;
        if !(near && (0.0..=64.0).contains(&reach)) {
            return None;
        }
        let n = reach.ceil() as i64;
        let (c0, r0) = (c.round() as i64, r.round() as i64);
        let mut best: Option<(f64, f32)> = None;
        for dr in -n..=n {
            for dc in -n..=n {
                let (pc, pr) = (c0 + dc, r0 + dr);
                let h = self.at(pc, pr);
                let d2 = (pc as f64 - c).powi(2) + (pr as f64 - r).powi(2);
                if h.is_finite() && d2 <= reach * reach && best.is_none_or(|(b, _)| d2 < b) {
                    best = Some((d2, h));
                }
            }
        }
        best.map(|(_, h)| h)
    }

    /// Map bounds of the pixel areas (min x, min y, max x, max y), without
    /// reading the heights.
    #[must_use]
    pub fn extent(&self) -> [f64; 4] {
        let xa = self.x0 - 0.5 * self.dx;
        let xb = self.x0 + (f64::from(self.width) - 0.5) * self.dx;
        let ya = self.y0 - 0.5 * self.dy;
        let yb = self.y0 + (f64::from(self.height) - 0.5) * self.dy;
        [xa.min(xb), ya.min(yb), xa.max(xb), ya.max(yb)]
    }

    /// Pixel size (x, y), map units.
    #[must_use]
    pub fn resolution(&self) -> [f64; 2] {
        [self.dx.abs(), self.dy.abs()]
    }

    /// Extent, resolution, height range and holes (reads every height).
    #[must_use]
    pub fn summary(&self) -> DemSummary {
        let mut range: Option<(f32, f32)> = None;
        let mut holes = 0;
        for &h in &self.heights {
            if h.is_finite() {
                range = Some(range.map_or((h, h), |(a, b)| (a.min(h), b.max(h))));
            } else {
                holes += 1;
            }
        }
        DemSummary { extent: self.extent(), resolution: self.resolution(), range, holes }
    }
}

fn kind_name(r: &DecodingResult) -> &'static str {
    match r {
        DecodingResult::U64(_) => "uint64",
        DecodingResult::I64(_) => "int64",
        DecodingResult::F16(_) => "float16",
        _ => "other",
    }
}

/// Where a GeoTIFF's pixels are: the map position of pixel (0, 0)'s centre
/// and the steps per column and row, its CRS and its nodata value.
pub(crate) struct Grid {
    pub x0: f64,
    pub dx: f64,
    pub y0: f64,
    pub dy: f64,
    pub epsg: Option<u32>,
    pub nodata: Option<f64>,
}

/// The largest height a DEM may hold, metres from its datum (either way).
pub const MAX_HEIGHT_M: f32 = 100_000.0;

/// The [`Grid`] of a GeoTIFF from its model tags, GeoKeys and `GDAL_NODATA`.
pub(crate) fn grid_of<R: Read + Seek>(d: &mut Decoder<R>) -> Result<Grid> {
    let (x0, dx, y0, dy, point) = georeference(d)?;
    let keys = geokeys(d);
    let epsg = crs_code(&keys)?;
    // Pixel-is-area (the default): the tiepoint is the corner of pixel (0, 0);
    // sample positions are pixel centres.
    let is_point = point || keys.iter().any(|k| k.0 == GT_RASTER_TYPE && k.1 == 2);
    let (x0, y0) = if is_point { (x0, y0) } else { (x0 + 0.5 * dx, y0 + 0.5 * dy) };
    let nodata = match d.find_tag(Tag::GdalNodata) {
        Ok(Some(v)) => v.into_string().ok().and_then(|s| s.trim_matches(char::from(0)).trim().parse::<f64>().ok()),
        _ => None,
    };
    Ok(Grid { x0, dx, y0, dy, epsg, nodata })
}

/// A TIFF decoder over `reader` whose decoded bytes are bounded, with the
/// image's width and height (checked: not empty, at most [`MAX_DEM_PIXELS`]),
/// the bound and the file's length. Decoded samples may be at most
/// [`MAX_EXPANSION`] times the file's bytes (deflate and LZW compress a flat
/// grid about 1000-fold): a hostile header cannot make the reader allocate
/// gigabytes for a small file. `flag` names the option in the advice.
pub(crate) fn bounded_decoder<R: Read + Seek>(mut reader: R, flag: &str) -> Result<(Decoder<R>, u32, u32, u64, u64)> {
    let file_len = reader.seek(std::io::SeekFrom::End(0)).map_err(|e| anyhow!("cannot read: {e}"))?;
    reader.seek(std::io::SeekFrom::Start(0)).map_err(|e| anyhow!("cannot read: {e}"))?;
    let budget = file_len.saturating_mul(MAX_EXPANSION).min(MAX_DEM_PIXELS * 8);
    let mut limits = Limits::default();
    limits.decoding_buffer_size = budget as usize;
    limits.intermediate_buffer_size = budget as usize;
    let mut d = Decoder::new(reader).map_err(|e| anyhow!("not a readable TIFF file: {e}"))?.with_limits(limits);
    let (width, height) = d.dimensions().map_err(|e| anyhow!("no image size: {e}"))?;
    if width == 0 || height == 0 {
        bail!("the image is empty ({width}×{height})");
    }
    if u64::from(width) * u64::from(height) > MAX_DEM_PIXELS {
        bail!("{width}×{height} pixels is more than the {MAX_DEM_PIXELS} one file may have: split it into tiles (pass several {flag})");
    }
    Ok((d, width, height, budget, file_len))
}

/// (x of pixel (0,0)'s tie corner, x step, y, y step, tiepoint-is-centre) from
/// the GeoTIFF model tags.
fn georeference<R: Read + Seek>(d: &mut Decoder<R>) -> Result<(f64, f64, f64, f64, bool)> {
    let scale = d.find_tag(Tag::ModelPixelScaleTag).ok().flatten().and_then(|v| v.into_f64_vec().ok());
    let tie = d.find_tag(Tag::ModelTiepointTag).ok().flatten().and_then(|v| v.into_f64_vec().ok());
    if let (Some(s), Some(t)) = (&scale, &tie) {
        if s.len() < 2 || t.len() < 6 {
            bail!("ModelPixelScale ({} values) or ModelTiepoint ({} values) is too short", s.len(), t.len());
        }
        let (sx, sy) = (s[0], s[1]);
        if !(sx.is_finite() && sy.is_finite() && sx > 0.0 && sy > 0.0) {
            bail!("ModelPixelScale {sx} × {sy} is not a positive pixel size");
        }
        // Tiepoint (i, j, k) → (x, y, z): pixel (i, j) is at (x, y); rows go south.
        let (i, j, x, y) = (t[0], t[1], t[3], t[4]);
        if ![i, j, x, y].iter().all(|v| v.is_finite()) {
            bail!("ModelTiepoint has non-finite values");
        }
        return Ok((x - i * sx, sx, y + j * sy, -sy, false));
    }
    let m = d.find_tag(Tag::ModelTransformationTag).ok().flatten().and_then(|v| v.into_f64_vec().ok());
    if let Some(m) = m {
        if m.len() < 8 || !m.iter().all(|v| v.is_finite()) {
            bail!("ModelTransformation is not a 4×4 matrix of finite numbers");
        }
        if m[1] != 0.0 || m[4] != 0.0 {
            bail!("the grid is rotated (ModelTransformation has shear terms): warp it north-up first (gdalwarp)");
        }
        if m[0] == 0.0 || m[5] == 0.0 {
            bail!("ModelTransformation has a zero pixel size");
        }
        return Ok((m[3], m[0], m[7], m[5], false));
    }
    bail!(
        "no georeferencing: the file has neither ModelPixelScale + ModelTiepoint nor ModelTransformation tags \
         (is it a plain TIFF? a world file .tfw is not read: convert with gdal_translate -of GTiff)"
    )
}

/// The GeoKey directory as (key, value) pairs of the inline SHORT keys.
fn geokeys<R: Read + Seek>(d: &mut Decoder<R>) -> Vec<(u16, u16)> {
    let Ok(Some(v)) = d.find_tag(Tag::GeoKeyDirectoryTag) else { return Vec::new() };
    let Ok(words) = v.into_u16_vec() else { return Vec::new() };
    if words.len() < 4 {
        return Vec::new();
    }
    let n = usize::from(words[3]);
    words[4..].chunks_exact(4).take(n).filter(|k| k[1] == 0).map(|k| (k[0], k[3])).collect()
}

/// The EPSG code the GeoKeys name, `None` when they name none.
fn crs_code(keys: &[(u16, u16)]) -> Result<Option<u32>> {
    let get = |id: u16| keys.iter().find(|k| k.0 == id).map(|k| k.1);
    let code = match get(GT_MODEL_TYPE) {
        Some(2) => get(GEOGRAPHIC_TYPE),
        _ => get(PROJECTED_CS_TYPE).or_else(|| get(GEOGRAPHIC_TYPE)),
    };
    match code {
        Some(USER_DEFINED) => Ok(None),
        Some(0) | None => Ok(None),
        Some(c) => Ok(Some(u32::from(c))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;
    use tiff::encoder::{colortype, Compression, DeflateLevel, TiffEncoder};

    /// A `w`×`h` float32 GeoTIFF in EPSG:32633 with 5 m pixels whose corner is at
    /// (500000, 5300000), heights `f(col, row)`; `nodata` declared if given.
    fn geotiff(w: u32, h: u32, f: impl Fn(u32, u32) -> f32, nodata: Option<&str>) -> Vec<u8> {
        let data: Vec<f32> = (0..h).flat_map(|r| (0..w).map(move |c| (c, r))).map(|(c, r)| f(c, r)).collect();
        geotiff_of::<colortype::Gray32Float>(w, h, &data, Compression::Uncompressed, nodata)
    }

    /// A GeoTIFF as [`geotiff`] of samples `data` of type `C`, compressed.
    fn geotiff_of<C: colortype::ColorType>(
        w: u32,
        h: u32,
        data: &[C::Inner],
        compression: Compression,
        nodata: Option<&str>,
    ) -> Vec<u8>
    where
        [C::Inner]: tiff::encoder::TiffValue,
    {
        let mut out = Cursor::new(Vec::new());
        let mut enc = TiffEncoder::new(&mut out).unwrap().with_compression(compression);
        let mut img = enc.new_image::<C>(w, h).unwrap();
        let e = img.encoder();
        e.write_tag(Tag::ModelPixelScaleTag, &[5.0f64, 5.0, 0.0][..]).unwrap();
        e.write_tag(Tag::ModelTiepointTag, &[0.0f64, 0.0, 0.0, 500_000.0, 5_300_000.0, 0.0][..]).unwrap();
        // Version 1.1.0, 3 keys: projected, pixel is area, EPSG:32633.
        let keys: [u16; 16] = [1, 1, 0, 3, 1024, 0, 1, 1, 1025, 0, 1, 1, 3072, 0, 1, 32633];
        e.write_tag(Tag::GeoKeyDirectoryTag, &keys[..]).unwrap();
        if let Some(n) = nodata {
            e.write_tag(Tag::GdalNodata, n).unwrap();
        }
        img.write_data(data).unwrap();
        out.into_inner()
    }

    /// Small DEMs of every sample type and compression the reader takes (also
    /// the fuzz seeds: `SYLVA_FUZZ_SEEDS=fuzz/seeds/read_dem cargo test -p
    /// sylva-bake --lib dem` writes them).
    fn samples() -> Vec<(&'static str, Vec<u8>)> {
        let ramp = |c: u32, r: u32| (100 + 3 * c + 7 * r) as u16;
        let u16s: Vec<u16> = (0..8).flat_map(|r| (0..8).map(move |c| ramp(c, r))).collect();
        let i16s: Vec<i16> = u16s.iter().map(|v| *v as i16 - 200).collect();
        vec![
            ("float32.tif", geotiff(8, 8, |c, r| f32::from(ramp(c, r)), Some("-9999"))),
            ("float32-tiled.tif", tiled_geotiff(8, 8, 16, |c, r| f32::from(ramp(c, r)))),
            ("uint16-lzw.tif", geotiff_of::<colortype::Gray16>(8, 8, &u16s, Compression::Lzw, None)),
            (
                "int16-deflate.tif",
                geotiff_of::<colortype::GrayI16>(8, 8, &i16s, Compression::Deflate(DeflateLevel::Balanced), None),
            ),
        ]
    }

    #[test]
    fn every_sample_type_and_compression_reads() {
        for (name, bytes) in samples() {
            if let Some(dir) = std::env::var_os("SYLVA_FUZZ_SEEDS") {
                std::fs::write(Path::new(&dir).join(name), &bytes).unwrap();
            }
            let dem = Dem::read(Cursor::new(bytes)).unwrap();
            let want = if name.starts_with("int16") { -100.0 } else { 100.0 };
            assert_eq!(dem.at(0, 0), want, "{name}");
            assert_eq!(dem.at(7, 7), want + 70.0, "{name}");
            assert!(dem.layout.contains(name.split(['-', '.']).next().unwrap()), "{name}: {}", dem.layout);
        }
    }

    /// A tiled float32 GeoTIFF written byte by byte (the `tiff` encoder writes
    /// strips only): `w`×`h` pixels in `tile`² tiles, uncompressed, edge tiles
    /// padded as the TIFF spec has them, georeferenced as [`geotiff`].
    fn tiled_geotiff(w: u32, h: u32, tile: u32, f: impl Fn(u32, u32) -> f32) -> Vec<u8> {
        let (across, down) = (w.div_ceil(tile), h.div_ceil(tile));
        let mut pixels = Vec::new();
        let mut offsets = Vec::new();
        let data_at = 8u32;
        for ty in 0..down {
            for tx in 0..across {
                offsets.push(data_at + pixels.len() as u32);
                for r in 0..tile {
                    for c in 0..tile {
                        let (x, y) = (tx * tile + c, ty * tile + r);
                        let v = if x < w && y < h { f(x, y) } else { 0.0 };
                        pixels.extend_from_slice(&v.to_le_bytes());
                    }
                }
            }
        }
        let count = offsets.len() as u32;
        let tile_bytes = tile * tile * 4;
        // Out-of-line values after the pixels: offsets, byte counts, scale, tiepoint, keys.
        let mut extra = Vec::new();
        let extra_at = data_at + pixels.len() as u32;
        let mut put = |bytes: Vec<u8>| {
            let at = extra_at + extra.len() as u32;
            extra.extend_from_slice(&bytes);
            at
        };
        let offs = put(offsets.iter().flat_map(|o| o.to_le_bytes()).collect());
        let counts = put((0..count).flat_map(|_| tile_bytes.to_le_bytes()).collect());
        let scale = put([5.0f64, 5.0, 0.0].iter().flat_map(|v| v.to_le_bytes()).collect());
        let tie = put([0.0f64, 0.0, 0.0, 500_000.0, 5_300_000.0, 0.0].iter().flat_map(|v| v.to_le_bytes()).collect());
        let keys =
            put([1u16, 1, 0, 2, 1024, 0, 1, 1, 3072, 0, 1, 32633].iter().flat_map(|v| v.to_le_bytes()).collect());
        // (tag, type, count, value or offset); types: 3 SHORT, 4 LONG, 12 DOUBLE.
        let entries: [(u16, u16, u32, u32); 14] = [
            (256, 4, 1, w),
            (257, 4, 1, h),
            (258, 3, 1, 32),
            (259, 3, 1, 1),
            (262, 3, 1, 1),
            (277, 3, 1, 1),
            (322, 4, 1, tile),
            (323, 4, 1, tile),
            // A single LONG is stored in the entry itself.
            (324, 4, count, if count == 1 { offsets[0] } else { offs }),
            (325, 4, count, if count == 1 { tile_bytes } else { counts }),
            (339, 3, 1, 3),
            (33550, 12, 3, scale),
            (33922, 12, 6, tie),
            (34735, 3, 12, keys),
        ];
        let ifd_at = extra_at + extra.len() as u32;
        let mut out = b"II*\0".to_vec();
        out.extend_from_slice(&ifd_at.to_le_bytes());
        out.extend_from_slice(&pixels);
        out.extend_from_slice(&extra);
        out.extend_from_slice(&(entries.len() as u16).to_le_bytes());
        for (tag, ty, n, v) in entries {
            out.extend_from_slice(&tag.to_le_bytes());
            out.extend_from_slice(&ty.to_le_bytes());
            out.extend_from_slice(&n.to_le_bytes());
            // A lone LONG is its own value; a lone SHORT sits in the first two bytes.
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&0u32.to_le_bytes());
        out
    }

    #[test]
    fn a_tiled_geotiff_reads_like_a_striped_one() {
        let f = |c: u32, r: u32| 200.0 + c as f32 * 1.5 - r as f32 * 0.25;
        let tiled = Dem::read(Cursor::new(tiled_geotiff(40, 24, 16, f))).unwrap();
        let striped = Dem::read(Cursor::new(geotiff(40, 24, f, None))).unwrap();
        assert!(tiled.layout.contains("tiles 16×16"), "{}", tiled.layout);
        assert!(striped.layout.contains("strips"), "{}", striped.layout);
        assert_eq!((tiled.width, tiled.height), (40, 24));
        assert_eq!(tiled.heights, striped.heights, "every pixel, edge tiles included");
        assert_eq!(tiled.extent(), striped.extent());
        assert_eq!(tiled.at(39, 23), f(39, 23));
    }

    #[test]
    fn every_fuzz_seed_reads_or_fails_without_panicking() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/seeds/read_dem");
        let mut n = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            let result = Dem::read(Cursor::new(std::fs::read(&path).unwrap()));
            // Found by the fuzzer: a 600-byte header declaring 2 GB of heights.
            if path.to_string_lossy().contains("regression-oom") {
                let e = format!("{:#}", result.unwrap_err());
                assert!(e.contains("corrupt or truncated"), "{}: {e}", path.display());
            }
            n += 1;
        }
        assert!(n >= 3, "{n} seeds in {}", dir.display());
    }

    #[test]
    fn reads_a_geotiff_and_samples_it_bilinearly() {
        // A plane: 100 + 2·col − 3·row metres.
        let bytes = geotiff(20, 10, |c, r| 100.0 + 2.0 * c as f32 - 3.0 * r as f32, None);
        let dem = Dem::read(Cursor::new(bytes)).unwrap();
        assert_eq!((dem.width, dem.height, dem.epsg), (20, 10, Some(32633)));
        assert!(dem.layout.starts_with("float32"), "{}", dem.layout);
        let s = dem.summary();
        assert_eq!(s.extent, [500_000.0, 5_299_950.0, 500_100.0, 5_300_000.0]);
        assert_eq!(s.resolution, [5.0, 5.0]);
        assert_eq!(s.range, Some((73.0, 138.0)));
        // Pixel (0, 0)'s centre is 2.5 m in from the corner.
        assert_eq!(dem.sample(500_002.5, 5_299_997.5), Some(100.0));
        // Between centres: bilinear is exact on a plane (col 3.3, row 4.6).
        let h = dem.sample(500_002.5 + 3.3 * 5.0, 5_299_997.5 - 4.6 * 5.0).unwrap();
        assert!((h - (100.0 + 6.6 - 13.8)).abs() < 1e-3, "{h}");
        // The outer half pixels clamp to the edge centres; beyond the grid: none.
        assert_eq!(dem.sample(500_000.0, 5_300_000.0), Some(100.0));
        assert_eq!(dem.sample(499_999.0, 5_299_990.0), None);
        assert_eq!(dem.sample(500_050.0, 5_299_940.0), None);
    }

    #[test]
    fn holes_are_skipped_and_a_hole_everywhere_is_none() {
        let bytes = geotiff(4, 4, |c, r| if c >= 2 && r >= 2 { -9999.0 } else { 10.0 }, Some("-9999"));
        let dem = Dem::read(Cursor::new(bytes)).unwrap();
        assert_eq!(dem.nodata, Some(-9999.0));
        assert_eq!(dem.summary().holes, 4);
        // Between a valid and a hole pixel: the valid one.
        assert_eq!(dem.sample(500_002.5 + 1.5 * 5.0, 5_299_997.5 - 1.5 * 5.0), Some(10.0));
        // Inside the hole.
        assert_eq!(dem.sample(500_002.5 + 2.5 * 5.0, 5_299_997.5 - 2.5 * 5.0), None);
    }

    #[test]
    fn a_point_at_the_edge_of_the_data_takes_the_nearest_valid_height_within_reach() {
        // Valid on the left half (10 m), holes on the right.
        let bytes = geotiff(8, 4, |c, _| if c < 4 { 10.0 + c as f32 } else { -9999.0 }, Some("-9999"));
        let dem = Dem::read(Cursor::new(bytes)).unwrap();
        let x = |col: f64| 500_002.5 + col * 5.0;
        let y = 5_299_997.5 - 1.0 * 5.0;
        assert_eq!(dem.sample(x(5.0), y), None, "in the holes");
        assert_eq!(dem.nearest_within(x(4.6), y, 2.0), Some(13.0), "column 3 is 1.6 pixels away");
        assert_eq!(dem.nearest_within(x(6.5), y, 2.0), None, "3.5 pixels from data");
        // Beyond the grid's edge too.
        assert_eq!(dem.nearest_within(x(-1.5), y, 2.0), Some(10.0));
        assert_eq!(dem.nearest_within(x(-3.0), y, 2.0), None);
        // Far off the grid (a hostile pixel size, a stray tree): no overflow, nothing near.
        for far in [1e300, -1e300, f64::NAN, f64::INFINITY, 9.3e18] {
            assert_eq!(dem.nearest_within(far, y, 2.0), None, "{far}");
            assert_eq!(dem.nearest_within(x(0.0), far, 2.0), None, "{far}");
        }
    }

    #[test]
    fn a_height_no_ground_has_is_refused_naming_the_pixel_and_the_fix() {
        let bytes = geotiff(4, 4, |c, r| if (c, r) == (3, 1) { 3.0e38 } else { 10.0 }, None);
        let e = format!("{:#}", Dem::read(Cursor::new(bytes)).unwrap_err());
        assert!(e.contains("column 3, row 1") && e.contains("GDAL_NODATA"), "{e}");
        // Declared, the same value is a hole.
        let bytes = geotiff(4, 4, |c, r| if (c, r) == (3, 1) { -1.0e10 } else { 10.0 }, Some("-1e10"));
        assert_eq!(Dem::read(Cursor::new(bytes)).unwrap().summary().holes, 1);
    }

    #[test]
    fn unusable_files_fail_with_the_reason() {
        let err = |bytes: Vec<u8>| format!("{:#}", Dem::read(Cursor::new(bytes)).unwrap_err());
        assert!(err(b"GIF89a........".to_vec()).contains("not a readable TIFF"));
        // A TIFF without georeferencing.
        let mut out = Cursor::new(Vec::new());
        TiffEncoder::new(&mut out).unwrap().write_image::<colortype::Gray32Float>(2, 2, &[1.0; 4]).unwrap();
        assert!(err(out.into_inner()).contains("no georeferencing"));
        // An RGB image.
        let mut out = Cursor::new(Vec::new());
        TiffEncoder::new(&mut out).unwrap().write_image::<colortype::RGB8>(2, 2, &[0; 12]).unwrap();
        assert!(err(out.into_inner()).contains("3 samples per pixel"));
        // Truncated.
        let mut bytes = geotiff(8, 8, |_, _| 1.0, None);
        bytes.truncate(bytes.len() - 40);
        let e = err(bytes);
        assert!(e.contains("cannot decode") || e.contains("not a readable"), "{e}");
    }

    #[test]
    fn the_shared_lidar_dem_matches_its_stems() {
        // ../shared/data/terrain: a 1 m lidar DTM and 106 stems with the DTM pixel
        // under each (nearest pixel, no interpolation) as an expected value.
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/terrain");
        let Ok(dem) = Dem::open(&dir.join("NEON_D17_SOAP_DP3_298000_4100000_DTM.tif")) else {
            eprintln!("skipping: {} not present", dir.display());
            return;
        };
        assert_eq!((dem.width, dem.height, dem.epsg), (1000, 1000, Some(32611)));
        let s = dem.summary();
        assert_eq!(s.extent, [298_000.0, 4_100_000.0, 299_000.0, 4_101_000.0]);
        let (lo, hi) = s.range.unwrap();
        assert!((lo - 1093.01).abs() < 0.01 && (hi - 1297.89).abs() < 0.01, "{lo}–{hi}");
        let csv = std::fs::read_to_string(dir.join("soap_trees.csv")).unwrap();
        let mut lines = csv.lines();
        let header: Vec<&str> = lines.next().unwrap().split(',').collect();
        let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
        let (cx, cy, cz) = (col("x"), col("y"), col("ground_z_m"));
        let mut worst = 0.0f64;
        let mut n = 0;
        for line in lines {
            let f: Vec<&str> = line.split(',').collect();
            let (x, y, z): (f64, f64, f64) = (f[cx].parse().unwrap(), f[cy].parse().unwrap(), f[cz].parse().unwrap());
            // The nearest pixel reproduces the expected value exactly.
            let (c, r) = dem.pixel(x, y);
            let nearest = dem.at(c.round() as i64, r.round() as i64);
            assert!((f64::from(nearest) - z).abs() < 0.006, "stem at {x}, {y}: nearest pixel {nearest} vs {z}");
            // Bilinear differs by the slope over at most half a pixel diagonal.
            worst = worst.max((f64::from(dem.sample(x, y).unwrap()) - z).abs());
            n += 1;
        }
        assert_eq!(n, 106);
        assert!(worst < 1.0, "bilinear is {worst} m from the pixel under a stem");
    }
}
