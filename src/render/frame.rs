//! One frame, the same in both hosts: [`Frame`] owns the renderer, the stream
//! and the settings and runs stream step → prepare → cull pass → draw pass →
//! counter readback → [`FrameStats`]. The hosts keep only their target (an
//! offscreen texture in [`super::offscreen`], the canvas in `web.rs`) and how
//! they wait: natively a measured frame blocks until the GPU is done; the
//! browser never blocks, so its GPU times and counters arrive a few frames late.

use std::sync::{Arc, Mutex};

use super::forest::{ForestRenderer, GpuResidency, PoolConfig, RenderSettings};
use super::gpu_data::REPR_COUNT;
use super::stats::{CullCounters, FrameStats};
use crate::camera::ViewData;
use crate::scene::{Fetcher, SceneStream, StreamConfig};

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

/// A frame's command buffers: the cull pass, then the draw pass (submitted
/// apart so each one's GPU time can be measured).
pub struct Recorded {
    cull: wgpu::CommandBuffer,
    draw: wgpu::CommandBuffer,
    read_counters: bool,
}

/// The cull counters read back from the GPU: mapped asynchronously, collected
/// when the mapping is done (at once natively after a wait, a few frames later
/// in the browser).
struct CounterReadback {
    buffer: wgpu::Buffer,
    /// Bytes the pending mapping covers.
    mapped_len: u64,
    /// 0 idle, 1 copy recorded, 2 mapping, 3 mapped.
    state: Arc<Mutex<u8>>,
    counters: CullCounters,
    /// The frame whose counters the pending mapping holds, and of the counters read.
    pending_frame: u64,
    counters_frame: u64,
}

impl CounterReadback {
    fn new(device: &wgpu::Device, slots: u32) -> Self {
        Self {
            buffer: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("stats readback"),
                size: CullCounters::readback_bytes(slots),
                usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                mapped_at_creation: false,
            }),
            mapped_len: 0,
            state: Arc::new(Mutex::new(0)),
            counters: CullCounters::default(),
            pending_frame: 0,
            counters_frame: 0,
        }
    }

    fn state(&self) -> u8 {
        *self.state.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn set_state(&self, s: u8) {
        *self.state.lock().unwrap_or_else(std::sync::PoisonError::into_inner) = s;
    }

    /// Starts mapping after the copy was submitted.
    fn map(&mut self, frame: u64) {
        if self.state() != 1 {
            return;
        }
        self.set_state(2);
        self.pending_frame = frame;
        let state = self.state.clone();
        self.buffer.slice(..self.mapped_len).map_async(wgpu::MapMode::Read, move |r| {
            *state.lock().unwrap_or_else(std::sync::PoisonError::into_inner) = if r.is_ok() { 3 } else { 0 };
        });
    }

    /// Decodes a finished mapping.
    fn collect(&mut self) {
        if self.state() != 3 {
            return;
        }
        if let Ok(data) = self.buffer.slice(..self.mapped_len).get_mapped_range() {
            self.counters = CullCounters::from_bytes(&data);
            self.counters_frame = self.pending_frame;
        }
        self.buffer.unmap();
        self.set_state(0);
    }
}

/// GPU times of the passes of one frame, in ms.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct PassTimes {
    frame: u64,
    submitted_ms: f64,
    cull_done_ms: Option<f64>,
    draw_done_ms: Option<f64>,
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
    adapter: String,
    readback: CounterReadback,
    /// Times of the frame being measured, and of the last one measured whole.
    timing: Arc<Mutex<PassTimes>>,
    last_times: PassTimes,
    draw_calls: u32,
    cpu_ms: f64,
    frames: u64,
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
        Self {
            renderer,
            stream: SceneStream::new(scene, fetcher, StreamConfig::default()),
            settings: RenderSettings::default(),
            adapter,
            readback,
            timing: Arc::default(),
            last_times: PassTimes::default(),
            draw_calls: 0,
            cpu_ms: 0.0,
            frames: 0,
            device,
            queue,
        }
    }

    /// One non-blocking streaming step for `view` (`now_s`: a monotonic clock in
    /// seconds, for retry backoff). Events wait in the stream
    /// ([`SceneStream::drain_events`]).
    pub fn stream(&mut self, view: &ViewData, now_s: f64) {
        self.renderer.measure_reach(view, &self.settings);
        let mut residency = GpuResidency { renderer: &mut self.renderer, device: &self.device, queue: &self.queue };
        self.stream.update(&mut residency, view, self.settings.draw_distance_m, now_s);
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
        let t0 = now_ms();
        let data = self.renderer.prepare(&self.queue, view, &self.settings);
        let mut cull = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("cull") });
        self.renderer.encode_cull(&mut cull, &data);
        let mut draw = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("draw") });
        self.draw_calls = self.renderer.encode_draw(&mut draw, color, depth, &data);
        let read_counters = read_counters && self.readback.state() == 0;
        if read_counters {
            self.readback.mapped_len = CullCounters::readback_bytes(self.renderer.slot_count());
            self.renderer.copy_counters(&mut draw, &self.readback.buffer);
            self.readback.set_state(1);
        }
        let recorded = Recorded { cull: cull.finish(), draw: draw.finish(), read_counters };
        self.cpu_ms = (now_ms() - t0).max(0.0);
        recorded
    }

    /// Submits a recorded frame. With `wait` (native, measured), each pass is
    /// waited for and timed and the counters are read before this returns;
    /// without, GPU times and counters are collected when the GPU reports them
    /// (a later [`Self::collect`]).
    pub fn submit(&mut self, recorded: Recorded, wait: bool) {
        self.frames += 1;
        let frame = self.frames;
        let block = |device: &wgpu::Device| {
            // A lost device has nothing left to wait for; the frame's stats stay partial.
            let _ = device.poll(wgpu::PollType::wait_indefinitely());
        };
        if wait {
            // Earlier unwaited frames may still be running: their time is not this frame's.
            block(&self.device);
        }
        *self.timing.lock().unwrap_or_else(std::sync::PoisonError::into_inner) =
            PassTimes { frame, submitted_ms: now_ms(), cull_done_ms: None, draw_done_ms: None };
        self.queue.submit([recorded.cull]);
        let timing = self.timing.clone();
        self.queue.on_submitted_work_done(move || {
            let mut t = timing.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            if t.frame == frame {
                t.cull_done_ms = Some(now_ms());
            }
        });
        if wait {
            block(&self.device);
        }
        self.queue.submit([recorded.draw]);
        let timing = self.timing.clone();
        self.queue.on_submitted_work_done(move || {
            let mut t = timing.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            if t.frame == frame {
                t.draw_done_ms = Some(now_ms());
            }
        });
        if recorded.read_counters {
            self.readback.map(frame);
        }
        if wait {
            block(&self.device);
        }
        self.collect();
    }

    /// Picks up GPU times and counters the GPU has reported since the last call.
    pub fn collect(&mut self) {
        self.readback.collect();
        let t = *self.timing.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        if t.draw_done_ms.is_some() && t.frame != self.last_times.frame {
            self.last_times = t;
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
        self.readback.counters_frame
    }

    /// The adapter's name as shown in the stats.
    #[must_use]
    pub fn adapter(&self) -> &str {
        &self.adapter
    }

    /// The stats of the last frame: its draw calls and CPU time, the latest
    /// counters and GPU times read back, the stream's state.
    #[must_use]
    pub fn stats(&self) -> FrameStats {
        let mut stats = FrameStats::gather(&self.renderer, &self.stream, self.draw_calls, self.cpu_ms);
        stats.adapter.clone_from(&self.adapter);
        if self.readback.counters_frame > 0 {
            stats.apply_counters(&self.readback.counters);
        }
        let t = self.last_times;
        if let (Some(cull), Some(draw)) = (t.cull_done_ms, t.draw_done_ms) {
            stats.gpu_ms.insert("cull".into(), (cull - t.submitted_ms).max(0.0));
            stats.gpu_ms.insert("draw".into(), (draw - cull).max(0.0));
        }
        stats
    }
}
