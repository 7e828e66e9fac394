//! Imagery decoder (baked JPEGs, XYZ/WMTS tiles): any bytes → Ok or a
//! DecodeError; never a panic, never an image larger than the limit.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(img) = sylva::format::imagery::decode_image("fuzz.jpg", data, 256) {
        assert!(img.width <= 256 && img.height <= 256);
        assert_eq!(img.pixels.len(), img.width as usize * img.height as usize * 4);
    }
});
