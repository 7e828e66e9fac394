//! Headless scene rendering (native): a [`ForestRenderer`] drawing into an
//! offscreen target, fed by a [`SceneStream`], with stats and readback. Used by
//! `sylva render`, the tests and the benchmarks.

use std::time::Instant;

use glam::DVec3;
use serde::Serialize;

use super::camera::Camera;
use super::context::{read_texture_rgba8, GpuContext};
use super::cull::DrawItem;
use super::forest::{depth_texture, ForestRenderer, PoolConfig, RenderSettings};
use super::gpu_data::{Repr, REPR_COUNT};
use crate::format::tile::{GpuBatch, PackedInstance};
use crate::format::Manifest;
use crate::scene::{Fetcher, SceneStream, StreamConfig, StreamEvent, ThreadFetcher};

/// Colour format of offscreen targets (sRGB, like the browser canvas view).
pub const TARGET_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;

/// Per-frame statistics; the keys are stable and documented (docs/FORMAT.md §stats),
/// and the browser reports the same object.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct FrameStats {
    /// Draw calls recorded (≤ species × representations).
    pub draw_calls: u32,
    /// Instances drawn per representation (`mesh0`, `mesh1`, `billboard`).
    pub instances: std::collections::BTreeMap<String, u64>,
    /// Batch slots the cull pass tested.
    pub batches_tested: u32,
    /// Batches that passed the batch test.
    pub batches_visible: u32,
    /// Instances the per-instance pass tested.
    pub instances_tested: u32,
    /// Items dropped because a segment was full (should be 0).
    pub items_dropped: u32,
    /// Tiles resident in the GPU pools.
    pub tiles_resident: u64,
    /// Requests in flight.
    pub tiles_loading: u64,
    /// Bytes fetched so far.
    pub bytes_fetched: u64,
    /// Requests started so far (manifest, index nodes, tiles, packs).
    pub requests: u64,
    /// Tiles known so far (flat list, or leaves of the index nodes read).
    pub tiles_known: u64,
    /// Tiles in the scene.
    pub tiles_total: u64,
    /// Index nodes read so far (0 for a flat manifest).
    pub index_nodes_loaded: u64,
    /// Index nodes in the scene (0 for a flat manifest).
    pub index_nodes_total: u64,
    /// What budgets or device limits hold back (`pools_full`, `gpu_budget`,
    /// `bandwidth`, `reach_m`).
    pub degraded: std::collections::BTreeMap<String, serde_json::Value>,
    /// Files given up on (not found, corrupt, or failed every retry): what the
    /// image lacks. Empty when the view is complete.
    pub failed: Vec<crate::scene::streaming::LoadFailure>,
    /// Trees in the scene.
    pub trees_total: u64,
    /// Trees resident on the GPU.
    pub trees_resident: u64,
    /// GPU memory estimate (pools + packs), bytes.
    pub gpu_bytes: u64,
    /// CPU time to prepare and record the frame, ms.
    pub frame_cpu_ms: f64,
    /// GPU time per pass, ms (wall time around submit + wait: lavapipe's compute
    /// timestamps are unreliable).
    pub gpu_ms: std::collections::BTreeMap<String, f64>,
}

/// Named viewpoints derived from a scene's bounds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NamedView {
    /// The whole scene from afar, oblique.
    Far,
    /// A few hundred metres over the forest.
    Medium,
    /// Near the ground among the trees.
    Close,
    /// Straight down over the whole scene.
    Top,
}

impl NamedView {
    /// The camera for this view of `m`.
    #[must_use]
    pub fn camera(self, m: &Manifest) -> Camera {
        let lo = DVec3::from(m.bounds.min.map(f64::from));
        let hi = DVec3::from(m.bounds.max.map(f64::from));
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
                Camera::look_at(DVec3::new(c.x, c.y - 1.1 * ext, hi.z + 0.45 * ext), DVec3::new(c.x, c.y, lo.z))
            }
            NamedView::Medium => {
                Camera::look_at(DVec3::new(c.x, c.y - 260.0, ground + 110.0), DVec3::new(c.x, c.y + 120.0, ground))
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

/// A scene rendered headless into a `width`×`height` target.
pub struct OffscreenScene<F: Fetcher = ThreadFetcher> {
    /// The GPU.
    pub ctx: GpuContext,
    /// The renderer.
    pub renderer: ForestRenderer,
    /// The stream.
    pub stream: SceneStream<F>,
    /// Drawing settings.
    pub settings: RenderSettings,
    color: wgpu::Texture,
    depth: wgpu::Texture,
    width: u32,
    height: u32,
    started: Instant,
    readback: wgpu::Buffer,
}

impl OffscreenScene<ThreadFetcher> {
    /// Opens `scene` (directory, `scene.json` or URL) with a thread fetcher.
    ///
    /// # Errors
    /// When no GPU adapter can be created.
    pub fn open(scene: &str, width: u32, height: u32, pools: PoolConfig) -> Result<Self, super::ContextError> {
        let ctx = GpuContext::new_headless_blocking()?;
        Ok(Self::with_fetcher(ctx, scene, ThreadFetcher::new(6), width, height, pools))
    }
}

impl<F: Fetcher> OffscreenScene<F> {
    /// Opens `scene` with a given fetcher and context.
    pub fn with_fetcher(ctx: GpuContext, scene: &str, fetcher: F, width: u32, height: u32, pools: PoolConfig) -> Self {
        let renderer = ForestRenderer::new(&ctx.device, TARGET_FORMAT, pools);
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
        let slots = u64::from(pools.species * REPR_COUNT);
        let readback = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("stats readback"),
            size: 32 + slots * 20,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        Self {
            stream: SceneStream::new(scene, fetcher, StreamConfig::default()),
            renderer,
            ctx,
            settings: RenderSettings::default(),
            color,
            depth,
            width,
            height,
            started: Instant::now(),
            readback,
        }
    }

    /// One streaming step for `camera` (non-blocking).
    pub fn update_stream(&mut self, camera: &Camera) -> Vec<StreamEvent> {
        let view = camera.view_data(self.width, self.height);
        let now = self.started.elapsed().as_secs_f64();
        self.renderer.measure_reach(&view, &self.settings);
        self.stream.update(
            &mut self.renderer,
            &self.ctx.device,
            &self.ctx.queue,
            &view,
            self.settings.draw_distance_m,
            now,
        );
        self.stream.drain_events()
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

    /// The camera of a named view, placing the close view on the ground near the
    /// scene centre (loads the data around it to find the ground).
    pub fn named_camera(&mut self, view: NamedView, timeout_s: f64) -> Option<Camera> {
        let mut cam = view.camera(self.stream.manifest()?);
        if view == NamedView::Close {
            // Look straight down at the spot first so its tile is resident.
            let down = Camera { pitch_rad: -std::f64::consts::FRAC_PI_2, eye_m: cam.eye_m + DVec3::Z * 200.0, ..cam };
            self.load_view(&down, timeout_s);
            if let Some(z) = self.stream.ground_height_at(cam.eye_m.x as f32, cam.eye_m.y as f32) {
                cam.eye_m.z = f64::from(z) + 1.7;
            }
        }
        Some(cam)
    }

    /// Renders one frame from `camera`; with `measure`, waits for the GPU after each
    /// pass to time it and reads the counters back.
    pub fn render(&mut self, camera: &Camera, measure: bool) -> FrameStats {
        let cpu = Instant::now();
        let view = camera.view_data(self.width, self.height);
        self.renderer.prepare(&self.ctx.queue, &view, &self.settings);
        let mut cull = self.ctx.device.create_command_encoder(&Default::default());
        self.renderer.encode_cull(&mut cull);
        let mut draw = self.ctx.device.create_command_encoder(&Default::default());
        let color_view = self.color.create_view(&Default::default());
        let depth_view = self.depth.create_view(&Default::default());
        let draw_calls = self.renderer.encode_draw(&mut draw, &color_view, &depth_view, self.settings.clear);
        let (control, args, _) = self.renderer.readback_buffers();
        let slot_bytes = u64::from(self.renderer.slot_count()) * 20;
        if measure {
            draw.copy_buffer_to_buffer(control, 0, &self.readback, 0, 32);
            if slot_bytes > 0 {
                draw.copy_buffer_to_buffer(args, 0, &self.readback, 32, slot_bytes);
            }
        }
        let frame_cpu_ms = cpu.elapsed().as_secs_f64() * 1e3;
        let mut stats = FrameStats { draw_calls, frame_cpu_ms, ..Default::default() };
        let wait = |ctx: &GpuContext| ctx.device.poll(wgpu::PollType::wait_indefinitely()).expect("GPU wait");
        if measure {
            // Earlier unmeasured frames may still be running: their time is not this frame's.
            wait(&self.ctx);
        }
        let t = Instant::now();
        self.ctx.queue.submit([cull.finish()]);
        if measure {
            wait(&self.ctx);
            stats.gpu_ms.insert("cull".into(), t.elapsed().as_secs_f64() * 1e3);
        }
        let t = Instant::now();
        self.ctx.queue.submit([draw.finish()]);
        if measure {
            wait(&self.ctx);
            stats.gpu_ms.insert("draw".into(), t.elapsed().as_secs_f64() * 1e3);
            self.read_counters(&mut stats, slot_bytes);
        }
        let s = self.stream.stats();
        stats.batches_tested = self.renderer.batch_slots();
        stats.tiles_resident = s.tiles_resident;
        stats.tiles_loading = s.loading;
        stats.bytes_fetched = s.bytes_fetched;
        stats.requests = s.requests;
        stats.tiles_known = s.tiles_known;
        stats.tiles_total = self.stream.manifest().map_or(0, |m| m.counts.tiles);
        stats.index_nodes_loaded = s.index_nodes_loaded;
        stats.index_nodes_total = s.index_nodes_total;
        let d = s.degraded;
        stats.degraded = [
            ("pools_full", serde_json::json!(d.pools_full)),
            ("gpu_budget", serde_json::json!(d.gpu_budget)),
            ("bandwidth", serde_json::json!(d.bandwidth)),
            ("device_limit", serde_json::json!(d.device_limit)),
            ("reach_m", serde_json::json!(if d.reach_m.is_finite() { f64::from(d.reach_m) } else { -1.0 })),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect();
        stats.failed = self.stream.failures().to_vec();
        stats.trees_total = self.stream.manifest().map_or(0, |m| m.counts.trees);
        stats.trees_resident = self.renderer.resident_instances();
        stats.gpu_bytes = self.renderer.gpu_bytes();
        stats
    }

    fn read_counters(&self, stats: &mut FrameStats, slot_bytes: u64) {
        let slice = self.readback.slice(..32 + slot_bytes);
        slice.map_async(wgpu::MapMode::Read, |r| r.expect("map stats"));
        self.ctx.device.poll(wgpu::PollType::wait_indefinitely()).expect("GPU wait");
        {
            let data = slice.get_mapped_range().expect("mapped");
            let words: &[u32] = bytemuck::cast_slice(&data);
            stats.batches_visible = words[0];
            stats.instances_tested = words[4];
            stats.items_dropped = words[5];
            for repr in Repr::ALL {
                stats.instances.insert(repr.name().into(), 0);
            }
            for slot in 0..self.renderer.slot_count() as usize {
                let repr = Repr::ALL[slot % REPR_COUNT as usize];
                *stats.instances.entry(repr.name().into()).or_default() += u64::from(words[8 + slot * 5 + 1]);
            }
        }
        self.readback.unmap();
    }

    /// Reads back what the last cull pass selected, with the pools it selected
    /// from: (per-slot draw items, batches, instances, visible batch count).
    /// For tests against [`super::cull::cpu_select`].
    #[must_use]
    pub fn read_selection(&self) -> (Vec<Vec<DrawItem>>, Vec<GpuBatch>, Vec<PackedInstance>, u32) {
        let (control, args, items) = self.renderer.readback_buffers();
        let (batches, instances) = self.renderer.pool_buffers();
        let slots = self.renderer.slot_count() as usize;
        let control: Vec<u32> = bytemuck::cast_slice(&read_buffer(&self.ctx, control, 32)).to_vec();
        let args: Vec<u32> = bytemuck::cast_slice(&read_buffer(&self.ctx, args, slots as u64 * 20)).to_vec();
        let item_words: Vec<u32> = bytemuck::cast_slice(&read_buffer(&self.ctx, items, items.size())).to_vec();
        let table = self.renderer.species_table();
        let per_slot = (0..slots)
            .map(|slot| {
                let species = &table[slot / REPR_COUNT as usize];
                let base = species.slot_base[slot % REPR_COUNT as usize] as usize;
                let n = args[slot * 5 + 1] as usize;
                (0..n).map(|i| (item_words[2 * (base + i)], item_words[2 * (base + i) + 1])).collect()
            })
            .collect();
        let batch_count = u64::from(self.renderer.batch_slots());
        let pool_batches: Vec<GpuBatch> =
            bytemuck::pod_collect_to_vec(&read_buffer(&self.ctx, batches, batch_count * 80));
        let pool_instances: Vec<PackedInstance> =
            bytemuck::pod_collect_to_vec(&read_buffer(&self.ctx, instances, instances.size()));
        (per_slot, pool_batches, pool_instances, control[0])
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
    let size = size.max(4).next_multiple_of(4);
    let staging = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, size);
    ctx.queue.submit([encoder.finish()]);
    let slice = staging.slice(..);
    slice.map_async(wgpu::MapMode::Read, |r| r.expect("map readback"));
    ctx.device.poll(wgpu::PollType::wait_indefinitely()).expect("GPU wait");
    let data = slice.get_mapped_range().expect("mapped").to_vec();
    staging.unmap();
    data
}
