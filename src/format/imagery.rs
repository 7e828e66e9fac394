//! Ground imagery images: the baked JPEGs of `terrain.imagery`
//! ([`super::terrain::ImageryEntry`]) and the PNG or JPEG tiles of an XYZ or
//! WMTS raster source, decoded into RGBA8 (sRGB): natively with the `png` and
//! `zune-jpeg` crates (the decoders `image` uses); in the browser by the
//! browser itself (`createImageBitmap`, `src/web/fetch.rs`), which hands the
//! pixels over in a [`DECODED_MAGIC`] container, so the wasm module carries no
//! image decoder.
//!
//! The decoder bounds what it allocates: the image's side may not exceed
//! `max_px` (checked from the header before the pixels are decoded) and the
//! PNG decoder's allocations are capped, so a hostile file cannot make it
//! allocate more than a few times the largest allowed image.

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

/// The first bytes of an image the browser decoded: then the width and the
/// height (u32, little endian) and `width · height · 4` bytes of RGBA8.
pub const DECODED_MAGIC: &[u8; 8] = b"SYRGBA01";

/// An image's pixels in a [`DECODED_MAGIC`] container (magic, width, height,
/// the encoded image's bytes as fetched, each u32; then the pixels): what the
/// browser hands the streamer for a PNG or JPEG it decoded.
#[must_use]
pub fn encode_decoded(width: u32, height: u32, fetched_bytes: u32, pixels: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(20 + pixels.len());
    out.extend_from_slice(DECODED_MAGIC);
    out.extend_from_slice(&width.to_le_bytes());
    out.extend_from_slice(&height.to_le_bytes());
    out.extend_from_slice(&fetched_bytes.to_le_bytes());
    out.extend_from_slice(pixels);
    out
}

/// Bytes that came over the network for a response `body`: its length, or
/// for an image the browser decoded the encoded image's.
#[must_use]
pub fn fetched_bytes(body: &[u8]) -> u64 {
    match body.strip_prefix(DECODED_MAGIC).and_then(|rest| rest.get(8..12)) {
        Some(b) => u64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
        None => body.len() as u64,
    }
}

/// Decodes a PNG or JPEG image (natively; in the browser an image it
/// decoded, [`DECODED_MAGIC`]) of at most `max_px` pixels a side.
///
/// # Errors
/// A [`DecodeError`] naming `file` for bytes that are no such image, a
/// corrupt image, or one larger than `max_px` a side.
pub fn decode_image(file: &str, bytes: &[u8], max_px: u32) -> Result<Rgba8, DecodeError> {
    let bad = |m: String| DecodeError::new(file, Problem::Invalid(m));
    let img = if let Some(rest) = bytes.strip_prefix(DECODED_MAGIC) {
        let word = |k: usize| rest.get(4 * k..4 * k + 4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
        let (Some(width), Some(height), Some(_)) = (word(0), word(1), word(2)) else {
            return Err(bad("a decoded image without its size".into()));
        };
        Rgba8 { width, height, pixels: rest[12..].to_vec() }
    } else {
        decode_encoded(bytes, max_px).map_err(bad)?
    };
    if img.width == 0 || img.height == 0 || img.width > max_px || img.height > max_px {
        return Err(bad(format!("a {}×{} image: sides of 1–{max_px} pixels are read", img.width, img.height)));
    }
    if img.pixels.len() != img.width as usize * img.height as usize * 4 {
        return Err(bad("the image data does not match its size".into()));
    }
    Ok(img)
}

/// A PNG or JPEG in the browser: its own decoder gave none (the fetcher
/// decodes every response that starts as one).
#[cfg(target_arch = "wasm32")]
fn decode_encoded(bytes: &[u8], _max_px: u32) -> Result<Rgba8, String> {
    Err(if bytes.starts_with(b"\x89PNG\r\n\x1a\n") || bytes.starts_with(&[0xff, 0xd8]) {
        "the browser could not decode the image".into()
    } else {
        "not a PNG or JPEG image".into()
    })
}

#[cfg(not(target_arch = "wasm32"))]
fn decode_encoded(bytes: &[u8], max_px: u32) -> Result<Rgba8, String> {
    let img = if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
        decode_png(bytes, max_px).map_err(|e| format!("cannot decode the PNG image: {e}"))?
    } else if bytes.starts_with(&[0xff, 0xd8]) {
        decode_jpeg(bytes, max_px).map_err(|e| format!("cannot decode the JPEG image: {e}"))?
    } else {
        return Err("not a PNG or JPEG image".into());
    };
    Ok(img)
}

#[cfg(not(target_arch = "wasm32"))]
fn decode_png(bytes: &[u8], max_px: u32) -> Result<Rgba8, String> {
    let limits = png::Limits { bytes: (max_px as usize).pow(2) * 8 + (1 << 16) };
    let mut decoder = png::Decoder::new_with_limits(std::io::Cursor::new(bytes), limits);
    decoder.set_transformations(png::Transformations::normalize_to_color8());
    let mut reader = decoder.read_info().map_err(|e| e.to_string())?;
    let (w, h) = (reader.info().width, reader.info().height);
    if w > max_px || h > max_px {
        return Err(format!("{w}×{h} pixels is more than {max_px} a side"));
    }
    let size = reader.output_buffer_size().ok_or("the image is too large")?;
    let mut buf = vec![0; size];
    let info = reader.next_frame(&mut buf).map_err(|e| e.to_string())?;
    buf.truncate(info.buffer_size());
    let n = (w * h) as usize;
    let pixels: Vec<u8> = match info.color_type {
        png::ColorType::Rgba => buf,
        png::ColorType::Rgb => buf.chunks_exact(3).flat_map(|p| [p[0], p[1], p[2], 255]).collect(),
        png::ColorType::Grayscale => buf.iter().flat_map(|&g| [g, g, g, 255]).collect(),
        png::ColorType::GrayscaleAlpha => buf.chunks_exact(2).flat_map(|p| [p[0], p[0], p[0], p[1]]).collect(),
        png::ColorType::Indexed => return Err("an indexed image was not expanded".into()),
    };
    if pixels.len() != n * 4 {
        return Err(format!("{} bytes of pixels for {w}×{h}", pixels.len()));
    }
    Ok(Rgba8 { width: w, height: h, pixels })
}

/// Whether the JPEG's image data is followed by its end marker (EOI, `FF D9`).
///
/// The segments before the first scan are skipped by their lengths (an Exif
/// thumbnail's own EOI is inside one); within entropy-coded data a literal
/// `FF` is always followed by `00` or a restart marker, so the first `FF D9`
/// after the first scan is the image's end.
#[cfg(not(target_arch = "wasm32"))]
fn jpeg_is_whole(bytes: &[u8]) -> bool {
    let mut at = 2;
    while at + 4 <= bytes.len() {
        if bytes[at] != 0xff {
            return false;
        }
        let marker = bytes[at + 1];
        if marker == 0xff {
            at += 1; // fill byte
            continue;
        }
        // Markers without a length (TEM, RSTn).
        if marker == 0x01 || (0xd0..=0xd7).contains(&marker) {
            at += 2;
            continue;
        }
        let len = usize::from(u16::from_be_bytes([bytes[at + 2], bytes[at + 3]]));
        if len < 2 {
            return false; // a segment's length counts its own two bytes
        }
        at += 2 + len;
        if marker == 0xda {
            return bytes.get(at..).is_some_and(|rest| rest.windows(2).any(|w| w == [0xff, 0xd9]));
        }
    }
    false
}

#[cfg(not(target_arch = "wasm32"))]
fn decode_jpeg(bytes: &[u8], max_px: u32) -> Result<Rgba8, String> {
    if !jpeg_is_whole(bytes) {
        return Err("the file ends before the image does (no end marker after the image data)".into());
    }
    use zune_jpeg::zune_core::colorspace::ColorSpace;
    use zune_jpeg::zune_core::options::DecoderOptions;
    let options = DecoderOptions::default()
        .set_max_width(max_px as usize)
        .set_max_height(max_px as usize)
        .jpeg_set_out_colorspace(ColorSpace::RGBA)
        // A truncated JPEG is an error, not an image filled with grey.
        .set_strict_mode(true);
    let mut decoder = zune_jpeg::JpegDecoder::new_with_options(std::io::Cursor::new(bytes), options);
    let pixels = decoder.decode().map_err(|e| e.to_string())?;
    let info = decoder.info().ok_or("no image header")?;
    Ok(Rgba8 { width: u32::from(info.width), height: u32::from(info.height), pixels })
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
        // A JPEG too.
        let mut jpg = std::io::Cursor::new(Vec::new());
        image::RgbImage::from_fn(32, 16, |x, _| image::Rgb([x as u8 * 8, 100, 50]))
            .write_to(&mut jpg, image::ImageFormat::Jpeg)
            .unwrap();
        let img = decode_image("a.jpg", jpg.get_ref(), 256).unwrap();
        assert_eq!((img.width, img.height), (32, 16));
        assert!((i32::from(img.pixels[4 * 20 + 1]) - 100).abs() < 8);
        assert!(decode_image("big.jpg", jpg.get_ref(), 16).is_err());
        // A JPEG cut short (a broken download, a full disk) is refused, not grey.
        for keep in [jpg.get_ref().len() * 2 / 3, jpg.get_ref().len() - 2] {
            let e = decode_image("cut.jpg", &jpg.get_ref()[..keep], 256).unwrap_err().to_string();
            assert!(e.contains("cut.jpg") && e.contains("JPEG"), "{keep}: {e}");
        }
        let mut cut = png(16, 8);
        cut.truncate(cut.len() / 2);
        assert!(decode_image("cut.png", &cut, 256).is_err());
        // What the browser decoded: taken as it is, within the same limits.
        let pixels: Vec<u8> = (0..2 * 3 * 4).map(|k| k as u8).collect();
        let img = decode_image("b.jpg", &encode_decoded(2, 3, 99, &pixels), 256).unwrap();
        assert_eq!((img.width, img.height, img.pixels), (2, 3, pixels.clone()));
        assert!(decode_image("b.jpg", &encode_decoded(2, 3, 99, &pixels[1..]), 256).is_err(), "short");
        assert!(decode_image("b.jpg", &encode_decoded(300, 1, 99, &vec![0; 1200]), 256).is_err(), "too wide");
        assert!(decode_image("b.jpg", &DECODED_MAGIC[..], 256).is_err(), "no size");
        assert!(decode_image("b.jpg", &encode_decoded(0, 0, 0, &[]), 256).is_err(), "empty");
        // What came over the network: the encoded image's bytes, not its pixels'.
        assert_eq!(fetched_bytes(&encode_decoded(2, 3, 99, &pixels)), 99);
        assert_eq!(fetched_bytes(b"\xff\xd8\xff\xe0 a jpeg"), 11);
    }
}
