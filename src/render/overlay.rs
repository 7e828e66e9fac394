//! Passes drawn over the scene without depth writes and without vertex
//! buffers: the sky (first, at the far end of reversed Z) and the batch-bounds
//! debug overlay (boxes of the batches that passed the batch test, drawn
//! indirectly with the count the cull pass wrote).

use super::gpu_data::CullDispatch;
use super::layouts::{storage_entry, SharedLayouts};
use super::pools::Pools;

/// The sky and ground background.
pub struct SkyPass {
    pipeline: wgpu::RenderPipeline,
}

impl SkyPass {
    /// The pipeline for `format` targets.
    #[must_use]
    pub fn new(device: &wgpu::Device, shared: &SharedLayouts, format: wgpu::TextureFormat) -> Self {
        let pipeline = overlay_pipeline(
            device,
            "sky",
            &super::shaders::SKY.source(),
            &[Some(&shared.view)],
            wgpu::PrimitiveTopology::TriangleList,
            format,
        );
        Self { pipeline }
    }

    /// Draws the sky (view bound at group 0).
    pub fn draw(&self, pass: &mut wgpu::RenderPass<'_>) {
        pass.set_pipeline(&self.pipeline);
        pass.draw(0..3, 0..1);
    }
}

/// The batch-bounds debug overlay.
pub struct BoundsPass {
    pipeline: wgpu::RenderPipeline,
    /// Group 1: batches and the visible list (the pools make their group with it).
    pub layout: wgpu::BindGroupLayout,
}

impl BoundsPass {
    /// The pipeline for `format` targets.
    #[must_use]
    pub fn new(device: &wgpu::Device, shared: &SharedLayouts, format: wgpu::TextureFormat) -> Self {
        let vertex = wgpu::ShaderStages::VERTEX;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("bounds"),
            entries: &[storage_entry(0, vertex, true), storage_entry(1, vertex, true)],
        });
        let pipeline = overlay_pipeline(
            device,
            "bounds",
            &super::shaders::BOUNDS.source(),
            &[Some(&shared.view), Some(&layout)],
            wgpu::PrimitiveTopology::LineList,
            format,
        );
        Self { pipeline, layout }
    }

    /// Draws the boxes of the visible batches (view bound at group 0). One draw.
    pub fn draw<'p>(&'p self, pass: &mut wgpu::RenderPass<'p>, pools: &'p Pools) -> u32 {
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(1, &pools.groups.bounds, &[]);
        pass.draw_indirect(&pools.buffers.dispatch, CullDispatch::BOUNDS_DRAW_OFFSET);
        1
    }
}

/// A pipeline drawn over the scene without depth writes and without vertex
/// buffers (`vs_main`/`fs_main`): the sky and the debug overlays.
fn overlay_pipeline(
    device: &wgpu::Device,
    label: &str,
    source: &str,
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
    let target = super::layouts::PullingTarget {
        primitive: wgpu::PrimitiveState { topology, ..Default::default() },
        // The sky is at depth 0, the far end under reversed Z; overlays ignore depth.
        depth_stencil: super::layouts::depth_state(false, wgpu::CompareFunction::Always),
        format,
    };
    super::layouts::pulling_pipeline(device, label, &module, &layout, "fs_main", &target)
}

impl super::pass::DrawPass for SkyPass {
    fn enabled(&self, frame: &super::pass::FrameData) -> bool {
        frame.sky
    }

    /// The sky is not counted among the draw calls.
    fn draw<'p>(&'p self, pass: &mut wgpu::RenderPass<'p>, _cx: &super::pass::PassContext<'p>) -> u32 {
        SkyPass::draw(self, pass);
        0
    }
}

impl super::pass::DrawPass for BoundsPass {
    fn enabled(&self, frame: &super::pass::FrameData) -> bool {
        frame.debug_bounds
    }

    fn draw<'p>(&'p self, pass: &mut wgpu::RenderPass<'p>, cx: &super::pass::PassContext<'p>) -> u32 {
        BoundsPass::draw(self, pass, cx.pools)
    }
}
