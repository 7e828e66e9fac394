//! `sylva bench --stress`: a long path (10,000 frames by default) through a scene
//! with streaming as the viewer does it (non-blocking, tiles evicted as the
//! camera moves): memory must stay flat, frame time must not grow, nothing may
//! turn non-finite.

use std::path::Path;

use anyhow::{Context, Result};
use serde::Serialize;

use super::Stat;
use crate::camera::Camera;
use crate::offscreen::OffscreenScene;
use crate::render::forest::{PoolConfig, RenderSettings};

/// One frame of a stress run.
#[derive(Debug, Clone, Default, Serialize)]
pub struct StressFrame {
    /// Frame index.
    pub frame: usize,
    /// GPU ms (cull + draw, wall time around submit + wait).
    pub gpu_ms: f64,
    /// CPU ms to prepare and record.
    pub cpu_ms: f64,
    /// Resident set size of the process, bytes (0 where /proc is missing).
    pub rss_bytes: u64,
    /// GPU bytes (pools + packs).
    pub gpu_bytes: u64,
    /// Trees resident on the GPU.
    pub trees_resident: u64,
    /// Tiles resident.
    pub tiles_resident: u64,
    /// Instances drawn, all representations.
    pub drawn: u64,
    /// Bytes fetched so far.
    pub bytes_fetched: u64,
    /// The pools are full of wanted tiles (the reach is shortened).
    pub pools_full: bool,
    /// Tiles trimmed to fewer prefix levels so far (eviction by prefix).
    pub tiles_trimmed: u64,
}

/// What a stress run found (`stress.json`).
#[derive(Debug, Clone, Serialize)]
pub struct StressSummary {
    /// Frames rendered.
    pub frames: usize,
    /// GPU ms over the second pass along the path (the first after warm-up) and
    /// over the last pass.
    pub gpu_ms_first: Stat,
    /// See `gpu_ms_first`.
    pub gpu_ms_last: Stat,
    /// Largest resident set size during the warm-up pass, and at the end, bytes.
    pub rss_after_first: u64,
    /// Resident set size, bytes, over the second pass and over the last (median
    /// and 95th percentile). Single frames spike by 10 % and more as the driver
    /// and allocator take and return memory; a leak moves the median.
    pub rss_first: Stat,
    /// See `rss_first`.
    pub rss_last: Stat,
    /// See `rss_after_first`.
    pub rss_end: u64,
    /// Largest resident set size, bytes.
    pub rss_max: u64,
    /// GPU bytes, largest over the run.
    pub gpu_bytes_max: u64,
    /// Most trees resident at once, and the scene's total.
    pub trees_resident_max: u64,
    /// Trees in the scene.
    pub trees_total: u64,
    /// Bytes fetched over the run.
    pub bytes_fetched: u64,
    /// Frames whose counters were not finite (must be 0).
    pub non_finite_frames: usize,
    /// Frames whose pools were full of wanted tiles (the reach shortened).
    pub pools_full_frames: usize,
    /// Tiles trimmed to fewer prefix levels over the run (eviction by prefix).
    pub tiles_trimmed: u64,
    /// With a [`HoleCheck`]: frames of the first pass and their share of
    /// pixels where the streamed frame is lighter than the settled one.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub holes: Vec<HoleFrame>,
    /// The largest of `holes` (0 without a check).
    pub hole_fraction_max: f64,
    /// Whether memory stayed flat (the last pass's median resident set ≤ 1.10 ×
    /// the second pass's) and frame time did not grow (last pass's median ≤ 1.25 × the second's + 1 ms).
    pub passed: bool,
}

/// Frames to save and judge for holes: every `every`-th frame of the first
/// pass, as streamed and as settled (everything it needs loaded), into `dir`.
#[derive(Debug, Clone, Copy)]
pub struct HoleCheck<'a> {
    /// Where the PNGs go.
    pub dir: &'a Path,
    /// Every how many frames.
    pub every: usize,
}

/// A judged frame of a [`HoleCheck`].
#[derive(Debug, Clone, Serialize)]
pub struct HoleFrame {
    /// Frame index.
    pub frame: usize,
    /// Share of pixels whose luminance (sRGB 0–255) in the streamed frame
    /// exceeds the settled frame's by more than [`HOLE_LUMA`]: ground or sky
    /// showing where the settled frame draws the forest.
    pub fraction: f64,
    /// The share darker by as much: forest drawn twice (trees and a canopy
    /// standing in over them), or forest where the settled frame has none.
    pub darker: f64,
}

/// Luminance difference (sRGB 0–255) that counts a pixel as a hole: on the
/// 10^8 country's fly-down, frames with nothing missing differ by it in ≤ 1.7 %
/// of their pixels (a different subset of trees drawn), bare ground where the
/// forest should be in 14–68 %.
pub const HOLE_LUMA: f64 = 15.0;

/// The shares of pixels of `streamed` lighter and darker than `settled` by
/// [`HOLE_LUMA`] (RGBA8).
#[must_use]
pub fn hole_fraction(streamed: &[u8], settled: &[u8]) -> (f64, f64) {
    let luma = |p: &[u8]| 0.2126 * f64::from(p[0]) + 0.7152 * f64::from(p[1]) + 0.0722 * f64::from(p[2]);
    let n = (streamed.len().min(settled.len()) / 4).max(1) as f64;
    let pairs = || streamed.chunks_exact(4).zip(settled.chunks_exact(4));
    let lighter = pairs().filter(|(a, b)| luma(a) > luma(b) + HOLE_LUMA).count();
    let darker = pairs().filter(|(a, b)| luma(a) + HOLE_LUMA < luma(b)).count();
    (lighter as f64 / n, darker as f64 / n)
}

/// Resident set size of this process in bytes (Linux; 0 elsewhere).
#[must_use]
pub fn rss_bytes() -> u64 {
    std::fs::read_to_string("/proc/self/statm")
        .ok()
        .and_then(|s| s.split_whitespace().nth(1).and_then(|v| v.parse::<u64>().ok()))
        .map_or(0, |pages| pages * 4096)
}

/// A camera path of `frames` frames that runs `cameras` forwards and back again
/// as often as it takes.
#[must_use]
pub fn ping_pong(cameras: &[Camera], frames: usize) -> Vec<Camera> {
    let n = cameras.len();
    if n < 2 {
        return cameras.iter().copied().cycle().take(frames).collect();
    }
    let period = 2 * (n - 1);
    (0..frames)
        .map(|i| {
            let k = i % period;
            cameras[if k < n { k } else { period - k }]
        })
        .collect()
}

/// Runs Sylva along `cameras` on `scene`, streaming without waiting; `period` is
/// the length of one pass (see [`summarise`]); with `holes`, frames of the
/// first pass are saved and judged against settled ones.
///
/// # Errors
/// A scene that does not open.
pub fn run(
    scene: &str,
    cameras: &[Camera],
    period: usize,
    (width, height): (u32, u32),
    (settings, pools): (RenderSettings, PoolConfig),
    holes: Option<HoleCheck<'_>>,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(Vec<StressFrame>, StressSummary)> {
    let save = |dir: &Path, name: String, img: &[u8]| -> Result<()> {
        image::save_buffer(dir.join(&name), img, width, height, image::ColorType::Rgba8)
            .with_context(|| format!("writing {}", dir.join(&name).display()))
    };
    if let Some(h) = holes {
        std::fs::create_dir_all(h.dir).with_context(|| format!("cannot create {}", h.dir.display()))?;
    }
    let mut judged = Vec::new();
    let mut off = OffscreenScene::open(scene, width, height, pools).with_context(|| format!("opening {scene}"))?;
    off.settings = settings;
    if let Some(first) = cameras.first() {
        off.load_view(first, 120.0);
    }
    let mut out = Vec::with_capacity(cameras.len());
    let mut non_finite = 0;
    let mut trees_total = 0;
    for (i, cam) in cameras.iter().enumerate() {
        progress(i, cameras.len());
        off.update_stream(cam);
        let s = off.render(cam, true);
        let gpu_ms = s.gpu_ms.values().sum::<f64>();
        if !gpu_ms.is_finite() || !s.frame_cpu_ms.is_finite() {
            non_finite += 1;
        }
        trees_total = s.trees_total;
        out.push(StressFrame {
            frame: i,
            gpu_ms,
            cpu_ms: s.frame_cpu_ms,
            rss_bytes: rss_bytes(),
            gpu_bytes: s.gpu_bytes,
            trees_resident: s.trees_resident,
            tiles_resident: s.tiles_resident,
            drawn: s.instances.values().sum(),
            bytes_fetched: s.bytes_fetched,
            pools_full: s.degraded.get("pools_full").is_some_and(|v| v == &serde_json::Value::Bool(true)),
            tiles_trimmed: s.tiles_trimmed,
        });
        if let Some(h) = holes.filter(|h| i <= period / 2 && i % h.every.max(1) == 0) {
            let img = off.read_image();
            save(h.dir, format!("{i:05}-stream.png"), &img)?;
            judged.push((i, *cam, img));
        }
    }
    let mut summary = summarise(&out, non_finite, trees_total, period);
    if let Some(h) = holes {
        // The same cameras with everything they need loaded, in a scene of their own.
        let mut settled = OffscreenScene::open(scene, width, height, PoolConfig::default())
            .with_context(|| format!("opening {scene}"))?;
        settled.settings = off.settings;
        for (i, cam, img) in judged {
            settled.load_view(&cam, 120.0);
            settled.render(&cam, false);
            let reference = settled.read_image();
            save(h.dir, format!("{i:05}-settled.png"), &reference)?;
            let (fraction, darker) = hole_fraction(&img, &reference);
            summary.holes.push(HoleFrame { frame: i, fraction, darker });
        }
        summary.hole_fraction_max = summary.holes.iter().map(|f| f.fraction).fold(0.0, f64::max);
    }
    Ok((out, summary))
}

/// The summary of a run's frames. `period` is the length of one pass along the
/// path and back: the first pass is warm-up (tiles and packs stream in), the
/// second is compared with the last, whole passes against whole passes so the
/// same views are compared (runs under three passes use thirds instead).
#[must_use]
pub fn summarise(frames: &[StressFrame], non_finite_frames: usize, trees_total: u64, period: usize) -> StressSummary {
    let p = period.clamp(1, (frames.len() / 3).max(1));
    let warm = &frames[..p.min(frames.len())];
    let first = &frames[p.min(frames.len())..(2 * p).min(frames.len())];
    let last = &frames[frames.len().saturating_sub(p)..];
    let gpu_ms_first = Stat::of(first.iter().map(|f| f.gpu_ms));
    let gpu_ms_last = Stat::of(last.iter().map(|f| f.gpu_ms));
    let rss_after_first = warm.iter().map(|f| f.rss_bytes).max().unwrap_or(0);
    let rss_end = frames.last().map_or(0, |f| f.rss_bytes);
    let rss_max = frames.iter().map(|f| f.rss_bytes).max().unwrap_or(0);
    let rss_first = Stat::of(first.iter().map(|f| f.rss_bytes as f64));
    let rss_last = Stat::of(last.iter().map(|f| f.rss_bytes as f64));
    let memory_flat = rss_last.median <= rss_first.median * 1.10;
    let time_flat = gpu_ms_last.median <= gpu_ms_first.median * 1.25 + 1.0;
    StressSummary {
        frames: frames.len(),
        gpu_ms_first,
        gpu_ms_last,
        rss_after_first,
        rss_first,
        rss_last,
        rss_end,
        rss_max,
        gpu_bytes_max: frames.iter().map(|f| f.gpu_bytes).max().unwrap_or(0),
        trees_resident_max: frames.iter().map(|f| f.trees_resident).max().unwrap_or(0),
        trees_total,
        bytes_fetched: frames.last().map_or(0, |f| f.bytes_fetched),
        non_finite_frames,
        pools_full_frames: frames.iter().filter(|f| f.pools_full).count(),
        tiles_trimmed: frames.last().map_or(0, |f| f.tiles_trimmed),
        holes: Vec::new(),
        hole_fraction_max: 0.0,
        passed: memory_flat && time_flat && non_finite_frames == 0,
    }
}

/// Writes `stress.csv` and `stress.json` into `dir`.
///
/// # Errors
/// I/O errors.
pub fn write(dir: &Path, frames: &[StressFrame], summary: &StressSummary) -> Result<()> {
    use std::fmt::Write as _;
    let mut s =
        String::from("frame,gpu_ms,cpu_ms,rss_bytes,gpu_bytes,trees_resident,tiles_resident,drawn,bytes_fetched,pools_full,tiles_trimmed\n");
    for f in frames {
        writeln!(
            s,
            "{},{:.3},{:.4},{},{},{},{},{},{},{},{}",
            f.frame,
            f.gpu_ms,
            f.cpu_ms,
            f.rss_bytes,
            f.gpu_bytes,
            f.trees_resident,
            f.tiles_resident,
            f.drawn,
            f.bytes_fetched,
            u8::from(f.pools_full),
            f.tiles_trimmed
        )?;
    }
    std::fs::write(dir.join("stress.csv"), s).with_context(|| format!("writing {}", dir.display()))?;
    std::fs::write(dir.join("stress.json"), serde_json::to_string_pretty(summary)?)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn holes_are_pixels_lighter_than_the_settled_frame() {
        let forest = [30u8, 60, 30, 255];
        let field = [180u8, 170, 110, 255];
        let settled = [forest, forest, forest, field].concat();
        assert_eq!(hole_fraction(&settled, &settled), (0.0, 0.0));
        // Ground where the forest should be: a hole; forest over a field: darker.
        let streamed = [field, forest, forest, forest].concat();
        assert_eq!(hole_fraction(&streamed, &settled), (0.25, 0.25));
    }

    #[test]
    fn ping_pong_turns_at_both_ends() {
        let cams: Vec<Camera> =
            (0..3).map(|i| Camera { eye_m: glam::DVec3::X * f64::from(i), ..Camera::default() }).collect();
        let xs: Vec<f64> = ping_pong(&cams, 7).iter().map(|c| c.eye_m.x).collect();
        assert_eq!(xs, [0.0, 1.0, 2.0, 1.0, 0.0, 1.0, 2.0]);
    }

    #[test]
    fn growth_fails_the_summary() {
        let frame =
            |i: usize, ms: f64, rss: u64| StressFrame { frame: i, gpu_ms: ms, rss_bytes: rss, ..Default::default() };
        let flat: Vec<StressFrame> = (0..100).map(|i| frame(i, 5.0, 1_000_000)).collect();
        assert!(summarise(&flat, 0, 10, 10).passed);
        // Growth while the first pass streams tiles in is fine.
        let warm: Vec<StressFrame> = (0..100).map(|i| frame(i, 5.0, 1_000_000 + i.min(10) as u64 * 50_000)).collect();
        assert!(summarise(&warm, 0, 10, 10).passed);
        let leak: Vec<StressFrame> = (0..100).map(|i| frame(i, 5.0, 1_000_000 + i as u64 * 10_000)).collect();
        assert!(!summarise(&leak, 0, 10, 10).passed);
        // A frame now and then that takes 20 % more and gives it back is no leak.
        let spiky: Vec<StressFrame> =
            (0..100).map(|i| frame(i, 5.0, if i % 7 == 3 { 1_200_000 } else { 1_000_000 })).collect();
        assert!(summarise(&spiky, 0, 10, 10).passed);
        let slow: Vec<StressFrame> = (0..100).map(|i| frame(i, 5.0 + i as f64 * 0.1, 1_000_000)).collect();
        assert!(!summarise(&slow, 0, 10, 10).passed);
        assert!(!summarise(&flat, 1, 10, 10).passed);
    }
}
