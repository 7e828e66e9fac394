//! The canopy pass: the forest drawn from its canopy rasters where
//! trees are a pixel or two (`shaders/canopy.wgsl`; selection in
//! `crate::scene::canopy`). Rasters live in a pool of slots (uploaded once,
//! the least recently drawn replaced); one instanced draw a frame, a quad per
//! cell, blended over the trees.

use std::collections::HashMap;

use super::layouts::depth_state;
use super::layouts::{storage_entry, SharedLayouts};
use crate::format::canopy::{CanopyKey, CANOPY_CELLS, CANOPY_CELL_BYTES};
use crate::format::pack::Season;
use crate::scene::canopy::CanopyDraw;

/// Most rasters the pool holds (32 KB each; it starts at 8 and doubles as views
/// need): as many as a view draws.
pub const CANOPY_SLOTS: usize = crate::scene::canopy::MAX_CANOPY_DRAWS;

/// One drawn raster. Must match `CanopyRaster` in `shaders/canopy.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuCanopyRaster {
    /// Lowest corner, metres relative to the scene origin.
    pub origin_m: [f32; 2],
    /// Side, metres.
    pub size_m: f32,
    /// Cells per side.
    pub cells: u32,
    /// Ground heights' lowest.
    pub z_min: f32,
    /// Ground heights' range.
    pub z_span: f32,
    /// Height of quantised height 255.
    pub height_max: f32,
    /// Pool slot of the cells.
    pub slot: u32,
    /// 1: trees the view wants here are not resident, the raster stands in
    /// for them at full cover (`CanopyDraw::stand_in`); 0: cross-faded.
    pub stand_in: u32,
    /// The crowns' batches' tallest trees over their own heights
    /// (`Canopy::tallest_ratio`): the cross-fade sizes a cell's trees as the cull does.
    pub tallest_ratio: f32,
}

/// The pool's buffers (made when a scene first draws a raster).
struct Pool {
    cells: wgpu::Buffer,
    rasters: wgpu::Buffer,
    group: wgpu::BindGroup,
}

/// The canopy pass.
pub struct CanopyPass {
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    pool: Option<Pool>,
    /// Raster in each slot and the frame it was last drawn.
    slots: Vec<Option<(CanopyKey, u64)>>,
    by_key: HashMap<CanopyKey, u32>,
    frame: u64,
    count: u32,
    records: Vec<GpuCanopyRaster>,
    /// Rasters uploaded since the start.
    pub uploads: u64,
    /// Rasters selected but not drawn this frame (more than the pool holds).
    pub dropped: u32,
    /// The season the pool's cells show (a change uploads them again).
    season: Season,
}

impl CanopyPass {
    /// The pipeline for `format` targets, and the pool.
    #[must_use]
    pub fn new(device: &wgpu::Device, shared: &SharedLayouts, format: wgpu::TextureFormat) -> Self {
        let vertex = wgpu::ShaderStages::VERTEX;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("canopy"),
            entries: &[storage_entry(0, vertex, true), storage_entry(1, vertex, true)],
        });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("canopy"),
            source: wgpu::ShaderSource::Wgsl(super::shaders::CANOPY.source().into()),
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("canopy"),
            bind_group_layouts: &[Some(&shared.view), Some(&layout)],
            immediate_size: 0,
        });
        let target = super::layouts::PullingTarget {
            primitive: wgpu::PrimitiveState { cull_mode: None, ..Default::default() },
            depth_stencil: depth_state(false, wgpu::CompareFunction::Greater),
            format,
        };
        let pipeline = super::layouts::pulling_pipeline_blended(
            device,
            "canopy",
            &module,
            &pipeline_layout,
            &target,
            wgpu::BlendState::PREMULTIPLIED_ALPHA_BLENDING,
        );
        Self {
            pipeline,
            layout,
            pool: None,
            slots: Vec::new(),
            by_key: HashMap::new(),
            frame: 0,
            count: 0,
            records: Vec::new(),
            uploads: 0,
            season: Season::LeafOn,
            dropped: 0,
        }
    }

    /// GPU bytes of the pool (none until a raster is drawn).
    #[must_use]
    pub fn gpu_bytes(&self) -> u64 {
        self.pool.as_ref().map_or(0, |p| p.cells.size() + p.rasters.size())
    }

    fn make_pool(&mut self, device: &wgpu::Device, slots: usize) {
        let slot_bytes = (CANOPY_CELLS * CANOPY_CELLS) as u64 * CANOPY_CELL_BYTES as u64;
        let fits = (device.limits().max_storage_buffer_binding_size / slot_bytes).max(1);
        let capacity = (slots as u64).min(fits) as usize;
        let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let cells = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("canopy cells"),
            size: slot_bytes * capacity as u64,
            usage: storage,
            mapped_at_creation: false,
        });
        let rasters = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("canopy rasters"),
            size: (std::mem::size_of::<GpuCanopyRaster>() * capacity) as u64,
            usage: storage,
            mapped_at_creation: false,
        });
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("canopy"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: cells.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: rasters.as_entire_binding() },
            ],
        });
        self.pool = Some(Pool { cells, rasters, group });
        self.slots = vec![None; capacity];
        self.by_key.clear();
    }

    /// Rasters drawn by the last prepared frame.
    #[must_use]
    pub fn drawn(&self) -> u32 {
        self.count
    }

    /// Uploads newly drawn rasters and writes this frame's records for `draws`
    /// (the stream's selection; empty: nothing drawn), their cells as they
    /// look in `season` (rasters with seasons; a new season uploads them again).
    pub fn prepare(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, draws: &[CanopyDraw], season: Season) {
        if season != self.season {
            self.clear();
            self.season = season;
        }
        self.frame += 1;
        self.count = 0;
        self.dropped = 0;
        if draws.is_empty() {
            return;
        }
        // The pool grows (and is uploaded again) as a view draws more rasters.
        let slot_bytes = (CANOPY_CELLS * CANOPY_CELLS) as u64 * CANOPY_CELL_BYTES as u64;
        let fits = (device.limits().max_storage_buffer_binding_size / slot_bytes).max(1) as usize;
        let want = draws.len().next_power_of_two().clamp(8, CANOPY_SLOTS).min(fits);
        if self.slots.len() < want {
            self.make_pool(device, want);
        }
        let Some(pool) = &self.pool else { return };
        let mut records = std::mem::take(&mut self.records);
        records.clear();
        for d in draws {
            let c = &d.canopy;
            if c.cells != CANOPY_CELLS {
                self.dropped += 1;
                continue;
            }
            let slot = match self.by_key.get(&d.key) {
                Some(&s) => s,
                None => {
                    let Some(free) = super::terrain::free_or_oldest(&self.slots, self.frame) else {
                        self.dropped += 1;
                        continue;
                    };
                    if let Some((old, _)) = self.slots[free] {
                        self.by_key.remove(&old);
                    }
                    queue.write_buffer(&pool.cells, (c.data.len() * free) as u64, &c.cells_in(season));
                    self.uploads += 1;
                    self.by_key.insert(d.key, free as u32);
                    free as u32
                }
            };
            self.slots[slot as usize] = Some((d.key, self.frame));
            records.push(GpuCanopyRaster {
                origin_m: c.origin_m,
                size_m: c.size_m,
                cells: c.cells,
                z_min: c.z_range_m[0],
                z_span: c.z_range_m[1] - c.z_range_m[0],
                height_max: c.height_max_m,
                slot,
                stand_in: u32::from(d.stand_in),
                tallest_ratio: c.tallest_ratio,
            });
        }
        if !records.is_empty() {
            queue.write_buffer(&pool.rasters, 0, bytemuck::cast_slice(&records));
        }
        self.count = records.len() as u32;
        self.records = records;
    }

    /// Forgets what the pool holds (a new scene: keys mean other rasters).
    pub fn clear(&mut self) {
        self.slots.iter_mut().for_each(|s| *s = None);
        self.by_key.clear();
        self.count = 0;
    }

    /// Draws the prepared rasters (view bound at group 0); returns the draw calls (0 or 1).
    pub fn draw(&self, pass: &mut wgpu::RenderPass<'_>) -> u32 {
        let Some(pool) = &self.pool else { return 0 };
        if self.count == 0 {
            return 0;
        }
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(1, &pool.group, &[]);
        pass.draw(0..6, 0..self.count * CANOPY_CELLS * CANOPY_CELLS);
        1
    }
}

impl super::pass::DrawPass for CanopyPass {
    fn draw<'p>(&'p self, pass: &mut wgpu::RenderPass<'p>, _cx: &super::pass::PassContext<'p>) -> u32 {
        CanopyPass::draw(self, pass)
    }

    fn gpu_bytes(&self) -> u64 {
        CanopyPass::gpu_bytes(self)
    }
}
