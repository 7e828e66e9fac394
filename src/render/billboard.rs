//! Billboard pass: view-angle billboards (Eichner 2024, §3.3, eq. 3.1), one quad per
//! tree, drawn with one indirect draw per species. Shader: `shaders/billboard.wgsl`.

use super::layouts::{sampler_entry, texture_array_entry, SharedLayouts};
use super::mesh::upload_texture_array;
use super::shaders;
use crate::format::pack::{kind, BillboardMeta};
use crate::format::Pack;

/// Vertices per billboard (two triangles, no index buffer).
pub const BILLBOARD_VERTICES: u32 = 6;

/// A far-tier pass's pipelines (billboards, impostors): texture arrays and one
/// linear, clamped, mipmapped sampler in group 1 (arrays at bindings 0, 1, the
/// sampler at 2, further arrays from 3), the draw items in groups 2–3, a lit
/// variant and a depth-only one for the shadow casters.
pub struct FarTierPipeline {
    /// Group 1.
    pub texture_layout: wgpu::BindGroupLayout,
    pipeline: wgpu::RenderPipeline,
    /// A moving frame's (`fs_moving`; impostors alone), built when first asked for.
    moving: Option<super::layouts::LazyPulling>,
    shadow: wgpu::RenderPipeline,
    /// The id pass's (picking).
    pub id: super::layouts::IdPipeline,
    sampler: wgpu::Sampler,
}

/// The billboard pipeline (`shaders/billboard.wgsl`): colour, normal, sampler, occlusion.
pub type BillboardPipeline = FarTierPipeline;

impl FarTierPipeline {
    /// The billboards' pipelines for `color_format` targets.
    #[must_use]
    pub fn billboard(device: &wgpu::Device, shared: &SharedLayouts, color_format: wgpu::TextureFormat) -> Self {
        Self::new(device, shared, color_format, "billboard", &shaders::BILLBOARD.source(), 3, false)
    }

    /// A far tier's pipelines from WGSL `source` with `arrays` texture arrays;
    /// `moving`: a moving frame's too (the source's `fs_moving`).
    #[must_use]
    pub fn new(
        device: &wgpu::Device,
        shared: &SharedLayouts,
        color_format: wgpu::TextureFormat,
        label: &str,
        source: &str,
        arrays: u32,
        moving: bool,
    ) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let entries: Vec<_> =
            (0..=arrays).map(|b| if b == 2 { sampler_entry(2) } else { texture_array_entry(b) }).collect();
        let texture_layout =
            device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries: &entries });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(label),
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
            depth_stencil: super::layouts::depth_state(true, wgpu::CompareFunction::Greater),
            format: color_format,
        };
        let pipeline = super::layouts::pulling_pipeline(device, label, &module, &layout, "fs_main", &target);
        let moving = moving.then(|| super::layouts::LazyPulling::new(label, &module, &layout, "fs_moving", &target));
        let shadow = super::layouts::shadow_caster_pipeline(device, &format!("{label} shadow"), &module, &layout, &[]);
        let id = super::layouts::IdPipeline::new(label, &module, &layout, &[], target.primitive);
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some(label),
            address_mode_u: wgpu::AddressMode::ClampToEdge,
            address_mode_v: wgpu::AddressMode::ClampToEdge,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            mipmap_filter: wgpu::MipmapFilterMode::Linear,
            ..Default::default()
        });
        Self { texture_layout, pipeline, moving, shadow, id, sampler }
    }

    /// The lit pipeline.
    #[must_use]
    pub fn pipeline(&self) -> &wgpu::RenderPipeline {
        &self.pipeline
    }

    /// A moving frame's lit pipeline, where the tier has one and it is built
    /// ([`Self::build_moving`]).
    #[must_use]
    pub fn moving_pipeline(&self) -> Option<&wgpu::RenderPipeline> {
        self.moving.as_ref().and_then(super::layouts::LazyPulling::get)
    }

    /// Builds the moving frame's pipeline, where the tier has one.
    pub fn build_moving(&self, device: &wgpu::Device) {
        if let Some(m) = &self.moving {
            m.build(device);
        }
    }

    /// The shadow casters' pipeline (depth only).
    #[must_use]
    pub fn shadow_pipeline(&self) -> &wgpu::RenderPipeline {
        &self.shadow
    }

    /// Group 1 over `arrays` (2D-array views; the sampler goes between the
    /// second and the third).
    #[must_use]
    pub fn bind_group(&self, device: &wgpu::Device, label: &str, arrays: &[&wgpu::Texture]) -> wgpu::BindGroup {
        let views: Vec<wgpu::TextureView> = arrays
            .iter()
            .map(|t| {
                t.create_view(&wgpu::TextureViewDescriptor {
                    dimension: Some(wgpu::TextureViewDimension::D2Array),
                    ..Default::default()
                })
            })
            .collect();
        let mut entries: Vec<wgpu::BindGroupEntry<'_>> = views
            .iter()
            .enumerate()
            .map(|(i, v)| wgpu::BindGroupEntry {
                binding: if i < 2 { i as u32 } else { i as u32 + 1 },
                resource: wgpu::BindingResource::TextureView(v),
            })
            .collect();
        entries.push(wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::Sampler(&self.sampler) });
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(label),
            layout: &self.texture_layout,
            entries: &entries,
        })
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
    /// Uploads the billboard arrays of `pack` of far-tier state `state` (0
    /// leaf-on, 1 a deciduous species' bare wood), if it has them.
    #[must_use]
    pub fn upload(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        state: u32,
        pipeline: &BillboardPipeline,
        pack: &Pack<'_>,
    ) -> Option<Self> {
        let meta = pack.meta.billboards.clone()?;
        let color = pack.section(kind::BILLBOARD_COLOR, state)?;
        let normal = pack.section(kind::BILLBOARD_NORMAL, state)?;
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
        let ao = pack.section(kind::BILLBOARD_AO, state);
        let ao_tex = match ao {
            Some(bytes) => upload_texture_array(
                device,
                queue,
                "billboard occlusion",
                // R8 texels even where the colours are block-encoded.
                &crate::format::pack::TextureArrayMeta { encoding: None, ..meta.texture },
                bytes,
                wgpu::TextureFormat::R8Unorm,
            ),
            None => upload_texture_array(
                device,
                queue,
                "billboard occlusion (none)",
                &crate::format::pack::TextureArrayMeta::plain(1, meta.texture.layers, 1),
                &vec![255; meta.texture.layers as usize],
                wgpu::TextureFormat::R8Unorm,
            ),
        };
        let bind_group = pipeline.bind_group(device, "billboard textures", &[&color_tex, &normal_tex, &ao_tex]);
        let bytes = (color.len() + normal.len() + ao.map_or(0, <[u8]>::len)) as u64;
        Some(Self { bind_group, bytes, meta })
    }
}
