//! The forest renderer: GPU pools of resident batches and instances, the
//! per-species LoD resources, and the frame (cull pass, then one indirect draw
//! per species × representation).
//!
//! CPU work per frame is O(species): write the view uniform, record five
//! dispatches and at most `species × REPR_COUNT` draws. Tiles are uploaded once
//! when they arrive; nothing per tree is touched by the CPU after that.

use std::ops::Range;

use glam::Vec3;

use super::billboard::{BillboardGpu, BillboardPipeline, BILLBOARD_VERTICES};
use super::camera::ViewData;
use super::cluster::{cluster_tiers, ClusterGpu, ClusterPipeline};
use super::cull::CullPipelines;
use super::gpu_data::{CullControl, DrawArgs, DrawParams, GpuSpecies, Repr, ViewUniform, REPR_COUNT};
use super::layouts::SharedLayouts;
use super::mesh::{MeshGpu, MeshPipelines, DEPTH_FORMAT};
use super::Lighting;
use crate::format::tile::{GpuBatch, PackedInstance, Tile};
use crate::format::Pack;

/// Bytes of a draw item (instance index and batch slot, `vec2<u32>` in `shaders/cull.wgsl`).
const ITEM_BYTES: u64 = size_of::<[u32; 2]>() as u64;

/// Segment capacity of the full mesh level per species: only trees hundreds of
/// pixels tall use it, a few hundred at most on any screen.
pub const MESH0_CAPACITY: u32 = 1 << 15;
/// Segment capacity of the simplified mesh level per species.
pub const MESH1_CAPACITY: u32 = 1 << 18;
/// Segment capacity of each cluster tier per species.
pub const CLUSTER_CAPACITY: u32 = 1 << 18;

/// Pool sizes; the defaults keep every binding far below WebGPU's 128 MiB.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PoolConfig {
    /// Resident instances (8 bytes each).
    pub instances: u32,
    /// Resident batches (80 bytes each).
    pub batches: u32,
    /// Draw items (8 bytes each) shared by all slots.
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
        Self {
            instances: clamp(trees, self.instances),
            batches: clamp(batches, self.batches),
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
            + u64::from(self.batches) * size(size_of::<GpuBatch>() + 4)
            + u64::from(self.items) * ITEM_BYTES
            + u64::from(self.species)
                * (size(size_of::<GpuSpecies>())
                    + u64::from(REPR_COUNT) * size(size_of::<DrawArgs>() + size_of::<DrawParams>()))
    }
}

/// Which culling the cull pass does: Sylva's, or a baseline to compare with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CullingMode {
    /// Batches first (sphere, box, distance), then trees (seed 004).
    #[default]
    Batches,
    /// Every resident tree tested on its own (the batch step skipped).
    PerTree,
    /// No culling: every resident tree is drawn (LoD still chosen).
    None,
}

/// How to draw: quality, draw distance, transitions, debug colouring.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderSettings {
    /// Scales projected sizes before LoD selection (1, ½, ¼ like seed 002 Fig. 12).
    pub quality: f32,
    /// Trees farther than this are not drawn (metres).
    pub draw_distance_m: f32,
    /// Half width of a transition band, as a fraction of its threshold.
    pub fade_band: f32,
    /// Colour trees by representation.
    pub debug_lod: bool,
    /// Draw the boxes of the batches that pass the batch test.
    pub debug_bounds: bool,
    /// Sun and ambient.
    pub lighting: Lighting,
    /// Clear colour (linear RGBA).
    pub clear: [f64; 4],
    /// Culling (benchmark baselines).
    pub culling: CullingMode,
    /// Trees drawn at least this tall (px) but below the simplified mesh's
    /// threshold use the clustered ellipsoids and lines of their pack (seed 002);
    /// smaller ones billboards. Infinity: no ellipsoids; 0: no billboards.
    pub cluster_min_px: f32,
    /// Which representation families may be drawn (benchmark baselines); the
    /// coarsest allowed one reaches down to 0 px, the finest up to infinity.
    pub representations: Representations,
    /// Ellipsoids write their exact ray-cast depth per pixel. Off by default: the
    /// proxy then sits at the ellipsoid's front-most depth and early depth tests
    /// stay on — 2.2–2.5× cheaper cluster draws for +0.001 multi-scale RMSE
    /// (docs/BENCHMARKS.md); only interpenetrating primitives can sort wrongly.
    pub cluster_exact_depth: bool,
    /// Prefix thinning (seed 004 ch. 7): a density-ordered batch whose trees are
    /// below this many pixels tall draws a prefix of them, scaled up to keep the
    /// canopy's coverage. 0: off.
    pub thin_px: f32,
}

/// Projected tree height from which a tile's batches are bounded one by one.
const REFINE_PX: f32 = 40.0;

/// Default of [`RenderSettings::thin_px`].
pub const DEFAULT_THIN_PX: f32 = 8.0;

/// Representation families a frame may use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Representations {
    /// Mesh levels.
    pub meshes: bool,
    /// Clustered ellipsoids and lines.
    pub clusters: bool,
    /// Billboards.
    pub billboards: bool,
}

impl Representations {
    /// Everything (Sylva's mixed pipeline).
    pub const ALL: Self = Self { meshes: true, clusters: true, billboards: true };
    /// Meshes only.
    pub const MESHES: Self = Self { meshes: true, clusters: false, billboards: false };
    /// Ellipsoids and lines only.
    pub const CLUSTERS: Self = Self { meshes: false, clusters: true, billboards: false };
    /// Billboards only.
    pub const BILLBOARDS: Self = Self { meshes: false, clusters: false, billboards: true };
}

impl Default for Representations {
    fn default() -> Self {
        Self::ALL
    }
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            quality: 1.0,
            draw_distance_m: 6000.0,
            fade_band: 0.12,
            debug_lod: false,
            debug_bounds: false,
            lighting: Lighting::default(),
            clear: [0.55, 0.68, 0.82, 1.0],
            culling: CullingMode::Batches,
            cluster_min_px: DEFAULT_CLUSTER_MIN_PX,
            representations: Representations::ALL,
            cluster_exact_depth: false,
            thin_px: DEFAULT_THIN_PX,
        }
    }
}

/// Default of [`RenderSettings::cluster_min_px`].
pub const DEFAULT_CLUSTER_MIN_PX: f32 = 40.0;

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

/// Where a resident tile lives in the pools.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TileSlot {
    /// Batch pool range.
    pub batches: Range<u32>,
    /// Instance pool range.
    pub instances: Range<u32>,
    /// Instances per species (index, count), to keep residency counts.
    pub species_counts: Vec<(u32, u32)>,
}

/// Why a tile could not be made resident.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PoolError {
    /// Not enough contiguous room: evict something and retry.
    #[error("the GPU pools are full ({0})")]
    Full(&'static str),
    /// A batch names a species the renderer was not told about.
    #[error("batch species {0} is outside the scene's species list")]
    UnknownSpecies(u32),
}

struct SpeciesGpu {
    mesh: MeshGpu,
    billboard: Option<BillboardGpu>,
    cluster: Option<ClusterGpu>,
    /// Cluster level of each cluster tier in use (set by `rebuild_table`).
    tiers: Vec<usize>,
    sphere: [f32; 4],
    height_m: f32,
    select_px: [f32; 2],
    index_counts: [u32; 2],
    /// Mesh levels 0 and 1 on the GPU.
    has_level: [bool; 2],
    bytes: u64,
}

/// Buffers of the pools.
struct Pools {
    batches: wgpu::Buffer,
    instances: wgpu::Buffer,
    items: wgpu::Buffer,
    visible: wgpu::Buffer,
    control: wgpu::Buffer,
    dispatch: wgpu::Buffer,
    args: wgpu::Buffer,
    species: wgpu::Buffer,
    draw_params: wgpu::Buffer,
}

/// The GPU-driven forest renderer (see the module docs).
pub struct ForestRenderer {
    /// Shared bind group layouts.
    pub shared: SharedLayouts,
    color_format: wgpu::TextureFormat,
    // Draw pipelines are built when the first pack holding their representation
    // arrives: a scene or view that never needs one never compiles it.
    mesh: Option<MeshPipelines>,
    billboard: Option<BillboardPipeline>,
    cluster: Option<ClusterPipeline>,
    cull: CullPipelines,
    sky: wgpu::RenderPipeline,
    bounds: wgpu::RenderPipeline,
    bounds_layout: wgpu::BindGroupLayout,
    bounds_group: wgpu::BindGroup,
    debug_bounds: bool,
    /// Whether the pools were cut down to the device's limits.
    limited: bool,
    config: PoolConfig,
    pools: Pools,
    view_buffer: wgpu::Buffer,
    view_group: wgpu::BindGroup,
    instance_group: wgpu::BindGroup,
    cull_group: wgpu::BindGroup,
    dispatch_group: wgpu::BindGroup,
    draw_group: wgpu::BindGroup,
    batch_alloc: RangeAllocator,
    instance_alloc: RangeAllocator,
    batch_high_water: u32,
    species_count: u32,
    resident: Vec<u64>,
    packs: Vec<Option<SpeciesGpu>>,
    table: Vec<GpuSpecies>,
    table_dirty: bool,
    cluster_min_px: f32,
    representations: Representations,
    cluster_exact_depth: bool,
    /// Resident tiles' boxes and tallest tree per species, to skip draws no tree can need.
    tile_bounds: Vec<TileBounds>,
    /// Per species: an upper bound of the projected height (px) of its resident
    /// trees this frame (0: none within reach).
    species_max_px: Vec<f32>,
    /// The view (eye, px scale, reach, thresholds) `species_max_px` was measured
    /// for; `None` when residency changed since.
    reach_measured: Option<[f32; 7]>,
    fade_band: f32,
    last_view: ViewUniform,
}

/// What the CPU keeps of a resident tile: enough to bound its trees' projected sizes.
struct TileBounds {
    batch_start: u32,
    lo: Vec3,
    hi: Vec3,
    /// (species, tallest tree in metres).
    heights: Vec<(u32, f32)>,
    /// Each batch's box (lo, hi), species and tallest tree: the tighter bound
    /// for tiles near the eye.
    batches: Vec<(Vec3, Vec3, u32, f32)>,
}

fn buffer(device: &wgpu::Device, label: &str, size: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size.max(16),
        usage,
        mapped_at_creation: false,
    })
}

/// Bind groups over the pools.
struct PoolGroups {
    instance: wgpu::BindGroup,
    cull: wgpu::BindGroup,
    dispatch: wgpu::BindGroup,
    draw: wgpu::BindGroup,
    bounds: wgpu::BindGroup,
}

/// Creates the pool buffers of `config` and the bind groups over them.
fn create_pools(
    device: &wgpu::Device,
    config: PoolConfig,
    shared: &SharedLayouts,
    cull: &CullPipelines,
    bounds_layout: &wgpu::BindGroupLayout,
) -> (Pools, PoolGroups) {
    use wgpu::BufferUsages as U;
    let slots = u64::from(config.species) * u64::from(REPR_COUNT);
    let pools = Pools {
        // COPY_SRC everywhere tests and stats read back from.
        batches: buffer(
            device,
            "batch pool",
            u64::from(config.batches) * size_of::<GpuBatch>() as u64,
            U::STORAGE | U::COPY_DST | U::COPY_SRC,
        ),
        instances: buffer(
            device,
            "instance pool",
            u64::from(config.instances) * size_of::<PackedInstance>() as u64,
            U::STORAGE | U::COPY_DST | U::COPY_SRC,
        ),
        items: buffer(device, "draw items", u64::from(config.items) * ITEM_BYTES, U::STORAGE | U::COPY_SRC),
        visible: buffer(device, "visible batches", u64::from(config.batches) * 4, U::STORAGE),
        control: buffer(device, "cull control", size_of::<CullControl>() as u64, U::STORAGE | U::COPY_SRC),
        dispatch: buffer(device, "cull dispatch", 8 * 4, U::STORAGE | U::INDIRECT),
        args: buffer(device, "draw args", slots * size_of::<DrawArgs>() as u64, U::STORAGE | U::INDIRECT | U::COPY_SRC),
        species: buffer(
            device,
            "species table",
            u64::from(config.species) * std::mem::size_of::<GpuSpecies>() as u64,
            U::STORAGE | U::COPY_DST,
        ),
        draw_params: buffer(device, "draw params", slots * size_of::<DrawParams>() as u64, U::UNIFORM | U::COPY_DST),
    };
    let instance_group = shared.instance_group(device, &pools.batches, &pools.instances, &pools.items);
    let draw_group = shared.draw_group(device, &pools.draw_params);
    fn entry(binding: u32, b: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
        wgpu::BindGroupEntry { binding, resource: b.as_entire_binding() }
    }
    let cull_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("cull"),
        layout: &cull.layout,
        entries: &[
            entry(0, &pools.batches),
            entry(1, &pools.instances),
            entry(2, &pools.species),
            entry(3, &pools.visible),
            entry(4, &pools.control),
            entry(5, &pools.items),
            entry(6, &pools.args),
        ],
    });
    let bounds_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("bounds"),
        layout: bounds_layout,
        entries: &[entry(0, &pools.batches), entry(1, &pools.visible)],
    });
    let dispatch_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("cull dispatch"),
        layout: &cull.dispatch_layout,
        entries: &[entry(0, &pools.dispatch), entry(1, &pools.control)],
    });
    let groups = PoolGroups {
        instance: instance_group,
        cull: cull_group,
        dispatch: dispatch_group,
        draw: draw_group,
        bounds: bounds_group,
    };
    (pools, groups)
}

impl ForestRenderer {
    /// Creates pipelines and pools for `color_format` targets.
    #[must_use]
    pub fn new(device: &wgpu::Device, color_format: wgpu::TextureFormat, config: PoolConfig) -> Self {
        use wgpu::BufferUsages as U;
        let shared = SharedLayouts::new(device);
        let cull = CullPipelines::new(device, &shared);
        let sky = overlay_pipeline(
            device,
            "sky",
            super::shaders::SKY,
            &[Some(&shared.view)],
            wgpu::PrimitiveTopology::TriangleList,
            color_format,
        );
        let vertex = wgpu::ShaderStages::VERTEX;
        let bounds_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("bounds"),
            entries: &[super::layouts::storage_entry(0, vertex, true), super::layouts::storage_entry(1, vertex, true)],
        });
        let bounds = overlay_pipeline(
            device,
            "bounds",
            super::shaders::BOUNDS,
            &[Some(&shared.view), Some(&bounds_layout)],
            wgpu::PrimitiveTopology::LineList,
            color_format,
        );
        let (config, limited) = config.within_limits(&device.limits());
        let view_buffer = buffer(device, "view", std::mem::size_of::<ViewUniform>() as u64, U::STORAGE | U::COPY_DST);
        let view_group = shared.view_group(device, &view_buffer);
        let (pools, groups) = create_pools(device, config, &shared, &cull, &bounds_layout);
        Self {
            shared,
            color_format,
            mesh: None,
            billboard: None,
            cluster: None,
            cull,
            sky,
            bounds,
            bounds_layout,
            bounds_group: groups.bounds,
            debug_bounds: false,
            config,
            limited,
            pools,
            view_buffer,
            view_group,
            instance_group: groups.instance,
            cull_group: groups.cull,
            dispatch_group: groups.dispatch,
            draw_group: groups.draw,
            batch_alloc: RangeAllocator::new(config.batches),
            instance_alloc: RangeAllocator::new(config.instances),
            batch_high_water: 0,
            species_count: 0,
            resident: Vec::new(),
            packs: Vec::new(),
            table: Vec::new(),
            table_dirty: true,
            cluster_min_px: DEFAULT_CLUSTER_MIN_PX,
            representations: Representations::ALL,
            cluster_exact_depth: false,
            tile_bounds: Vec::new(),
            species_max_px: Vec::new(),
            reach_measured: None,
            fade_band: 0.12,
            last_view: bytemuck::Zeroable::zeroed(),
        }
    }

    /// The pool configuration.
    #[must_use]
    pub fn config(&self) -> PoolConfig {
        self.config
    }

    /// Re-creates the pools at `config` cut to the device's limits (when it
    /// differs from the current one). Only while nothing is resident: call it
    /// when a scene's manifest arrives, with [`PoolConfig::for_scene`], so a small
    /// scene does not hold memory for millions of trees.
    pub fn fit_pools(&mut self, device: &wgpu::Device, config: PoolConfig) {
        let (config, limited) = config.within_limits(&device.limits());
        if config == self.config || self.resident_instances() > 0 || self.batch_high_water > 0 {
            return;
        }
        let (pools, groups) = create_pools(device, config, &self.shared, &self.cull, &self.bounds_layout);
        self.pools = pools;
        self.instance_group = groups.instance;
        self.cull_group = groups.cull;
        self.dispatch_group = groups.dispatch;
        self.draw_group = groups.draw;
        self.bounds_group = groups.bounds;
        self.batch_alloc = RangeAllocator::new(config.batches);
        self.instance_alloc = RangeAllocator::new(config.instances);
        self.config = config;
        self.limited |= limited;
        self.table_dirty = true;
    }

    /// Whether the pools were cut down to the device's limits (reported in stats).
    #[must_use]
    pub fn pools_limited_by_device(&self) -> bool {
        self.limited
    }

    /// Sets the scene's species count (from the manifest). Drops loaded packs.
    ///
    /// # Panics
    /// If `count` exceeds the configured species capacity.
    pub fn set_species_count(&mut self, count: u32) {
        assert!(count <= self.config.species, "{count} species exceed the renderer's {}", self.config.species);
        self.species_count = count;
        self.tile_bounds.clear();
        self.reach_measured = None;
        self.resident = vec![0; count as usize];
        self.packs = (0..count).map(|_| None).collect();
        self.table_dirty = true;
    }

    /// Whether species `i`'s pack is on the GPU.
    #[must_use]
    pub fn has_pack(&self, i: u32) -> bool {
        self.packs.get(i as usize).is_some_and(Option::is_some)
    }

    /// Uploads a decoded pack as species `index`.
    pub fn upload_pack(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, index: u32, pack: &Pack<'_>) {
        if self.packs.get(index as usize).is_none() {
            return;
        }
        let m = &pack.meta;
        use crate::format::pack::kind;
        let (shared, format) = (&self.shared, self.color_format);
        let any_level = (0..m.mesh_levels.len() as u32).any(|l| pack.section(kind::MESH_VERTICES, l).is_some());
        let mesh = if any_level {
            let pipelines = self.mesh.get_or_insert_with(|| MeshPipelines::new(device, shared, format));
            MeshGpu::upload(device, queue, pipelines, pack)
        } else {
            MeshGpu { levels: Vec::new() }
        };
        let billboard = if m.billboards.is_some() && pack.section(kind::BILLBOARD_COLOR, 0).is_some() {
            let pipeline = self.billboard.get_or_insert_with(|| BillboardPipeline::new(device, shared, format));
            BillboardGpu::upload(device, queue, pipeline, pack)
        } else {
            None
        };
        let cluster = if m.clusters.is_some() && pack.section(kind::ELLIPSOIDS, 0).is_some() {
            let pipeline = self.cluster.get_or_insert_with(|| ClusterPipeline::new(device, shared, format));
            ClusterGpu::upload(device, queue, pipeline, pack)
        } else {
            None
        };
        let Some(slot) = self.packs.get_mut(index as usize) else { return };
        let lo = Vec3::from(m.bounds_min);
        let hi = Vec3::from(m.bounds_max);
        let c = (lo + hi) * 0.5;
        let level = |l: usize| m.mesh_levels.get(l);
        // What goes to the GPU: every section but the JSON metadata.
        let bytes =
            pack.sections.iter().filter(|(e, _)| e.kind != crate::format::pack::kind::META).map(|(e, _)| e.bytes).sum();
        *slot = Some(SpeciesGpu {
            sphere: [c.x, c.y, c.z, ((hi - lo) * 0.5).length()],
            height_m: m.height_m,
            select_px: [level(0).map_or(0.0, |l| l.select_px), level(1).map_or(0.0, |l| l.select_px)],
            index_counts: [level(0).map_or(0, |l| l.index_count), level(1).map_or(0, |l| l.index_count)],
            has_level: [mesh.has_level(0), mesh.has_level(1)],
            mesh,
            billboard,
            cluster,
            tiers: Vec::new(),
            bytes,
        });
        self.table_dirty = true;
    }

    /// Makes a tile resident: copies its batches (offsets rebased to the pool) and
    /// its instance records (as they are) into the pools.
    ///
    /// # Errors
    /// [`PoolError::Full`] when there is no room (nothing is changed), or
    /// [`PoolError::UnknownSpecies`].
    pub fn upload_tile(&mut self, queue: &wgpu::Queue, tile: &Tile) -> Result<TileSlot, PoolError> {
        if let Some(b) = tile.batches.iter().find(|b| b.species >= self.species_count) {
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
            &self.pools.batches,
            u64::from(batches.start) * size_of::<GpuBatch>() as u64,
            bytemuck::cast_slice(&rebased),
        );
        queue.write_buffer(
            &self.pools.instances,
            u64::from(instances.start) * size_of::<PackedInstance>() as u64,
            bytemuck::cast_slice(&tile.instances),
        );
        let mut bounds = TileBounds {
            batch_start: batches.start,
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
        if !tile.batches.is_empty() {
            self.tile_bounds.push(bounds);
            self.reach_measured = None;
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
        self.table_dirty = true;
        Ok(TileSlot { batches, instances, species_counts: counts })
    }

    /// Evicts a resident tile: its batches are zeroed (the cull pass skips empty
    /// batches) and its ranges returned.
    pub fn evict_tile(&mut self, queue: &wgpu::Queue, slot: TileSlot) {
        self.tile_bounds.retain(|t| t.batch_start != slot.batches.start);
        self.reach_measured = None;
        let zeros = vec![0u8; slot.batches.len() * size_of::<GpuBatch>()];
        queue.write_buffer(&self.pools.batches, u64::from(slot.batches.start) * size_of::<GpuBatch>() as u64, &zeros);
        for (s, n) in &slot.species_counts {
            self.resident[*s as usize] -= u64::from(*n);
        }
        self.batch_alloc.release(slot.batches);
        self.instance_alloc.release(slot.instances);
        self.table_dirty = true;
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

    /// Which parts of species `s`'s pack ([`crate::format::pack::PackPart::ALL`]
    /// order: billboards, clusters, coarse mesh levels, full mesh) the resident
    /// trees within reach can need, from the projected heights of the last
    /// [`Self::measure_reach`] and the representations allowed: a far view needs
    /// neither meshes nor clusters, a medium one not the full mesh.
    #[must_use]
    pub fn parts_needed(&self, s: usize, meta: &crate::format::PackMeta) -> [bool; 4] {
        let max_px = self.species_max_px.get(s).copied().unwrap_or(0.0);
        let allow = self.representations;
        let has_bb = allow.billboards && meta.billboards.is_some();
        let has_cl = allow.clusters && meta.clusters.as_ref().is_some_and(|c| !c.ellipsoid_levels.is_empty());
        let has_mesh = allow.meshes && !meta.mesh_levels.is_empty();
        // Cross-fades start below a threshold: fetch a little early.
        let slack = 1.0 - self.fade_band;
        let select = |l: usize| meta.mesh_levels.get(l).map_or(f32::INFINITY, |m| m.select_px);
        let mesh_floor = if has_mesh { select(meta.mesh_levels.len() - 1) } else { f32::INFINITY };
        let cluster_floor = if has_bb { self.cluster_min_px } else { 0.0 };
        let coarsest_is_mesh = !has_bb && !has_cl;
        let meshes = has_mesh && (max_px >= mesh_floor * slack || coarsest_is_mesh);
        // The full mesh only where a tree can reach its threshold (one level: always).
        let full = meshes && (meta.mesh_levels.len() == 1 || max_px >= select(0) * slack);
        let clusters = has_cl && cluster_floor < mesh_floor && max_px >= cluster_floor * slack;
        [has_bb, clusters, meshes, full]
    }

    /// Each species' bound on the projected height (px) of its resident trees
    /// within reach, from the last [`Self::measure_reach`].
    #[must_use]
    pub fn species_max_px(&self) -> &[f32] {
        &self.species_max_px
    }

    /// Which draw pipelines have been built (meshes, clusters, billboards): each
    /// only once a pack holding that representation arrived.
    #[must_use]
    pub fn pipelines_built(&self) -> [bool; 3] {
        [self.mesh.is_some(), self.cluster.is_some(), self.billboard.is_some()]
    }

    /// GPU bytes: pools plus uploaded packs.
    #[must_use]
    pub fn gpu_bytes(&self) -> u64 {
        self.config.bytes() + self.packs.iter().flatten().map(|p| p.bytes).sum::<u64>()
    }

    fn rebuild_table(&mut self, queue: &wgpu::Queue) {
        let mut base = 0u32;
        let mut table = Vec::with_capacity(self.species_count as usize);
        let mut params = Vec::with_capacity((self.species_count * REPR_COUNT) as usize);
        let budget = self.config.items;
        let allow = self.representations;
        // Without billboards the coarsest cluster level reaches down to 0 px.
        let cluster_min_px = if allow.billboards { self.cluster_min_px } else { 0.0 };
        for (i, pack) in self.packs.iter_mut().enumerate() {
            let resident = self.resident[i].min(u64::from(u32::MAX)) as u32;
            let mut s = GpuSpecies::default();
            let mut draw: Vec<DrawParams> = Repr::ALL
                .iter()
                .map(|r| DrawParams { ids: [0, *r as u32, i as u32, 0], ..Default::default() })
                .collect();
            if let Some(p) = pack {
                s.sphere = p.sphere;
                s.select = [p.height_m, 0.0, 0.0, 0.0];
                let mut want = [0u32; REPR_COUNT as usize];
                let mut lower = [0f32; REPR_COUNT as usize];
                if p.has_level[0] && allow.meshes {
                    want[Repr::Mesh0 as usize] = resident.min(MESH0_CAPACITY);
                    lower[Repr::Mesh0 as usize] = p.select_px[0];
                    s.index_count[Repr::Mesh0 as usize] = p.index_counts[0];
                }
                if p.has_level[1] && allow.meshes {
                    want[Repr::Mesh1 as usize] = resident.min(MESH1_CAPACITY);
                    lower[Repr::Mesh1 as usize] = p.select_px[1];
                    s.index_count[Repr::Mesh1 as usize] = p.index_counts[1];
                }
                // Cluster tiers: the levels whose size band meets [cluster_min_px, the
                // coarsest mesh level's threshold).
                let mesh_floor = if allow.meshes {
                    // The coarsest level on the GPU.
                    (0..2).rev().find(|&l| p.has_level[l]).map_or(f32::INFINITY, |l| p.select_px[l])
                } else {
                    f32::INFINITY
                };
                p.tiers.clear();
                if let Some(c) = p.cluster.as_ref().filter(|_| allow.clusters) {
                    for (tier, (level, lo)) in
                        cluster_tiers(&c.levels, cluster_min_px, mesh_floor).into_iter().enumerate()
                    {
                        let r = Repr::CLUSTERS[tier] as usize;
                        want[r] = resident.min(CLUSTER_CAPACITY);
                        lower[r] = lo;
                        s.index_count[r] = c.vertices(level);
                        c.draw_params(level, &mut draw[r]);
                        p.tiers.push(level);
                    }
                }
                if let Some(bb) = p.billboard.as_ref().filter(|_| allow.billboards) {
                    let r = Repr::Billboard as usize;
                    want[r] = resident;
                    s.index_count[r] = BILLBOARD_VERTICES;
                    draw[r].ids[3] = bb.meta.angles | (bb.meta.azimuths << 16);
                    draw[r].bb_center = [bb.meta.center[0], bb.meta.center[1], bb.meta.center[2], bb.meta.half_width];
                    draw[r].bb_size = [bb.meta.half_height, 0.0, 0.0, 0.0];
                }
                // Billboards first: the far field must never starve for items.
                let order = std::iter::once(Repr::Billboard as usize).chain(0..Repr::Billboard as usize);
                for r in order {
                    let cap = want[r].min(budget.saturating_sub(base));
                    s.slot_base[r] = base;
                    s.slot_cap[r] = cap;
                    s.lower_px[r] = lower[r];
                    base += cap;
                }
            }
            for (r, d) in draw.iter_mut().enumerate() {
                d.ids[0] = s.slot_base[r];
            }
            params.extend(draw);
            table.push(s);
        }
        if !table.is_empty() {
            queue.write_buffer(&self.pools.species, 0, bytemuck::cast_slice(&table));
            queue.write_buffer(&self.pools.draw_params, 0, bytemuck::cast_slice(&params));
        }
        self.table = table;
        self.table_dirty = false;
    }

    /// Takes the view's settings and bounds each species' projected tree height
    /// from the resident tiles' boxes: what [`Self::prepare`] skips draws by and
    /// [`Self::parts_needed`] decides fetches by. Call before streaming a frame.
    pub fn measure_reach(&mut self, view: &ViewData, settings: &RenderSettings) {
        if settings.cluster_min_px != self.cluster_min_px || settings.representations != self.representations {
            self.cluster_min_px = settings.cluster_min_px;
            self.representations = settings.representations;
            self.table_dirty = true;
        }
        self.cluster_exact_depth = settings.cluster_exact_depth;
        self.fade_band = settings.fade_band;
        // Bound each species' projected tree height from the resident tiles' boxes
        // (nearest point) and tallest trees: draws no tree can need are skipped.
        let eye = view.eye_hi + view.eye_lo;
        let px = view.px_per_m_at_1m * settings.quality;
        let reach = if settings.culling == CullingMode::None { f32::INFINITY } else { settings.draw_distance_m };
        // Streaming and the frame both ask for the same view: measure it once.
        let key = [eye.x, eye.y, eye.z, px, reach, self.cluster_min_px, self.fade_band];
        if self.reach_measured == Some(key) {
            return;
        }
        self.reach_measured = Some(key);
        self.species_max_px.clear();
        self.species_max_px.resize(self.species_count as usize, 0.0);
        // Tiles whose trees may reach this size on screen are bounded batch by batch
        // (tighter: which mesh levels and clusters a view needs); the others whole.
        let refine_px = self.cluster_min_px.min(REFINE_PX) * (1.0 - self.fade_band);
        for t in &self.tile_bounds {
            let d = (t.lo - eye).max(eye - t.hi).max(Vec3::ZERO).length();
            if d > reach {
                continue;
            }
            let tallest = t.heights.iter().map(|(_, h)| *h).fold(0.0, f32::max);
            if tallest * px / d.max(1e-3) >= refine_px {
                for &(lo, hi, s, h) in &t.batches {
                    let d = (lo - eye).max(eye - hi).max(Vec3::ZERO).length();
                    if d <= reach {
                        if let Some(m) = self.species_max_px.get_mut(s as usize) {
                            *m = m.max(h * px / d.max(1e-3));
                        }
                    }
                }
                continue;
            }
            for &(s, h) in &t.heights {
                if let Some(m) = self.species_max_px.get_mut(s as usize) {
                    *m = m.max(h * px / d.max(1e-3));
                }
            }
        }
    }

    /// Writes the frame's uniforms (and the species table if residency changed).
    pub fn prepare(&mut self, queue: &wgpu::Queue, view: &ViewData, settings: &RenderSettings) -> ViewUniform {
        self.measure_reach(view, settings);
        if self.table_dirty {
            self.rebuild_table(queue);
        }
        let l = &settings.lighting;
        let uniform = ViewUniform {
            clip_from_eye: view.clip_from_eye.to_cols_array_2d(),
            eye_hi: view.eye_hi.extend(0.0).to_array(),
            eye_lo: view.eye_lo.extend(0.0).to_array(),
            frustum: view.frustum.map(|p| p.to_array()),
            sun_dir: l.sun_dir.extend(0.0).to_array(),
            sun_color: l.sun_color.extend(0.0).to_array(),
            ambient: l.ambient.extend(0.0).to_array(),
            lod: [
                view.px_per_m_at_1m * settings.quality,
                settings.draw_distance_m,
                settings.fade_band,
                match settings.culling {
                    CullingMode::Batches => 0.0,
                    CullingMode::PerTree => 1.0,
                    CullingMode::None => 2.0,
                },
            ],
            params: [0, self.batch_high_water, u32::from(settings.debug_lod), self.species_count],
            eye_from_clip: view.clip_from_eye.inverse().to_cols_array_2d(),
            viewport: [view.viewport[0] as f32, view.viewport[1] as f32, settings.thin_px, 0.0],
        };
        queue.write_buffer(&self.view_buffer, 0, bytemuck::bytes_of(&uniform));
        self.last_view = uniform;
        self.debug_bounds = settings.debug_bounds;
        uniform
    }

    /// Records the cull pass (after [`Self::prepare`]).
    pub fn encode_cull(&self, encoder: &mut wgpu::CommandEncoder) {
        let slots = self.species_count * REPR_COUNT;
        let mut pass =
            encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("cull"), timestamp_writes: None });
        pass.set_bind_group(0, &self.view_group, &[]);
        pass.set_bind_group(1, &self.cull_group, &[]);
        pass.set_pipeline(&self.cull.reset);
        pass.dispatch_workgroups(slots.div_ceil(64).max(1), 1, 1);
        if self.batch_high_water > 0 {
            pass.set_pipeline(&self.cull.cull_batches);
            pass.dispatch_workgroups(self.batch_high_water.div_ceil(64), 1, 1);
        }
        pass.set_pipeline(&self.cull.prepare_dispatch);
        pass.set_bind_group(2, &self.dispatch_group, &[]);
        pass.dispatch_workgroups(1, 1, 1);
        pass.set_pipeline(&self.cull.cull_instances);
        pass.dispatch_workgroups_indirect(&self.pools.dispatch, 0);
        pass.set_pipeline(&self.cull.finalize);
        pass.dispatch_workgroups(slots.div_ceil(64).max(1), 1, 1);
    }

    /// Records the draw pass: at most one indirect draw per species × representation.
    /// Returns the number of draw calls recorded.
    pub fn encode_draw(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        clear: [f64; 4],
    ) -> u32 {
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("forest"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: color,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color { r: clear[0], g: clear[1], b: clear[2], a: clear[3] }),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: depth,
                depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(0.0), store: wgpu::StoreOp::Discard }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_bind_group(0, &self.view_group, &[]);
        pass.set_pipeline(&self.sky);
        pass.draw(0..3, 0..1);
        pass.set_bind_group(2, &self.instance_group, &[]);
        let mut draws = 0;
        for (i, p) in self.packs.iter().enumerate() {
            let (Some(p), Some(s)) = (p, self.table.get(i)) else { continue };
            let max_px = self.species_max_px.get(i).copied().unwrap_or(f32::INFINITY);
            let coarsest = Repr::ALL.iter().rposition(|r| s.slot_cap[*r as usize] > 0);
            for (k, repr) in Repr::ALL.into_iter().enumerate() {
                if s.slot_cap[repr as usize] == 0 {
                    continue;
                }
                // Nothing of the species within reach, or no tree tall enough on screen
                // for this representation (fade bands included): skip the draw.
                let lower = if Some(k) == coarsest { 0.0 } else { s.lower_px[repr as usize] * (1.0 - self.fade_band) };
                if max_px <= 0.0 || lower > max_px {
                    continue;
                }
                let slot = i as u32 * REPR_COUNT + repr as u32;
                pass.set_bind_group(3, &self.draw_group, &[slot * size_of::<DrawParams>() as u32]);
                let args_offset = u64::from(slot) * size_of::<DrawArgs>() as u64;
                match repr {
                    Repr::Mesh0 | Repr::Mesh1 => {
                        let level = repr as usize;
                        let Some(pipelines) = &self.mesh else { continue };
                        if p.mesh.bind_level(&mut pass, pipelines, super::gpu_data::RenderMode::Lit, level) > 0 {
                            pass.draw_indexed_indirect(&self.pools.args, args_offset);
                            draws += 1;
                        }
                    }
                    Repr::Cluster0 | Repr::Cluster1 | Repr::Cluster2 | Repr::Cluster3 => {
                        if let (Some(c), Some(pipeline)) = (&p.cluster, &self.cluster) {
                            pass.set_pipeline(pipeline.pipeline(self.cluster_exact_depth));
                            pass.set_bind_group(1, &c.bind_group, &[]);
                            pass.draw_indirect(&self.pools.args, args_offset);
                            draws += 1;
                        }
                    }
                    Repr::Billboard => {
                        if let (Some(bb), Some(pipeline)) = (&p.billboard, &self.billboard) {
                            pass.set_pipeline(pipeline.pipeline());
                            pass.set_bind_group(1, &bb.bind_group, &[]);
                            pass.draw_indirect(&self.pools.args, args_offset);
                            draws += 1;
                        }
                    }
                }
            }
        }
        if self.debug_bounds {
            pass.set_pipeline(&self.bounds);
            pass.set_bind_group(1, &self.bounds_group, &[]);
            pass.draw_indirect(&self.pools.dispatch, 16);
            draws += 1;
        }
        draws
    }

    /// The last frame's view uniform (for the CPU oracle and tests).
    #[must_use]
    pub fn last_view(&self) -> &ViewUniform {
        &self.last_view
    }

    /// The species table as last uploaded.
    #[must_use]
    pub fn species_table(&self) -> &[GpuSpecies] {
        &self.table
    }

    /// Batch slots the cull pass tests (the high-water mark of the batch pool).
    #[must_use]
    pub fn batch_slots(&self) -> u32 {
        self.batch_high_water
    }

    /// Copies the cull counters and draw arguments into `readback` (laid out as
    /// [`super::stats::CullCounters`] reads them).
    pub fn copy_counters(&self, encoder: &mut wgpu::CommandEncoder, readback: &wgpu::Buffer) {
        let control = size_of::<CullControl>() as u64;
        encoder.copy_buffer_to_buffer(&self.pools.control, 0, readback, 0, control);
        let slots = u64::from(self.slot_count()) * size_of::<DrawArgs>() as u64;
        if slots > 0 {
            encoder.copy_buffer_to_buffer(&self.pools.args, 0, readback, control, slots);
        }
    }

    /// The buffers stats and tests read back: (control, args, items).
    #[must_use]
    pub fn readback_buffers(&self) -> (&wgpu::Buffer, &wgpu::Buffer, &wgpu::Buffer) {
        (&self.pools.control, &self.pools.args, &self.pools.items)
    }

    /// The batch and instance pools (for tests that check the GPU against the CPU oracle).
    #[must_use]
    pub fn pool_buffers(&self) -> (&wgpu::Buffer, &wgpu::Buffer) {
        (&self.pools.batches, &self.pools.instances)
    }

    /// Number of draw slots in use.
    #[must_use]
    pub fn slot_count(&self) -> u32 {
        self.species_count * REPR_COUNT
    }
}

/// A pipeline drawn over the scene without depth writes and without vertex
/// buffers (`vs_main`/`fs_main`): the sky and the debug overlays.
fn overlay_pipeline(
    device: &wgpu::Device,
    label: &str,
    source: &'static str,
    groups: &[Option<&wgpu::BindGroupLayout>],
    topology: wgpu::PrimitiveTopology,
    format: wgpu::TextureFormat,
) -> wgpu::RenderPipeline {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(label),
        bind_group_layouts: groups,
        immediate_size: 0,
    });
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(label),
        layout: Some(&layout),
        vertex: wgpu::VertexState {
            module: &module,
            entry_point: Some("vs_main"),
            compilation_options: Default::default(),
            buffers: &[],
        },
        primitive: wgpu::PrimitiveState { topology, ..Default::default() },
        // The sky is at depth 0, the far end under reversed Z; overlays ignore depth.
        depth_stencil: super::mesh::depth_state(false, wgpu::CompareFunction::Always),
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module: &module,
            entry_point: Some("fs_main"),
            compilation_options: Default::default(),
            targets: &[Some(format.into())],
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// Creates the depth texture every Sylva target needs.
#[must_use]
pub fn depth_texture(device: &wgpu::Device, width: u32, height: u32) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some("depth"),
        size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: DEPTH_FORMAT,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
        view_formats: &[],
    })
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
        assert_eq!((small.instances, small.batches, small.items, small.species), (3000, 200, 21000, 3));
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
