//! Headless scene rendering (native): the shared [`Frame`] drawing into an
//! offscreen target, with named views, blocking loads and readback. Used by
//! `sylva render`, the tests and the benchmarks.

use std::time::Instant;

use glam::DVec3;

use crate::camera::Camera;
use crate::format::tile::{GpuBatch, PackedInstance};
use crate::format::Manifest;
pub use crate::frame::stats::FrameStats;
use crate::frame::Frame;
use crate::lod::select::DrawItem;
use crate::render::context::{read_texture_rgba8, GpuContext};
use crate::render::forest::{depth_texture, PoolConfig};
use crate::render::gpu_data::{CullControl, DrawArgs, REPR_COUNT};
use crate::scene::{Fetcher, StreamEvent, ThreadFetcher};

/// Colour format of offscreen targets (sRGB, like the browser canvas view).
pub const TARGET_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;

/// Named viewpoints derived from a scene's bounds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NamedView {
    /// The whole scene from afar, oblique.
    Far,
    /// A few hundred metres over the forest (nearer over a small plot).
    Medium,
    /// Near the ground among the trees.
    Close,
    /// Straight down over the whole scene.
    Top,
}

/// How far south of the first trees the close view stands (metres).
const CLOSE_STANDOFF_M: f64 = 6.0;
/// With no tree this near the close view's spot (metres), it moves to the
/// nearest tree: the view's near trees are meshes within about this distance.
const CLOSE_EMPTY_M: f64 = 25.0;

impl NamedView {
    /// The camera for this view of `m`.
    #[must_use]
    pub fn camera(self, m: &Manifest) -> Camera {
        // Where the trees are (two districts far apart: the larger), not the
        // middle of the whole extent.
        let focus = m.focus();
        let lo = DVec3::from(focus.min.map(f64::from));
        let hi = DVec3::from(focus.max.map(f64::from));
        let c = (lo + hi) * 0.5;
        let ext = ((hi - lo) * 0.5).truncate().max_element().max(10.0);
        // Ground near the centre: the lowest tree base of the tile holding it.
        let ground = m
            .tiles
            .iter()
            .filter(|t| {
                let (a, b) = (t.bounds.min, t.bounds.max);
                f64::from(a[0]) <= c.x && c.x <= f64::from(b[0]) && f64::from(a[1]) <= c.y && c.y <= f64::from(b[1])
            })
            .map(|t| f64::from(t.bounds.min[2]))
            .fold(lo.z, f64::max);
        match self {
            NamedView::Far => {
                // A small plot is seen from farther than its own size: its tallest trees whole.
                let ext = ext.max(4.0 * (hi.z - ground));
                Camera::look_at(DVec3::new(c.x, c.y - 1.1 * ext, hi.z + 0.45 * ext), DVec3::new(c.x, c.y, lo.z))
            }
            NamedView::Medium => {
                // A small plot (under 300 m across) is seen from nearer, so it
                // fills the view, but far enough to see its tallest trees whole.
                let s = (ext.max(1.2 * (hi.z - ground)) / 150.0).min(1.0);
                Camera::look_at(
                    DVec3::new(c.x, c.y - 260.0 * s, ground + 110.0 * s),
                    DVec3::new(c.x, c.y + 120.0 * s, ground),
                )
            }
            // At the southern edge of the forest, looking in, at eye height.
            NamedView::Close => Camera {
                eye_m: DVec3::new(c.x, lo.y - 6.0, ground + 1.7),
                heading_rad: 0.0,
                pitch_rad: 6f64.to_radians(),
                ..Camera::default()
            },
            NamedView::Top => {
                let cam = Camera::default();
                let h = ext * 1.1 / (f64::from(cam.fov_y_rad) * 0.5).tan();
                Camera {
                    eye_m: DVec3::new(c.x, c.y, hi.z + h),
                    heading_rad: 0.0,
                    pitch_rad: -std::f64::consts::FRAC_PI_2,
                    ..cam
                }
            }
        }
    }
}

/// A scene rendered headless into a `width`×`height` target: a [`Frame`] (it
/// dereferences to it: `renderer`, `stream`, `settings`) with a texture target.
pub struct OffscreenScene<F: Fetcher = ThreadFetcher> {
    /// The GPU.
    pub ctx: GpuContext,
    frame: Frame<F>,
    color: wgpu::Texture,
    depth: wgpu::Texture,
    width: u32,
    height: u32,
    started: Instant,
}

impl<F: Fetcher> std::ops::Deref for OffscreenScene<F> {
    type Target = Frame<F>;
    fn deref(&self) -> &Frame<F> {
        &self.frame
    }
}

impl<F: Fetcher> std::ops::DerefMut for OffscreenScene<F> {
    fn deref_mut(&mut self) -> &mut Frame<F> {
        &mut self.frame
    }
}

impl OffscreenScene<ThreadFetcher> {
    /// Opens `scene` (directory, `scene.json` or URL) with a thread fetcher.
    ///
    /// # Errors
    /// When no GPU adapter can be created.
    pub fn open(scene: &str, width: u32, height: u32, pools: PoolConfig) -> Result<Self, crate::render::ContextError> {
        let ctx = GpuContext::new_headless_blocking()?;
        Ok(Self::with_fetcher(ctx, scene, ThreadFetcher::new(6), width, height, pools))
    }
}

impl<F: Fetcher> OffscreenScene<F> {
    /// Opens `scene` with a given fetcher and context.
    pub fn with_fetcher(ctx: GpuContext, scene: &str, fetcher: F, width: u32, height: u32, pools: PoolConfig) -> Self {
        let color = ctx.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("offscreen colour"),
            size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: TARGET_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let depth = depth_texture(&ctx.device, width, height);
        let (device, queue, adapter) = (ctx.device.clone(), ctx.queue.clone(), ctx.adapter_summary());
        let mut frame = Frame::new(device, queue, adapter, TARGET_FORMAT, pools, scene, fetcher);
        // A CPU rasteriser (lavapipe) decodes BC7 at every texture sample: the
        // demo's draw took 157 s instead of 5.3 at 960×540. Plain packs there.
        if ctx.adapter.get_info().device_type == wgpu::DeviceType::Cpu {
            frame.set_block_textures(false);
        }
        Self { frame, ctx, color, depth, width, height, started: Instant::now() }
    }

    /// One streaming step for `camera` (non-blocking).
    pub fn update_stream(&mut self, camera: &Camera) -> Vec<StreamEvent> {
        let view = camera.view_data(self.width, self.height);
        self.frame.stream(&view, self.started.elapsed().as_secs_f64());
        self.frame.stream.drain_events()
    }

    /// Streams until everything `camera` needs is resident (or given up on), or
    /// `timeout_s` passes. Returns the events seen.
    pub fn load_view(&mut self, camera: &Camera, timeout_s: f64) -> Vec<StreamEvent> {
        let deadline = Instant::now() + std::time::Duration::from_secs_f64(timeout_s);
        let mut events = Vec::new();
        loop {
            events.extend(self.update_stream(camera));
            if self.stream.is_settled() || Instant::now() > deadline {
                // One more step so packs of just-arrived tiles are requested.
                events.extend(self.update_stream(camera));
                if self.stream.is_settled() || Instant::now() > deadline {
                    return events;
                }
            }
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
    }

    /// Streams until the manifest is in (or given up on, or `timeout_s` passes),
    /// fetching nothing a view would: the camera looks down from far below the
    /// scene. Returns the events seen.
    pub fn load_manifest(&mut self, timeout_s: f64) -> Vec<StreamEvent> {
        let nowhere = Camera::nowhere();
        let deadline = Instant::now() + std::time::Duration::from_secs_f64(timeout_s);
        let mut events = Vec::new();
        loop {
            events.extend(self.update_stream(&nowhere));
            if self.stream.manifest().is_some() || self.stream.is_settled() || Instant::now() > deadline {
                return events;
            }
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
    }

    /// The camera of a named view, placing the close view on the ground near the
    /// scene centre, and the medium view of an indexed scene (whose manifest
    /// lists no tiles to take the ground from) over the ground it looks at
    /// (loads the data around them to find the ground).
    pub fn named_camera(&mut self, view: NamedView, timeout_s: f64) -> Option<Camera> {
        let manifest = self.stream.manifest()?;
        let mut cam = view.camera(manifest);
        // The ground `camera` took for an indexed scene: its lowest tree.
        let guess = manifest.tiles.is_empty().then(|| f64::from(manifest.focus().min[2]));
        if let Some(guess) = guess.filter(|_| view == NamedView::Medium && cam.pitch_rad < -0.05) {
            // Where the view meets that ground.
            let f = cam.forward();
            let target = cam.eye_m + f * ((guess - cam.eye_m.z) / f.z);
            let (eye, mid) = (cam.eye_m, (cam.eye_m + target) * 0.5);
            let span = (target - eye).truncate().length();
            // Looking down from above the eye and the tallest tree, so the ground is in view.
            let top = cam.eye_m.z.max(f64::from(manifest.focus().max[2]));
            let down = Camera {
                pitch_rad: -std::f64::consts::FRAC_PI_2,
                eye_m: DVec3::new(mid.x, mid.y, top + 1.5 * span),
                ..cam
            };
            self.load_view(&down, timeout_s);
            let at = |s: &Self, p: DVec3| s.stream.ground_height_at(p.x as f32, p.y as f32).map(f64::from);
            if let Some(g) = at(self, target) {
                let dz = g - target.z;
                let mut eye = eye + DVec3::Z * dz;
                // Over a ridge between the eye and what it looks at: higher.
                if let Some(ge) = at(self, eye) {
                    eye.z = eye.z.max(ge + 20.0);
                }
                cam = Camera { fov_y_rad: cam.fov_y_rad, ..Camera::look_at(eye, DVec3::new(target.x, target.y, g)) };
            }
        }
        if view == NamedView::Close {
            // Look straight down at the spot first so its tile is resident.
            let down = Camera { pitch_rad: -std::f64::consts::FRAC_PI_2, eye_m: cam.eye_m + DVec3::Z * 200.0, ..cam };
            self.load_view(&down, timeout_s);
            // Among trees: the spot (the forest's southern edge, looking in) may
            // hold none in a sparse inventory (street trees around an empty
            // park). Then stand a few metres south of the nearest tree.
            let ahead = cam.eye_m + DVec3::Y * CLOSE_STANDOFF_M;
            if let Some(tree) = self.nearest_resident_tree(ahead) {
                if (tree - ahead).truncate().length() > CLOSE_EMPTY_M {
                    cam.eye_m = DVec3::new(tree.x, tree.y - CLOSE_STANDOFF_M, tree.z + 1.7);
                    let down = Camera { eye_m: cam.eye_m + DVec3::Z * 200.0, ..down };
                    self.load_view(&down, timeout_s);
                }
            }
            if let Some(z) = self.stream.ground_height_at(cam.eye_m.x as f32, cam.eye_m.y as f32) {
                cam.eye_m.z = f64::from(z) + 1.7;
            }
        }
        Some(cam)
    }

    /// The trunk base of the resident tree nearest to `at` (horizontally),
    /// read from the resident tiles' files: a one-off for a named view.
    fn nearest_resident_tree(&self, at: DVec3) -> Option<DVec3> {
        let species = u32::try_from(self.stream.manifest()?.species.len()).ok()?;
        let mut urls: Vec<String> = self.stream.tile_locations().into_iter().map(|(_, t)| t.tile_url).collect();
        urls.sort_unstable();
        urls.dedup();
        let mut best: Option<(f64, DVec3)> = None;
        for url in &urls {
            let Ok(bytes) = crate::scene::fetch::fetch_once(url) else { continue };
            let Ok(tile) = crate::format::tile::Tile::decode(url, &bytes, species) else { continue };
            for b in &tile.batches {
                let first = b.instance_offset as usize;
                for i in tile.instances.get(first..first + b.instance_count as usize).unwrap_or_default() {
                    let p = i.decode(b).position_m.map(f64::from);
                    let p = DVec3::from(p);
                    let d = (p - at).truncate().length();
                    if best.is_none_or(|(bd, _)| d < bd) {
                        best = Some((d, p));
                    }
                }
            }
        }
        best.map(|(_, p)| p)
    }

    /// Renders one frame from `camera`; with `measure`, waits for the GPU after each
    /// pass to time it and reads the counters back.
    pub fn render(&mut self, camera: &Camera, measure: bool) -> FrameStats {
        let view = camera.view_data(self.width, self.height);
        let color = self.color.create_view(&Default::default());
        let depth = self.depth.create_view(&Default::default());
        let recorded = self.frame.record(&view, &color, &depth, measure);
        self.frame.submit(recorded, measure);
        // Counters and GPU times of this frame only (none when not measured).
        self.frame.stats_of_last_frame()
    }

    /// Refines the image of `camera` while it rests ([`crate::render::refine`], with
    /// `config`, enabled here and off again after) from the plain frame until
    /// it has converged, `max_steps` frames were drawn or `timeout_s` passed,
    /// streaming what the finer levels need between steps. Each step is
    /// measured. Returns the last step's stats and the steps' summed GPU times
    /// (ms; `cull`, `draw`, `shadow`). [`Self::read_image`] then reads the
    /// refined image.
    pub fn render_converged(
        &mut self,
        camera: &Camera,
        config: crate::render::refine::RefineConfig,
        max_steps: u32,
        timeout_s: f64,
    ) -> (FrameStats, std::collections::BTreeMap<String, f64>) {
        self.frame.refine =
            crate::render::refine::Refinement::new(crate::render::refine::RefineConfig { enabled: true, ..config });
        let deadline = Instant::now() + std::time::Duration::from_secs_f64(timeout_s.max(0.0));
        let mut total = std::collections::BTreeMap::new();
        let mut stats = FrameStats::default();
        for _ in 0..max_steps.max(1) {
            // Finer levels may need finer parts of the packs: wait for them.
            let left = deadline.saturating_duration_since(Instant::now()).as_secs_f64();
            self.load_view(camera, left);
            stats = self.render(camera, true);
            for (pass, ms) in &stats.gpu_ms {
                *total.entry(pass.clone()).or_insert(0.0) += ms;
            }
            if stats.refine_converged || Instant::now() > deadline {
                break;
            }
        }
        self.frame.refine.config.enabled = false;
        (stats, total)
    }

    /// Runs the cull pass of the last frame's shadow cascade `i` again, alone,
    /// so [`Self::read_selection`] reads the casters it chose (tests against
    /// [`crate::lod::select::cpu_select`] with the cascade's view).
    ///
    /// # Panics
    /// If the last frame had no cascade `i`.
    pub fn rerun_cascade_cull(&mut self, i: usize) {
        let mut encoder = self.ctx.device.create_command_encoder(&Default::default());
        self.frame.renderer.encode_cascade_cull(&mut encoder, i);
        self.ctx.queue.submit([encoder.finish()]);
        let _ = self.ctx.device.poll(wgpu::PollType::wait_indefinitely());
    }

    /// Reads back what the last cull pass selected, with the pools it selected
    /// from: (per-slot draw items, batches, instances, visible batch count).
    /// For tests against [`crate::lod::select::cpu_select`].
    #[must_use]
    pub fn read_selection(&self) -> (Vec<Vec<DrawItem>>, Vec<GpuBatch>, Vec<PackedInstance>, u32) {
        let (control, args, items) = self.renderer.readback_buffers();
        let (batches, instances) = self.renderer.pool_buffers();
        let slots = self.renderer.slot_count() as usize;
        let control: CullControl =
            bytemuck::pod_read_unaligned(&read_buffer(&self.ctx, control, size_of::<CullControl>() as u64));
        let args: Vec<DrawArgs> =
            bytemuck::pod_collect_to_vec(&read_buffer(&self.ctx, args, (slots * size_of::<DrawArgs>()) as u64));
        let item_words: Vec<u32> = bytemuck::cast_slice(&read_buffer(&self.ctx, items, items.size())).to_vec();
        let table = self.renderer.species_table();
        let per_slot = (0..slots)
            .map(|slot| {
                let species = &table[slot / REPR_COUNT as usize];
                let base = species.slot_base[slot % REPR_COUNT as usize] as usize;
                let n = args[slot].instance_count as usize;
                (0..n).map(|i| (item_words[2 * (base + i)], item_words[2 * (base + i) + 1])).collect()
            })
            .collect();
        let batch_count = u64::from(self.renderer.batch_slots());
        let pool_batches: Vec<GpuBatch> =
            bytemuck::pod_collect_to_vec(&read_buffer(&self.ctx, batches, batch_count * size_of::<GpuBatch>() as u64));
        let pool_instances: Vec<PackedInstance> =
            bytemuck::pod_collect_to_vec(&read_buffer(&self.ctx, instances, instances.size()));
        (per_slot, pool_batches, pool_instances, control.batches_visible)
    }

    /// The last rendered image, RGBA8 sRGB, tightly packed rows.
    #[must_use]
    pub fn read_image(&self) -> Vec<u8> {
        read_texture_rgba8(&self.ctx, &self.color, 0, 0)
    }

    /// Target size.
    #[must_use]
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }
}

/// Copies `size` bytes of a GPU buffer (which needs COPY_SRC) to the CPU. Blocks.
#[must_use]
pub fn read_buffer(ctx: &GpuContext, buffer: &wgpu::Buffer, size: u64) -> Vec<u8> {
    crate::render::readback::read_buffer(ctx, buffer, size)
}
