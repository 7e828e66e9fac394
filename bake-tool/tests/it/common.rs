//! Helpers shared by the `sylva-bake` binary tests.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The binary, without a runtime folder as on a headless machine (it makes its
/// own), with the tests' shared pack cache: a pack of the same model and
/// options is built once for all tests (each a process of its own under
/// nextest), which is most of a small bake's time. Tests of the packs
/// themselves (what they hold, that building is deterministic) use
/// [`bin_building_packs`].
pub fn bin() -> Command {
    let mut c = bin_building_packs();
    c.env("SYLVA_BAKE_PACK_CACHE", pack_cache());
    c
}

/// The binary as [`bin`], but building every pack (no pack cache).
pub fn bin_building_packs() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_sylva-bake"));
    c.env_remove("XDG_RUNTIME_DIR");
    c.env_remove("SYLVA_BAKE_PACK_CACHE");
    c
}

/// The pack cache the tests share (keyed by the bake tool's build among the
/// rest, so a rebuilt tool never takes an older one's packs).
pub fn pack_cache() -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("pack-cache")
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

pub const SMALL: [&str; 6] = ["--billboard-size", "32", "--impostor-size", "32", "--texture-size", "64"];

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

/// Writes an RGB8 GeoTIFF orthophoto of `w`×`h` pixels of `pixel_m` metres in
/// EPSG:32633 whose north-west corner is `(x0, y0)`, colours `colour(x, y)` at
/// the pixel centres (map coordinates).
pub fn write_geotiff_ortho(
    path: &Path,
    (w, h): (u32, u32),
    pixel_m: f64,
    (x0, y0): (f64, f64),
    colour: impl Fn(f64, f64) -> [u8; 3],
) {
    use tiff::encoder::{colortype, TiffEncoder};
    use tiff::tags::Tag;
    let mut file = std::fs::File::create(path).unwrap();
    let mut enc = TiffEncoder::new(&mut file).unwrap();
    let mut img = enc.new_image::<colortype::RGB8>(w, h).unwrap();
    let e = img.encoder();
    e.write_tag(Tag::ModelPixelScaleTag, &[pixel_m, pixel_m, 0.0][..]).unwrap();
    e.write_tag(Tag::ModelTiepointTag, &[0.0f64, 0.0, 0.0, x0, y0, 0.0][..]).unwrap();
    let keys: [u16; 12] = [1, 1, 0, 2, 1024, 0, 1, 1, 3072, 0, 1, 32633];
    e.write_tag(Tag::GeoKeyDirectoryTag, &keys[..]).unwrap();
    let half = pixel_m * 0.5;
    let data: Vec<u8> = (0..h)
        .flat_map(|r| (0..w).map(move |c| (c, r)))
        .flat_map(|(c, r)| colour(x0 + half + pixel_m * f64::from(c), y0 - half - pixel_m * f64::from(r)))
        .collect();
    img.write_data(&data).unwrap();
}

/// A local XYZ tile server (never the internet): answers `GET /{z}/{x}/{y}.png`
/// with a 256² PNG whose pixel colours are `colour(lon, lat)` at the pixel
/// centres, `404` for anything else. Returns its URL template and a request counter.
pub fn xyz_server(
    colour: impl Fn(f64, f64) -> [u8; 3] + Send + Sync + 'static,
) -> (String, std::sync::Arc<std::sync::atomic::AtomicUsize>) {
    use std::io::{BufRead, BufReader, Write};
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Arc;
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    let count = Arc::new(AtomicUsize::new(0));
    let colour = Arc::new(colour);
    let served = Arc::clone(&count);
    std::thread::spawn(move || {
        for stream in listener.incoming() {
            let Ok(mut stream) = stream else { continue };
            let (colour, served) = (Arc::clone(&colour), Arc::clone(&served));
            std::thread::spawn(move || {
                let mut line = String::new();
                let mut reader = BufReader::new(stream.try_clone().unwrap());
                if reader.read_line(&mut line).is_err() {
                    return;
                }
                // Drain the headers.
                let mut h = String::new();
                while reader.read_line(&mut h).is_ok_and(|n| n > 2) {
                    h.clear();
                }
                let path = line.split_whitespace().nth(1).unwrap_or("").to_string();
                let parts: Vec<u32> = path
                    .trim_start_matches('/')
                    .trim_end_matches(".png")
                    .split('/')
                    .filter_map(|p| p.parse().ok())
                    .collect();
                let body = if let [z, x, y] = parts[..] {
                    served.fetch_add(1, Ordering::SeqCst);
                    let n = f64::from(1u32 << z) * 256.0;
                    let img = image::RgbImage::from_fn(256, 256, |i, j| {
                        let (mx, my) = ((f64::from(x * 256 + i) + 0.5) / n, (f64::from(y * 256 + j) + 0.5) / n);
                        let lon = mx * 360.0 - 180.0;
                        let lat = (std::f64::consts::PI * (1.0 - 2.0 * my)).sinh().atan().to_degrees();
                        image::Rgb(colour(lon, lat))
                    });
                    let mut png = std::io::Cursor::new(Vec::new());
                    img.write_to(&mut png, image::ImageFormat::Png).unwrap();
                    Some(png.into_inner())
                } else {
                    None
                };
                let _ = match body {
                    Some(b) => stream
                        .write_all(
                            format!("HTTP/1.1 200 OK\r\nContent-Type: image/png\r\nContent-Length: {}\r\nConnection: close\r\n\r\n", b.len())
                                .as_bytes(),
                        )
                        .and_then(|()| stream.write_all(&b)),
                    None => stream.write_all(b"HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\nConnection: close\r\n\r\n"),
                };
            });
        }
    });
    (format!("http://127.0.0.1:{port}/{{z}}/{{x}}/{{y}}.png"), count)
}
