//! One frame, the same in both hosts: [`Frame`] owns the renderer, the stream
//! and the settings and runs stream step → prepare → cull pass → draw pass →
//! counter readback → [`FrameStats`]. The hosts keep only their target (an
//! offscreen texture in [`crate::offscreen`], the canvas in `web/`) and how
//! they wait: natively a measured frame blocks until the GPU is done; the
//! browser never blocks, so its GPU times and counters arrive a few frames late.

pub mod pacing;
pub mod stats;

use crate::camera::ViewData;
use crate::render::forest::{ForestRenderer, GpuResidency, PoolConfig, RenderSettings};
use crate::render::gpu_data::REPR_COUNT;
use crate::render::readback::{CounterReadback, PassTimer};
use crate::render::refine::{Accumulator, Plan, Refinement};
use crate::scene::{Fetcher, SceneStream, StreamConfig};
use stats::FrameStats;

/// Milliseconds on a monotonic clock: `performance.now()` in the browser, a
/// process-wide [`std::time::Instant`] natively.
#[must_use]
pub fn now_ms() -> f64 {
    #[cfg(target_arch = "wasm32")]
    {
        use wasm_bindgen::JsCast;
        let global = js_sys::global();
        let performance = js_sys::Reflect::get(&global, &"performance".into()).ok();
        let now = performance.as_ref().and_then(|p| js_sys::Reflect::get(p, &"now".into()).ok());
        match (performance, now.as_ref().and_then(|f| f.dyn_ref::<js_sys::Function>())) {
            (Some(p), Some(f)) => f.call0(&p).ok().and_then(|v| v.as_f64()).unwrap_or(0.0),
            _ => js_sys::Date::now(),
        }
    }
    #[cfg(not(target_arch = "wasm32"))]
    {
        static START: std::sync::OnceLock<std::time::Instant> = std::sync::OnceLock::new();
        START.get_or_init(std::time::Instant::now).elapsed().as_secs_f64() * 1e3
    }
}

/// A frame's command buffers: the shadow cascades (when shadows are on), the
/// cull pass, then the draw pass (submitted apart so each one's GPU time can
/// be measured).
pub struct Recorded {
    /// The shadow cascades (cull and casters of each), when shadows are drawn.
    shadow: Option<wgpu::CommandBuffer>,
    /// None when a converged refinement draws no scene.
    cull: Option<wgpu::CommandBuffer>,
    draw: wgpu::CommandBuffer,
    /// The refinement's accumulate and resolve passes, after the draw.
    refine: Option<wgpu::CommandBuffer>,
    read_counters: bool,
}

/// A pick recorded ([`Frame::record_pick`]): its commands, and the buffer
/// the picked pixel's id is copied into (map it once they are submitted;
/// [`read_pick`] reads it).
pub struct PickRecorded {
    /// Cull pass, id pass and the copy of the pixel.
    pub commands: wgpu::CommandBuffer,
    /// 256 bytes, `MAP_READ`.
    pub readback: wgpu::Buffer,
}

/// The pool instance a mapped pick readback names (None: no tree at the pixel).
#[must_use]
pub fn read_pick(mapped: &[u8]) -> Option<u32> {
    let id = u32::from_le_bytes(mapped.get(..4)?.try_into().ok()?);
    id.checked_sub(1)
}

/// A style and what of it is on the GPU.
#[derive(Default)]
struct StyleState {
    style: Option<crate::scene::style::TreeStyle>,
    /// Bumped by every change of style or selection.
    generation: u64,
    /// (style generation, styles epoch) of the header on the GPU.
    header: Option<(u64, u64)>,
    /// The style bytes (one per pool instance) as uploaded.
    bytes: Vec<u8>,
    /// Per resident tile (number, instance range): the style generation its
    /// bytes were made with and its data's state then (pending, ready, broken).
    written: std::collections::HashMap<(usize, u32, u32), (u64, u8)>,
    /// The growth bytes (one per pool instance) as uploaded, at a date.
    growth: Vec<u8>,
    /// The view's date (days since 1970-01-01) for a scene with a timeline.
    day: Option<i64>,
    /// The scene's timeline, resolved once its manifest is in (`None` inside: none).
    timeline: Option<Option<crate::format::timeline::TimelineColumns>>,
}

/// The frustum of pixel `px` of `view` (eye-relative planes, as [`ViewData::frustum`]).
#[must_use]
pub fn pixel_frustum(view: &ViewData, px: [u32; 2]) -> [glam::Vec4; 6] {
    let [w, h] = view.viewport.map(|v| v.max(1) as f32);
    // The pixel's box in normalised device coordinates (y up), mapped onto −1…1.
    let (x0, x1) = (px[0] as f32 / w * 2.0 - 1.0, (px[0] + 1) as f32 / w * 2.0 - 1.0);
    let (y0, y1) = (1.0 - (px[1] + 1) as f32 / h * 2.0, 1.0 - px[1] as f32 / h * 2.0);
    let (sx, sy) = (2.0 / (x1 - x0), 2.0 / (y1 - y0));
    let zoom = glam::Mat4::from_cols(
        glam::Vec4::new(sx, 0.0, 0.0, 0.0),
        glam::Vec4::new(0.0, sy, 0.0, 0.0),
        glam::Vec4::Z,
        glam::Vec4::new(-(x0 + x1) * 0.5 * sx, -(y0 + y1) * 0.5 * sy, 0.0, 1.0),
    );
    crate::camera::frustum_planes(&(zoom * view.clip_from_eye))
}

/// The id pass's targets, kept between picks (remade when the viewport changes).
struct PickTargets {
    ids: wgpu::Texture,
    depth: wgpu::Texture,
    size: [u32; 2],
}

/// The frame shared by both hosts (see the module docs).
pub struct Frame<F: Fetcher> {
    /// The device.
    pub device: wgpu::Device,
    /// The queue.
    pub queue: wgpu::Queue,
    /// The renderer (passes and resident data).
    pub renderer: ForestRenderer,
    /// The stream feeding it.
    pub stream: SceneStream<F>,
    /// How to draw.
    pub settings: RenderSettings,
    /// Progressive refinement while the camera rests (off unless its
    /// `config.enabled`; [`crate::render::refine`]).
    pub refine: Refinement,
    accumulator: Option<Accumulator>,
    color_format: wgpu::TextureFormat,
    adapter: String,
    readback: CounterReadback,
    /// Timestamp queries around the passes, where asked for and available.
    timer: Option<PassTimer>,
    /// Wall times (cull, draw, shadow) of the last frame waited for, and its number.
    waited: Option<(u64, [f64; 3])>,
    /// Shadow cascades of the last frame recorded.
    cascades: u32,
    /// The texture encodings the stream takes (the settings' choice, applied).
    textures: crate::render::settings::TextureChoice,
    /// Block-compressed packs where the device samples them (off on CPU
    /// rasterisers natively: lavapipe decodes BC7 at every sample, ~30× slower draws).
    block_textures: bool,
    draw_calls: u32,
    cpu_ms: f64,
    frames: u64,
    pick: Option<PickTargets>,
    style: StyleState,
}

impl<F: Fetcher> Frame<F> {
    /// A frame drawing `scene` (directory, `scene.json` path or URL) fetched by
    /// `fetcher` into `color_format` targets, with pools of at most `pools`.
    /// `adapter` names the GPU in the stats.
    #[must_use]
    pub fn new(
        device: wgpu::Device,
        queue: wgpu::Queue,
        adapter: String,
        color_format: wgpu::TextureFormat,
        pools: PoolConfig,
        scene: &str,
        fetcher: F,
    ) -> Self {
        let renderer = ForestRenderer::new(&device, color_format, pools);
        let readback = CounterReadback::new(&device, pools.species * REPR_COUNT);
        let mut stream = SceneStream::new(scene, fetcher, StreamConfig::default());
        // Packs with block-compressed textures where the GPU samples them.
        stream.set_texture_encodings(crate::render::mesh::block_formats(&device));
        Self {
            renderer,
            stream,
            settings: RenderSettings::default(),
            refine: Refinement::default(),
            accumulator: None,
            color_format,
            adapter,
            readback,
            timer: None,
            waited: None,
            cascades: 0,
            textures: crate::render::settings::TextureChoice::Auto,
            block_textures: true,
            draw_calls: 0,
            cpu_ms: 0.0,
            frames: 0,
            pick: None,
            style: StyleState::default(),
            device,
            queue,
        }
    }

    /// Whether packs' block-compressed variants are taken where the device
    /// samples them (default on; `OffscreenScene` turns it off on a CPU
    /// adapter, where sampling BC7 costs ~30× the draw time). Applies to
    /// packs not yet chosen: call before streaming.
    pub fn set_block_textures(&mut self, on: bool) {
        self.block_textures = on;
        self.apply_texture_choice();
    }

    fn apply_texture_choice(&mut self) {
        use crate::render::settings::TextureChoice;
        let sampled = crate::render::mesh::block_formats(&self.device);
        let encodings = match self.textures {
            TextureChoice::Plain => Vec::new(),
            TextureChoice::Only(e) => sampled.into_iter().filter(|s| *s == e).collect(),
            TextureChoice::Auto if self.block_textures => sampled,
            TextureChoice::Auto => Vec::new(),
        };
        self.stream.set_texture_encodings(encodings);
    }

    /// Times the passes with timestamp queries where the device has them (the
    /// browser: it cannot wait per pass). Natively the wall clock around each
    /// waited-for pass is used instead: lavapipe's compute timestamps read ~0.
    pub fn use_timestamps(&mut self) {
        self.timer = PassTimer::new(&self.device, &self.queue);
    }

    /// One non-blocking streaming step for `view` (`now_s`: a monotonic clock in
    /// seconds, for retry backoff). Events wait in the stream
    /// ([`SceneStream::drain_events`]).
    pub fn stream(&mut self, view: &ViewData, now_s: f64) {
        // Plain packs even where the GPU samples block-compressed ones, or one
        // encoding alone (`RenderSettings::textures`): for packs not yet fetched.
        if self.settings.textures != self.textures {
            self.textures = self.settings.textures;
            self.apply_texture_choice();
        }
        // The terrain setting decides what is fetched too, not only what is drawn.
        if self.stream.config().terrain != self.settings.terrain {
            let config = crate::scene::StreamConfig { terrain: self.settings.terrain, ..self.stream.config() };
            self.stream.set_config(config);
        }
        // A refinement's finer levels need finer parts of the packs: fetch for them.
        let settings = self.refine_plan(view).map_or(self.settings, |p| self.refine.settings(&self.settings, &p));
        self.renderer.measure_reach(view, &settings);
        // Far tiles are fetched as far as prefix thinning draws them.
        // (Thinning draws billboards: without them every tree is drawn.)
        let thinned = settings.thin_px > 0.0
            && settings.culling == crate::render::settings::CullingMode::Batches
            && settings.representations.billboards
            && !settings.whole_tiles;
        self.stream.set_prefix_view(thinned.then_some(crate::scene::streaming::PrefixView {
            thin_px: settings.thin_px,
            lod_scale: settings.quality,
            canopy: None,
        }));
        // Far trees give way to the canopy rasters (scenes that have them).
        self.stream.set_canopy_view(settings.canopy.then_some(crate::scene::streaming::CanopyView {
            px_lo: crate::render::settings::CANOPY_PX[0],
            px_hi: crate::render::settings::CANOPY_PX[1],
            cell_px: crate::render::settings::CANOPY_CELL_PX,
            lod_scale: settings.quality,
        }));
        let mut residency = GpuResidency { renderer: &mut self.renderer, device: &self.device, queue: &self.queue };
        self.stream.update(&mut residency, view, self.settings.draw_distance_m, now_s);
        if let Some(m) = self.stream.manifest() {
            let low = m.terrain.as_ref().map_or(m.bounds.min[2], |t| t.height_range_m[0].min(m.bounds.min[2]));
            self.renderer.set_height_span(m.bounds.max[2] - low);
        }
        if let Some(t) = self.stream.manifest().and_then(|m| m.terrain.as_ref()) {
            self.renderer.reserve_terrain(&self.device, t.grid, t.tiles, t.imagery.as_ref().map_or(0, |i| i.tiles));
        }
        self.apply_style();
    }

    /// Sets the style (colours, filter; `None` or a plain style: none). The
    /// selection is kept ([`Self::select`]).
    pub fn set_style(&mut self, style: Option<crate::scene::style::TreeStyle>) {
        let selected = self.style.style.as_ref().map_or(Vec::new(), crate::scene::style::TreeStyle::selection);
        let mut style = style.unwrap_or_default();
        style.set_selection(selected);
        self.style.style = Some(style);
        self.style.generation += 1;
        // A converged image shows the old style: start over.
        self.refine.invalidate();
    }

    /// Highlights the trees with these ids at every level of detail (replacing the selection).
    pub fn select<I: Into<crate::scene::style::TreeId>>(&mut self, ids: impl IntoIterator<Item = I>) {
        self.style.style.get_or_insert_with(Default::default).set_selection(ids);
        self.style.generation += 1;
        self.refine.invalidate();
    }

    /// Shows the trees standing on `day` (days since 1970-01-01; `None`: the
    /// latest date), for a scene with a timeline (censuses, planting and
    /// removal dates); other scenes are unchanged.
    pub fn set_day(&mut self, day: Option<i64>) {
        if self.style.day != day {
            self.style.day = day;
            self.style.generation += 1;
            self.refine.invalidate();
        }
    }

    /// The date the trees are shown at (`None`: the latest).
    #[must_use]
    pub fn day(&self) -> Option<i64> {
        self.style.day
    }

    /// The style in use.
    #[must_use]
    pub fn style(&self) -> Option<&crate::scene::style::TreeStyle> {
        self.style.style.as_ref()
    }

    /// Brings the GPU's styles up to date: the header once per change, the
    /// bytes of each resident tile once its ids and attributes are in (until
    /// then its trees keep their look, or are hidden while a filter is on).
    fn apply_style(&mut self) {
        let st = &mut self.style;
        // The date's part of the style: once the manifest says whether there is a timeline.
        if st.timeline.is_none() {
            if let Some(m) = self.stream.manifest() {
                st.timeline = Some(m.timeline.as_ref().and_then(|t| t.resolve(m.attributes.as_ref()).ok()));
                st.generation += 1;
            }
        }
        let timeline = st.timeline.as_ref().and_then(Option::as_ref);
        let wanted = st.day.filter(|d| timeline.is_some_and(|t| t.needs_trees(*d)));
        if st.style.as_ref().and_then(crate::scene::style::TreeStyle::date) != wanted {
            st.style.get_or_insert_with(Default::default).set_date(timeline, wanted);
            st.generation += 1;
        }
        let Some(style) = st.style.as_ref().filter(|s| !s.is_plain()) else {
            // None: the bytes' memory given back, the header cleared.
            self.stream.set_tree_data(false, false);
            if self.renderer.set_styles(&self.device, false, false) || st.header.is_some() {
                self.renderer.write_style_header(&self.queue, &[0; 128]);
            }
            st.header = None;
            st.bytes = Vec::new();
            st.growth = Vec::new();
            st.written.clear();
            return;
        };
        let needs = style.needs_trees();
        self.stream.set_tree_data(needs, needs && style.needs_attributes());
        // (Growth bytes only for a scene with a timeline.)
        let changed = self.renderer.set_styles(&self.device, needs, timeline.is_some());
        let epoch = self.renderer.styles_epoch();
        if changed || st.header.is_some_and(|(_, e)| e != epoch) {
            st.header = None;
            st.written.clear();
        }
        let n = self.renderer.config().instances as usize;
        if st.header != Some((st.generation, epoch)) {
            let mut header = style.header();
            header[crate::scene::style::STYLE_GROWTH_AT as usize] = crate::render::gpu_data::growth_words_at(n as u32);
            self.renderer.write_style_header(&self.queue, &header);
            st.header = Some((st.generation, epoch));
        }
        if !needs {
            return;
        }
        let dated = style.date().is_some();
        st.bytes.resize(n.next_multiple_of(4), 0);
        st.growth.resize(if dated { n.next_multiple_of(4) } else { 0 }, 128);
        let schema = self.stream.manifest().and_then(|m| m.attributes.as_ref());
        let hidden = if style.filters() { crate::scene::style::STYLE_HIDDEN } else { 0 };
        let mut present = std::collections::HashSet::new();
        for (t, range, runs, data) in self.stream.resident_tree_data() {
            use crate::scene::streaming::TreeDataState as S;
            // (A tile grown or trimmed in place holds other trees at the same start.)
            let key = (t, range.start, range.end);
            present.insert(key);
            let state = (
                st.generation,
                match data {
                    S::Pending => 0,
                    S::Ready(_) => 1,
                    S::Broken => 2,
                },
            );
            if st.written.get(&key) == Some(&state) || range.end as usize > n {
                continue;
            }
            let out = &mut st.bytes[range.start as usize..range.end as usize];
            match data {
                // A tile holding a prefix: each batch's resident trees are a run of the tile's.
                S::Ready(d) if !runs.is_empty() => {
                    for r in runs {
                        let (at, n, first) = (r[0] as usize, r[1] as usize, r[2] as usize);
                        style.tile_bytes(schema, &d.ids, d.codes.as_ref(), first, &mut out[at..at + n]);
                        if dated {
                            let start = range.start as usize + at;
                            style.tile_growth(schema, d.codes.as_ref(), first, &mut st.growth[start..start + n]);
                        }
                    }
                }
                S::Ready(d) => {
                    style.tile_bytes(schema, &d.ids, d.codes.as_ref(), 0, out);
                    if dated {
                        let g = &mut st.growth[range.start as usize..range.end as usize];
                        style.tile_growth(schema, d.codes.as_ref(), 0, g);
                    }
                }
                // Until its ids and attributes arrive a filter hides the tile's trees;
                // without them for good (a sidecar failed) they keep their own look.
                S::Pending => out.fill(hidden),
                S::Broken => out.fill(0),
            }
            if dated && !matches!(data, S::Ready(_)) {
                st.growth[range.start as usize..range.end as usize].fill(128);
            }
            let (a, b) = (range.start & !3, (range.end.next_multiple_of(4) as usize).min(st.bytes.len()));
            self.renderer.write_style_bytes(&self.queue, a, &st.bytes[a as usize..b]);
            if dated {
                self.renderer.write_growth_bytes(&self.queue, a, &st.growth[a as usize..b]);
            }
            st.written.insert(key, state);
        }
        st.written.retain(|k, _| present.contains(k));
    }

    /// Prepares and records a frame of `view` into `color` and `depth`; with
    /// `read_counters` (and no readback pending), its cull counters are copied
    /// for [`Self::stats`]. The CPU time of this is the frame's `frame_cpu_ms`.
    pub fn record(
        &mut self,
        view: &ViewData,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        read_counters: bool,
    ) -> Recorded {
        // Refining: the scene goes into the accumulator's target, which is
        // blended into the accumulation and resolved into `color`.
        let (counters, counters_frame) = self.readback.latest();
        self.refine.note_counters(counters_frame, counters.control.items_dropped);
        let Some(plan) = self.refine_plan(view) else {
            // Not refining: no accumulation images held either.
            self.accumulator = None;
            let settings = self.settings;
            return self.record_scene(view, &settings, color, depth, read_counters);
        };
        let t0 = now_ms();
        let accumulator = self.accumulator.get_or_insert_with(|| Accumulator::new(&self.device, self.color_format));
        let scene = accumulator.scene_target(&self.device, view.viewport);
        let mut recorded = if plan.render {
            let settings = self.refine.settings(&self.settings, &plan);
            let jittered = crate::render::refine::jittered(view, plan.jitter_px);
            self.record_scene(&jittered, &settings, &scene, depth, read_counters)
        } else {
            // Converged: only the image is shown again.
            let draw = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("draw") });
            self.draw_calls = 0;
            self.cascades = 0;
            self.cpu_ms = (now_ms() - t0).max(0.0);
            Recorded { shadow: None, cull: None, draw: draw.finish(), refine: None, read_counters: false }
        };
        let swap = self.refine.advance(self.frames + 1);
        let mut encoder = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("refine") });
        if let Some(accumulator) = self.accumulator.as_mut() {
            accumulator.encode(&mut encoder, &plan, swap, color);
        }
        // After the scene's draw (and its counter copy), in the same submission.
        recorded.refine = Some(encoder.finish());
        recorded
    }

    /// The refinement step `view` would draw next (None: not refining).
    fn refine_plan(&mut self, view: &ViewData) -> Option<Plan> {
        if !self.refine.config.enabled {
            return None;
        }
        // What is resident: a change (arrivals, evictions) restarts the level.
        let s = self.stream.stats();
        let data = [s.bytes_fetched, s.tiles_resident, s.terrain_resident, s.imagery_resident]
            .iter()
            .fold(self.renderer.resident_instances(), |h, &v| {
                h.rotate_left(13) ^ v.wrapping_mul(0x9e37_79b9_7f4a_7c15)
            });
        self.refine.observe(view, &self.settings, self.stream.is_settled(), data);
        Some(self.refine.plan())
    }

    fn record_scene(
        &mut self,
        view: &ViewData,
        settings: &RenderSettings,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        read_counters: bool,
    ) -> Recorded {
        let t0 = now_ms();
        self.apply_style();
        let data = self.prepare(view, settings);
        let queries = self.timer.as_ref().and_then(PassTimer::queries);
        let timed = queries.is_some();
        let mut shadow = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("shadow") });
        let shadow_draws = self.renderer.encode_shadows(&self.device, &mut shadow, &data, queries);
        self.cascades = data.cascades;
        let mut cull = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("cull") });
        self.renderer.encode_cull(&mut cull, &data, queries);
        let mut draw = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("draw") });
        self.draw_calls = self.renderer.encode_draw(&mut draw, color, depth, &data, queries) + shadow_draws;
        if let (true, Some(timer)) = (timed, self.timer.as_mut()) {
            timer.resolve(&mut draw);
        }
        let read_counters = read_counters && self.readback.is_idle();
        if read_counters {
            let slots = self.renderer.slot_count();
            self.renderer.copy_counters(&mut draw, self.readback.record(slots, data.cascades), data.cascades);
        }
        // Prepared and recorded; `finish` (wgpu's own validation) is not counted,
        // as before the frame was shared (docs/BENCHMARKS.md compares like with like).
        self.cpu_ms = (now_ms() - t0).max(0.0);
        let shadow = (data.cascades > 0).then(|| shadow.finish());
        Recorded { shadow, cull: Some(cull.finish()), draw: draw.finish(), refine: None, read_counters }
    }

    /// Prepares the terrain and the renderer for a frame of `view`.
    fn prepare(&mut self, view: &ViewData, settings: &RenderSettings) -> crate::render::forest::FrameData {
        let threshold = self.stream.config().terrain_error_px;
        let flags = if settings.debug_lod { crate::render::terrain::TERRAIN_LEVEL_COLOURS } else { 0 }
            | if settings.terrain_morph { 0 } else { crate::render::terrain::TERRAIN_NO_MORPH }
            | if settings.debug_cascades { crate::render::terrain::TERRAIN_CASCADE_COLOURS } else { 0 }
            | if settings.debug_next_cascade { crate::render::terrain::TERRAIN_NEXT_CASCADE } else { 0 };
        // (The threshold travels to the shader for reference only: the morph
        // is worked out per tile by the selection.)
        let threshold = threshold * settings.quality;
        let terrain = if settings.terrain { self.stream.terrain_draws() } else { &[] };
        self.renderer.prepare_terrain(&self.device, &self.queue, terrain, threshold, flags);
        let canopy = self.stream.canopy_active().filter(|_| settings.canopy).map(|c| [c.px_lo, c.px_hi]);
        self.renderer.prepare_canopy(
            &self.device,
            &self.queue,
            self.stream.canopy_draws(),
            canopy,
            settings.canopy_season(),
        );
        self.renderer.prepare(&self.device, &self.queue, view, settings)
    }

    /// Records a pick of the pixel `px` (from the top left) of `view`: the
    /// cull pass and the id pass (the trees as the plain frame draws them,
    /// alpha-tested, the ground hiding what is behind it; only that pixel is
    /// shaded), then the pixel's id copied out. None when `px` is outside the
    /// viewport. Nothing is drawn to the screen, and the next frame culls again.
    pub fn record_pick(&mut self, view: &ViewData, px: [u32; 2]) -> Option<PickRecorded> {
        let size = view.viewport;
        if px[0] >= size[0] || px[1] >= size[1] {
            return None;
        }
        // The plain frame's settings: no refinement step's dither or levels.
        let settings = self.settings;
        self.apply_style();
        // Only trees whose bounds reach the pixel are culled in: its own
        // frustum (the LoD choice is the view's, from its pixels per metre).
        let narrow = ViewData { frustum: pixel_frustum(view, px), ..*view };
        let data = self.prepare(&narrow, &settings);
        let targets = match self.pick.take() {
            Some(t) if t.size == size => t,
            _ => {
                let ids = self.device.create_texture(&wgpu::TextureDescriptor {
                    label: Some("tree ids"),
                    size: wgpu::Extent3d { width: size[0], height: size[1], depth_or_array_layers: 1 },
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format: crate::render::layouts::ID_FORMAT,
                    usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
                    view_formats: &[],
                });
                let depth = crate::render::forest::depth_texture(&self.device, size[0], size[1]);
                PickTargets { ids, depth, size }
            }
        };
        let readback = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("pick readback"),
            size: 256,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let mut encoder = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("pick") });
        self.renderer.encode_cull(&mut encoder, &data, None);
        let ids = targets.ids.create_view(&Default::default());
        let depth = targets.depth.create_view(&Default::default());
        self.renderer.encode_ids(&self.device, &mut encoder, &ids, &depth, &data, [px[0], px[1], 1, 1]);
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture: &targets.ids,
                mip_level: 0,
                origin: wgpu::Origin3d { x: px[0], y: px[1], z: 0 },
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &readback,
                layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(256), rows_per_image: Some(1) },
            },
            wgpu::Extent3d { width: 1, height: 1, depth_or_array_layers: 1 },
        );
        self.pick = Some(targets);
        Some(PickRecorded { commands: encoder.finish(), readback })
    }

    /// Picks the pixel `px` of `view` and waits for the answer: the pool
    /// instance of the tree drawn there (None: none, or `px` outside the
    /// viewport). [`crate::scene::SceneStream::locate_instance`] names its tile.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn pick_blocking(&mut self, view: &ViewData, px: [u32; 2]) -> Option<u32> {
        self.pick_many_blocking(view, &[px]).pop().flatten()
    }

    /// [`Self::pick_blocking`] for many pixels of one view, waiting once: each
    /// pick is submitted in turn (its uniforms written before its own submit,
    /// so each sees its own pixel's frustum) and all are read back together.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn pick_many_blocking(&mut self, view: &ViewData, pixels: &[[u32; 2]]) -> Vec<Option<u32>> {
        let readbacks: Vec<Option<wgpu::Buffer>> = pixels
            .iter()
            .map(|&px| {
                let recorded = self.record_pick(view, px)?;
                self.queue.submit([recorded.commands]);
                recorded.readback.slice(..).map_async(wgpu::MapMode::Read, |_| {});
                Some(recorded.readback)
            })
            .collect();
        if self.device.poll(wgpu::PollType::wait_indefinitely()).is_err() {
            return vec![None; pixels.len()];
        }
        readbacks
            .into_iter()
            .map(|buffer| {
                let buffer = buffer?;
                let id = read_pick(&buffer.slice(..).get_mapped_range().ok()?);
                buffer.unmap();
                id
            })
            .collect()
    }

    /// Submits a recorded frame. With `wait` (native, measured), each pass is
    /// waited for and timed by the wall clock, and the counters are read before
    /// this returns; without, counters and timestamps (where the device has them)
    /// are collected when the GPU is done (a later [`Self::collect`]).
    pub fn submit(&mut self, recorded: Recorded, wait: bool) {
        self.frames += 1;
        let frame = self.frames;
        let block = |device: &wgpu::Device| {
            // A lost device has nothing left to wait for: the frame's counters and
            // times then never arrive, and its stats say so (none of this frame's).
            let _ = device.poll(wgpu::PollType::wait_indefinitely());
        };
        if wait {
            // Earlier unwaited frames may still be running: their time is not this frame's.
            block(&self.device);
        }
        let ts = now_ms();
        let shadowed = recorded.shadow.is_some();
        if let Some(shadow) = recorded.shadow {
            self.queue.submit([shadow]);
            if wait {
                block(&self.device);
            }
        }
        let t0 = now_ms();
        if let Some(cull) = recorded.cull {
            self.queue.submit([cull]);
        }
        if wait {
            block(&self.device);
        }
        let t1 = now_ms();
        self.queue.submit(std::iter::once(recorded.draw).chain(recorded.refine));
        if recorded.read_counters {
            self.readback.map(frame);
        }
        if let Some(timer) = &mut self.timer {
            timer.map(frame);
        }
        if wait {
            block(&self.device);
            let shadow_ms = if shadowed { t0 - ts } else { 0.0 };
            self.waited = Some((frame, [t1 - t0, now_ms() - t1, shadow_ms]));
        }
        self.collect();
    }

    /// Picks up counters and timestamps the GPU has finished since the last call.
    pub fn collect(&mut self) {
        self.readback.collect();
        if let Some(timer) = &mut self.timer {
            timer.collect();
        }
    }

    /// Frames submitted so far.
    #[must_use]
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// The frame whose counters [`Self::stats`] reports (0: none yet).
    #[must_use]
    pub fn counters_frame(&self) -> u64 {
        self.readback.latest().1
    }

    /// The adapter's name as shown in the stats.
    #[must_use]
    pub fn adapter(&self) -> &str {
        &self.adapter
    }

    /// The stats of the last frame: its draw calls and CPU time, the stream's
    /// state, and the latest counters and GPU times read back (in the browser
    /// those of a frame or two earlier).
    #[must_use]
    pub fn stats(&self) -> FrameStats {
        self.stats_of(None)
    }

    /// Like [`Self::stats`], but counters and GPU times only of the last frame
    /// submitted (none when it was not waited for): what a blocking host reports.
    #[must_use]
    pub fn stats_of_last_frame(&self) -> FrameStats {
        self.stats_of(Some(self.frames))
    }

    fn stats_of(&self, frame: Option<u64>) -> FrameStats {
        let mut stats = FrameStats::gather(&self.renderer, &self.stream, self.draw_calls, self.cpu_ms);
        stats.adapter.clone_from(&self.adapter);
        stats.governor.impostors = if self.settings.moving_impostors { "moving" } else { "full" }.into();
        if self.refine.config.enabled {
            stats.refine_step = self.refine.step();
            stats.refine_level = self.refine.level();
            stats.refine_converged = self.refine.converged();
        }
        stats.gpu_bytes += self.accumulator.as_ref().map_or(0, Accumulator::bytes);
        let wanted = |f: u64| f > 0 && frame.is_none_or(|want| want == f);
        let (counters, counters_frame) = self.readback.latest();
        if wanted(counters_frame) {
            stats.apply_counters(counters);
        } else {
            stats.shadow_cascades = self.cascades;
        }
        let timed = self.timer.as_ref().and_then(PassTimer::latest).filter(|(f, _)| wanted(*f));
        if let Some((_, [cull, draw, shadow])) = timed {
            stats.gpu_ms.insert("cull".into(), cull);
            stats.gpu_ms.insert("draw".into(), draw);
            if stats.shadow_cascades > 0 {
                stats.gpu_ms.insert("shadow".into(), shadow);
            }
        } else if let Some((_, [cull, draw, shadow])) = self.waited.filter(|(f, _)| wanted(*f)) {
            stats.gpu_ms.insert("cull".into(), cull);
            stats.gpu_ms.insert("draw".into(), draw);
            if self.cascades > 0 {
                stats.gpu_ms.insert("shadow".into(), shadow);
            }
        }
        stats
    }
}
