//! Billboard pass: view-angle billboards (seed 004 §3.3, eq. 3.1), one quad per
//! tree, drawn with one indirect draw per species. Shader: `shaders/billboard.wgsl`.

use super::layouts::{sampler_entry, texture_array_entry, SharedLayouts};
use super::mesh::upload_texture_array;
use super::shaders;
use crate::format::pack::{kind, BillboardMeta};
use crate::format::Pack;

/// Vertices per billboard (two triangles, no index buffer).
pub const BILLBOARD_VERTICES: u32 = 6;

/// The billboard pipeline and its texture layout.
pub struct BillboardPipeline {
    /// Group 1: colour array, normal array, sampler, occlusion array.
    pub texture_layout: wgpu::BindGroupLayout,
    pipeline: wgpu::RenderPipeline,
    shadow: wgpu::RenderPipeline,
    sampler: wgpu::Sampler,
}

impl BillboardPipeline {
    /// Creates the pipeline for `color_format` targets.
    #[must_use]
    pub fn new(device: &wgpu::Device, shared: &SharedLayouts, color_format: wgpu::TextureFormat) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("billboard.wgsl"),
            source: wgpu::ShaderSource::Wgsl(shaders::BILLBOARD.into()),
        });
        let texture_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("billboard textures"),
            entries: &[texture_array_entry(0), texture_array_entry(1), sampler_entry(2), texture_array_entry(3)],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("billboard"),
            bind_group_layouts: &[
                Some(&shared.view),
                Some(&texture_layout),
                Some(&shared.instances),
                Some(&shared.draw),
            ],
            immediate_size: 0,
        });
        let target = super::layouts::PullingTarget {
            primitive: wgpu::PrimitiveState { cull_mode: None, ..Default::default() },
            depth_stencil: super::mesh::depth_state(true, wgpu::CompareFunction::Greater),
            format: color_format,
        };
        let pipeline = super::layouts::pulling_pipeline(device, "billboard", &module, &layout, "fs_main", &target);
        let shadow = super::layouts::shadow_caster_pipeline(device, "billboard shadow", &module, &layout, &[]);
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("billboard"),
            address_mode_u: wgpu::AddressMode::ClampToEdge,
            address_mode_v: wgpu::AddressMode::ClampToEdge,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            mipmap_filter: wgpu::MipmapFilterMode::Linear,
            ..Default::default()
        });
        Self { texture_layout, pipeline, shadow, sampler }
    }

    /// The pipeline.
    #[must_use]
    pub fn pipeline(&self) -> &wgpu::RenderPipeline {
        &self.pipeline
    }

    /// The shadow casters' pipeline (depth only, quads turned to the sun).
    #[must_use]
    pub fn shadow_pipeline(&self) -> &wgpu::RenderPipeline {
        &self.shadow
    }
}

/// One species' billboard arrays on the GPU.
pub struct BillboardGpu {
    /// Group 1 of the billboard pipeline.
    pub bind_group: wgpu::BindGroup,
    /// The metadata (angles, quad size).
    pub meta: BillboardMeta,
    /// Bytes uploaded.
    pub bytes: u64,
}

impl BillboardGpu {
    /// Uploads the billboard arrays of `pack`, if it has them.
    #[must_use]
    pub fn upload(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        pipeline: &BillboardPipeline,
        pack: &Pack<'_>,
    ) -> Option<Self> {
        let meta = pack.meta.billboards.clone()?;
        let color = pack.section(kind::BILLBOARD_COLOR, 0)?;
        let normal = pack.section(kind::BILLBOARD_NORMAL, 0)?;
        let color_tex = upload_texture_array(
            device,
            queue,
            "billboard colour",
            &meta.texture,
            color,
            wgpu::TextureFormat::Rgba8UnormSrgb,
        );
        let normal_tex = upload_texture_array(
            device,
            queue,
            "billboard normal",
            &meta.texture,
            normal,
            wgpu::TextureFormat::Rgba8Unorm,
        );
        // The tree's own occlusion (`BBAO`, R8); a pack without it gets one
        // open (white) texel per layer.
        let ao = pack.section(kind::BILLBOARD_AO, 0);
        let ao_tex = match ao {
            Some(bytes) => upload_texture_array(
                device,
                queue,
                "billboard occlusion",
                &meta.texture,
                bytes,
                wgpu::TextureFormat::R8Unorm,
            ),
            None => upload_texture_array(
                device,
                queue,
                "billboard occlusion (none)",
                &crate::format::pack::TextureArrayMeta { size: 1, layers: meta.texture.layers, mips: 1 },
                &vec![255; meta.texture.layers as usize],
                wgpu::TextureFormat::R8Unorm,
            ),
        };
        let view = |t: &wgpu::Texture| {
            t.create_view(&wgpu::TextureViewDescriptor {
                dimension: Some(wgpu::TextureViewDimension::D2Array),
                ..Default::default()
            })
        };
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("billboard textures"),
            layout: &pipeline.texture_layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(&view(&color_tex)) },
                wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(&view(&normal_tex)) },
                wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::Sampler(&pipeline.sampler) },
                wgpu::BindGroupEntry { binding: 3, resource: wgpu::BindingResource::TextureView(&view(&ao_tex)) },
            ],
        });
        let bytes = (color.len() + normal.len() + ao.map_or(0, <[u8]>::len)) as u64;
        Some(Self { bind_group, bytes, meta })
    }
}
