//! Cull pass: GPU culling and LoD selection over grouped batches (Eichner 2024
//! §3.5): batches (sphere, box, draw distance) → visible list → instances (fine
//! sphere test, projected-size LoD with cross-fade bands) → compacted draw items
//! and indirect draw arguments per (species × representation).
//!
//! [`crate::lod::select::cpu_select`] is the same selection written plainly on
//! the CPU: the oracle the GPU pass is tested against.

use super::layouts::{storage_entry, SharedLayouts};
use super::pools::Pools;
use super::shaders;

/// The compute pipelines of the cull pass.
pub struct CullPipelines {
    /// Group 1: batches, instances, species, visible, control, items, args.
    pub layout: wgpu::BindGroupLayout,
    /// Group 2 of `prepare_dispatch`: the indirect dispatch arguments.
    pub dispatch_layout: wgpu::BindGroupLayout,
    pub(crate) reset: wgpu::ComputePipeline,
    pub(crate) cull_batches: wgpu::ComputePipeline,
    pub(crate) prepare_dispatch: wgpu::ComputePipeline,
    pub(crate) cull_instances: wgpu::ComputePipeline,
    pub(crate) finalize: wgpu::ComputePipeline,
}

impl CullPipelines {
    /// Creates the pipelines.
    #[must_use]
    pub fn new(device: &wgpu::Device, shared: &SharedLayouts) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("cull.wgsl"),
            source: wgpu::ShaderSource::Wgsl(shaders::CULL.source().into()),
        });
        let c = wgpu::ShaderStages::COMPUTE;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("cull"),
            entries: &[
                storage_entry(0, c, true),
                storage_entry(1, c, true),
                storage_entry(2, c, true),
                storage_entry(3, c, false),
                storage_entry(4, c, false),
                storage_entry(5, c, false),
                storage_entry(6, c, false),
            ],
        });
        let dispatch_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("cull dispatch args"),
            entries: &[storage_entry(0, c, false), storage_entry(1, c, false)],
        });
        // The dispatch arguments are bound only while they are written: the
        // instance pass reads them as INDIRECT, which may not meet a writable binding.
        let main_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("cull"),
            bind_group_layouts: &[Some(&shared.view), Some(&layout)],
            immediate_size: 0,
        });
        let prepare_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("cull prepare"),
            // Group 1 left out: view + cull + dispatch would be 9 storage buffers.
            bind_group_layouts: &[Some(&shared.view), None, Some(&dispatch_layout)],
            immediate_size: 0,
        });
        let make = |entry: &str, layout: &wgpu::PipelineLayout| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: Some(layout),
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        Self {
            reset: make("reset", &main_layout),
            cull_batches: make("cull_batches", &main_layout),
            prepare_dispatch: make("prepare_dispatch", &prepare_layout),
            cull_instances: make("cull_instances", &main_layout),
            finalize: make("finalize", &main_layout),
            layout,
            dispatch_layout,
        }
    }

    /// Records the cull pass: reset → cull_batches → prepare_dispatch →
    /// cull_instances → finalize over the pools, for `slots` draw slots (view
    /// uniform bound through `view_group`).
    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        view_group: &wgpu::BindGroup,
        pools: &Pools,
        slots: u32,
        timestamp_writes: Option<wgpu::ComputePassTimestampWrites<'_>>,
    ) {
        let mut pass =
            encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("cull"), timestamp_writes });
        pass.set_bind_group(0, view_group, &[]);
        pass.set_bind_group(1, &pools.groups.cull, &[]);
        pass.set_pipeline(&self.reset);
        pass.dispatch_workgroups(slots.div_ceil(64).max(1), 1, 1);
        let batches = pools.batch_high_water();
        if batches > 0 {
            pass.set_pipeline(&self.cull_batches);
            pass.dispatch_workgroups(batches.div_ceil(64), 1, 1);
        }
        pass.set_pipeline(&self.prepare_dispatch);
        pass.set_bind_group(2, &pools.groups.dispatch, &[]);
        pass.dispatch_workgroups(1, 1, 1);
        pass.set_pipeline(&self.cull_instances);
        pass.dispatch_workgroups_indirect(&pools.buffers.dispatch, 0);
        pass.set_pipeline(&self.finalize);
        pass.dispatch_workgroups(slots.div_ceil(64).max(1), 1, 1);
    }
}
