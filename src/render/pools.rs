//! The GPU pools of resident trees: batches, instances, draw items, the cull
//! pass's counters and indirect arguments, the species table and draw params,
//! with their allocators and what the CPU keeps of each resident tile (its
//! boxes, for [`super::reach`]). Long-lived: the passes bind these buffers; tiles
//! are copied in once when they arrive and zeroed when evicted.

use std::ops::Range;

use glam::Vec3;

use super::gpu_data::{
    control_buffer_bytes, CullDispatch, DrawArgs, DrawParams, GpuSpecies, REPR_COUNT, STYLE_HEADER_WORDS,
    STYLE_OFFSET_BYTES,
};
use super::layouts::SharedLayouts;
use crate::format::tile::{GpuBatch, PackedInstance, Tile};
use crate::scene::{PoolError, TileSlot};

/// Bytes of a draw item (instance index and batch slot, `vec2<u32>` in `shaders/cull.wgsl`).
pub const ITEM_BYTES: u64 = size_of::<[u32; 2]>() as u64;

/// Pool sizes; the defaults keep every binding far below WebGPU's 128 MiB.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PoolConfig {
    /// Resident instances ([`PackedInstance`], 8 bytes each).
    pub instances: u32,
    /// Resident batches ([`GpuBatch`], 80 bytes each).
    pub batches: u32,
    /// Draw items ([`ITEM_BYTES`] each) shared by all slots.
    pub items: u32,
    /// Species the renderer can hold.
    pub species: u32,
}

impl Default for PoolConfig {
    fn default() -> Self {
        Self { instances: 4 << 20, batches: 1 << 16, items: 6 << 20, species: 256 }
    }
}

impl PoolConfig {
    /// This config cut down to what `limits` allow: every pool within the largest
    /// storage binding and buffer (WebGPU's defaults: 128 MiB and 256 MiB). Returns
    /// whether anything was cut.
    #[must_use]
    pub fn within_limits(self, limits: &wgpu::Limits) -> (Self, bool) {
        let max = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
        let fit = |count: u32, stride: u64| (u64::from(count).min(max / stride)) as u32;
        let c = Self {
            instances: fit(self.instances, size_of::<PackedInstance>() as u64),
            batches: fit(self.batches, size_of::<GpuBatch>() as u64),
            items: fit(self.items, ITEM_BYTES),
            species: self.species,
        };
        (c, c != self)
    }

    /// The smaller of this config and what a scene of `trees` in `batches` of
    /// `species` species can ever need: a small scene allocates little.
    #[must_use]
    pub fn for_scene(self, trees: u64, batches: u64, species: u32) -> Self {
        let clamp = |v: u64, max: u32| v.min(u64::from(max)).max(1) as u32;
        // A quarter more than the scene holds (at least 4,096 trees and 256
        // batches): a tile growing by prefix levels is uploaded again before its
        // old copy's room is given back, and freed ranges leave holes.
        Self {
            instances: clamp(trees.saturating_add((trees / 4).max(4096)), self.instances),
            batches: clamp(batches.saturating_add((batches / 4).max(256)), self.batches),
            // Each species' segments may each hold all its trees (one per representation).
            items: clamp(trees.saturating_mul(u64::from(REPR_COUNT)), self.items),
            species: species.clamp(1, self.species),
        }
    }

    /// GPU bytes the pools take.
    #[must_use]
    pub fn bytes(&self) -> u64 {
        let size = |bytes: usize| bytes as u64;
        // Instances, batches with their visible-list word, draw items (two words),
        // and per species its table record and per slot draw args and params.
        u64::from(self.instances) * size(size_of::<PackedInstance>())
            + u64::from(self.batches) * size(size_of::<GpuBatch>() + size_of::<u32>())
            + u64::from(self.items) * ITEM_BYTES
            + u64::from(self.species)
                * (size(size_of::<GpuSpecies>())
                    + u64::from(REPR_COUNT) * size(size_of::<DrawArgs>() + size_of::<DrawParams>()))
    }
}

/// First-fit allocator of index ranges.
#[derive(Debug, Clone)]
pub struct RangeAllocator {
    free: Vec<Range<u32>>,
}

impl RangeAllocator {
    /// All of `0..capacity` free.
    #[must_use]
    pub fn new(capacity: u32) -> Self {
        Self { free: std::iter::once(0..capacity).collect() }
    }

    /// Allocates `len` contiguous indices.
    pub fn alloc(&mut self, len: u32) -> Option<Range<u32>> {
        if len == 0 {
            return Some(0..0);
        }
        let i = self.free.iter().position(|r| r.len() as u32 >= len)?;
        let start = self.free[i].start;
        self.free[i].start += len;
        if self.free[i].is_empty() {
            self.free.remove(i);
        }
        Some(start..start + len)
    }

    /// Returns a range; neighbours are merged.
    pub fn release(&mut self, r: Range<u32>) {
        if r.is_empty() {
            return;
        }
        let i = self.free.partition_point(|f| f.start < r.start);
        self.free.insert(i, r);
        if i + 1 < self.free.len() && self.free[i].end == self.free[i + 1].start {
            self.free[i].end = self.free[i + 1].end;
            self.free.remove(i + 1);
        }
        if i > 0 && self.free[i - 1].end == self.free[i].start {
            self.free[i - 1].end = self.free[i].end;
            self.free.remove(i);
        }
    }

    /// Free indices in total.
    #[must_use]
    pub fn free_len(&self) -> u32 {
        self.free.iter().map(|r| r.len() as u32).sum()
    }
}

/// What the CPU keeps of a resident tile: enough to bound its trees' projected sizes.
pub struct TileBounds {
    /// First batch slot (identifies the tile).
    pub batch_start: u32,
    /// The tile's box.
    pub lo: Vec3,
    /// Upper corner.
    pub hi: Vec3,
    /// (species, tallest tree in metres).
    pub heights: Vec<(u32, f32)>,
    /// Each batch's box (lo, hi), species and tallest tree: the tighter bound
    /// for tiles near the eye.
    pub batches: Vec<(Vec3, Vec3, u32, f32)>,
}

impl TileBounds {
    fn of(tile: &Tile, batch_start: u32) -> Self {
        let mut bounds = TileBounds {
            batch_start,
            lo: Vec3::splat(f32::MAX),
            hi: Vec3::splat(f32::MIN),
            heights: Vec::new(),
            batches: Vec::with_capacity(tile.batches.len()),
        };
        for b in &tile.batches {
            let (c, h) = (Vec3::from(b.center_m), Vec3::from(b.half_extent_m));
            bounds.lo = bounds.lo.min(c - h);
            bounds.hi = bounds.hi.max(c + h);
            bounds.batches.push((c - h, c + h, b.species, b.max_height_m));
            match bounds.heights.iter_mut().find(|(s, _)| *s == b.species) {
                Some(x) => x.1 = x.1.max(b.max_height_m),
                None => bounds.heights.push((b.species, b.max_height_m)),
            }
        }
        bounds
    }
}

/// The pool buffers.
pub struct PoolBuffers {
    /// [`GpuBatch`] per batch slot.
    pub batches: wgpu::Buffer,
    /// [`PackedInstance`] per instance slot.
    pub instances: wgpu::Buffer,
    /// Draw items (instance, batch slot) written by the cull pass.
    pub items: wgpu::Buffer,
    /// Visible batch list.
    pub visible: wgpu::Buffer,
    /// [`super::gpu_data::CullControl`], then the styles ([`control_buffer_bytes`]).
    pub control: wgpu::Buffer,
    /// [`CullDispatch`].
    pub dispatch: wgpu::Buffer,
    /// [`DrawArgs`] per draw slot.
    pub args: wgpu::Buffer,
    /// [`GpuSpecies`] per species.
    pub species: wgpu::Buffer,
    /// [`DrawParams`] per draw slot (dynamic uniform offsets).
    pub draw_params: wgpu::Buffer,
}

/// Bind groups over the pools.
pub struct PoolGroups {
    /// Group 2 of the draw passes: batches, instances, items.
    pub instance: wgpu::BindGroup,
    /// Group 1 of the cull pass.
    pub cull: wgpu::BindGroup,
    /// Group 2 of `prepare_dispatch`.
    pub dispatch: wgpu::BindGroup,
    /// Group 3 of the draw passes: draw params.
    pub draw: wgpu::BindGroup,
    /// Group 1 of the bounds overlay.
    pub bounds: wgpu::BindGroup,
}

/// The layouts the pools' bind groups are made for.
pub struct PoolLayouts<'a> {
    /// Shared draw layouts.
    pub shared: &'a SharedLayouts,
    /// The cull pass's group 1 (`CullPipelines::layout`).
    pub cull: &'a wgpu::BindGroupLayout,
    /// The cull pass's dispatch group (`CullPipelines::dispatch_layout`).
    pub cull_dispatch: &'a wgpu::BindGroupLayout,
    /// The bounds overlay's group 1.
    pub bounds: &'a wgpu::BindGroupLayout,
}

/// Creates a GPU buffer (at least 16 bytes: empty bindings are invalid).
pub(crate) fn buffer(device: &wgpu::Device, label: &str, size: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size.max(16),
        usage,
        mapped_at_creation: false,
    })
}

fn create(device: &wgpu::Device, config: PoolConfig, layouts: &PoolLayouts<'_>) -> (PoolBuffers, PoolGroups) {
    use wgpu::BufferUsages as U;
    let slots = u64::from(config.species) * u64::from(REPR_COUNT);
    let bytes = |count: u64, record: usize| count * record as u64;
    let b = PoolBuffers {
        // COPY_SRC everywhere tests and stats read back from.
        batches: buffer(
            device,
            "batch pool",
            bytes(config.batches.into(), size_of::<GpuBatch>()),
            U::STORAGE | U::COPY_DST | U::COPY_SRC,
        ),
        instances: buffer(
            device,
            "instance pool",
            bytes(config.instances.into(), size_of::<PackedInstance>()),
            U::STORAGE | U::COPY_DST | U::COPY_SRC,
        ),
        items: buffer(device, "draw items", u64::from(config.items) * ITEM_BYTES, U::STORAGE | U::COPY_SRC),
        visible: buffer(device, "visible batches", bytes(config.batches.into(), size_of::<u32>()), U::STORAGE),
        // The control words, then the styles (none until a style asks: `set_styles`).
        control: buffer(device, "cull control", control_buffer_bytes(0, false), U::STORAGE | U::COPY_SRC | U::COPY_DST),
        dispatch: buffer(device, "cull dispatch", bytes(1, size_of::<CullDispatch>()), U::STORAGE | U::INDIRECT),
        args: buffer(device, "draw args", bytes(slots, size_of::<DrawArgs>()), U::STORAGE | U::INDIRECT | U::COPY_SRC),
        species: buffer(
            device,
            "species table",
            bytes(config.species.into(), size_of::<GpuSpecies>()),
            U::STORAGE | U::COPY_DST,
        ),
        draw_params: buffer(device, "draw params", bytes(slots, size_of::<DrawParams>()), U::UNIFORM | U::COPY_DST),
    };
    let groups = groups(device, &b, layouts);
    (b, groups)
}

/// The bind groups over the pool buffers `b`.
fn groups(device: &wgpu::Device, b: &PoolBuffers, layouts: &PoolLayouts<'_>) -> PoolGroups {
    fn entry(binding: u32, b: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
        wgpu::BindGroupEntry { binding, resource: b.as_entire_binding() }
    }
    let group = |label: &str, layout: &wgpu::BindGroupLayout, entries: &[wgpu::BindGroupEntry<'_>]| {
        device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some(label), layout, entries })
    };
    PoolGroups {
        instance: layouts.shared.instance_group(device, &b.batches, &b.instances, &b.items, &b.control),
        draw: layouts.shared.draw_group(device, &b.draw_params),
        cull: group(
            "cull",
            layouts.cull,
            &[
                entry(0, &b.batches),
                entry(1, &b.instances),
                entry(2, &b.species),
                entry(3, &b.visible),
                entry(4, &b.control),
                entry(5, &b.items),
                entry(6, &b.args),
            ],
        ),
        dispatch: group("cull dispatch", layouts.cull_dispatch, &[entry(0, &b.dispatch), entry(1, &b.control)]),
        bounds: group("bounds", layouts.bounds, &[entry(0, &b.batches), entry(1, &b.visible)]),
    }
}

/// The resident trees: pool buffers, their bind groups, allocators and counts.
pub struct Pools {
    config: PoolConfig,
    /// Whether the pools were cut down to the device's limits.
    limited: bool,
    /// The buffers.
    pub buffers: PoolBuffers,
    /// Bind groups over them.
    pub groups: PoolGroups,
    batch_alloc: RangeAllocator,
    instance_alloc: RangeAllocator,
    batch_high_water: u32,
    /// Resident instances per species.
    resident: Vec<u64>,
    tile_bounds: Vec<TileBounds>,
    /// Counts residency changes (tiles in or out), for caches of what depends on them.
    generation: u64,
}

impl Pools {
    /// Pools of `config` cut to the device's limits.
    #[must_use]
    pub fn new(device: &wgpu::Device, config: PoolConfig, layouts: &PoolLayouts<'_>) -> Self {
        let (config, limited) = config.within_limits(&device.limits());
        let (buffers, groups) = create(device, config, layouts);
        Self {
            config,
            limited,
            buffers,
            groups,
            batch_alloc: RangeAllocator::new(config.batches),
            instance_alloc: RangeAllocator::new(config.instances),
            batch_high_water: 0,
            resident: Vec::new(),
            tile_bounds: Vec::new(),
            generation: 0,
        }
    }

    /// Re-creates the pools at `config` cut to the device's limits when it differs
    /// and nothing was ever resident. Returns whether they were re-created.
    pub fn fit(&mut self, device: &wgpu::Device, config: PoolConfig, layouts: &PoolLayouts<'_>) -> bool {
        let (config, limited) = config.within_limits(&device.limits());
        if config == self.config || self.resident_instances() > 0 || self.batch_high_water > 0 {
            return false;
        }
        let (species, old_limited, generation) = (self.resident.len(), self.limited, self.generation);
        *self = Self::new(device, config, layouts);
        self.limited = old_limited || limited;
        self.resident = vec![0; species];
        // Caches keyed on the generation must not meet an old value again.
        self.generation = generation + 1;
        true
    }

    /// Makes room for a style byte per pool instance (`on`), or gives it back:
    /// the control buffer is re-created (its header cleared: no style) and
    /// the bind groups with it. Returns whether anything changed.
    pub fn set_styles(&mut self, device: &wgpu::Device, on: bool, growth: bool, layouts: &PoolLayouts<'_>) -> bool {
        let bytes = control_buffer_bytes(if on { self.config.instances } else { 0 }, growth);
        if self.buffers.control.size() == bytes {
            return false;
        }
        use wgpu::BufferUsages as U;
        self.buffers.control = buffer(device, "cull control", bytes, U::STORAGE | U::COPY_SRC | U::COPY_DST);
        self.groups = groups(device, &self.buffers, layouts);
        true
    }

    /// Whether a style byte per pool instance has room.
    #[must_use]
    pub fn has_style_bytes(&self) -> bool {
        self.buffers.control.size() > control_buffer_bytes(0, false)
    }

    /// Writes the styles' header ([`STYLE_HEADER_WORDS`] words).
    pub fn write_style_header(&self, queue: &wgpu::Queue, header: &[u32]) {
        queue.write_buffer(&self.buffers.control, STYLE_OFFSET_BYTES, bytemuck::cast_slice(header));
    }

    /// Writes the style bytes of pool instances from `first` on (a multiple of
    /// 4; `bytes` padded to 4). Ignored without room for style bytes.
    pub fn write_style_bytes(&self, queue: &wgpu::Queue, first: u32, bytes: &[u8]) {
        if !self.has_style_bytes() || !first.is_multiple_of(4) || !bytes.len().is_multiple_of(4) || bytes.is_empty() {
            return;
        }
        let at = STYLE_OFFSET_BYTES + u64::from(STYLE_HEADER_WORDS) * 4 + u64::from(first);
        if at + bytes.len() as u64 <= self.buffers.control.size() {
            queue.write_buffer(&self.buffers.control, at, bytes);
        }
    }

    /// Writes the growth bytes of pool instances from `first` on (as
    /// [`Self::write_style_bytes`]).
    pub fn write_growth_bytes(&self, queue: &wgpu::Queue, first: u32, bytes: &[u8]) {
        if !self.has_style_bytes() || !first.is_multiple_of(4) || !bytes.len().is_multiple_of(4) || bytes.is_empty() {
            return;
        }
        let at = STYLE_OFFSET_BYTES
            + u64::from(super::gpu_data::growth_words_at(self.config.instances)) * 4
            + u64::from(first);
        // (Without room for growth bytes, a scene without a timeline: nothing to write.)
        if at + bytes.len() as u64 <= self.buffers.control.size() {
            queue.write_buffer(&self.buffers.control, at, bytes);
        }
    }

    /// The configuration in use.
    #[must_use]
    pub fn config(&self) -> PoolConfig {
        self.config
    }

    /// Whether the pools were cut down to the device's limits.
    #[must_use]
    pub fn limited_by_device(&self) -> bool {
        self.limited
    }

    /// Starts a scene of `count` species: residency counts reset.
    pub fn set_species_count(&mut self, count: u32) {
        self.tile_bounds.clear();
        self.resident = vec![0; count as usize];
        self.generation += 1;
    }

    /// Copies a tile's batches (offsets rebased to the pool) and instance records
    /// (as they are) into the pools.
    ///
    /// # Errors
    /// [`PoolError::Full`] when there is no room (nothing is changed), or
    /// [`PoolError::UnknownSpecies`].
    pub fn upload_tile(&mut self, queue: &wgpu::Queue, tile: &Tile) -> Result<TileSlot, PoolError> {
        let species_count = self.resident.len() as u32;
        if let Some(b) = tile.batches.iter().find(|b| b.species >= species_count) {
            return Err(PoolError::UnknownSpecies(b.species));
        }
        let instances = self.instance_alloc.alloc(tile.instances.len() as u32).ok_or(PoolError::Full("instances"))?;
        let Some(batches) = self.batch_alloc.alloc(tile.batches.len() as u32) else {
            self.instance_alloc.release(instances);
            return Err(PoolError::Full("batches"));
        };
        let rebased: Vec<GpuBatch> = tile
            .batches
            .iter()
            .map(|b| GpuBatch { instance_offset: b.instance_offset + instances.start, ..*b })
            .collect();
        queue.write_buffer(
            &self.buffers.batches,
            u64::from(batches.start) * size_of::<GpuBatch>() as u64,
            bytemuck::cast_slice(&rebased),
        );
        queue.write_buffer(
            &self.buffers.instances,
            u64::from(instances.start) * size_of::<PackedInstance>() as u64,
            bytemuck::cast_slice(&tile.instances),
        );
        if !tile.batches.is_empty() {
            self.tile_bounds.push(TileBounds::of(tile, batches.start));
        }
        let mut counts: Vec<(u32, u32)> = Vec::new();
        for b in &tile.batches {
            match counts.iter_mut().find(|(s, _)| *s == b.species) {
                Some(c) => c.1 += b.instance_count,
                None => counts.push((b.species, b.instance_count)),
            }
            self.resident[b.species as usize] += u64::from(b.instance_count);
        }
        self.batch_high_water = self.batch_high_water.max(batches.end);
        self.generation += 1;
        Ok(TileSlot { batches, instances, species_counts: counts })
    }

    /// Evicts a resident tile: its batches are zeroed (the cull pass skips empty
    /// batches) and its ranges returned.
    pub fn evict_tile(&mut self, queue: &wgpu::Queue, slot: TileSlot) {
        self.tile_bounds.retain(|t| t.batch_start != slot.batches.start);
        let zeros = vec![0u8; slot.batches.len() * size_of::<GpuBatch>()];
        queue.write_buffer(&self.buffers.batches, u64::from(slot.batches.start) * size_of::<GpuBatch>() as u64, &zeros);
        for (s, n) in &slot.species_counts {
            self.resident[*s as usize] -= u64::from(*n);
        }
        self.batch_alloc.release(slot.batches);
        self.instance_alloc.release(slot.instances);
        self.generation += 1;
    }

    /// Resident instances of species `s`.
    #[must_use]
    pub fn resident(&self, s: usize) -> u64 {
        self.resident.get(s).copied().unwrap_or(0)
    }

    /// Resident instances in total.
    #[must_use]
    pub fn resident_instances(&self) -> u64 {
        self.resident.iter().sum()
    }

    /// Free instance slots.
    #[must_use]
    pub fn free_instances(&self) -> u32 {
        self.instance_alloc.free_len()
    }

    /// Batch slots the cull pass tests (the high-water mark of the batch pool).
    #[must_use]
    pub fn batch_high_water(&self) -> u32 {
        self.batch_high_water
    }

    /// What the CPU keeps of each resident tile.
    #[must_use]
    pub fn tile_bounds(&self) -> &[TileBounds] {
        &self.tile_bounds
    }

    /// Changes with every tile made resident or evicted.
    #[must_use]
    pub fn generation(&self) -> u64 {
        self.generation
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pools_fit_device_limits_and_small_scenes() {
        // WebGPU's default limits: 128 MiB per storage binding.
        let limits = wgpu::Limits::default();
        let huge = PoolConfig { instances: 40 << 20, batches: 1 << 16, items: 60 << 20, species: 256 };
        let (fit, cut) = huge.within_limits(&limits);
        assert!(cut);
        assert_eq!(u64::from(fit.instances) * 8, limits.max_storage_buffer_binding_size / 8 * 8);
        assert_eq!(fit.batches, huge.batches, "what fits is kept");
        let (same, cut) = PoolConfig::default().within_limits(&limits);
        assert!(!cut && same == PoolConfig::default(), "the defaults fit WebGPU's limits");
        let small = PoolConfig::default().for_scene(3000, 200, 3);
        assert_eq!((small.instances, small.batches, small.items, small.species), (7096, 456, 24000, 3));
        assert!(small.bytes() < PoolConfig::default().bytes() / 100);
        assert_eq!(PoolConfig::default().for_scene(u64::MAX, 0, 0).instances, PoolConfig::default().instances);
    }

    #[test]
    fn range_allocator_first_fit_and_merge() {
        let mut a = RangeAllocator::new(100);
        let x = a.alloc(30).unwrap();
        let y = a.alloc(30).unwrap();
        let z = a.alloc(40).unwrap();
        assert_eq!((x.clone(), y.clone(), z.clone()), (0..30, 30..60, 60..100));
        assert!(a.alloc(1).is_none());
        a.release(y);
        assert_eq!(a.alloc(31), None);
        a.release(x);
        assert_eq!(a.free_len(), 60);
        assert_eq!(a.alloc(60), Some(0..60), "neighbours merged");
        a.release(0..60);
        a.release(z);
        assert_eq!(a.alloc(100), Some(0..100));
    }
}
