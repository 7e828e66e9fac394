//! What a frame reads back from the GPU without blocking it: the cull pass's
//! counters and, where the device has timestamp queries (the browser), the
//! passes' GPU times. Each maps its buffer after the frame is submitted and is
//! collected once the mapping is done: at once natively after a wait, a few
//! frames later in the browser. One frame is in flight at a time; frames in
//! between read nothing back.

use std::sync::{Arc, Mutex};

use super::counters::CullCounters;

/// A mapping's state, shared with its callback.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum MapState {
    /// Free for the next frame's copy.
    Idle,
    /// A copy was recorded into a frame not yet submitted.
    Recorded,
    /// Submitted, mapping.
    Mapping,
    /// Mapped: ready to decode.
    Mapped,
}

/// A readback buffer and its state.
struct Mapped {
    buffer: wgpu::Buffer,
    len: u64,
    state: Arc<Mutex<MapState>>,
    frame: u64,
}

impl Mapped {
    fn new(device: &wgpu::Device, label: &str, size: u64) -> Self {
        Self {
            buffer: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                mapped_at_creation: false,
            }),
            len: 0,
            state: Arc::new(Mutex::new(MapState::Idle)),
            frame: 0,
        }
    }

    fn state(&self) -> MapState {
        *self.state.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn set(&self, s: MapState) {
        *self.state.lock().unwrap_or_else(std::sync::PoisonError::into_inner) = s;
    }

    /// Marks a copy of `len` bytes as recorded.
    fn recorded(&mut self, len: u64) {
        self.len = len;
        self.set(MapState::Recorded);
    }

    /// Starts mapping after the frame with the copy was submitted.
    fn map(&mut self, frame: u64) {
        if self.state() != MapState::Recorded {
            return;
        }
        self.set(MapState::Mapping);
        self.frame = frame;
        let state = self.state.clone();
        self.buffer.slice(..self.len).map_async(wgpu::MapMode::Read, move |r| {
            let next = if r.is_ok() { MapState::Mapped } else { MapState::Idle };
            *state.lock().unwrap_or_else(std::sync::PoisonError::into_inner) = next;
        });
    }

    /// Decodes a finished mapping with `decode`; returns its frame.
    fn take(&mut self, decode: impl FnOnce(&[u8])) -> Option<u64> {
        if self.state() != MapState::Mapped {
            return None;
        }
        let read = self.buffer.slice(..self.len).get_mapped_range().map(|data| decode(&data)).is_ok();
        self.buffer.unmap();
        self.set(MapState::Idle);
        read.then_some(self.frame)
    }
}

/// The cull counters read back (see the module docs).
pub struct CounterReadback {
    mapped: Mapped,
    /// (slots, cascades) of the copy recorded last.
    layout: (u32, u32),
    counters: CullCounters,
    /// The frame whose counters were read (0: none yet).
    frame: u64,
}

impl CounterReadback {
    /// A readback of up to `slots` draw slots.
    #[must_use]
    pub fn new(device: &wgpu::Device, slots: u32) -> Self {
        Self {
            mapped: Mapped::new(
                device,
                "stats readback",
                CullCounters::readback_bytes(slots, super::shadow::MAX_CASCADES as u32),
            ),
            counters: CullCounters::default(),
            layout: (0, 0),
            frame: 0,
        }
    }

    /// Whether a frame may record a copy now.
    #[must_use]
    pub fn is_idle(&self) -> bool {
        self.mapped.state() == MapState::Idle
    }

    /// The buffer to copy the counters of `slots` draw slots and `cascades`
    /// shadow cascades into; marks the copy recorded.
    pub fn record(&mut self, slots: u32, cascades: u32) -> &wgpu::Buffer {
        self.layout = (slots, cascades);
        self.mapped.recorded(CullCounters::readback_bytes(slots, cascades));
        &self.mapped.buffer
    }

    /// Starts mapping after frame `frame` was submitted.
    pub fn map(&mut self, frame: u64) {
        self.mapped.map(frame);
    }

    /// Decodes a finished mapping.
    pub fn collect(&mut self) {
        let mut counters = None;
        let (slots, cascades) = self.layout;
        if let Some(frame) = self.mapped.take(|d| counters = Some(CullCounters::from_bytes(d, slots, cascades))) {
            self.counters = counters.unwrap_or_default();
            self.frame = frame;
        }
    }

    /// The latest counters read, and their frame (0: none yet).
    #[must_use]
    pub fn latest(&self) -> (&CullCounters, u64) {
        (&self.counters, self.frame)
    }
}

/// Timestamp queries around the shadow, cull and draw passes (devices with
/// `TIMESTAMP_QUERY`; used in the browser, where waiting per pass is impossible).
pub struct PassTimer {
    queries: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    mapped: Mapped,
    /// Nanoseconds per tick.
    period_ns: f64,
    /// The latest frame read and its (cull ms, draw ms, shadow ms).
    latest: Option<(u64, [f64; 3])>,
}

/// Timestamps written per frame: cull begin, cull end, draw begin, draw end,
/// shadow cascades begin (their first cull pass) and end (their last draw;
/// both 0 in a frame without shadows).
const TIMESTAMPS: u32 = 6;

impl PassTimer {
    /// A timer, when the device has timestamp queries.
    #[must_use]
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue) -> Option<Self> {
        if !device.features().contains(wgpu::Features::TIMESTAMP_QUERY) {
            return None;
        }
        let bytes = u64::from(TIMESTAMPS) * size_of::<u64>() as u64;
        Some(Self {
            queries: device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("pass times"),
                ty: wgpu::QueryType::Timestamp,
                count: TIMESTAMPS,
            }),
            resolve: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("pass times resolve"),
                size: bytes,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            }),
            mapped: Mapped::new(device, "pass times readback", bytes),
            period_ns: f64::from(queue.get_timestamp_period()),
            latest: None,
        })
    }

    /// The query set to write this frame's timestamps into (indices 0, 1 for the
    /// cull pass, 2, 3 for the draw pass, 4, 5 around the shadow cascades), or
    /// `None` while the last is read.
    #[must_use]
    pub fn queries(&self) -> Option<&wgpu::QuerySet> {
        (self.mapped.state() == MapState::Idle).then_some(&self.queries)
    }

    /// Records the resolve and copy after the passes wrote their timestamps.
    pub fn resolve(&mut self, encoder: &mut wgpu::CommandEncoder) {
        let bytes = u64::from(TIMESTAMPS) * size_of::<u64>() as u64;
        encoder.resolve_query_set(&self.queries, 0..TIMESTAMPS, &self.resolve, 0);
        encoder.copy_buffer_to_buffer(&self.resolve, 0, &self.mapped.buffer, 0, bytes);
        self.mapped.recorded(bytes);
    }

    /// Starts mapping after frame `frame` was submitted.
    pub fn map(&mut self, frame: u64) {
        self.mapped.map(frame);
    }

    /// Decodes a finished mapping.
    pub fn collect(&mut self) {
        let mut ticks = [0u64; TIMESTAMPS as usize];
        if let Some(frame) = self.mapped.take(|d| ticks = bytemuck::pod_read_unaligned(d)) {
            let ms = |a: u64, b: u64| b.saturating_sub(a) as f64 * self.period_ns / 1e6;
            self.latest = Some((frame, [ms(ticks[0], ticks[1]), ms(ticks[2], ticks[3]), ms(ticks[4], ticks[5])]));
        }
    }

    /// The latest frame read and its (cull ms, draw ms, shadow ms).
    #[must_use]
    pub fn latest(&self) -> Option<(u64, [f64; 3])> {
        self.latest
    }
}

#[cfg(not(target_arch = "wasm32"))]
/// Copies `size` bytes of a GPU buffer (which needs COPY_SRC) to the CPU. Blocks.
#[must_use]
pub fn read_buffer(ctx: &super::GpuContext, buffer: &wgpu::Buffer, size: u64) -> Vec<u8> {
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
