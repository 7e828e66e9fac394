//! The browser entry point (wasm32): a [`Viewer`] drawing a streamed scene into a
//! canvas with WebGPU, driven by the JS shell in `web/` (`web/sylva.js` wraps it
//! in the public JS API). Same renderer and streamer as natively; only the fetch
//! (`fetch`) and the surface (a canvas) differ.

use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::Arc;

use glam::DVec3;
use wasm_bindgen::prelude::*;
use wasm_bindgen::JsCast;
use wasm_bindgen_futures::JsFuture;

use crate::camera::Camera;
use crate::frame::Frame;
use crate::geo::GeoFrame;
use crate::orbit::Orbit;
use crate::render::forest::{depth_texture, PoolConfig};
use crate::scene::StreamEvent;

mod camera;
mod fetch;
mod math;
mod photo;
mod query;
mod settings;

pub use fetch::WebFetcher;
pub use query::{query_may_match, query_tile, WebTileWalk};

/// The browser viewer.
#[wasm_bindgen]
pub struct Viewer {
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    view_format: wgpu::TextureFormat,
    /// The frame shared with the native host: renderer, stream, settings, stats.
    frame: Frame<WebFetcher>,
    depth: wgpu::Texture,
    orbit: Orbit,
    placed: bool,
    events: Vec<StreamEvent>,
    geo: Option<GeoFrame>,
    /// The first frame drawn with the stream settled since the last change.
    settled_frame: Option<u64>,
    /// A geographic camera asked for before the manifest (and so the CRS) arrived.
    pending_geo: Option<PendingGeo>,
    /// Vertical field of view (radians; `set_fov`).
    fov_y_rad: f32,
    /// Walking mode: the eye stays at eye height above the ground and looks around itself.
    fly: bool,
    lost: Arc<AtomicBool>,
    /// Frames submitted whose GPU work has not finished (the queue says when).
    frames_ahead: Arc<AtomicU32>,
    /// The last finished frame's GPU time (ms as f64 bits; 0: none new): from
    /// when it was submitted or the frame before it finished, whichever was
    /// later, to when it finished.
    frame_done_ms: Arc<AtomicU64>,
    /// The same for the page's governor (`take_frame_ms`), and when the last
    /// frame finished (`js_sys::Date::now()`, f64 bits).
    governor_ms: Arc<AtomicU64>,
    last_done: Arc<AtomicU64>,
    /// Whether to draw while loading (a slow GPU waits for the stream).
    pacer: crate::frame::pacing::LoadPacer,
    /// The camera of the last frame drawn.
    drawn_camera: Option<Camera>,
    /// The scene's URL as given (the path tracer fetches its files).
    scene_url: String,
    /// The path-traced view (`set_renderer`), and its pipelines once made.
    photo: Option<photo::Photo>,
    photo_pipes: Option<photo::PhotoPipelines>,
    /// Loads of a path-traced view started (`photo_json`'s `load`).
    photo_loads: u32,
}

/// A geographic camera asked for before the scene's CRS was known.
#[derive(Debug, Clone, Copy)]
enum PendingGeo {
    /// `set_camera_geo`: lon, lat, height, heading, pitch.
    Pose([f64; 5]),
    /// `set_camera_look_geo`: eye lon, lat, height, target lon, lat, height, bearing.
    Look([f64; 7]),
}

/// At most this many frames queued on the GPU: on a slow GPU (a CPU one, a
/// phone) further frames are skipped until one finishes, so input lag stays
/// at a frame or two instead of growing with every animation frame.
const MAX_FRAMES_AHEAD: u32 = 2;

pub(crate) fn js_err(e: impl std::fmt::Display) -> JsValue {
    JsValue::from_str(&e.to_string())
}

#[wasm_bindgen]
impl Viewer {
    /// Creates a viewer on `canvas` streaming `scene` (URL of a scene directory or scene.json).
    ///
    /// # Errors
    /// A message naming what is missing: WebGPU, an adapter, a device.
    pub async fn create(canvas: web_sys::HtmlCanvasElement, scene: String) -> Result<Viewer, JsValue> {
        console_error_panic_hook_install();
        let gpu = js_sys::Reflect::get(&web_sys::window().ok_or("no window")?.navigator(), &"gpu".into())?;
        if gpu.is_undefined() {
            return Err(js_err("WebGPU is not available in this browser (navigator.gpu is missing). Use a recent Chrome, Edge or Firefox Nightly, or Chromium with --enable-unsafe-webgpu."));
        }
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
            backends: wgpu::Backends::BROWSER_WEBGPU,
            ..wgpu::InstanceDescriptor::new_without_display_handle()
        });
        let (width, height) = (canvas.width().max(1), canvas.height().max(1));
        let surface = instance.create_surface(wgpu::SurfaceTarget::Canvas(canvas)).map_err(js_err)?;
        let adapter = instance
            .request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                compatible_surface: Some(&surface),
                ..Default::default()
            })
            .await
            .map_err(|e| {
                js_err(format!(
                    "This browser has WebGPU but no usable GPU adapter ({e}). Turn on hardware acceleration in the \
                     browser settings or update the graphics driver; a current Chrome or Edge works, and on Linux \
                     Chromium needs --enable-unsafe-webgpu --enable-features=Vulkan."
                ))
            })?;
        let (device, queue) = crate::render::context::request_device(&adapter).await.map_err(js_err)?;
        let lost = Arc::new(AtomicBool::new(false));
        let flag = lost.clone();
        device.set_device_lost_callback(move |reason, message| {
            web_sys::console::warn_1(&JsValue::from_str(&format!("sylva: GPU device lost ({reason:?}): {message}")));
            flag.store(true, Ordering::SeqCst);
        });
        let caps = surface.get_capabilities(&adapter);
        let format = caps.formats.first().copied().unwrap_or(wgpu::TextureFormat::Bgra8Unorm);
        // Canvases prefer a non-sRGB format; draw through an sRGB view so colours match native.
        let view_format = format.add_srgb_suffix();
        let config = wgpu::SurfaceConfiguration {
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            format,
            width,
            height,
            present_mode: wgpu::PresentMode::Fifo,
            desired_maximum_frame_latency: 2,
            alpha_mode: wgpu::CompositeAlphaMode::Opaque,
            view_formats: vec![view_format],
            color_space: wgpu::SurfaceColorSpace::Auto,
        };
        surface.configure(&device, &config);
        let pools = PoolConfig { instances: 2 << 20, items: 3 << 20, ..PoolConfig::default() };
        let depth = depth_texture(&device, width, height);
        let name = adapter_name(&adapter).await;
        let scene_url = scene.clone();
        let mut frame = Frame::new(device, queue, name, view_format, pools, &scene, WebFetcher::default());
        frame.use_timestamps();
        // A resting camera refines its image, then the viewer idles (`setRefine`).
        frame.refine.config.enabled = true;
        // The sun casts shadows unless a page turns them down (`setLighting`).
        frame.settings.shadows = crate::render::shadow::ShadowQuality::High;
        Ok(Viewer {
            surface,
            config,
            view_format,
            frame,
            depth,
            orbit: Orbit { target: DVec3::ZERO, distance: 800.0, heading: 0.0, pitch: -0.5 },
            placed: false,
            events: Vec::new(),
            geo: None,
            settled_frame: None,
            pending_geo: None,
            fov_y_rad: Camera::default().fov_y_rad,
            fly: false,
            lost,
            frames_ahead: Default::default(),
            frame_done_ms: Default::default(),
            governor_ms: Default::default(),
            last_done: Default::default(),
            pacer: Default::default(),
            drawn_camera: None,
            scene_url,
            photo: None,
            photo_pipes: None,
            photo_loads: 0,
        })
    }

    /// Picks the drawing-buffer pixel (`x`, `y`) from the top left: the id
    /// pass of the current view runs now (cull and ids, only that pixel
    /// shaded) and the promise resolves to JSON `{tile, ids, attributes,
    /// index}` (the files of the tree drawn there and its index in the tile,
    /// for [`Self::describe_tree`]) or `null` where no tree is drawn.
    pub fn pick(&mut self, x: f64, y: f64) -> js_sys::Promise {
        let none = || js_sys::Promise::resolve(&JsValue::NULL);
        if self.is_lost() || !(x.is_finite() && y.is_finite() && x >= 0.0 && y >= 0.0) {
            return none();
        }
        let view = self.camera().view_data(self.config.width, self.config.height);
        let Some(recorded) = self.frame.record_pick(&view, [x as u32, y as u32]) else { return none() };
        let tiles = self.frame.stream.tile_locations();
        self.frame.queue.submit([recorded.commands]);
        let buffer = recorded.readback;
        js_sys::Promise::new(&mut |resolve: js_sys::Function, _reject| {
            let mapped = buffer.clone();
            let tiles = tiles.clone();
            buffer.slice(..).map_async(wgpu::MapMode::Read, move |result| {
                let instance = result.ok().and_then(|()| {
                    let id = crate::frame::read_pick(&mapped.slice(..).get_mapped_range().ok()?);
                    mapped.unmap();
                    id
                });
                let answer = match instance.and_then(|i| crate::scene::streaming::locate(&tiles, i)) {
                    Some(t) => JsValue::from_str(
                        &serde_json::json!({
                            "tile": t.tile_url, "ids": t.ids_url, "attributes": t.attributes_url, "index": t.index,
                        })
                        .to_string(),
                    ),
                    None => JsValue::NULL,
                };
                let _ = resolve.call1(&JsValue::NULL, &answer);
            });
        })
    }

    /// What a pick says of the `index`th tree of a tile, from the files
    /// [`Self::pick`] named (`attr` for scenes with attributes): JSON `{id,
    /// species, attributes, lon, lat, height, position}`, as `sylva pick`.
    ///
    /// # Errors
    /// No manifest yet, or a file that does not decode.
    pub fn describe_tree(&self, tile: &[u8], ids: &[u8], attr: Option<Vec<u8>>, index: u32) -> Result<String, JsValue> {
        let m = self.frame.stream.manifest().ok_or_else(|| js_err("the scene is not loaded yet"))?;
        let files = ["tile", "ids", "attributes"];
        crate::scene::query::describe_tree(m, self.geo.as_ref(), [tile, ids], attr.as_deref(), files, index)
            .map(|v| v.to_string())
            .map_err(js_err)
    }

    /// Sets the style (JSON, see `scene::style`; `null` or `{}`: none) and
    /// returns its legend as JSON `{title, entries: [{label, color}]}`.
    ///
    /// # Errors
    /// Before the manifest arrived, or a style that does not fit the scene (the message says why).
    pub fn set_style(&mut self, style: &str) -> Result<String, JsValue> {
        let value: serde_json::Value = serde_json::from_str(style).map_err(js_err)?;
        if value.is_null() {
            self.frame.set_style(None);
            return Ok(r#"{"title":"","entries":[]}"#.into());
        }
        let m = self.frame.stream.manifest().ok_or_else(|| js_err("the scene is not loaded yet"))?;
        let species: Vec<String> = m.species.iter().map(|s| s.name.clone()).collect();
        let compiled =
            crate::scene::style::TreeStyle::parse(m.attributes.as_ref(), &species, &value).map_err(js_err)?;
        let legend = compiled.legend_json().to_string();
        self.frame.set_style(Some(compiled));
        Ok(legend)
    }

    /// Highlights the trees with these ids (a JSON array of numbers and text
    /// ids; `[]`: none).
    ///
    /// # Errors
    /// Not a JSON array of whole numbers and texts.
    pub fn select(&mut self, ids: &str) -> Result<(), JsValue> {
        let ids: Vec<crate::scene::style::TreeId> = serde_json::from_str(ids)
            .map_err(|e| js_err(format!("select takes a list of tree ids (whole numbers or texts): {e}")))?;
        self.frame.select(ids);
        Ok(())
    }

    /// The scene's attribute columns as JSON (`null`: none, or no manifest yet).
    pub fn attributes_json(&self) -> String {
        self.frame
            .stream
            .manifest()
            .and_then(|m| m.attributes.as_ref())
            .map_or_else(|| "null".into(), |a| serde_json::json!(a).to_string())
    }

    /// The scene's timeline as JSON: `{censuses, latest, first, last}` (dates
    /// `YYYY-MM-DD`; `first`–`last` the span its trees start and stop
    /// standing in, the censuses' within it), or `null` (none, or not loaded yet).
    pub fn timeline_json(&self) -> String {
        use crate::format::attributes::format_date;
        let Some(m) = self.frame.stream.manifest() else { return "null".into() };
        let (Some(t), Ok(columns)) = (
            m.timeline.as_ref(),
            m.timeline.as_ref().map_or(Err(()), |t| t.resolve(m.attributes.as_ref()).map_err(|_| ())),
        ) else {
            return "null".into();
        };
        // From the first census, planting or removal (the day before: the tree still stands).
        let earliest = |name: &str, less: i64| {
            m.attributes
                .as_ref()
                .and_then(|a| a.column(name))
                .filter(|(_, c)| c.count > 0)
                .map(|(_, c)| c.min as i64 - less)
        };
        let first = columns.censuses.first().copied().unwrap_or(columns.latest);
        let first = first.min(earliest(&t.from, 0).unwrap_or(first)).min(earliest(&t.until, 1).unwrap_or(first));
        let last = columns.latest.max(columns.last_change);
        serde_json::json!({
            "censuses": t.censuses,
            "latest": t.latest,
            "first": format_date(first),
            "last": format_date(last),
        })
        .to_string()
    }

    /// Whether the scene keeps per-tree attributes (false before its manifest arrives).
    pub fn has_attributes(&self) -> bool {
        self.frame.stream.manifest().is_some_and(|m| m.attributes.is_some())
    }

    /// Resizes the drawing buffer (device pixels).
    pub fn resize(&mut self, width: u32, height: u32) {
        let (width, height) = (width.clamp(1, 8192), height.clamp(1, 8192));
        if (width, height) != (self.config.width, self.config.height) {
            self.config.width = width;
            self.config.height = height;
            self.surface.configure(&self.frame.device, &self.config);
            self.depth = depth_texture(&self.frame.device, width, height);
        }
    }

    /// Streams and draws one frame. `now_ms` is `performance.now()`. Returns
    /// whether a frame was drawn: not while [`MAX_FRAMES_AHEAD`] frames are
    /// still on the GPU (streaming goes on; draw again on a later animation frame).
    ///
    /// # Errors
    /// When the surface is lost for good (the page should recreate the viewer).
    pub fn frame(&mut self, now_ms: f64) -> Result<bool, JsValue> {
        if self.is_lost() {
            return Ok(false);
        }
        // GPU times and counters of earlier frames, as the GPU reports them.
        self.frame.collect();
        // Until the first view is placed where the trees are, stream the manifest only.
        let camera = if self.placed { self.camera() } else { Camera::nowhere() };
        let view = camera.view_data(self.config.width, self.config.height);
        self.frame.stream(&view, now_ms / 1e3);
        self.events.extend(self.frame.stream.drain_events());
        if !self.placed {
            if let Some(m) = self.frame.stream.manifest() {
                // Start over where the trees are (the largest group of them), looking
                // north and down.
                let focus = m.focus();
                let lo = DVec3::from(focus.min.map(f64::from));
                let hi = DVec3::from(focus.max.map(f64::from));
                let ext = ((hi - lo) * 0.5).truncate().max_element().max(20.0);
                self.orbit = Orbit { target: (lo + hi) * 0.5, distance: ext * 1.6, heading: 0.0, pitch: -0.6 };
                self.placed = true;
            }
        }
        if self.geo.is_none() {
            if let Some(m) = self.frame.stream.manifest() {
                match GeoFrame::for_scene(&m.crs, m.origin_m) {
                    Ok(g) => self.geo = Some(g),
                    Err(e) => web_sys::console::warn_1(&JsValue::from_str(&format!("sylva: {e}"))),
                }
                match self.pending_geo.take() {
                    Some(PendingGeo::Pose([lon, lat, h, heading, pitch])) => {
                        self.set_camera_geo(lon, lat, h, heading, pitch);
                    }
                    Some(PendingGeo::Look([lon, lat, h, at_lon, at_lat, at_h, bearing])) => {
                        self.set_camera_look_geo(lon, lat, h, at_lon, at_lat, at_h, bearing);
                    }
                    None => {}
                }
            }
        }
        if self.frames_ahead.load(Ordering::Relaxed) >= MAX_FRAMES_AHEAD {
            return Ok(false);
        }
        // A slow GPU loading draws when the stream settles or goes quiet, not
        // for every arrival (`crate::frame::pacing`); a moved camera draws.
        let done = f64::from_bits(self.frame_done_ms.swap(0, Ordering::Relaxed));
        if done > 0.0 {
            self.pacer.frame_done(done);
        }
        let s = self.frame.stream.stats();
        let settled = self.frame.stream.is_settled() && self.frame.stream.manifest().is_some();
        // The camera again: placing it, or the ground under it, may have moved it.
        let camera = self.camera();
        let moved = self.drawn_camera != Some(camera);
        // (A moving camera sees the raster; the trace starts once it rests.)
        let tracing = self.poll_photo(&camera) && !moved;
        if !tracing && !self.pacer.should_draw(now_ms, settled, s.bytes_fetched + s.requests) && !moved {
            return Ok(false);
        }
        let target = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(f) | wgpu::CurrentSurfaceTexture::Suboptimal(f) => f,
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => return Ok(false),
            wgpu::CurrentSurfaceTexture::Outdated => {
                self.surface.configure(&self.frame.device, &self.config);
                return Ok(false);
            }
            other => return Err(js_err(format!("the canvas surface failed: {other:?}"))),
        };
        let view = camera.view_data(self.config.width, self.config.height);
        let color = target
            .texture
            .create_view(&wgpu::TextureViewDescriptor { format: Some(self.view_format), ..Default::default() });
        let traced = if tracing { self.record_photo(&camera, &color) } else { None };
        if let Some(work) = traced {
            self.frame.queue.submit([work]);
        } else {
            let depth = self.depth.create_view(&Default::default());
            let recorded = self.frame.record(&view, &color, &depth, true);
            self.frame.submit(recorded, false);
        }
        self.frame.queue.present(target);
        self.frames_ahead.fetch_add(1, Ordering::Relaxed);
        let (ahead, done_ms) = (self.frames_ahead.clone(), self.frame_done_ms.clone());
        let (governor_ms, last_done) = (self.governor_ms.clone(), self.last_done.clone());
        let submitted = js_sys::Date::now();
        self.frame.queue.on_submitted_work_done(move || {
            ahead.fetch_sub(1, Ordering::Relaxed);
            // (Frames queue behind each other: this one's GPU time began when
            // the one before finished, if that was after its submission.)
            let now = js_sys::Date::now();
            let began = submitted.max(f64::from_bits(last_done.swap(now.to_bits(), Ordering::Relaxed)));
            let ms = (now - began).max(0.001).to_bits();
            done_ms.store(ms, Ordering::Relaxed);
            governor_ms.store(ms, Ordering::Relaxed);
        });
        self.pacer.drew(now_ms);
        self.drawn_camera = Some(camera);
        if self.frame.stream.is_settled() && self.frame.stream.manifest().is_some() {
            self.settled_frame.get_or_insert(self.frame.frames());
        } else {
            self.settled_frame = None;
        }
        Ok(true)
    }

    /// Takes a finished load of the path-traced view (its error as an
    /// event) and reloads one the eye left: whether the traced image can be
    /// what this frame shows (else the raster view, while it loads).
    fn poll_photo(&mut self, camera: &Camera) -> bool {
        let Some(p) = self.photo.as_mut() else { return false };
        if p.stale(camera.eye_m) {
            self.photo_loads += 1;
            *p = photo::Photo::start(&self.scene_url, camera.eye_m, p.settings, self.photo_loads);
        }
        if let Some(message) = p.poll() {
            self.events.push(StreamEvent::Failed { url: "path-trace".into(), message, retrying: false });
        }
        p.ready()
    }

    /// The next traced sample and its display on `color` (the display alone
    /// once complete), or `None` on a failure (it goes to the events; the
    /// raster view is drawn).
    fn record_photo(&mut self, camera: &Camera, color: &wgpu::TextureView) -> Option<wgpu::CommandBuffer> {
        let p = self.photo.as_mut()?;
        let pipes =
            self.photo_pipes.get_or_insert_with(|| photo::PhotoPipelines::new(&self.frame.device, self.view_format));
        let lighting = self.frame.settings.lighting;
        let parts = self.frame.settings.light_parts;
        let size = (self.config.width, self.config.height);
        match p.record(pipes, &self.frame.device, &self.frame.queue, camera, &lighting, parts, size, color) {
            Ok(work) => work,
            Err(message) => {
                self.events.push(StreamEvent::Failed { url: "path-trace".into(), message, retrying: false });
                None
            }
        }
    }

    fn camera(&self) -> Camera {
        // No tunnelling: keep the eye above the ground near it; walking keeps eye height.
        let eye = self.orbit.camera().eye_m;
        let ground = self.frame.stream.ground_height_at(eye.x as f32, eye.y as f32).map(f64::from);
        Camera { fov_y_rad: self.fov_y_rad, ..self.orbit.camera_over(ground, self.fly) }
    }

    /// The GPU time (ms) of the last frame finished since the last call, or 0
    /// when none finished: what the page's frame-time governor holds to its
    /// target (`web/governor.js`).
    pub fn take_frame_ms(&self) -> f64 {
        f64::from_bits(self.governor_ms.swap(0, Ordering::Relaxed))
    }

    /// Whether the GPU device was lost (the page then creates a new viewer).
    pub fn is_lost(&self) -> bool {
        self.lost.load(Ordering::SeqCst)
    }

    /// Frames submitted whose GPU work has not finished yet (at most 2).
    pub fn frames_in_flight(&self) -> u32 {
        self.frames_ahead.load(Ordering::Relaxed)
    }

    /// Destroys the device as a driver reset would (for tests of the recovery).
    pub fn simulate_device_loss(&self) {
        self.frame.device.destroy();
    }

    /// Whether everything the current view needs is drawn.
    pub fn settled(&self) -> bool {
        self.frame.stream.is_settled()
    }

    /// Whether a frame with everything the view needs has been drawn and its
    /// counters read back (so `stats_json` describes it).
    pub fn is_ready(&mut self) -> bool {
        self.frame.collect();
        // A converged refinement draws no scene, so no later counters come:
        // the last ones read are the view's.
        let converged = self.frame.refine.converged() && self.frame.counters_frame() > 0;
        self.settled_frame.is_some_and(|f| self.frame.counters_frame() >= f || converged)
    }

    /// Frame statistics with the keys of `sylva render --stats` (docs/FORMAT.md),
    /// gathered by the same code ([`Frame::stats`]); GPU times and counters are
    /// those of the latest frame the GPU finished.
    pub fn stats_json(&mut self) -> String {
        self.frame.collect();
        serde_json::to_string(&self.frame.stats()).unwrap_or_default()
    }

    /// Loading progress: `{manifest, tiles_wanted, tiles_resident, loading,
    /// bytes_fetched, settled, frames_held}` (`frames_held`: animation frames a
    /// slow GPU did not draw while files arrived, `crate::frame::pacing`).
    pub fn progress_json(&self) -> String {
        let s = self.frame.stream.stats();
        serde_json::json!({
            "manifest": self.frame.stream.manifest().is_some(),
            "tiles_wanted": s.tiles_wanted,
            "tiles_resident": s.tiles_resident,
            "loading": s.loading,
            "bytes_fetched": s.bytes_fetched,
            "settled": self.frame.stream.is_settled(),
            "frames_held": self.pacer.held(),
        })
        .to_string()
    }

    /// Events since the last call, as a JSON array of `{kind, url?, message}`.
    pub fn take_events_json(&mut self) -> String {
        let events: Vec<serde_json::Value> = self
            .events
            .drain(..)
            .map(|e| match e {
                StreamEvent::ManifestLoaded { trees } => serde_json::json!({"kind": "manifest", "trees": trees}),
                StreamEvent::Failed { url, message, retrying } => {
                    serde_json::json!({"kind": "warning", "url": url, "message": message, "retrying": retrying})
                }
                StreamEvent::Fatal { message } => serde_json::json!({"kind": "error", "message": message}),
            })
            .collect();
        serde_json::Value::Array(events).to_string()
    }
}

fn console_error_panic_hook_install() {
    std::panic::set_hook(Box::new(|info| {
        web_sys::console::error_1(&JsValue::from_str(&format!("sylva panicked: {info}")));
    }));
}

/// The adapter's name: what wgpu reports, else the browser's `GPUAdapterInfo`
/// vendor and architecture (Chromium leaves the description empty).
async fn adapter_name(adapter: &wgpu::Adapter) -> String {
    let info = adapter.get_info();
    if !info.name.trim().is_empty() {
        return format!("{} ({:?}, {:?})", info.name, info.backend, info.device_type);
    }
    let get = |o: &JsValue, k: &str| js_sys::Reflect::get(o, &JsValue::from_str(k)).ok();
    let text = |o: &JsValue, k: &str| get(o, k).and_then(|v| v.as_string()).filter(|s| !s.is_empty());
    let described = async {
        let gpu = get(&web_sys::window()?.navigator().into(), "gpu")?;
        let request = get(&gpu, "requestAdapter")?.dyn_into::<js_sys::Function>().ok()?;
        // The same preference as the adapter in use (a dual-GPU machine has two).
        let options = js_sys::Object::new();
        js_sys::Reflect::set(&options, &"powerPreference".into(), &"high-performance".into()).ok()?;
        let promise = request.call1(&gpu, &options).ok()?.dyn_into::<js_sys::Promise>().ok()?;
        let js_adapter = JsFuture::from(promise).await.ok()?;
        let js_info = get(&js_adapter, "info")?;
        let parts: Vec<String> =
            ["vendor", "architecture", "device", "description"].iter().filter_map(|k| text(&js_info, k)).collect();
        (!parts.is_empty()).then(|| parts.join(" "))
    };
    let name = described.await.unwrap_or_else(|| "unnamed WebGPU adapter".into());
    format!("{name} ({:?}, {:?})", info.backend, info.device_type)
}
