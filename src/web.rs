//! The browser entry point (wasm32): a [`Viewer`] drawing a streamed scene into a
//! canvas with WebGPU, driven by the JS shell in `web/` (`web/sylva.js` wraps it
//! in the public JS API). Same renderer and streamer as natively; only the fetch
//! (`fetch`) and the surface (a canvas) differ.

use std::cell::{Cell, RefCell};
use std::rc::Rc;

use glam::DVec3;
use wasm_bindgen::prelude::*;
use wasm_bindgen::JsCast;
use wasm_bindgen_futures::JsFuture;

use crate::geo::GeoFrame;
use crate::render::camera::Camera;
use crate::render::forest::{depth_texture, ForestRenderer, PoolConfig, RenderSettings};
use crate::render::gpu_data::REPR_COUNT;
use crate::render::stats::{CullCounters, FrameStats};
use crate::scene::{FetchError, Fetcher, RequestId, SceneStream, StreamConfig, StreamEvent};

type Done = Vec<(RequestId, Result<Vec<u8>, FetchError>)>;

/// Fetches with the browser's `fetch`; completions queue up until polled.
#[derive(Default)]
pub struct WebFetcher {
    next: RequestId,
    pending: Rc<Cell<usize>>,
    done: Rc<RefCell<Done>>,
}

async fn fetch_bytes(url: &str, range: Option<crate::scene::fetch::ByteRange>) -> Result<Vec<u8>, FetchError> {
    let transport = |e: JsValue| FetchError::Transport {
        url: url.to_string(),
        message: e.as_string().unwrap_or_else(|| format!("{e:?}")),
    };
    let window = web_sys::window().ok_or_else(|| transport(JsValue::from_str("no window")))?;
    let promise = match range {
        Some((a, b)) => {
            // A single range is a CORS-safelisted header: no preflight on a static host.
            let headers = web_sys::Headers::new().map_err(transport)?;
            headers.set("Range", &format!("bytes={a}-{}", b.max(a + 1) - 1)).map_err(transport)?;
            let init = web_sys::RequestInit::new();
            init.set_headers(&headers);
            window.fetch_with_str_and_init(url, &init)
        }
        None => window.fetch_with_str(url),
    };
    let resp: web_sys::Response = JsFuture::from(promise).await.map_err(transport)?.dyn_into().map_err(transport)?;
    match resp.status() {
        404 => return Err(FetchError::NotFound { url: url.to_string() }),
        s if !(200..300).contains(&s) => return Err(FetchError::Status { url: url.to_string(), status: s }),
        _ => {}
    }
    let buffer = JsFuture::from(resp.array_buffer().map_err(transport)?).await.map_err(transport)?;
    Ok(js_sys::Uint8Array::new(&buffer).to_vec())
}

impl Fetcher for WebFetcher {
    fn start_range(&mut self, url: &str, range: Option<crate::scene::fetch::ByteRange>) -> RequestId {
        let id = self.next;
        self.next += 1;
        self.pending.set(self.pending.get() + 1);
        let (pending, done, url) = (self.pending.clone(), self.done.clone(), url.to_string());
        wasm_bindgen_futures::spawn_local(async move {
            let result = fetch_bytes(&url, range).await;
            done.borrow_mut().push((id, result));
            pending.set(pending.get() - 1);
        });
        id
    }

    fn poll(&mut self) -> Done {
        std::mem::take(&mut *self.done.borrow_mut())
    }

    fn in_flight(&self) -> usize {
        self.pending.get() + self.done.borrow().len()
    }
}

/// An orbit camera: a target on the ground, a distance, a heading and a pitch.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Orbit {
    target: DVec3,
    distance: f64,
    heading: f64,
    pitch: f64,
}

impl Orbit {
    fn camera(&self) -> Camera {
        let c = Camera { heading_rad: self.heading, pitch_rad: self.pitch, ..Camera::default() };
        Camera {
            eye_m: self.target - c.forward() * self.distance,
            near_m: (self.distance * 0.002).clamp(0.05, 5.0) as f32,
            ..c
        }
    }
}

/// Counters read back from the GPU a few frames late (mapping is asynchronous on the web).
struct Readback {
    buffer: wgpu::Buffer,
    /// Bytes mapped by the pending request (the same range is read back).
    mapped_len: u64,
    state: Rc<Cell<u8>>, // 0 idle, 1 mapping, 2 mapped
    counters: CullCounters,
    /// Frame whose counters the pending mapping holds, and of the counters read.
    pending_frame: u64,
    words_frame: u64,
}

/// The browser viewer.
#[wasm_bindgen]
pub struct Viewer {
    surface: wgpu::Surface<'static>,
    device: wgpu::Device,
    queue: wgpu::Queue,
    config: wgpu::SurfaceConfiguration,
    view_format: wgpu::TextureFormat,
    renderer: ForestRenderer,
    stream: SceneStream<WebFetcher>,
    depth: wgpu::Texture,
    orbit: Orbit,
    placed: bool,
    settings: RenderSettings,
    readback: Readback,
    last_draw_calls: u32,
    last_cpu_ms: f64,
    events: Vec<StreamEvent>,
    adapter: String,
    geo: Option<GeoFrame>,
    /// Frames drawn, and the first frame drawn with the stream settled since the last change.
    frames: u64,
    settled_frame: Option<u64>,
    /// A geographic camera asked for before the manifest (and so the CRS) arrived.
    pending_geo: Option<[f64; 5]>,
    /// Walking mode: the eye stays at eye height above the ground and looks around itself.
    fly: bool,
    lost: std::sync::Arc<std::sync::atomic::AtomicBool>,
}

/// `performance.now()` of the page or worker, in milliseconds.
fn performance_now() -> Option<f64> {
    let performance = js_sys::Reflect::get(&js_sys::global(), &JsValue::from_str("performance")).ok()?;
    let now = js_sys::Reflect::get(&performance, &JsValue::from_str("now")).ok()?;
    now.dyn_ref::<js_sys::Function>()?.call0(&performance).ok()?.as_f64()
}

fn js_err(e: impl std::fmt::Display) -> JsValue {
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
        let lost = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let flag = lost.clone();
        device.set_device_lost_callback(move |reason, message| {
            web_sys::console::warn_1(&JsValue::from_str(&format!("sylva: GPU device lost ({reason:?}): {message}")));
            flag.store(true, std::sync::atomic::Ordering::SeqCst);
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
        let renderer = ForestRenderer::new(&device, view_format, pools);
        let depth = depth_texture(&device, width, height);
        let slots = u64::from(pools.species * REPR_COUNT);
        let readback = Readback {
            buffer: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("stats readback"),
                size: CullCounters::readback_bytes(slots as u32),
                usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                mapped_at_creation: false,
            }),
            mapped_len: 0,
            state: Rc::new(Cell::new(0)),
            counters: CullCounters::default(),
            pending_frame: 0,
            words_frame: 0,
        };
        let info = adapter.get_info();
        Ok(Viewer {
            surface,
            device,
            queue,
            config,
            view_format,
            renderer,
            stream: SceneStream::new(&scene, WebFetcher::default(), StreamConfig::default()),
            depth,
            orbit: Orbit { target: DVec3::ZERO, distance: 800.0, heading: 0.0, pitch: -0.5 },
            placed: false,
            settings: RenderSettings::default(),
            readback,
            last_draw_calls: 0,
            last_cpu_ms: 0.0,
            events: Vec::new(),
            adapter: format!("{} ({:?})", info.name, info.backend),
            geo: None,
            frames: 0,
            settled_frame: None,
            pending_geo: None,
            fly: false,
            lost,
        })
    }

    /// Resizes the drawing buffer (device pixels).
    pub fn resize(&mut self, width: u32, height: u32) {
        let (width, height) = (width.clamp(1, 8192), height.clamp(1, 8192));
        if (width, height) != (self.config.width, self.config.height) {
            self.config.width = width;
            self.config.height = height;
            self.surface.configure(&self.device, &self.config);
            self.depth = depth_texture(&self.device, width, height);
        }
    }

    /// Streams and draws one frame. `now_ms` is `performance.now()`.
    ///
    /// # Errors
    /// When the surface is lost for good (the page should recreate the viewer).
    pub fn frame(&mut self, now_ms: f64) -> Result<(), JsValue> {
        if self.is_lost() {
            return Ok(());
        }
        // CPU time of this frame alone (`now_ms` is the animation frame's start).
        let t0 = performance_now().unwrap_or(now_ms);
        let cam = self.camera();
        let view = cam.view_data(self.config.width, self.config.height);
        self.renderer.measure_reach(&view, &self.settings);
        self.stream.update(
            &mut self.renderer,
            &self.device,
            &self.queue,
            &view,
            self.settings.draw_distance_m,
            now_ms / 1e3,
        );
        self.events.extend(self.stream.drain_events());
        if !self.placed {
            if let Some(m) = self.stream.manifest() {
                // Start over the whole scene, looking north and down.
                let lo = DVec3::from(m.bounds.min.map(f64::from));
                let hi = DVec3::from(m.bounds.max.map(f64::from));
                let ext = ((hi - lo) * 0.5).truncate().max_element().max(20.0);
                self.orbit = Orbit { target: (lo + hi) * 0.5, distance: ext * 1.6, heading: 0.0, pitch: -0.6 };
                self.placed = true;
            }
        }
        if self.geo.is_none() {
            if let Some(m) = self.stream.manifest() {
                match GeoFrame::new(&m.crs.proj4, m.origin_m) {
                    Ok(g) => self.geo = Some(g),
                    Err(e) => web_sys::console::warn_1(&JsValue::from_str(&format!("sylva: {e}"))),
                }
                if let Some([lon, lat, h, heading, pitch]) = self.pending_geo.take() {
                    self.set_camera_geo(lon, lat, h, heading, pitch);
                }
            }
        }
        let frame = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(f) | wgpu::CurrentSurfaceTexture::Suboptimal(f) => f,
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => return Ok(()),
            wgpu::CurrentSurfaceTexture::Outdated => {
                self.surface.configure(&self.device, &self.config);
                return Ok(());
            }
            other => return Err(js_err(format!("the canvas surface failed: {other:?}"))),
        };
        let cam = self.camera();
        let view = cam.view_data(self.config.width, self.config.height);
        self.renderer.prepare(&self.queue, &view, &self.settings);
        let color = frame
            .texture
            .create_view(&wgpu::TextureViewDescriptor { format: Some(self.view_format), ..Default::default() });
        let depth = self.depth.create_view(&Default::default());
        let mut encoder = self.device.create_command_encoder(&Default::default());
        self.renderer.encode_cull(&mut encoder);
        self.last_draw_calls = self.renderer.encode_draw(&mut encoder, &color, &depth, self.settings.clear);
        let copy = self.readback.state.get() == 0;
        if copy {
            self.renderer.copy_counters(&mut encoder, &self.readback.buffer);
        }
        self.queue.submit([encoder.finish()]);
        self.queue.present(frame);
        self.frames += 1;
        if self.stream.is_settled() && self.stream.manifest().is_some() {
            self.settled_frame.get_or_insert(self.frames);
        } else {
            self.settled_frame = None;
        }
        self.collect_readback();
        if copy {
            let state = self.readback.state.clone();
            state.set(1);
            self.readback.mapped_len = CullCounters::readback_bytes(self.renderer.slot_count());
            self.readback.pending_frame = self.frames;
            self.readback.buffer.slice(..self.readback.mapped_len).map_async(wgpu::MapMode::Read, move |r| {
                state.set(if r.is_ok() { 2 } else { 0 });
            });
        }
        // Both ends on the page's clock (`performance.now()`): Date.now() counts from 1970.
        self.last_cpu_ms = (performance_now().unwrap_or(t0) - t0).max(0.0);
        Ok(())
    }

    fn collect_readback(&mut self) {
        if self.readback.state.get() != 2 {
            return;
        }
        {
            let data = self.readback.buffer.slice(..self.readback.mapped_len).get_mapped_range();
            if let Ok(data) = data {
                self.readback.counters = CullCounters::from_bytes(&data);
                self.readback.words_frame = self.readback.pending_frame;
            }
        }
        self.readback.buffer.unmap();
        self.readback.state.set(0);
    }

    fn camera(&self) -> Camera {
        let mut cam = self.orbit.camera();
        // No tunnelling: keep the eye above the ground near it; walking keeps eye height.
        if let Some(z) = self.stream.ground_height_at(cam.eye_m.x as f32, cam.eye_m.y as f32) {
            let ground = f64::from(z);
            cam.eye_m.z = if self.fly { ground + 1.7 } else { cam.eye_m.z.max(ground + 1.5) };
        }
        cam
    }

    /// Walking mode on or off. In walking mode `look` turns the head and `walk` moves.
    pub fn set_fly(&mut self, on: bool) {
        if on && !self.fly {
            // Stand where the camera is looking, facing the same way, nearly level.
            let target = self.orbit.target;
            self.orbit = Orbit { target, distance: 3.0, heading: self.orbit.heading, pitch: 0.05 };
        }
        self.fly = on;
    }

    /// Whether walking mode is on.
    pub fn fly(&self) -> bool {
        self.fly
    }

    /// Turns the view around the eye by `d_heading`, `d_pitch` radians.
    pub fn look(&mut self, d_heading: f64, d_pitch: f64) {
        let eye = self.orbit.camera().eye_m;
        self.orbit.heading += d_heading;
        self.orbit.pitch = (self.orbit.pitch + d_pitch).clamp(-1.5, 1.2);
        let forward =
            Camera { heading_rad: self.orbit.heading, pitch_rad: self.orbit.pitch, ..Camera::default() }.forward();
        self.orbit.target = eye + forward * self.orbit.distance;
    }

    /// Moves the eye `forward_m` along the heading and `right_m` to the side.
    pub fn walk(&mut self, forward_m: f64, right_m: f64) {
        let (s, c) = self.orbit.heading.sin_cos();
        self.orbit.target += DVec3::new(s * forward_m + c * right_m, c * forward_m - s * right_m, 0.0);
    }

    /// Sets a geographic camera: WGS 84 lon/lat (degrees), height (metres, in the
    /// scene's vertical datum), heading and pitch (degrees). Applied once the scene's
    /// CRS is known if the manifest has not arrived yet.
    pub fn set_camera_geo(&mut self, lon: f64, lat: f64, height: f64, heading_deg: f64, pitch_deg: f64) {
        let Some(geo) = &self.geo else {
            self.pending_geo = Some([lon, lat, height, heading_deg, pitch_deg]);
            self.placed = true;
            return;
        };
        match geo.to_local(lon, lat, height) {
            Ok(p) => self.set_camera(p.x, p.y, p.z, heading_deg, pitch_deg),
            Err(e) => {
                self.events.push(StreamEvent::Failed { url: String::new(), message: e.to_string(), retrying: false })
            }
        }
    }

    /// Scene-relative `[x, y, z]` of a geographic point as JSON, or `null` before the
    /// scene's CRS is known.
    pub fn geo_to_local_json(&self, lon: f64, lat: f64, height: f64) -> String {
        match self.geo.as_ref().map(|g| g.to_local(lon, lat, height)) {
            Some(Ok(p)) => serde_json::json!([p.x, p.y, p.z]).to_string(),
            _ => "null".into(),
        }
    }

    /// Whether the GPU device was lost (the page then creates a new viewer).
    pub fn is_lost(&self) -> bool {
        self.lost.load(std::sync::atomic::Ordering::SeqCst)
    }

    /// Destroys the device as a driver reset would (for tests of the recovery).
    pub fn simulate_device_loss(&self) {
        self.device.destroy();
    }

    /// Orbits around the target: `dx`, `dy` in radians of heading and pitch.
    pub fn orbit(&mut self, d_heading: f64, d_pitch: f64) {
        self.orbit.heading += d_heading;
        self.orbit.pitch = (self.orbit.pitch + d_pitch).clamp(-1.55, 0.6);
    }

    /// Moves the target in the view's ground plane by screen fractions of the distance.
    pub fn pan(&mut self, right: f64, forward: f64) {
        let (s, c) = self.orbit.heading.sin_cos();
        let d = self.orbit.distance;
        self.orbit.target += DVec3::new(c * right * d + s * forward * d, -s * right * d + c * forward * d, 0.0);
    }

    /// Multiplies the distance to the target (< 1 zooms in).
    pub fn zoom(&mut self, factor: f64) {
        self.orbit.distance = (self.orbit.distance * factor.clamp(0.2, 5.0)).clamp(2.0, 200_000.0);
    }

    /// Sets the camera: eye position relative to the scene origin (metres) and
    /// heading/pitch in degrees. The orbit target is placed ahead of the eye.
    pub fn set_camera(&mut self, x: f64, y: f64, z: f64, heading_deg: f64, pitch_deg: f64) {
        let cam = Camera {
            heading_rad: heading_deg.to_radians(),
            pitch_rad: pitch_deg.clamp(-89.0, 34.0).to_radians(),
            ..Camera::default()
        };
        let distance =
            if pitch_deg < -5.0 { (z - self.orbit.target.z).abs().max(10.0) / (-cam.pitch_rad).sin() } else { 100.0 };
        let eye = DVec3::new(x, y, z);
        self.orbit =
            Orbit { target: eye + cam.forward() * distance, distance, heading: cam.heading_rad, pitch: cam.pitch_rad };
        self.placed = true;
    }

    /// The camera as JSON: `{x, y, z, heading, pitch}` (metres relative to the
    /// scene origin, degrees) plus `origin` (the scene origin) and `epsg`.
    pub fn camera_json(&self) -> String {
        let c = self.camera();
        let origin = self.stream.manifest().map_or([0.0; 3], |m| m.origin_m);
        let epsg = self.stream.manifest().map_or(0, |m| m.crs.epsg);
        let mut v = serde_json::json!({
            "x": c.eye_m.x, "y": c.eye_m.y, "z": c.eye_m.z,
            "heading": c.heading_rad.to_degrees(), "pitch": c.pitch_rad.to_degrees(),
            "origin": origin, "epsg": epsg, "fly": self.fly,
        });
        if let Some((lon, lat, height)) = self.geo.as_ref().and_then(|g| g.to_geo(c.eye_m).ok()) {
            v["lon"] = lon.into();
            v["lat"] = lat.into();
            v["height"] = height.into();
        }
        v.to_string()
    }

    /// Colours trees by representation and/or draws batch boxes.
    pub fn set_debug(&mut self, lod: bool, bounds: bool) {
        self.settings.debug_lod = lod;
        self.settings.debug_bounds = bounds;
    }

    /// Level-of-detail policy: trees at least `ellipsoid_min_px` tall (and below
    /// the simplified mesh) use clustered ellipsoids (infinity: none); `only`
    /// restricts drawing to one family (`"meshes"`, `"ellipsoids"`, `"billboards"`,
    /// anything else: all); `exact_depth` writes the ellipsoids' exact ray-cast depth;
    /// far batches whose trees are below `thin_px` pixels draw an even, scaled-up
    /// subset of them (0: off).
    pub fn set_lod(&mut self, ellipsoid_min_px: f32, only: &str, exact_depth: bool, thin_px: f32) {
        use crate::render::forest::Representations;
        self.settings.cluster_min_px =
            if ellipsoid_min_px.is_nan() { f32::INFINITY } else { ellipsoid_min_px.max(0.0) };
        self.settings.representations = match only {
            "meshes" => Representations::MESHES,
            "ellipsoids" => Representations::CLUSTERS,
            "billboards" => Representations::BILLBOARDS,
            _ => Representations::ALL,
        };
        self.settings.cluster_exact_depth = exact_depth;
        self.settings.thin_px = if thin_px.is_finite() { thin_px.clamp(0.0, 64.0) } else { 0.0 };
    }

    /// Budgets: GPU memory for pools and packs in MB (0: none), download bytes per
    /// second (0: none), requests in flight (at least 1). The viewer degrades within
    /// them (coarser levels, shorter reach for new tiles) and says so in `stats()`.
    pub fn set_budget(&mut self, gpu_mb: f64, bytes_per_s: f64, in_flight: u32) {
        let mut c = self.stream.config();
        c.gpu_budget_bytes = if gpu_mb.is_finite() && gpu_mb > 0.0 { (gpu_mb * 1e6) as u64 } else { 0 };
        c.max_bytes_per_s = if bytes_per_s.is_finite() && bytes_per_s > 0.0 { bytes_per_s } else { 0.0 };
        c.max_in_flight = in_flight.clamp(1, 64) as usize;
        self.stream.set_config(c);
    }

    /// LoD quality factor (1, 0.5, 0.25).
    pub fn set_quality(&mut self, quality: f32) {
        self.settings.quality = quality.clamp(0.05, 4.0);
    }

    /// Whether everything the current view needs is drawn.
    pub fn settled(&self) -> bool {
        self.stream.is_settled()
    }

    /// Whether a frame with everything the view needs has been drawn and its
    /// counters read back (so `stats_json` describes it).
    pub fn is_ready(&self) -> bool {
        self.settled_frame.is_some_and(|f| self.readback.words_frame >= f)
    }

    /// Frame statistics with the keys of `sylva render --stats` (docs/FORMAT.md),
    /// gathered by the same code ([`FrameStats`]), plus `adapter`.
    pub fn stats_json(&self) -> String {
        let mut stats = FrameStats::gather(&self.renderer, &self.stream, self.last_draw_calls, self.last_cpu_ms);
        stats.apply_counters(&self.readback.counters);
        let mut json = serde_json::to_value(&stats).unwrap_or_default();
        json["adapter"] = self.adapter.clone().into();
        json.to_string()
    }

    /// Loading progress: `{manifest, tiles_wanted, tiles_resident, loading, bytes_fetched, settled}`.
    pub fn progress_json(&self) -> String {
        let s = self.stream.stats();
        serde_json::json!({
            "manifest": self.stream.manifest().is_some(),
            "tiles_wanted": s.tiles_wanted,
            "tiles_resident": s.tiles_resident,
            "loading": s.loading,
            "bytes_fetched": s.bytes_fetched,
            "settled": self.stream.is_settled(),
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
