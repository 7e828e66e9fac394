//! Ground imagery images: the baked JPEGs of `terrain.imagery`
//! ([`super::terrain::ImageryEntry`]) and the PNG/JPEG/WebP tiles of an XYZ or
//! WMTS raster source, decoded with the `image` crate into RGBA8 (sRGB).
//!
//! The decoder bounds what it allocates: the image's side may not exceed
//! `max_px` and the decoder's own allocations are capped, so a hostile file
//! cannot make it allocate more than a few times the largest allowed image.

use super::error::{DecodeError, Problem};

/// A decoded image: `width × height` RGBA8 pixels, row 0 at the top (north).
#[derive(Debug, Clone, PartialEq)]
pub struct Rgba8 {
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// `width · height · 4` bytes.
    pub pixels: Vec<u8>,
}

/// Decodes a PNG, JPEG or WebP image of at most `max_px` pixels a side.
///
/// # Errors
/// A [`DecodeError`] naming `file` for bytes that are no such image, a
/// corrupt image, or one larger than `max_px` a side.
pub fn decode_image(file: &str, bytes: &[u8], max_px: u32) -> Result<Rgba8, DecodeError> {
    let bad = |m: String| DecodeError::new(file, Problem::Invalid(m));
    let mut reader = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| bad(format!("cannot read the image: {e}")))?;
    if reader.format().is_none() {
        return Err(bad("not a PNG, JPEG or WebP image".into()));
    }
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(max_px);
    limits.max_image_height = Some(max_px);
    limits.max_alloc = Some(u64::from(max_px) * u64::from(max_px) * 16 + (1 << 20));
    reader.limits(limits);
    let img = reader.decode().map_err(|e| bad(format!("cannot decode the image: {e}")))?;
    let rgba = img.into_rgba8();
    let (width, height) = rgba.dimensions();
    if width == 0 || height == 0 {
        return Err(bad("the image is empty".into()));
    }
    Ok(Rgba8 { width, height, pixels: rgba.into_raw() })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn png(w: u32, h: u32) -> Vec<u8> {
        let img = image::RgbImage::from_fn(w, h, |x, y| image::Rgb([x as u8, y as u8, 9]));
        let mut out = std::io::Cursor::new(Vec::new());
        img.write_to(&mut out, image::ImageFormat::Png).unwrap();
        out.into_inner()
    }

    #[test]
    fn images_decode_within_their_limit_and_garbage_is_refused() {
        let img = decode_image("a.png", &png(16, 8), 256).unwrap();
        assert_eq!((img.width, img.height, img.pixels.len()), (16, 8, 16 * 8 * 4));
        assert_eq!(&img.pixels[4 * 17..4 * 18], &[1, 1, 9, 255]);
        let e = decode_image("big.png", &png(300, 8), 256).unwrap_err().to_string();
        assert!(e.starts_with("big.png: ") && e.contains("decode"), "{e}");
        let e = decode_image("x.jpg", b"not an image at all", 256).unwrap_err().to_string();
        assert!(e.contains("x.jpg") && e.contains("not a PNG"), "{e}");
        let mut cut = png(16, 8);
        cut.truncate(cut.len() / 2);
        assert!(decode_image("cut.png", &cut, 256).is_err());
    }
}
