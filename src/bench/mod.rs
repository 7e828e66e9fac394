//! `sylva bench`: run time against image error on camera paths, every method on
//! the same scene and the same frames. Native only.
//!
//! Paths: `flyover` (Clasen et al. 2010, Fig. 10: overview, descent to eye height inside
//! the forest, towards a smaller group, turn back), `far` / `medium` / `close`
//! (360° horizontal sweeps, Eichner 2024, ch. 5) or a JSON file of keyframes.
//! Methods: `reference` (every tree full mesh, no LoD, 2× supersampled),
//! `mesh` (full mesh, per-tree culling), `per-tree` (Sylva's LoD, trees culled one
//! by one), `billboard` (meshes near, billboards beyond), `ellipsoid` (meshes
//! near, ellipsoids beyond), `impostor` (meshes near, multi-view impostors
//! beyond), `sylva` (the full mix) at quality 1, ½, ¼, and `sylva-converged`
//! (the full mix refined while the camera rests: the converged image of
//! progressive refinement, its GPU time summed over the steps).
//! Per frame: GPU ms (wall time around submit + wait, see platform.md), CPU ms,
//! draw calls, instances per representation, GPU bytes, bytes fetched, image
//! error against `reference` (multi-scale RMSE) and temporal noise (RMSE to the
//! previous frame minus the reference's own frame-to-frame RMSE).

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{bail, Context, Result};
use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::camera::Camera;
use crate::format::Manifest;
use crate::offscreen::{NamedView, OffscreenScene};
use crate::render::forest::{CullingMode, PoolConfig, RenderSettings, Representations};
use crate::render::refine::RefineConfig;
use crate::render::settings::FarTier;
use crate::render::shadow::ShadowQuality;

pub mod memory;
mod plots;
pub mod stress;
pub mod trace;
pub use plots::write_plots;

/// A keyframe of a camera path (scene-relative metres, degrees).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Keyframe {
    /// Eye, metres from the scene origin (x east, y north, z up).
    pub eye: [f64; 3],
    /// Heading, degrees clockwise from north.
    pub heading_deg: f64,
    /// Pitch, degrees above the horizon.
    pub pitch_deg: f64,
}

/// A custom path file: keyframes (interpolated with smoothstep easing) and the
/// frame count.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PathFile {
    /// At least two keyframes.
    pub keyframes: Vec<Keyframe>,
    /// Frames along the whole path.
    pub frames: Option<usize>,
}

fn camera(k: &Keyframe) -> Camera {
    Camera {
        eye_m: DVec3::from(k.eye),
        heading_rad: k.heading_deg.to_radians(),
        pitch_rad: k.pitch_deg.to_radians(),
        ..Camera::default()
    }
}

fn lerp_key(a: &Keyframe, b: &Keyframe, t: f64) -> Keyframe {
    let s = t * t * (3.0 - 2.0 * t);
    let mut dh = (b.heading_deg - a.heading_deg) % 360.0;
    if dh > 180.0 {
        dh -= 360.0;
    } else if dh < -180.0 {
        dh += 360.0;
    }
    Keyframe {
        eye: std::array::from_fn(|i| a.eye[i] + (b.eye[i] - a.eye[i]) * s),
        heading_deg: a.heading_deg + dh * s,
        pitch_deg: a.pitch_deg + (b.pitch_deg - a.pitch_deg) * s,
    }
}

/// `frames` cameras along `keys` (equal time per segment).
#[must_use]
pub fn interpolate(keys: &[Keyframe], frames: usize) -> Vec<Camera> {
    if keys.len() < 2 || frames < 2 {
        return keys.iter().take(frames.max(1)).map(camera).collect();
    }
    let segments = (keys.len() - 1) as f64;
    (0..frames)
        .map(|f| {
            let u = f as f64 / (frames - 1) as f64 * segments;
            let i = (u.floor() as usize).min(keys.len() - 2);
            camera(&lerp_key(&keys[i], &keys[i + 1], u - i as f64))
        })
        .collect()
}

/// The named camera paths over a scene's bounds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NamedPath {
    /// Overview, descent to eye height, towards a smaller group, turn back.
    Flyover,
    /// 360° sweep high over the scene's centre.
    Far,
    /// 360° sweep 110 m over the forest's centre.
    Medium,
    /// 360° sweep at eye height among the trees.
    Close,
}

/// Keyframes of a named path over `m`; `ground` is the terrain height at the
/// scene's centre when known (else the lowest tree base near it).
#[must_use]
pub fn named_path(path: NamedPath, m: &Manifest, ground: Option<f64>) -> Vec<Keyframe> {
    let key = |c: &Camera| Keyframe {
        eye: c.eye_m.to_array(),
        heading_deg: c.heading_rad.to_degrees(),
        pitch_deg: c.pitch_rad.to_degrees(),
    };
    let sweep = |c: Camera, pitch: f64| -> Vec<Keyframe> {
        (0..=4)
            .map(|k| Keyframe { eye: c.eye_m.to_array(), heading_deg: f64::from(k) * 90.0, pitch_deg: pitch })
            .collect()
    };
    let lo = DVec3::from(m.bounds.min.map(f64::from));
    let hi = DVec3::from(m.bounds.max.map(f64::from));
    let c = (lo + hi) * 0.5;
    let ext = ((hi - lo) * 0.5).truncate().max_element().max(10.0);
    match path {
        // The sweeps turn on the spot over the scene's centre, so every heading
        // looks over trees: high above, a few hundred metres up, at eye height.
        NamedPath::Far | NamedPath::Medium | NamedPath::Close => {
            let ground = ground.unwrap_or(NamedView::Close.camera(m).eye_m.z - 1.7);
            let (height, pitch) = match path {
                NamedPath::Far => (hi.z - ground + 0.45 * ext, -25.0),
                NamedPath::Medium => (110.0, -20.0),
                _ => (1.7, 4.0),
            };
            sweep(Camera { eye_m: DVec3::new(c.x, c.y, ground + height), ..Camera::default() }, pitch)
        }
        NamedPath::Flyover => {
            let far = NamedView::Far.camera(m);
            let ground = ground.unwrap_or(NamedView::Close.camera(m).eye_m.z - 1.7);
            vec![
                key(&far),
                Keyframe { eye: [c.x, c.y - 0.45 * ext, ground + 0.2 * ext], heading_deg: 0.0, pitch_deg: -25.0 },
                Keyframe { eye: [c.x, c.y - 0.1 * ext, ground + 2.0], heading_deg: 0.0, pitch_deg: 2.0 },
                Keyframe { eye: [c.x + 0.1 * ext, c.y + 0.05 * ext, ground + 2.0], heading_deg: 60.0, pitch_deg: 0.0 },
                Keyframe { eye: [c.x + 0.1 * ext, c.y + 0.05 * ext, ground + 6.0], heading_deg: 200.0, pitch_deg: 5.0 },
                Keyframe { eye: [c.x, c.y - 0.5 * ext, ground + 0.3 * ext], heading_deg: 180.0, pitch_deg: -20.0 },
            ]
        }
    }
}

/// One method of the comparison.
#[derive(Debug, Clone)]
pub struct Method {
    /// Name in the outputs.
    pub name: String,
    /// Renderer settings.
    pub settings: RenderSettings,
    /// Supersampling factor per axis (the references: 2, or
    /// `sylva bench --reference-supersample`).
    pub supersample: u32,
    /// The index of the reference this method's error is measured against
    /// (`None`: it is one): the shadowed reference for shadowed methods.
    pub reference: Option<usize>,
    /// Progressive refinement: each frame is the converged image of the
    /// camera at rest (its GPU time the sum over the steps).
    pub refine: Option<RefineConfig>,
}

/// The reference of shadowed methods: every tree a full mesh, and casters too,
/// in four 3072² cascades.
pub const SHADOWED_REFERENCE: &str = "reference-shadows";

/// Quality so high every visible tree is above the full mesh's threshold.
const ALL_FULL_MESH: f32 = crate::render::refine::FULL_MESH_QUALITY;

/// The methods named in `list` (comma-separated; `all` for every one), the
/// references first: `reference` for methods drawn without shadows,
/// [`SHADOWED_REFERENCE`] for those drawn with (`sylva-shadows-low`,
/// `sylva-shadows-high`, or every method when `shadows` is not off).
///
/// # Errors
/// An unknown method name.
pub fn methods(list: &str, shadows: ShadowQuality) -> Result<Vec<Method>> {
    let base = RenderSettings { shadows, ..RenderSettings::default() };
    let full = RenderSettings { quality: ALL_FULL_MESH, representations: Representations::MESHES, ..base };
    let make = |name: &str| -> Result<Method> {
        let m = |settings: RenderSettings, supersample| Method {
            name: name.to_string(),
            settings,
            supersample,
            reference: Some(0),
            refine: None,
        };
        Ok(match name {
            "reference" => m(RenderSettings { shadows: ShadowQuality::Off, full_res_alpha: true, ..full }, 2),
            SHADOWED_REFERENCE => {
                m(RenderSettings { shadows: ShadowQuality::Reference, full_res_alpha: true, ..full }, 2)
            }
            "mesh" => m(RenderSettings { culling: CullingMode::PerTree, ..full }, 1),
            "mesh-plain-alpha" => {
                m(RenderSettings { culling: CullingMode::PerTree, adaptive_alpha: false, ..full }, 1)
            }
            "per-tree" => m(RenderSettings { culling: CullingMode::PerTree, ..base }, 1),
            "billboard" => m(
                RenderSettings {
                    representations: Representations { meshes: true, clusters: false, billboards: true, clouds: false },
                    lod_policy: false,
                    far_tier: FarTier::Billboards,
                    ..base
                },
                1,
            ),
            "impostor" => m(
                RenderSettings {
                    representations: Representations { meshes: true, clusters: false, billboards: true, clouds: false },
                    lod_policy: false,
                    far_tier: FarTier::Impostors,
                    ..base
                },
                1,
            ),
            "ellipsoid" => m(
                RenderSettings {
                    representations: Representations { meshes: true, clusters: true, billboards: false, clouds: false },
                    lod_policy: false,
                    ..base
                },
                1,
            ),
            // Seed 001's pipeline: meshes close, the billboard cloud (with its
            // shader LoD) for every tree below the simplified mesh.
            "billboard-cloud" => m(
                RenderSettings {
                    representations: Representations { meshes: true, clusters: false, billboards: false, clouds: true },
                    lod_policy: false,
                    ..base
                },
                1,
            ),
            "sylva" => m(base, 1),
            "sylva-plain-alpha" => m(RenderSettings { adaptive_alpha: false, ..base }, 1),
            // Trees at every size, no canopy rasters (scenes that have them).
            "sylva-no-canopy" => m(RenderSettings { canopy: false, ..base }, 1),
            "sylva-converged" => Method {
                refine: Some(RefineConfig { enabled: true, ..RefineConfig::default() }),
                ..m(base, 1)
            },
            "sylva-q0.5" => m(RenderSettings { quality: 0.5, ..base }, 1),
            "sylva-q0.25" => m(RenderSettings { quality: 0.25, ..base }, 1),
            "sylva-shadows-low" => m(RenderSettings { shadows: ShadowQuality::Low, ..base }, 1),
            "sylva-shadows-high" => m(RenderSettings { shadows: ShadowQuality::High, ..base }, 1),
            // The light's parts alone or together (issue 49): sylva-light-none
            // is the light before it, sylva-light-sky+aerial two parts.
            other if other.starts_with("sylva-light-") => {
                let parts = other["sylva-light-".len()..].replace('+', ",");
                let light_parts = parts.parse().map_err(|e: String| anyhow::anyhow!("method {other}: {e}"))?;
                m(RenderSettings { light_parts, ..base }, 1)
            }
            other => bail!(
                "unknown method {other:?}: use reference, mesh, mesh-plain-alpha, per-tree, billboard, impostor, billboard-cloud, ellipsoid, sylva, sylva-plain-alpha, \
                 sylva-no-canopy, sylva-converged, sylva-q0.5, sylva-q0.25, sylva-shadows-low, sylva-shadows-high, \
                 sylva-light-PARTS (none, all, or sky, aerial, sky-light, transmission, soft-shadows joined by +) or all"
            ),
        })
    };
    let names: Vec<&str> = if list.trim() == "all" {
        vec![
            "mesh",
            "per-tree",
            "billboard",
            "impostor",
            "billboard-cloud",
            "ellipsoid",
            "sylva",
            "sylva-no-canopy",
            "sylva-converged",
            "sylva-q0.5",
            "sylva-q0.25",
            "sylva-shadows-low",
            "sylva-shadows-high",
        ]
    } else {
        list.split(',').map(str::trim).filter(|s| !s.is_empty()).collect()
    };
    let mut rest: Vec<Method> = Vec::new();
    for n in names {
        if n != "reference" && n != SHADOWED_REFERENCE && !rest.iter().any(|m| m.name == n) {
            rest.push(make(n)?);
        }
    }
    let shadowed = |m: &Method| m.settings.shadows != ShadowQuality::Off;
    let mut out = Vec::new();
    if rest.is_empty() || rest.iter().any(|m| !shadowed(m)) {
        out.push(make("reference")?);
    }
    if rest.iter().any(shadowed) {
        out.push(make(SHADOWED_REFERENCE)?);
    }
    for m in &mut out {
        m.reference = None;
    }
    for mut m in rest {
        let want = if shadowed(&m) { SHADOWED_REFERENCE } else { "reference" };
        m.reference = out.iter().position(|r| r.name == want);
        out.push(m);
    }
    Ok(out)
}

/// One measured frame.
#[derive(Debug, Clone, Default, Serialize)]
pub struct FrameRecord {
    /// Method name.
    pub method: String,
    /// Frame index along the path.
    pub frame: usize,
    /// GPU ms of the cull pass.
    pub cull_ms: f64,
    /// GPU ms of the draw pass.
    pub draw_ms: f64,
    /// GPU ms of the shadow cascades (their cull passes and casters; 0 without shadows).
    pub shadow_ms: f64,
    /// GPU ms, every pass.
    pub gpu_ms: f64,
    /// CPU ms to prepare and record the frame.
    pub cpu_ms: f64,
    /// Draw calls.
    pub draw_calls: u32,
    /// Instances drawn per representation.
    pub instances: BTreeMap<String, u64>,
    /// GPU bytes (pools + packs).
    pub gpu_bytes: u64,
    /// Bytes fetched so far.
    pub bytes_fetched: u64,
    /// Multi-scale RMSE against the reference frame (0–1).
    pub error: f64,
    /// Mean FLIP error against the reference frame (0–1, perceptual; NVIDIA's
    /// FLIP through `nv-flip`, at its default 67 pixels per degree).
    pub flip: f64,
    /// RMSE to this method's previous frame minus the reference's (0–1; NaN on frame 0).
    pub temporal_noise: f64,
}

/// Median and 95th percentile.
#[derive(Debug, Clone, Copy, Default, Serialize, PartialEq)]
pub struct Stat {
    /// Median.
    pub median: f64,
    /// 95th percentile.
    pub p95: f64,
}

impl Stat {
    /// Of the finite values (0, 0 when there are none).
    #[must_use]
    pub fn of(values: impl IntoIterator<Item = f64>) -> Self {
        let mut v: Vec<f64> = values.into_iter().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return Self::default();
        }
        v.sort_by(f64::total_cmp);
        let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
        Self { median: at(0.5), p95: at(0.95) }
    }
}

/// Per-method summary in `summary.json`.
#[derive(Debug, Clone, Default, Serialize)]
pub struct MethodSummary {
    /// GPU ms (cull + draw).
    pub gpu_ms: Stat,
    /// CPU ms.
    pub cpu_ms: Stat,
    /// Multi-scale RMSE against the reference.
    pub error: Stat,
    /// Mean FLIP against the reference.
    pub flip: Stat,
    /// Temporal noise.
    pub temporal_noise: Stat,
    /// Draw calls.
    pub draw_calls: Stat,
}

/// Plain RMSE of two RGBA8 images over RGB (0–1).
#[must_use]
pub fn rmse(a: &[u8], b: &[u8]) -> f64 {
    let mut sum = 0.0;
    let mut n = 0.0;
    for (p, q) in a.chunks_exact(4).zip(b.chunks_exact(4)) {
        for c in 0..3 {
            let d = (f64::from(p[c]) - f64::from(q[c])) / 255.0;
            sum += d * d;
        }
        n += 3.0;
    }
    if n > 0.0 {
        (sum / n).sqrt()
    } else {
        0.0
    }
}

/// Mean FLIP error (0–1) of `test` against `reference`, both sRGB RGBA8
/// `width`×`height` (alpha ignored).
#[must_use]
pub fn flip(reference: &[u8], test: &[u8], width: u32, height: u32) -> f64 {
    let rgb = |img: &[u8]| -> Vec<u8> { img.chunks_exact(4).flat_map(|p| [p[0], p[1], p[2]]).collect() };
    let r = nv_flip::FlipImageRgb8::with_data(width, height, &rgb(reference));
    let t = nv_flip::FlipImageRgb8::with_data(width, height, &rgb(test));
    let map = nv_flip::flip(r, t, nv_flip::DEFAULT_PIXELS_PER_DEGREE);
    f64::from(nv_flip::FlipPool::from_image(&map).mean())
}

/// Box-downsamples an sRGB RGBA8 image by `f` per axis, averaging in linear light.
#[must_use]
pub fn downsample(img: &[u8], width: u32, height: u32, f: u32) -> Vec<u8> {
    if f <= 1 {
        return img.to_vec();
    }
    let to_lin: Vec<f32> = (0..256).map(|v| crate::format::cluster::srgb_to_linear(v as f32 / 255.0)).collect();
    let (w, h) = (width / f, height / f);
    let mut out = vec![0u8; (w * h * 4) as usize];
    let n = (f * f) as f32;
    for y in 0..h {
        for x in 0..w {
            let mut acc = [0.0f32; 4];
            for dy in 0..f {
                for dx in 0..f {
                    let i = (((y * f + dy) * width + x * f + dx) * 4) as usize;
                    for c in 0..3 {
                        acc[c] += to_lin[img[i + c] as usize];
                    }
                    acc[3] += f32::from(img[i + 3]) / 255.0;
                }
            }
            let o = ((y * w + x) * 4) as usize;
            for c in 0..3 {
                out[o + c] = (crate::format::cluster::linear_to_srgb(acc[c] / n) * 255.0).round() as u8;
            }
            out[o + 3] = (acc[3] / n * 255.0).round() as u8;
        }
    }
    out
}

/// Everything a run produced.
pub struct BenchRun {
    /// Every frame of every method.
    pub frames: Vec<FrameRecord>,
    /// Every frame of every method judged against the path-traced reference
    /// (`sylva bench --reference path-traced`; empty without).
    pub traced: Vec<TracedRecord>,
    /// Per method.
    pub summary: BTreeMap<String, MethodSummary>,
    /// The adapter.
    pub adapter: String,
}

/// The path-traced reference (`sylva bench --reference path-traced`): each
/// frame also traced at full detail (issue 48), under the physical light and
/// under the raster's simple light, and every method judged against both.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TracedReference {
    /// Samples per pixel of each traced image.
    pub spp: u32,
    /// Bounces after the first hit (physical light).
    pub bounces: u32,
    /// Trees within this many metres of the eye are traced.
    pub reach_m: f64,
    /// The clear sky's turbidity.
    pub turbidity: f32,
    /// The raster light's parts the trace under the raster's light mirrors.
    pub raster_parts: crate::render::sky_light::LightParts,
}

/// The name of the traced image under the raster's light among the traced
/// records: its `error` is the raster light model's own error.
pub const TRACED_RASTER_LIGHT: &str = "path-traced-raster-light";

/// One method's frame against the path-traced reference.
#[derive(Debug, Clone, Default, Serialize)]
pub struct TracedRecord {
    /// Method name ([`TRACED_RASTER_LIGHT`]: the traced image under the raster's light).
    pub method: String,
    /// Frame index along the path.
    pub frame: usize,
    /// Multi-scale RMSE against the image traced under the physical light:
    /// geometry and light together (0–1).
    pub error: f64,
    /// Mean FLIP against it.
    pub flip: f64,
    /// Multi-scale RMSE against the image traced under the raster's own
    /// light: the geometry's error alone.
    pub geometry_error: f64,
    /// Foliage IoU against the image traced under the raster's light (the
    /// check that both see the same forest; [`crate::metrics::foliage_iou`]).
    pub foliage_iou: f64,
}

/// The path-traced images of one camera: under the physical light and under
/// the raster's (each `width`×`height` sRGB RGBA8).
fn trace_frame(
    ctx: &crate::render::GpuContext,
    tracer: &crate::render::path_trace::PathTracer,
    dir: &Path,
    cam: &Camera,
    lighting: &crate::render::Lighting,
    (width, height): (u32, u32),
    t: &TracedReference,
) -> Result<[Vec<u8>; 2]> {
    use crate::render::path_trace::{to_srgb8, PathOptions, PathView};
    let albedo = PathOptions::default().ground_albedo;
    let (scene, report) = crate::trace::load::load_dir(dir, cam.eye_m, t.reach_m, Some(albedo))
        .map_err(|e| anyhow::anyhow!("the traced reference: {e}"))?;
    let mut out = Vec::new();
    for simple in [false, true] {
        let view = PathView::under_parts(
            lighting,
            cam.eye_m.as_vec3(),
            cam.forward().as_vec3(),
            cam.fov_y_rad,
            t.turbidity,
            if simple { t.raster_parts } else { crate::render::sky_light::LightParts::ALL },
        );
        let options = PathOptions {
            spp: t.spp,
            bounces: t.bounces,
            simple,
            ground_z: (report.terrain_triangles == 0).then_some(report.ground_z),
            ..PathOptions::default()
        };
        let image = tracer
            .render(ctx, &scene, None, &view, (width, height), &options, &mut |_| {})
            .map_err(|e| anyhow::anyhow!("the traced reference: {e}"))?;
        out.push(to_srgb8(&image));
    }
    let raster = out.pop().unwrap_or_default();
    let physical = out.pop().unwrap_or_default();
    Ok([physical, raster])
}

/// Runs `methods` over `cameras` on `scene` at `width`×`height`. `progress(method,
/// frame, frames)` is called per frame. With `frames_dir`, each method's frames
/// are written there as `NNN-method.png`, and per frame a strip of all of them
/// side by side in the methods' order (`NNN-strip.png`, the reference first).
/// With `traced`, each frame is also path traced under both lights and every
/// method judged against the two images ([`BenchRun::traced`]; with
/// `frames_dir` they are written too, the physical one first in the strip).
///
/// # Errors
/// A scene that does not open, no GPU adapter, or a frame that cannot be
/// written; with `traced`, a scene that is not a directory.
#[allow(clippy::too_many_arguments)]
pub fn run(
    scene: &str,
    cameras: &[Camera],
    methods: &[Method],
    width: u32,
    height: u32,
    frames_dir: Option<&Path>,
    traced: Option<TracedReference>,
    progress: &mut dyn FnMut(&str, usize, usize),
) -> Result<BenchRun> {
    let trace_dir = match traced {
        Some(_) => {
            let dir = Path::new(scene);
            let dir = if dir.is_file() { dir.parent().unwrap_or(dir) } else { dir };
            if !dir.join("scene.json").is_file() {
                bail!("--reference path-traced reads a scene directory (or its scene.json), not {scene}");
            }
            Some(dir.to_path_buf())
        }
        None => None,
    };
    if methods.first().is_none_or(|m| m.reference.is_some())
        || methods.iter().any(|m| m.reference.is_some_and(|r| methods.get(r).is_none_or(|r| r.reference.is_some())))
    {
        bail!("the references must come first and every method name one (bench::methods does)");
    }
    // Every method has its own scene and device, and the methods take turns frame
    // by frame: anything else running on the machine then slows them alike.
    let mut scenes = Vec::with_capacity(methods.len());
    for method in methods {
        let ss = method.supersample.max(1);
        let mut off = OffscreenScene::open(scene, width * ss, height * ss, PoolConfig::default())
            .with_context(|| format!("opening {scene}"))?;
        off.settings = method.settings;
        scenes.push(off);
    }
    let adapter = scenes.first().map(|s| s.ctx.adapter_summary()).unwrap_or_default();
    let tracer = traced.and(scenes.first()).map(|s| crate::render::path_trace::PathTracer::new(&s.ctx.device));
    let mut traced_records = Vec::new();
    let mut frames = Vec::new();
    let mut prev: Vec<Option<Vec<u8>>> = vec![None; methods.len()];
    for (i, cam) in cameras.iter().enumerate() {
        // Each reference's image of this frame and its own change since the last.
        let mut reference: Vec<Option<Vec<u8>>> = vec![None; methods.len()];
        let mut ref_motion = vec![f64::NAN; methods.len()];
        let mut strip: Vec<Vec<u8>> = Vec::new();
        // Each method's image of this frame, for the traced reference.
        let mut images: Vec<Vec<u8>> = Vec::new();
        for (k, (method, off)) in methods.iter().zip(scenes.iter_mut()).enumerate() {
            progress(&method.name, i, cameras.len());
            let ss = method.supersample.max(1);
            off.load_view(cam, 120.0);
            // One unmeasured frame settles LoD-dependent loads (packs) and pipelines.
            off.render(cam, false);
            let s = match method.refine {
                Some(config) => {
                    let (mut s, total) = off.render_converged(cam, config, 8 * config.total_steps(), 600.0);
                    if !s.refine_converged {
                        eprintln!("warning: {} frame {i} did not converge (step {})", method.name, s.refine_step);
                    }
                    s.gpu_ms = total;
                    s
                }
                None => off.render(cam, true),
            };
            if method.reference.is_none() && s.items_dropped + s.shadow_items_dropped > 0 {
                eprintln!(
                    "warning: {} frame {i} lost {} trees and {} shadow casters to full segments: \
                     its image lacks them (a smaller scene or view keeps the reference whole)",
                    method.name, s.items_dropped, s.shadow_items_dropped
                );
            }
            let img = downsample(&off.read_image(), width * ss, height * ss, ss);
            let cull = s.gpu_ms.get("cull").copied().unwrap_or(0.0);
            let draw = s.gpu_ms.get("draw").copied().unwrap_or(0.0);
            let shadow = s.gpu_ms.get("shadow").copied().unwrap_or(0.0);
            let mut rec = FrameRecord {
                method: method.name.clone(),
                frame: i,
                cull_ms: cull,
                draw_ms: draw,
                shadow_ms: shadow,
                gpu_ms: cull + draw + shadow,
                cpu_ms: s.frame_cpu_ms,
                draw_calls: s.draw_calls,
                instances: s.instances.clone(),
                gpu_bytes: s.gpu_bytes,
                bytes_fetched: s.bytes_fetched,
                error: 0.0,
                flip: 0.0,
                temporal_noise: f64::NAN,
            };
            match method.reference {
                None => {
                    // A reference (methods() puts them first).
                    if let Some(p) = &prev[k] {
                        ref_motion[k] = rmse(&img, p);
                    }
                    reference[k] = Some(img.clone());
                }
                Some(r) => {
                    if let Some(r) = &reference[r] {
                        rec.error = crate::metrics::multiscale_rmse(&img, r, width, height);
                        rec.flip = flip(r, &img, width, height);
                    }
                }
            }
            if let Some(p) = &prev[k] {
                // The reference's own change is the baseline: 0 for itself.
                rec.temporal_noise = match method.reference {
                    None => 0.0,
                    Some(r) => rmse(&img, p) - ref_motion[r],
                };
            }
            if let Some(dir) = frames_dir {
                let path = dir.join(format!("{i:03}-{}.png", method.name));
                image::save_buffer(&path, &img, width, height, image::ColorType::Rgba8)
                    .with_context(|| format!("cannot write {}", path.display()))?;
                strip.push(img.clone());
            }
            if traced.is_some() {
                images.push(img.clone());
            }
            prev[k] = Some(img);
            frames.push(rec);
        }
        if let (Some(t), Some(tracer), Some(dir), Some(first)) = (traced, &tracer, &trace_dir, scenes.first()) {
            progress("path-traced", i, cameras.len());
            let [physical, raster_light] =
                trace_frame(&first.ctx, tracer, dir, cam, &methods[0].settings.lighting, (width, height), &t)?;
            let judge = |name: &str, img: &[u8]| TracedRecord {
                method: name.to_string(),
                frame: i,
                error: crate::metrics::multiscale_rmse(img, &physical, width, height),
                flip: flip(&physical, img, width, height),
                geometry_error: crate::metrics::multiscale_rmse(img, &raster_light, width, height),
                foliage_iou: crate::metrics::foliage_iou(img, &raster_light).0,
            };
            for (method, img) in methods.iter().zip(&images) {
                traced_records.push(judge(&method.name, img));
            }
            traced_records.push(judge(TRACED_RASTER_LIGHT, &raster_light));
            if let Some(dir) = frames_dir {
                for (name, img) in [("path-traced", &physical), (TRACED_RASTER_LIGHT, &raster_light)] {
                    let path = dir.join(format!("{i:03}-{name}.png"));
                    image::save_buffer(&path, img, width, height, image::ColorType::Rgba8)
                        .with_context(|| format!("cannot write {}", path.display()))?;
                }
                strip.insert(0, physical);
            }
        }
        if let Some(dir) = frames_dir {
            let path = dir.join(format!("{i:03}-strip.png"));
            let n = strip.len() as u32;
            let mut side = vec![0u8; (width * n * height * 4) as usize];
            for (k, img) in strip.iter().enumerate() {
                for y in 0..height as usize {
                    let row = width as usize * 4;
                    let at = (y * n as usize + k) * row;
                    side[at..at + row].copy_from_slice(&img[y * row..(y + 1) * row]);
                }
            }
            image::save_buffer(&path, &side, width * n, height, image::ColorType::Rgba8)
                .with_context(|| format!("cannot write {}", path.display()))?;
        }
    }
    // Grouped by method, in path order.
    frames.sort_by_key(|r| (methods.iter().position(|m| m.name == r.method), r.frame));
    let names: Vec<String> = methods.iter().map(|m| m.name.clone()).collect();
    let summary = summarise(&frames, &names);
    Ok(BenchRun { frames, traced: traced_records, summary, adapter })
}

/// One method against the path-traced reference, over the frames.
#[derive(Debug, Clone, Serialize)]
pub struct TracedSummary {
    /// Against the image traced under the physical light.
    pub error: Stat,
    /// Mean FLIP against it.
    pub flip: Stat,
    /// Against the image traced under the raster's light (geometry alone).
    pub geometry_error: Stat,
    /// `error` − `geometry_error` per frame: what the raster's light adds.
    pub light_error: Stat,
    /// Foliage IoU against the image traced under the raster's light.
    pub foliage_iou: Stat,
}

/// Per-method medians and p95s of `records` (in first-seen order of methods).
#[must_use]
pub fn summarise_traced(records: &[TracedRecord]) -> Vec<(String, TracedSummary)> {
    let mut names: Vec<&str> = Vec::new();
    for r in records {
        if !names.contains(&r.method.as_str()) {
            names.push(&r.method);
        }
    }
    names
        .into_iter()
        .map(|name| {
            let f: Vec<&TracedRecord> = records.iter().filter(|r| r.method == name).collect();
            let summary = TracedSummary {
                error: Stat::of(f.iter().map(|r| r.error)),
                flip: Stat::of(f.iter().map(|r| r.flip)),
                geometry_error: Stat::of(f.iter().map(|r| r.geometry_error)),
                light_error: Stat::of(f.iter().map(|r| r.error - r.geometry_error)),
                foliage_iou: Stat::of(f.iter().map(|r| r.foliage_iou)),
            };
            (name.to_string(), summary)
        })
        .collect()
}

/// Writes `traced.csv`: one row per method and frame against the traced reference.
///
/// # Errors
/// The file cannot be written.
pub fn write_traced_csv(dir: &Path, records: &[TracedRecord]) -> Result<()> {
    let mut csv = String::from("method,frame,error,flip,geometry_error,light_error,foliage_iou\n");
    for r in records {
        csv.push_str(&format!(
            "{},{},{:.6},{:.6},{:.6},{:.6},{:.4}\n",
            r.method,
            r.frame,
            r.error,
            r.flip,
            r.geometry_error,
            r.error - r.geometry_error,
            r.foliage_iou
        ));
    }
    let path = dir.join("traced.csv");
    std::fs::write(&path, csv).with_context(|| format!("cannot write {}", path.display()))
}

/// Per-method medians and p95s of `frames`.
#[must_use]
pub fn summarise(frames: &[FrameRecord], names: &[String]) -> BTreeMap<String, MethodSummary> {
    let mut summary = BTreeMap::new();
    for name in names {
        let f: Vec<&FrameRecord> = frames.iter().filter(|r| &r.method == name).collect();
        summary.insert(
            name.clone(),
            MethodSummary {
                gpu_ms: Stat::of(f.iter().map(|r| r.gpu_ms)),
                cpu_ms: Stat::of(f.iter().map(|r| r.cpu_ms)),
                error: Stat::of(f.iter().map(|r| r.error)),
                flip: Stat::of(f.iter().map(|r| r.flip)),
                temporal_noise: Stat::of(f.iter().map(|r| r.temporal_noise)),
                draw_calls: Stat::of(f.iter().map(|r| f64::from(r.draw_calls))),
            },
        );
    }
    summary
}

/// Reads a `frames.csv` written by [`write_csv`] (to re-plot a run).
///
/// # Errors
/// I/O errors or a malformed file (the line is named).
pub fn read_csv(path: &Path) -> Result<Vec<FrameRecord>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let bad = || anyhow::anyhow!("{} line {}: not a frames.csv row", path.display(), n + 1);
        // 15 columns: written before the FLIP column was added; 16 before
        // shadow_ms; 17 before cloud.
        let has_flip = match f.len() {
            16..=18 => true,
            15 => false,
            _ => return Err(bad()),
        };
        let tn = if has_flip { 15 } else { 14 };
        let num = |i: usize| -> Result<f64> { f[i].parse::<f64>().map_err(|_| bad()) };
        let int = |i: usize| -> Result<u64> { f[i].parse::<u64>().map_err(|_| bad()) };
        let shadow_ms = if f.len() >= 17 { num(16)? } else { 0.0 };
        let mut instances = ["mesh0", "mesh1", "ellipsoid", "billboard"]
            .iter()
            .enumerate()
            .map(|(k, name)| Ok((name.to_string(), int(7 + k)?)))
            .collect::<Result<BTreeMap<_, _>>>()?;
        if f.len() == 18 {
            instances.insert("cloud".to_string(), int(17)?);
        }
        out.push(FrameRecord {
            method: f[0].to_string(),
            frame: int(1)? as usize,
            gpu_ms: num(2)?,
            cull_ms: num(3)?,
            draw_ms: num(4)?,
            shadow_ms,
            cpu_ms: num(5)?,
            draw_calls: int(6)? as u32,
            instances,
            gpu_bytes: int(11)?,
            bytes_fetched: int(12)?,
            error: num(13)?,
            flip: if has_flip { num(14)? } else { f64::NAN },
            temporal_noise: if f[tn].is_empty() { f64::NAN } else { num(tn)? },
        });
    }
    Ok(out)
}

/// Writes `frames.csv` into `dir`.
///
/// # Errors
/// I/O errors.
pub fn write_csv(dir: &Path, frames: &[FrameRecord]) -> Result<()> {
    use std::fmt::Write as _;
    let reprs = ["mesh0", "mesh1", "ellipsoid", "billboard"];
    let mut s = String::from(
        "method,frame,gpu_ms,cull_ms,draw_ms,cpu_ms,draw_calls,mesh0,mesh1,ellipsoid,billboard,gpu_bytes,bytes_fetched,error,flip,temporal_noise,shadow_ms,cloud\n",
    );
    for r in frames {
        let inst: Vec<String> = reprs.iter().map(|k| r.instances.get(*k).copied().unwrap_or(0).to_string()).collect();
        let tn = if r.temporal_noise.is_finite() { format!("{:.6}", r.temporal_noise) } else { String::new() };
        writeln!(
            s,
            "{},{},{:.3},{:.3},{:.3},{:.4},{},{},{},{},{:.6},{:.6},{},{:.3},{}",
            r.method,
            r.frame,
            r.gpu_ms,
            r.cull_ms,
            r.draw_ms,
            r.cpu_ms,
            r.draw_calls,
            inst.join(","),
            r.gpu_bytes,
            r.bytes_fetched,
            r.error,
            r.flip,
            tn,
            r.shadow_ms,
            r.instances.get("cloud").copied().unwrap_or(0)
        )?;
    }
    std::fs::write(dir.join("frames.csv"), s).with_context(|| format!("writing {}", dir.join("frames.csv").display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_interpolate_through_their_keyframes() {
        let keys = [
            Keyframe { eye: [0.0, 0.0, 10.0], heading_deg: 350.0, pitch_deg: 0.0 },
            Keyframe { eye: [100.0, 0.0, 10.0], heading_deg: 10.0, pitch_deg: -10.0 },
        ];
        let cams = interpolate(&keys, 11);
        assert_eq!(cams.len(), 11);
        assert_eq!(cams[0].eye_m, DVec3::new(0.0, 0.0, 10.0));
        assert!((cams[10].eye_m.x - 100.0).abs() < 1e-9);
        // The heading turns the short way (350° → 10° through 0°).
        let mid = cams[5].heading_rad.to_degrees().rem_euclid(360.0);
        assert!(!(20.0..340.0).contains(&mid), "{mid}");
    }

    #[test]
    fn methods_parse_with_the_reference_first() {
        let m = methods("sylva,mesh", ShadowQuality::Off).unwrap();
        assert_eq!(m.iter().map(|m| m.name.as_str()).collect::<Vec<_>>(), ["reference", "sylva", "mesh"]);
        assert_eq!(m[0].supersample, 2);
        assert!(m[1..].iter().all(|m| m.reference == Some(0)));
        // Shadowed methods are measured against the shadowed reference.
        let all = methods("all", ShadowQuality::Off).unwrap();
        assert_eq!(all.len(), 15);
        // Only sylva-converged refines; the plain-alpha comparisons parse.
        let refined: Vec<&str> = all.iter().filter(|m| m.refine.is_some()).map(|m| m.name.as_str()).collect();
        assert_eq!(refined, ["sylva-converged"]);
        let plain = methods("mesh-plain-alpha,sylva-plain-alpha", ShadowQuality::Off).unwrap();
        assert!(plain[1..].iter().all(|m| !m.settings.adaptive_alpha));
        assert!(all.iter().all(|m| m.settings.adaptive_alpha));
        // The references see far crowns whole; the far tiers are told apart.
        assert!(all[..2].iter().all(|m| m.settings.full_res_alpha));
        assert!(all[2..].iter().all(|m| !m.settings.full_res_alpha));
        let tier = |n: &str| all.iter().find(|m| m.name == n).unwrap().settings.far_tier;
        assert_eq!((tier("billboard"), tier("impostor")), (FarTier::Billboards, FarTier::Impostors));
        assert_eq!((all[0].name.as_str(), all[1].name.as_str()), ("reference", SHADOWED_REFERENCE));
        let high = all.iter().find(|m| m.name == "sylva-shadows-high").unwrap();
        assert_eq!((high.reference, high.settings.shadows), (Some(1), ShadowQuality::High));
        assert_eq!(all.iter().find(|m| m.name == "sylva").unwrap().reference, Some(0));
        // --shadows low: every method shadowed, one (shadowed) reference.
        let low = methods("sylva,billboard", ShadowQuality::Low).unwrap();
        assert_eq!(low.iter().map(|m| m.name.as_str()).collect::<Vec<_>>(), [SHADOWED_REFERENCE, "sylva", "billboard"]);
        assert!(low[1..].iter().all(|m| m.reference == Some(0) && m.settings.shadows == ShadowQuality::Low));
        assert!(format!("{:#}", methods("fast", ShadowQuality::Off).unwrap_err()).contains("unknown method \"fast\""));
    }

    #[test]
    fn stats_and_downsampling() {
        let s = Stat::of([5.0, 1.0, 3.0, f64::NAN, 2.0, 4.0]);
        assert_eq!(s, Stat { median: 3.0, p95: 5.0 });
        // 2×2 of black and white → one grey pixel, averaged in linear light.
        let img = [0, 0, 0, 255, 255, 255, 255, 255, 0, 0, 0, 255, 255, 255, 255, 255];
        let d = downsample(&img, 2, 2, 2);
        assert_eq!(d.len(), 4);
        assert!((186..=189).contains(&d[0]), "linear mid-grey in sRGB: {}", d[0]);
        assert_eq!(rmse(&img, &img), 0.0);
    }

    #[test]
    fn flip_is_zero_for_equal_images_and_grows_with_the_difference() {
        let (w, h) = (32u32, 32u32);
        let a: Vec<u8> = (0..w * h).flat_map(|i| [(i * 7 % 256) as u8, 120, 60, 255]).collect();
        let mut b = a.clone();
        let mut c = a.clone();
        for p in b.chunks_exact_mut(4).take(64) {
            p[1] = 200;
        }
        for p in c.chunks_exact_mut(4).take(512) {
            p[1] = 200;
        }
        assert!(flip(&a, &a, w, h) < 1e-6);
        let (fb, fc) = (flip(&a, &b, w, h), flip(&a, &c, w, h));
        assert!(fb > 0.0 && fc > 2.0 * fb, "{fb} {fc}");
    }
}
