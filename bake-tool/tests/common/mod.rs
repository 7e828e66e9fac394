//! Helpers shared by the `sylva-bake` binary tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The binary, without a runtime folder as on a headless machine (it makes its own).
pub fn bin() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_sylva-bake"));
    c.env_remove("XDG_RUNTIME_DIR");
    c
}

pub fn tmp(name: &str) -> PathBuf {
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

pub fn run(cmd: &mut Command) -> Output {
    let out = cmd.output().expect("run sylva-bake");
    assert!(
        out.status.success(),
        "failed: {}\n{}",
        String::from_utf8_lossy(&out.stderr),
        String::from_utf8_lossy(&out.stdout)
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("XDG_RUNTIME_DIR"), "a false 'error:' line on a run that worked: {stderr}");
    out
}

pub fn fails(cmd: &mut Command) -> String {
    let out = cmd.output().expect("run sylva-bake");
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "expected failure, got success: {stderr}");
    assert!(!stderr.contains("panicked"), "panicked: {stderr}");
    stderr
}

/// Every file under `dir`, relative path → bytes.
pub fn snapshot(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push((p.strip_prefix(dir).unwrap().display().to_string(), std::fs::read(&p).unwrap()));
            }
        }
    }
    out.sort();
    out
}

pub const SMALL: [&str; 4] = ["--billboard-size", "32", "--texture-size", "64"];

/// Writes a float32 GeoTIFF DEM of `n`×`n` pixels of `pixel_m` metres in
/// EPSG:32633 whose north-west corner is (500000, 5300000), heights
/// `height(x, y)` at the pixel centres (map coordinates).
pub fn write_geotiff_dem(path: &Path, n: u32, pixel_m: f64, height: impl Fn(f64, f64) -> f64) {
    use tiff::encoder::{colortype, TiffEncoder};
    use tiff::tags::Tag;
    let mut file = std::fs::File::create(path).unwrap();
    let mut enc = TiffEncoder::new(&mut file).unwrap();
    let mut img = enc.new_image::<colortype::Gray32Float>(n, n).unwrap();
    let e = img.encoder();
    e.write_tag(Tag::ModelPixelScaleTag, &[pixel_m, pixel_m, 0.0][..]).unwrap();
    e.write_tag(Tag::ModelTiepointTag, &[0.0f64, 0.0, 0.0, 500_000.0, 5_300_000.0, 0.0][..]).unwrap();
    // Projected, EPSG:32633 (pixel-is-area by default).
    let keys: [u16; 12] = [1, 1, 0, 2, 1024, 0, 1, 1, 3072, 0, 1, 32633];
    e.write_tag(Tag::GeoKeyDirectoryTag, &keys[..]).unwrap();
    let half = pixel_m * 0.5;
    let data: Vec<f32> = (0..n)
        .flat_map(|r| (0..n).map(move |c| (c, r)))
        .map(|(c, r)| {
            height(500_000.0 + half + pixel_m * f64::from(c), 5_300_000.0 - half - pixel_m * f64::from(r)) as f32
        })
        .collect();
    img.write_data(&data).unwrap();
}
