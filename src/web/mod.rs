//! The browser entry point (wasm32): a [`Viewer`] drawing a streamed scene into a
//! canvas with WebGPU, driven by the JS shell in `web/` (`web/sylva.js` wraps it
//! in the public JS API). Same renderer and streamer as natively; only the fetch
//! (`fetch`) and the surface (a canvas) differ.

use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
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

mod fetch;
mod query;

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
                match GeoFrame::new(&m.crs.proj4, m.origin_m) {
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
        let target = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(f) | wgpu::CurrentSurfaceTexture::Suboptimal(f) => f,
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => return Ok(false),
            wgpu::CurrentSurfaceTexture::Outdated => {
                self.surface.configure(&self.frame.device, &self.config);
                return Ok(false);
            }
            other => return Err(js_err(format!("the canvas surface failed: {other:?}"))),
        };
        // The camera again: placing it, or the ground under it, may have moved it.
        let view = self.camera().view_data(self.config.width, self.config.height);
        let color = target
            .texture
            .create_view(&wgpu::TextureViewDescriptor { format: Some(self.view_format), ..Default::default() });
        let depth = self.depth.create_view(&Default::default());
        let recorded = self.frame.record(&view, &color, &depth, true);
        self.frame.submit(recorded, false);
        self.frame.queue.present(target);
        self.frames_ahead.fetch_add(1, Ordering::Relaxed);
        let ahead = self.frames_ahead.clone();
        self.frame.queue.on_submitted_work_done(move || {
            ahead.fetch_sub(1, Ordering::Relaxed);
        });
        if self.frame.stream.is_settled() && self.frame.stream.manifest().is_some() {
            self.settled_frame.get_or_insert(self.frame.frames());
        } else {
            self.settled_frame = None;
        }
        Ok(true)
    }

    fn camera(&self) -> Camera {
        // No tunnelling: keep the eye above the ground near it; walking keeps eye height.
        let eye = self.orbit.camera().eye_m;
        let ground = self.frame.stream.ground_height_at(eye.x as f32, eye.y as f32).map(f64::from);
        Camera { fov_y_rad: self.fov_y_rad, ..self.orbit.camera_over(ground, self.fly) }
    }

    /// Walking mode on or off. In walking mode `look` turns the head and `walk` moves.
    pub fn set_fly(&mut self, on: bool) {
        if on && !self.fly {
            // Stand where the camera is looking, facing the same way, nearly level.
            self.orbit = self.orbit.standing();
        }
        self.fly = on;
    }

    /// Whether walking mode is on.
    pub fn fly(&self) -> bool {
        self.fly
    }

    /// Turns the view around the eye by `d_heading`, `d_pitch` radians.
    pub fn look(&mut self, d_heading: f64, d_pitch: f64) {
        self.orbit.look(d_heading, d_pitch);
    }

    /// Moves the eye `forward_m` along the heading and `right_m` to the side.
    pub fn walk(&mut self, forward_m: f64, right_m: f64) {
        self.orbit.walk(forward_m, right_m);
    }

    /// Sets a geographic camera: WGS 84 lon/lat (degrees), height (metres, in the
    /// scene's vertical datum), heading and pitch (degrees). Applied once the scene's
    /// CRS is known if the manifest has not arrived yet.
    pub fn set_camera_geo(&mut self, lon: f64, lat: f64, height: f64, heading_deg: f64, pitch_deg: f64) {
        let Some(geo) = &self.geo else {
            self.pending_geo = Some(PendingGeo::Pose([lon, lat, height, heading_deg, pitch_deg]));
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

    /// Sets the camera as a map or a globe gives it: the eye at WGS 84 `lon`,
    /// `lat`, `height` looking at the point `at_lon`, `at_lat`, `at_height`
    /// (heights in metres, the scene's vertical datum). `bearing_deg`
    /// (clockwise from true north) turns the view when it looks straight
    /// down; otherwise the two points alone set it, so the scene's grid
    /// convergence is taken in. Pitch is not limited: a map looking straight
    /// down is drawn straight down.
    #[allow(clippy::too_many_arguments)]
    pub fn set_camera_look_geo(
        &mut self,
        lon: f64,
        lat: f64,
        height: f64,
        at_lon: f64,
        at_lat: f64,
        at_height: f64,
        bearing_deg: f64,
    ) {
        let Some(geo) = &self.geo else {
            self.pending_geo = Some(PendingGeo::Look([lon, lat, height, at_lon, at_lat, at_height, bearing_deg]));
            self.placed = true;
            return;
        };
        let (eye, at) = match (geo.to_local(lon, lat, height), geo.to_local(at_lon, at_lat, at_height)) {
            (Ok(eye), Ok(at)) => (eye, at),
            (Err(e), _) | (_, Err(e)) => {
                let message = e.to_string();
                self.events.push(StreamEvent::Failed { url: String::new(), message, retrying: false });
                return;
            }
        };
        let straight_down = || geo.grid_heading(eye, bearing_deg).unwrap_or(bearing_deg.to_radians());
        let Some(orbit) = Orbit::looking_at(eye, at, straight_down) else { return };
        self.orbit = orbit;
        self.placed = true;
    }

    /// Where the current camera draws the WGS 84 point `lon`, `lat`,
    /// `height` (the scene's datum): JSON `[x, y]` in drawing-buffer pixels
    /// from the top left, or `null` behind the eye or before the scene's CRS
    /// is known (a map layer's tests compare it with the map's projection).
    pub fn project_geo(&self, lon: f64, lat: f64, height: f64) -> String {
        let Some(Ok(p)) = self.geo.as_ref().map(|g| g.to_local(lon, lat, height)) else { return "null".into() };
        match crate::orbit::project(&self.camera(), self.config.width, self.config.height, p) {
            Some(xy) => serde_json::json!(xy).to_string(),
            None => "null".into(),
        }
    }

    /// The WGS 84 box `[west, south, east, north]` (degrees) around where the
    /// scene's views aim first (its home, else its densest group of trees) as
    /// JSON, or `null` before the manifest and its CRS arrived: a map fits
    /// its view to it.
    pub fn focus_geo_json(&self) -> String {
        let (Some(geo), Some(m)) = (&self.geo, self.frame.stream.manifest()) else { return "null".into() };
        let b = m.focus();
        let corners = [[b.min[0], b.min[1]], [b.max[0], b.min[1]], [b.min[0], b.max[1]], [b.max[0], b.max[1]]];
        let mut bbox = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
        for [x, y] in corners {
            let Ok((lon, lat, _)) = geo.to_geo(DVec3::new(f64::from(x), f64::from(y), 0.0)) else {
                return "null".into();
            };
            bbox = [bbox[0].min(lon), bbox[1].min(lat), bbox[2].max(lon), bbox[3].max(lat)];
        }
        serde_json::json!(bbox).to_string()
    }

    /// Vertical field of view in degrees (default 50; clamped to 1–150).
    pub fn set_fov(&mut self, fov_y_deg: f64) {
        if fov_y_deg.is_finite() {
            self.fov_y_rad = (fov_y_deg.clamp(1.0, 150.0) as f32).to_radians();
        }
    }

    /// A layer over a map (on) or a viewer of its own (off): on, neither
    /// sky nor clear colour is drawn (the canvas is transparent where the
    /// scene draws nothing, composited premultiplied over what lies beneath
    /// it); the terrain stays as `set_terrain` has it.
    pub fn set_overlay(&mut self, on: bool) {
        self.frame.settings.sky = !on;
        self.frame.settings.clear =
            if on { [0.0; 4] } else { crate::render::settings::RenderSettings::default().clear };
        // Every WebGPU canvas takes "premultiplied" (the spec's two modes),
        // though wgpu's capabilities on the web list "opaque" only.
        let alpha = if on { wgpu::CompositeAlphaMode::PreMultiplied } else { wgpu::CompositeAlphaMode::Opaque };
        if alpha != self.config.alpha_mode {
            self.config.alpha_mode = alpha;
            self.surface.configure(&self.frame.device, &self.config);
        }
        self.frame.refine.invalidate();
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

    /// Orbits around the target: `dx`, `dy` in radians of heading and pitch.
    pub fn orbit(&mut self, d_heading: f64, d_pitch: f64) {
        self.orbit.orbit(d_heading, d_pitch);
    }

    /// Moves the target in the view's ground plane by screen fractions of the distance.
    pub fn pan(&mut self, right: f64, forward: f64) {
        self.orbit.pan(right, forward);
    }

    /// Multiplies the distance to the target (< 1 zooms in).
    pub fn zoom(&mut self, factor: f64) {
        self.orbit.zoom(factor);
    }

    /// Sets the camera: eye position relative to the scene origin (metres) and
    /// heading/pitch in degrees. The orbit target is placed ahead of the eye.
    pub fn set_camera(&mut self, x: f64, y: f64, z: f64, heading_deg: f64, pitch_deg: f64) {
        self.orbit = Orbit::posed(DVec3::new(x, y, z), heading_deg, pitch_deg, self.orbit.target.z);
        self.placed = true;
    }

    /// Ground height (metres, in the scene's vertical datum) at WGS 84 `lon`,
    /// `lat`: the terrain's where it is loaded, else the trees' bases nearby;
    /// NaN where nothing is known (yet) or before the scene's CRS is.
    pub fn height_at(&self, lon: f64, lat: f64) -> f64 {
        let (Some(geo), Some(m)) = (&self.geo, self.frame.stream.manifest()) else { return f64::NAN };
        let Ok(p) = geo.to_local(lon, lat, 0.0) else { return f64::NAN };
        self.frame.stream.ground_height_at(p.x as f32, p.y as f32).map_or(f64::NAN, |h| f64::from(h) + m.origin_m[2])
    }

    /// Ground height at `(x, y)` metres relative to the scene origin,
    /// relative to the origin like the camera's `z`; NaN where unknown.
    pub fn height_at_local(&self, x: f64, y: f64) -> f64 {
        self.frame.stream.ground_height_at(x as f32, y as f32).map_or(f64::NAN, f64::from)
    }

    /// The camera as JSON: `{x, y, z, heading, pitch}` (metres relative to the
    /// scene origin, degrees) plus `origin` (the scene origin), `epsg` and
    /// `ground` (the ground height under the eye, scene-relative like `z`; null
    /// where unknown).
    pub fn camera_json(&self) -> String {
        let c = self.camera();
        let origin = self.frame.stream.manifest().map_or([0.0; 3], |m| m.origin_m);
        let epsg = self.frame.stream.manifest().map_or(0, |m| m.crs.epsg);
        let ground = self.frame.stream.ground_height_at(c.eye_m.x as f32, c.eye_m.y as f32);
        let mut v = serde_json::json!({
            "x": c.eye_m.x, "y": c.eye_m.y, "z": c.eye_m.z,
            "heading": c.heading_rad.to_degrees(), "pitch": c.pitch_rad.to_degrees(),
            "origin": origin, "epsg": epsg, "fly": self.fly, "ground": ground,
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
        self.frame.settings.debug_lod = lod;
        self.frame.settings.debug_bounds = bounds;
    }

    /// Level-of-detail policy: trees at least `ellipsoid_min_px` tall (and below
    /// the simplified mesh) use clustered ellipsoids (infinity: none); `only`
    /// restricts drawing to one family (`"meshes"`, `"ellipsoids"`, `"billboards"`,
    /// `"clouds"`: every baked level of that family; `"all"`: the default mix by
    /// size, the bake's LoD policy); `exact_depth` writes the ellipsoids' exact ray-cast depth;
    /// far batches whose trees are below `thin_px` pixels draw an even, scaled-up
    /// subset of them (0: off).
    ///
    /// # Errors
    /// An `only` that is none of these (nothing is changed).
    pub fn set_lod(
        &mut self,
        ellipsoid_min_px: f32,
        only: &str,
        exact_depth: bool,
        thin_px: f32,
    ) -> Result<(), JsValue> {
        use crate::render::forest::Representations;
        self.frame.settings.representations = match only {
            "all" => Representations::default(),
            "meshes" => Representations::MESHES,
            "ellipsoids" => Representations::CLUSTERS,
            "billboards" => Representations::BILLBOARDS,
            "clouds" => Representations::CLOUDS,
            other => {
                return Err(JsValue::from_str(&format!(
                    "setLod: only '{other}' is not one of all, meshes, ellipsoids, billboards, clouds"
                )))
            }
        };
        // A family asked for by name draws every baked level (no LoD policy).
        self.frame.settings.lod_policy = only == "all";
        self.frame.settings.cluster_min_px =
            if ellipsoid_min_px.is_nan() { f32::INFINITY } else { ellipsoid_min_px.max(0.0) };
        self.frame.settings.cluster_exact_depth = exact_depth;
        self.frame.settings.thin_px = if thin_px.is_finite() { thin_px.clamp(0.0, 64.0) } else { 0.0 };
        Ok(())
    }

    /// Budgets: GPU memory for pools and packs in MB (0: none), download bytes per
    /// second (0: none), requests in flight (at least 1). The viewer degrades within
    /// them (coarser levels, shorter reach for new tiles) and says so in `stats()`.
    pub fn set_budget(&mut self, gpu_mb: f64, bytes_per_s: f64, in_flight: u32) {
        let mut c = self.frame.stream.config();
        c.gpu_budget_bytes = if gpu_mb.is_finite() && gpu_mb > 0.0 { (gpu_mb * 1e6) as u64 } else { 0 };
        c.max_bytes_per_s = if bytes_per_s.is_finite() && bytes_per_s > 0.0 { bytes_per_s } else { 0.0 };
        c.max_in_flight = in_flight.clamp(1, 64) as usize;
        self.frame.stream.set_config(c);
        self.frame.refine.invalidate();
    }

    /// The canopy rasters on (the default: where trees are a pixel or two they
    /// give way to the scene's canopy rasters, and trees under a pixel are
    /// neither fetched nor drawn) or off (every tree, however small).
    pub fn set_canopy(&mut self, on: bool) {
        self.frame.settings.canopy = on;
        self.frame.refine.invalidate();
    }

    /// Terrain on or off (off: neither fetched nor drawn), and the projected
    /// geometric error (pixels) up to which a coarser terrain level is kept.
    pub fn set_terrain(&mut self, on: bool, error_px: f32) {
        self.frame.settings.terrain = on;
        let mut c = self.frame.stream.config();
        c.terrain_error_px = if error_px.is_finite() { error_px.clamp(0.25, 64.0) } else { 2.0 };
        self.frame.stream.set_config(c);
        self.frame.refine.invalidate();
    }

    /// Where ground imagery comes from: `"scene"` (the scene's baked imagery,
    /// the default), `"off"`, or an XYZ/WMTS URL template in Web Mercator
    /// (`{z}/{x}/{y}`, `{-y}`, or `{TileMatrix}/{TileCol}/{TileRow}`) whose
    /// finest zoom is `max_zoom`.
    ///
    /// # Errors
    /// A template without the placeholders (the message says which are needed).
    pub fn set_imagery(&mut self, source: &str, max_zoom: u8) -> Result<(), JsValue> {
        use crate::scene::imagery::{ImageryChoice, XyzSource};
        let choice = match source {
            "" | "scene" => ImageryChoice::Scene,
            "off" => ImageryChoice::Off,
            t => ImageryChoice::Xyz(XyzSource::new(t, max_zoom).map_err(|e| JsValue::from_str(&e))?),
        };
        self.frame.stream.set_imagery(choice);
        self.frame.refine.invalidate();
        Ok(())
    }

    /// The sun at a local date and time of the scene's place (ISO 8601, e.g.
    /// `2026-06-21T15:00`, `Z` or `±HH:MM` for the offset from UTC; without
    /// one the whole hour of the place's longitude); `""` restores the
    /// default light. Returns `{azimuth, elevation}` (degrees) as JSON.
    ///
    /// # Errors
    /// A time that does not parse (the message shows the form), or a scene
    /// not loaded yet.
    pub fn set_sun_time(&mut self, time: &str) -> Result<String, JsValue> {
        if time.trim().is_empty() {
            self.frame.settings.lighting = crate::render::Lighting::default();
            return Ok("null".into());
        }
        let t = crate::sun::SunTime::parse(time).map_err(|e| JsValue::from_str(&e))?;
        let (Some(geo), Some(m)) = (&self.geo, self.frame.stream.manifest()) else {
            return Err(JsValue::from_str("the scene is not loaded yet"));
        };
        let (l, p) = crate::render::Lighting::at_time(geo, crate::render::Lighting::sun_point(m), &t)
            .map_err(|e| JsValue::from_str(&e))?;
        self.frame.settings.lighting = l;
        Ok(serde_json::json!({ "azimuth": p.azimuth_deg, "elevation": p.elevation_deg }).to_string())
    }

    /// The sun at `azimuth` (degrees clockwise from north) and `elevation`.
    ///
    /// # Errors
    /// A scene not loaded yet, or angles out of range.
    pub fn set_sun_angles(&mut self, azimuth: f64, elevation: f64) -> Result<(), JsValue> {
        if !(azimuth.is_finite() && (-90.0..=90.0).contains(&elevation)) {
            return Err(JsValue::from_str("setSun: azimuth in degrees, elevation −90–90"));
        }
        let (Some(geo), Some(m)) = (&self.geo, self.frame.stream.manifest()) else {
            return Err(JsValue::from_str("the scene is not loaded yet"));
        };
        self.frame.settings.lighting =
            crate::render::Lighting::at_angles(geo, crate::render::Lighting::sun_point(m), azimuth, elevation)
                .map_err(|e| JsValue::from_str(&e))?;
        Ok(())
    }

    /// The sun's shadows: `"off"`, `"low"` or `"high"`.
    ///
    /// # Errors
    /// Any other quality (the message names the three).
    pub fn set_shadows(&mut self, quality: &str) -> Result<(), JsValue> {
        self.frame.settings.shadows =
            quality.parse().map_err(|e: String| JsValue::from_str(&format!("setLighting: {e}")))?;
        Ok(())
    }

    /// Each tree's own baked ambient occlusion on or off.
    pub fn set_ao(&mut self, on: bool) {
        self.frame.settings.ao = on;
    }

    /// Progressive refinement while the camera rests: on or off, jittered
    /// frames per quality level (1–256) and quality levels above the plain
    /// frame (0–4, the last one full meshes).
    pub fn set_refine(&mut self, on: bool, frames: u32, levels: u32) {
        self.frame.refine.config = crate::render::refine::RefineConfig {
            enabled: on,
            jitter_frames: frames.clamp(1, 256),
            levels: levels.min(crate::render::refine::MAX_REFINE_LEVELS),
        };
    }

    /// Whether a refinement is under way: more frames would improve the image.
    /// False when it has converged (the viewer idles) or is off.
    pub fn refining(&self) -> bool {
        self.frame.refine.config.enabled && !self.frame.refine.converged() && self.frame.stream.manifest().is_some()
    }

    /// Frames submitted to the GPU so far.
    pub fn frames_drawn(&self) -> f64 {
        self.frame.frames() as f64
    }

    /// LoD quality factor (1, 0.5, 0.25).
    pub fn set_quality(&mut self, quality: f32) {
        self.frame.settings.quality = quality.clamp(0.05, 4.0);
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

    /// Loading progress: `{manifest, tiles_wanted, tiles_resident, loading, bytes_fetched, settled}`.
    pub fn progress_json(&self) -> String {
        let s = self.frame.stream.stats();
        serde_json::json!({
            "manifest": self.frame.stream.manifest().is_some(),
            "tiles_wanted": s.tiles_wanted,
            "tiles_resident": s.tiles_resident,
            "loading": s.loading,
            "bytes_fetched": s.bytes_fetched,
            "settled": self.frame.stream.is_settled(),
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
