//! The browser's path tracer (issue 48): `setRenderer('path-trace')` traces
//! the view at full detail with the native tracer's pass
//! ([`crate::render::path_trace`], one code path): the trees within reach of
//! the eye and the terrain under them are fetched and built into the two
//! levels ([`crate::trace::load::load_with`], the files of each phase
//! together), then every animation frame while the camera rests adds a sample
//! a pixel until the page's count is reached (the viewer idles then); a move
//! starts the image over, and one far from where the scene was loaded loads
//! it again (the raster view is drawn meanwhile).

use std::cell::{Cell, RefCell};
use std::collections::HashMap;
use std::rc::Rc;

use glam::{DVec3, Vec3};
use wasm_bindgen::prelude::*;
use wasm_bindgen_futures::JsFuture;

use crate::camera::Camera;
use crate::render::path_trace::{path_params, PathDisplay, PathOptions, PathScene, PathTracer, PathView};
use crate::render::Lighting;
use crate::trace::load::{load_with, LoadReport, SceneFiles};
use crate::trace::scene::TraceScene;

/// What a page asks of the tracer (`setRenderer('path-trace', {…})`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct PhotoSettings {
    /// Samples per pixel, then the viewer idles.
    pub spp: u32,
    /// Trees within this many metres of the eye are traced.
    pub reach_m: f64,
    /// Bounces after the first hit.
    pub bounces: u32,
    /// The raster's simple light instead of the physical one.
    pub simple: bool,
    /// The clear sky's turbidity.
    pub turbidity: f32,
}

type Job = Rc<RefCell<Option<Result<(TraceScene, LoadReport), String>>>>;

// (One per viewer: the variants' sizes do not matter.)
#[allow(clippy::large_enum_variant)]
enum State {
    Loading(Job),
    Ready {
        /// The scene until it is on the GPU (then only there).
        traced: Option<TraceScene>,
        report: LoadReport,
        scene: Option<PathScene>,
        /// The camera and light the accumulation is of.
        drawn: Option<(Camera, Lighting, u32)>,
    },
    Failed(String),
}

/// The path-traced view: its settings, the scene for it and the image.
pub(super) struct Photo {
    pub settings: PhotoSettings,
    /// The eye the scene was loaded for (scene frame): instances are placed around it.
    eye: DVec3,
    state: State,
    /// Fetch rounds, bytes of the load and the last pass's ms (the one that
    /// decodes the packs and builds both levels), for `photo_json`.
    fetched: Rc<RefCell<(u32, u64, f64)>>,
    /// Set when this view is dropped: its load stops at its next step.
    cancelled: Rc<Cell<bool>>,
    /// The viewer's count of loads started, this one's (for `photo_json`).
    pub load: u32,
    /// Times the image started over (a move, a new light or settings).
    restarts: u32,
    /// When the load began (`Date.now()`, ms), and how long it took to the scene built.
    started_ms: f64,
    load_ms: f64,
}

impl Drop for Photo {
    fn drop(&mut self) {
        // A superseded load (the renderer switched back, the eye moved on)
        // fetches and builds nothing more.
        self.cancelled.set(true);
    }
}

/// The pipelines, made once a viewer first traces.
pub(super) struct PhotoPipelines {
    tracer: PathTracer,
    display: PathDisplay,
}

impl PhotoPipelines {
    pub fn new(device: &wgpu::Device, format: wgpu::TextureFormat) -> Self {
        Self { tracer: PathTracer::new(device), display: PathDisplay::new(device, format) }
    }
}

/// The ground's albedo under the traced trees (as natively).
fn ground_albedo() -> Vec3 {
    PathOptions::default().ground_albedo
}

impl Photo {
    /// Starts loading the scene at `scene_url` for a view from `eye` (the
    /// viewer's `load`-th load).
    pub fn start(scene_url: &str, eye: DVec3, settings: PhotoSettings, load_number: u32) -> Self {
        let job: Job = Rc::default();
        let fetched: Rc<RefCell<(u32, u64, f64)>> = Rc::default();
        let cancelled: Rc<Cell<bool>> = Rc::default();
        let (base, manifest_url) = crate::scene::fetch::scene_locations(scene_url);
        let (cell, counts, stop) = (job.clone(), fetched.clone(), cancelled.clone());
        wasm_bindgen_futures::spawn_local(async move {
            let result = load(base, manifest_url, eye, settings.reach_m, counts, stop).await;
            *cell.borrow_mut() = Some(result);
        });
        Self {
            settings,
            eye,
            state: State::Loading(job),
            fetched,
            cancelled,
            load: load_number,
            restarts: 0,
            started_ms: js_sys::Date::now(),
            load_ms: 0.0,
        }
    }

    /// Whether its load failed (or its upload): setting the renderer again
    /// loads anew.
    pub fn failed(&self) -> bool {
        matches!(self.state, State::Failed(_))
    }

    /// New settings for the same scene: the image starts over.
    pub fn set(&mut self, settings: PhotoSettings) {
        self.settings = settings;
        if let State::Ready { drawn, scene, .. } = &mut self.state {
            // (Cleared at the next frame: until then nothing counts as done.)
            *drawn = None;
            if let Some(s) = scene.as_mut() {
                s.samples = 0;
            }
        }
    }

    /// Whether the eye went so far from where the scene was loaded that its
    /// trees no longer surround it (a quarter of the reach).
    pub fn stale(&self, eye: DVec3) -> bool {
        (eye - self.eye).truncate().length() > 0.25 * self.settings.reach_m
    }

    /// Whether more frames would change the image: loading, or samples to add.
    pub fn wants_frames(&self) -> bool {
        match &self.state {
            State::Loading(_) => true,
            State::Ready { scene, .. } => scene.as_ref().is_none_or(|s| s.samples < self.settings.spp),
            State::Failed(_) => false,
        }
    }

    /// Takes a finished load; the error of a failed one (once).
    pub fn poll(&mut self) -> Option<String> {
        let State::Loading(job) = &self.state else { return None };
        let done = job.borrow_mut().take()?;
        self.load_ms = js_sys::Date::now() - self.started_ms;
        match done {
            Ok((traced, report)) => {
                self.state = State::Ready { traced: Some(traced), report, scene: None, drawn: None };
                None
            }
            Err(e) => {
                let message = format!("path-trace: {e}");
                self.state = State::Failed(message.clone());
                Some(message)
            }
        }
    }

    /// Records the next sample of `camera`'s view under `lighting` and its
    /// display on `target` (`size`) — the display alone once the image is
    /// complete —, or `None` while the scene loads. The raster light traced
    /// (`simple`) mirrors the viewer's light `parts`.
    ///
    /// # Errors
    /// The scene larger than the device binds (then the raster view stays).
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &mut self,
        pipes: &PhotoPipelines,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        camera: &Camera,
        lighting: &Lighting,
        parts: crate::render::sky_light::LightParts,
        size: (u32, u32),
        target: &wgpu::TextureView,
    ) -> Result<Option<wgpu::CommandBuffer>, String> {
        let settings = self.settings;
        let eye = self.eye;
        let State::Ready { traced, report, scene, drawn } = &mut self.state else { return Ok(None) };
        if scene.as_ref().is_none_or(|s| s.size() != size) {
            let made = match scene.as_mut() {
                Some(s) => pipes.tracer.resize(device, s, size),
                None => match traced.take() {
                    Some(t) => pipes.tracer.upload(device, &t, None, size).map(|s| *scene = Some(s)),
                    None => Err("the scene was lost before it was uploaded".to_string()),
                },
            };
            match made {
                Ok(()) => {}
                Err(e) => {
                    let message = format!("path-trace: {e}");
                    self.state = State::Failed(message.clone());
                    return Err(message);
                }
            }
            *drawn = None;
        }
        let Some(scene) = scene.as_mut() else { return Ok(None) };
        let mut encoder = device.create_command_encoder(&Default::default());
        let now = (*camera, *lighting, parts.0);
        if drawn.as_ref() != Some(&now) {
            scene.restart(&mut encoder);
            *drawn = Some(now);
            self.restarts += 1;
        } else if scene.samples >= settings.spp {
            // Complete: shown again (a canvas texture taken and not drawn shows black).
            pipes.display.draw(device, queue, &mut encoder, scene, target);
            return Ok(Some(encoder.finish()));
        }
        let view = PathView::under_parts(
            lighting,
            camera.eye_m.as_vec3(),
            camera.forward().as_vec3(),
            camera.fov_y_rad,
            settings.turbidity,
            if settings.simple { parts } else { crate::render::sky_light::LightParts::ALL },
        );
        let options = PathOptions {
            spp: settings.spp,
            bounces: settings.bounces,
            simple: settings.simple,
            ground_z: (report.terrain_triangles == 0).then_some(report.ground_z),
            ground_albedo: ground_albedo(),
            ..PathOptions::default()
        };
        let params = path_params(&view, &options, size, eye.as_vec3());
        pipes.tracer.dispatch(queue, &mut encoder, scene, &params, 0, 1);
        pipes.display.draw(device, queue, &mut encoder, scene, target);
        Ok(Some(encoder.finish()))
    }

    /// `{state, samples, spp, reach_m, load, restarts, fetch_rounds,
    /// bytes_loaded, load_ms, build_ms}` (`load`: the viewer's count of loads started,
    /// this one's; `bytes_loaded`: the files as loaded, packs inflated;
    /// `load_ms`: from the start to the scene built, 0 until then;
    /// `build_ms`: the last pass over the files, which decodes the packs and
    /// builds the species' BVHs; the top level is built on the GPU) and,
    /// ready, `trees, trees_in_scene, instanced_triangles,
    /// terrain_triangles, gpu_bytes`; failed, `error`.
    pub fn json(&self) -> String {
        let (rounds, bytes, build_ms) = *self.fetched.borrow();
        let (state, samples, more) = match &self.state {
            State::Loading(_) => ("loading", 0, String::new()),
            State::Ready { report: r, scene, .. } => (
                "ready",
                scene.as_ref().map_or(0, |s| s.samples),
                format!(
                    r#","trees":{},"trees_in_scene":{},"instanced_triangles":{},"terrain_triangles":{},"gpu_bytes":{}"#,
                    r.trees,
                    r.trees_in_scene,
                    r.instanced_triangles,
                    r.terrain_triangles,
                    scene.as_ref().map_or(r.bytes, |s| s.bytes)
                ),
            ),
            State::Failed(e) => ("failed", 0, format!(r#","error":{}"#, serde_json::Value::from(e.as_str()))),
        };
        format!(
            r#"{{"state":"{state}","samples":{samples},"spp":{},"reach_m":{},"load":{},"restarts":{},"fetch_rounds":{rounds},"bytes_loaded":{bytes},"load_ms":{:.0},"build_ms":{build_ms:.0}{more}}}"#,
            self.settings.spp, self.settings.reach_m, self.load, self.restarts, self.load_ms
        )
    }

    /// Whether the traced image is what the view shows (the scene is loaded).
    pub fn ready(&self) -> bool {
        matches!(self.state, State::Ready { .. })
    }
}

/// The files fetched so far, and those a load asked for that are not.
struct BrowserFiles {
    files: HashMap<String, Vec<u8>>,
    packs: HashMap<String, Vec<u8>>,
    /// Files whose fetch failed, and why (a load decides what that means:
    /// a ground image missing leaves the plain ground, a tile fails the load).
    failed: HashMap<(String, bool), String>,
    /// (path, whether a pack).
    wanted: Vec<(String, bool)>,
}

impl BrowserFiles {
    fn get(&mut self, rel: &str, pack: bool) -> Result<Option<Vec<u8>>, String> {
        let held = if pack { &self.packs } else { &self.files };
        if let Some(b) = held.get(rel) {
            return Ok(Some(b.clone()));
        }
        if let Some(e) = self.failed.get(&(rel.to_string(), pack)) {
            return Err(e.clone());
        }
        if !self.wanted.iter().any(|(w, p)| w == rel && *p == pack) {
            self.wanted.push((rel.to_string(), pack));
        }
        Ok(None)
    }
}

impl SceneFiles for BrowserFiles {
    fn file(&mut self, rel: &str) -> Result<Option<Vec<u8>>, String> {
        self.get(rel, false)
    }

    fn pack(&mut self, rel: &str) -> Result<Option<Vec<u8>>, String> {
        self.get(rel, true)
    }
}

/// Most fetch rounds a load takes (the index's levels + the terrain's + 2 is far less).
const MAX_ROUNDS: u32 = 64;

/// Most bytes a load holds (files as loaded, packs inflated): wasm's memory
/// ends at 4 GB, and the load's images and arrays come after.
const MAX_LOAD_BYTES: u64 = 1 << 30;

/// Loads the view's scene: [`load_with`] again after each round of fetches.
async fn load(
    base: String,
    manifest_url: String,
    eye: DVec3,
    reach_m: f64,
    counts: Rc<RefCell<(u32, u64, f64)>>,
    cancelled: Rc<Cell<bool>>,
) -> Result<(TraceScene, LoadReport), String> {
    let mut files =
        BrowserFiles { files: HashMap::new(), packs: HashMap::new(), failed: HashMap::new(), wanted: Vec::new() };
    let mut held = 0u64;
    for _ in 0..MAX_ROUNDS {
        if cancelled.get() {
            return Err("superseded".into());
        }
        let t = js_sys::Date::now();
        let done = load_with(&mut files, eye, reach_m, Some(ground_albedo()))?;
        counts.borrow_mut().2 = js_sys::Date::now() - t;
        if let Some(done) = done {
            return Ok(done);
        }
        let wanted = std::mem::take(&mut files.wanted);
        if wanted.is_empty() {
            return Err("the scene's files were asked for and not used".into());
        }
        // The round's files together.
        let promises = js_sys::Array::new();
        for (rel, pack) in &wanted {
            let url = if rel == "scene.json" { manifest_url.clone() } else { crate::scene::fetch::join(&base, rel) };
            let pack = *pack;
            promises.push(&wasm_bindgen_futures::future_to_promise(async move {
                // (A failure resolves to its message: the load decides what it means.)
                let bytes = match super::fetch::fetch_bytes(&url, None).await {
                    Ok(b) if b.len() as u64 > crate::paths::MAX_SCENE_FILE_BYTES => {
                        return Ok(JsValue::from_str(&format!(
                            "{url}: {} bytes, more than a scene file may hold ({})",
                            b.len(),
                            crate::paths::MAX_SCENE_FILE_BYTES
                        )))
                    }
                    Ok(b) => b,
                    Err(e) => return Ok(JsValue::from_str(&e.to_string())),
                };
                let bytes = if pack {
                    match inflate_pack(&url, bytes).await {
                        Ok(b) => b,
                        Err(e) => return Ok(JsValue::from_str(&e)),
                    }
                } else {
                    bytes
                };
                Ok(js_sys::Uint8Array::from(&bytes[..]).into())
            }));
        }
        let all = JsFuture::from(js_sys::Promise::all(&promises))
            .await
            .map_err(|e| e.as_string().unwrap_or_else(|| format!("{e:?}")))?;
        let all: js_sys::Array = all.into();
        if cancelled.get() {
            return Err("superseded".into());
        }
        let mut c = counts.borrow_mut();
        c.0 += 1;
        for ((rel, pack), got) in wanted.into_iter().zip(all.iter()) {
            if let Some(message) = got.as_string() {
                files.failed.insert((rel, pack), message);
                continue;
            }
            let bytes = js_sys::Uint8Array::new(&got).to_vec();
            c.1 += bytes.len() as u64;
            held += bytes.len() as u64;
            if held > MAX_LOAD_BYTES {
                return Err(format!(
                    "the view's files take more than {} MB within {reach_m} m: trace a shorter reach",
                    MAX_LOAD_BYTES >> 20
                ));
            }
            if pack {
                files.packs.insert(rel, bytes);
            } else {
                files.files.insert(rel, bytes);
            }
        }
    }
    Err(format!("the scene's files took more than {MAX_ROUNDS} rounds of fetches"))
}

/// A whole pack with its stored parts inflated by the browser.
async fn inflate_pack(url: &str, file: Vec<u8>) -> Result<Vec<u8>, String> {
    let head = crate::format::pack::PackHead::decode(url, &file).map_err(|e| e.to_string())?;
    let mut parts = Vec::with_capacity(head.stored.len());
    for b in &head.stored {
        let (lo, hi) = b.stored;
        if lo > hi || hi > file.len() as u64 {
            return Err(format!("{url}: a stored part at bytes {lo}..{hi} lies outside its {} bytes", file.len()));
        }
        let len = b.logical.1.saturating_sub(b.logical.0);
        parts.push(
            super::fetch::inflate_in_browser(url, &file[lo as usize..hi as usize], len)
                .await
                .map_err(|e| e.to_string())?,
        );
    }
    let mut parts = parts.into_iter();
    crate::format::stored::unstore_with(url, file, &mut |_, _| {
        parts.next().ok_or_else(|| "more stored parts than inflated".to_string())
    })
    .map_err(|e| e.to_string())
}
