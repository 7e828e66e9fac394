//! Orthophotos (`--ortho FILE.tif`): georeferenced RGB(A) GeoTIFFs read with
//! the `tiff` crate (the same layouts, georeferencing and CRS rules as the
//! DEMs, [`crate::input::dem`]), sampled bilinearly between pixel centres. Samples
//! are 8- or 16-bit grey, RGB or RGBA (16-bit is scaled to 8); a pixel whose
//! alpha is 0, or whose value equals `GDAL_NODATA` in every band, has no data.

use std::io::{Read, Seek};
use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use tiff::decoder::DecodingResult;
use tiff::tags::Tag;

use crate::input::dem::{bounded_decoder, grid_of, Grid};

/// RGBA pixels of `n`-sample values (grey, RGB or RGBA): alpha 0 where every
/// colour sample equals `nodata`.
fn to_rgba<T: Copy + Into<f64>>(values: &[T], n: usize, nodata: Option<f64>, to8: impl Fn(T) -> u8) -> Vec<[u8; 4]> {
    values
        .chunks_exact(n)
        .map(|p| {
            let no_data = nodata.is_some_and(|nd| p.iter().take(n.min(3)).all(|&v| v.into() == nd));
            let [r, g, b] = if n == 1 { [p[0]; 3] } else { [p[0], p[1], p[2]] };
            let a = if no_data {
                0
            } else if n == 4 {
                to8(p[3])
            } else {
                255
            };
            [to8(r), to8(g), to8(b), a]
        })
        .collect()
}

/// A georeferenced colour image.
#[derive(Debug, Clone)]
pub struct Ortho {
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Map x of the centre of pixel (0, 0).
    pub x0: f64,
    /// Map x step per column.
    pub dx: f64,
    /// Map y of the centre of pixel (0, 0).
    pub y0: f64,
    /// Map y step per row (negative for north-up images).
    pub dy: f64,
    /// EPSG code of the image's CRS from its GeoKeys, if it names one.
    pub epsg: Option<u32>,
    /// RGBA, row-major; alpha 0 where there is no data.
    pub rgba: Vec<[u8; 4]>,
    /// Sample layout, for reports (e.g. "RGB 8-bit, deflate").
    pub layout: String,
}

impl Ortho {
    /// Reads a GeoTIFF orthophoto file.
    ///
    /// # Errors
    /// A file that cannot be opened or is no TIFF, a sample layout other than
    /// grey, RGB or RGBA of 8 or 16 bits, no georeferencing, a rotated grid, or
    /// more than [`crate::input::dem::MAX_DEM_PIXELS`] pixels; the message names the file.
    pub fn open(path: &Path) -> Result<Self> {
        let file = std::fs::File::open(path).with_context(|| format!("ortho {}: cannot open", path.display()))?;
        Self::read(std::io::BufReader::new(file)).with_context(|| format!("ortho {}", path.display()))
    }

    /// Reads a GeoTIFF orthophoto from `reader` (errors do not name a file).
    ///
    /// # Errors
    /// See [`Ortho::open`].
    pub fn read<R: Read + Seek>(reader: R) -> Result<Self> {
        let (mut d, width, height, budget, file_len) = bounded_decoder(reader, "--ortho")?;
        let pixels = u64::from(width) * u64::from(height);
        let samples = d.find_tag_unsigned::<u16>(Tag::SamplesPerPixel).ok().flatten().unwrap_or(1);
        if !matches!(samples, 1 | 3 | 4) {
            bail!("{samples} samples per pixel: an orthophoto has 1 (grey), 3 (RGB) or 4 (RGBA)");
        }
        if pixels * u64::from(samples) > budget {
            bail!(
                "the header declares {width}×{height} pixels of {samples} samples, more than this {file_len}-byte \
                 file can hold: it is corrupt or truncated"
            );
        }
        if d.find_tag_unsigned::<u16>(Tag::PlanarConfiguration).ok().flatten().unwrap_or(1) != 1 {
            bail!(
                "the bands are stored in separate planes: convert to interleaved (gdal_translate -co INTERLEAVE=PIXEL)"
            );
        }
        let Grid { x0, dx, y0, dy, epsg, nodata } = grid_of(&mut d)?;
        let image = d.read_image().map_err(|e| anyhow!("cannot decode the pixels: {e}"))?;
        let n = usize::from(samples);
        let expect = pixels * u64::from(samples);
        // Samples as 8 bits: 16-bit images are scaled by their largest value
        // (so 12-bit data stored in 16 bits keeps its range).
        let (bits, rgba) = match image {
            DecodingResult::U8(v) if v.len() as u64 == expect => (8, to_rgba(&v, n, nodata, |x| x)),
            DecodingResult::U16(v) if v.len() as u64 == expect => {
                let max = v.iter().copied().max().unwrap_or(0).max(255);
                let scale = 255.0 / f32::from(max);
                (16, to_rgba(&v, n, nodata, |x| (f32::from(x) * scale).round() as u8))
            }
            DecodingResult::U8(_) | DecodingResult::U16(_) => {
                bail!("decoded the wrong number of samples for {width}×{height} pixels of {samples}")
            }
            _ => bail!("unsupported sample format: an orthophoto has 8- or 16-bit unsigned samples"),
        };
        let kind = match samples {
            1 => "grey",
            3 => "RGB",
            _ => "RGBA",
        };
        Ok(Self { width, height, x0, dx, y0, dy, epsg, rgba, layout: format!("{kind} {bits}-bit") })
    }

    /// Map bounds of the pixel areas (min x, min y, max x, max y).
    #[must_use]
    pub fn extent(&self) -> [f64; 4] {
        let xa = self.x0 - 0.5 * self.dx;
        let xb = self.x0 + (f64::from(self.width) - 0.5) * self.dx;
        let ya = self.y0 - 0.5 * self.dy;
        let yb = self.y0 + (f64::from(self.height) - 0.5) * self.dy;
        [xa.min(xb), ya.min(yb), xa.max(xb), ya.max(yb)]
    }

    /// Pixel size, map units (the larger of x and y).
    #[must_use]
    pub fn resolution(&self) -> f64 {
        self.dx.abs().max(self.dy.abs())
    }

    /// Bilinear colour (linear in the stored values) at a map point, with the
    /// share of the four surrounding pixels that have data as alpha; `None`
    /// outside the image or where none has data.
    #[must_use]
    pub fn sample(&self, x: f64, y: f64) -> Option<[f32; 4]> {
        let (c, r) = ((x - self.x0) / self.dx, (y - self.y0) / self.dy);
        if !(-0.5..=f64::from(self.width) - 0.5).contains(&c) || !(-0.5..=f64::from(self.height) - 0.5).contains(&r) {
            return None;
        }
        let c = c.clamp(0.0, f64::from(self.width - 1));
        let r = r.clamp(0.0, f64::from(self.height - 1));
        let (c0, r0) = (c.floor() as i64, r.floor() as i64);
        let (fc, fr) = ((c - c0 as f64) as f32, (r - r0 as f64) as f32);
        let mut sum = [0.0f32; 4];
        let mut weight = 0.0;
        for (dc, dr, w) in
            [(0, 0, (1.0 - fc) * (1.0 - fr)), (1, 0, fc * (1.0 - fr)), (0, 1, (1.0 - fc) * fr), (1, 1, fc * fr)]
        {
            let (cc, rr) = ((c0 + dc).min(i64::from(self.width) - 1), (r0 + dr).min(i64::from(self.height) - 1));
            let p = self.rgba[rr as usize * self.width as usize + cc as usize];
            if p[3] > 0 && w > 0.0 {
                for k in 0..3 {
                    sum[k] += f32::from(p[k]) * w;
                }
                sum[3] += f32::from(p[3]) * w;
                weight += w;
            }
        }
        (weight > 0.0).then(|| [sum[0] / weight, sum[1] / weight, sum[2] / weight, sum[3] / 255.0])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;
    use tiff::encoder::{colortype, TiffEncoder};

    /// A north-up RGB GeoTIFF at 2 m pixels with its corner at (1000, 2000), UTM 33N.
    pub(crate) fn rgb_geotiff(w: u32, h: u32, f: impl Fn(u32, u32) -> [u8; 3]) -> Vec<u8> {
        let mut out = Cursor::new(Vec::new());
        let mut enc = TiffEncoder::new(&mut out).unwrap();
        let mut img = enc.new_image::<colortype::RGB8>(w, h).unwrap();
        img.encoder().write_tag(Tag::ModelPixelScaleTag, &[2.0f64, 2.0, 0.0][..]).unwrap();
        img.encoder().write_tag(Tag::ModelTiepointTag, &[0.0f64, 0.0, 0.0, 1000.0, 2000.0, 0.0][..]).unwrap();
        img.encoder()
            .write_tag(Tag::GeoKeyDirectoryTag, &[1u16, 1, 0, 2, 1024, 0, 1, 1, 3072, 0, 1, 32633][..])
            .unwrap();
        let data: Vec<u8> =
            (0..h).flat_map(|r| (0..w).map(move |c| (c, r))).flat_map(|(c, r)| f(c, r)).collect::<Vec<_>>();
        img.write_data(&data).unwrap();
        out.into_inner()
    }

    #[test]
    fn reads_an_rgb_geotiff_and_samples_it() {
        let bytes = rgb_geotiff(8, 4, |c, r| [(c * 30) as u8, (r * 60) as u8, 7]);
        let o = Ortho::read(Cursor::new(bytes)).unwrap();
        assert_eq!((o.width, o.height, o.epsg), (8, 4, Some(32633)));
        assert_eq!(o.extent(), [1000.0, 1992.0, 1016.0, 2000.0]);
        assert_eq!(o.resolution(), 2.0);
        assert!(o.layout.starts_with("RGB 8-bit"));
        // Pixel (2, 1)'s centre is at (1005, 1997).
        let p = o.sample(1005.0, 1997.0).unwrap();
        assert_eq!(p, [60.0, 60.0, 7.0, 1.0]);
        // Half-way between pixel centres (2, 1) and (3, 1).
        let p = o.sample(1006.0, 1997.0).unwrap();
        assert!((p[0] - 75.0).abs() < 1e-3, "{p:?}");
        assert_eq!(o.sample(999.0, 1997.0), None);
    }

    #[test]
    fn a_dem_is_not_an_ortho_and_garbage_fails_cleanly() {
        let err = Ortho::read(Cursor::new(b"II*\0garbage".to_vec())).unwrap_err();
        assert!(format!("{err:#}").contains("TIFF") || format!("{err:#}").contains("size"), "{err:#}");
        let mut out = Cursor::new(Vec::new());
        let mut enc = TiffEncoder::new(&mut out).unwrap();
        let img = enc.new_image::<colortype::Gray32Float>(2, 2).unwrap();
        img.write_data(&[1.0f32; 4]).unwrap();
        let err = Ortho::read(Cursor::new(out.into_inner())).unwrap_err();
        assert!(
            format!("{err:#}").contains("8- or 16-bit") || format!("{err:#}").contains("georeferencing"),
            "{err:#}"
        );
    }
}
