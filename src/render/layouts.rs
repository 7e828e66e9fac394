//! Bind group layouts shared by every draw pass: the view (group 0), the
//! resident instance data (group 2) and the per-draw constants (group 3).
//! Group 1 belongs to each pass (mesh level, billboard textures).

use super::gpu_data::{DrawParams, ViewUniform};

/// Depth format of every Sylva pass (reversed Z: clear to 0, keep greater).
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// The depth state of every Sylva pipeline: reversed Z, so nearer is greater.
/// Overlays pass `write = false` and `CompareFunction::Always`.
#[must_use]
pub fn depth_state(write: bool, compare: wgpu::CompareFunction) -> Option<wgpu::DepthStencilState> {
    Some(wgpu::DepthStencilState {
        format: DEPTH_FORMAT,
        depth_write_enabled: Some(write),
        depth_compare: Some(compare),
        stencil: Default::default(),
        bias: Default::default(),
    })
}

/// Creates a shadow map: `layers` square depth layers of `size` texels.
#[must_use]
pub fn shadow_map(device: &wgpu::Device, size: u32, layers: u32) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some("shadow map"),
        size: wgpu::Extent3d { width: size, height: size, depth_or_array_layers: layers },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: DEPTH_FORMAT,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
        view_formats: &[],
    })
}

/// The shared layouts, created once per device.
pub struct SharedLayouts {
    /// Group 0: `View`, a read-only storage buffer rather than a uniform: Mesa 22.3's
    /// lavapipe (Debian 12, our CI) compiles a new shader variant with the uniform
    /// values inlined at every pipeline bind and never frees it — 1.5 MB and a JIT
    /// compile per frame. Storage reads cost the same on real GPUs.
    /// Bindings 1 and 2 are the sun's shadow map (a depth array, one layer
    /// per cascade) and its comparison sampler: see [`super::shadow`].
    pub view: wgpu::BindGroupLayout,
    /// Group 2: batches, instances, draw items (read-only storage, vertex stage).
    pub instances: wgpu::BindGroupLayout,
    /// Group 3: `DrawParams` uniform with a dynamic offset.
    pub draw: wgpu::BindGroupLayout,
    /// A 1×1 shadow map for views drawn without shadows (and for the shadow
    /// cascades themselves, which may not sample the map they draw into).
    no_shadow_map: wgpu::TextureView,
    /// The shadow map's comparison sampler (bilinear: 2×2 PCF per tap).
    shadow_sampler: wgpu::Sampler,
}

fn storage(binding: u32, visibility: wgpu::ShaderStages, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// A read-only or read-write storage entry (used by the cull pass too).
#[must_use]
pub fn storage_entry(binding: u32, visibility: wgpu::ShaderStages, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    storage(binding, visibility, read_only)
}

/// A uniform buffer read by `visibility`, bound at a dynamic offset where `dynamic`.
#[must_use]
pub fn uniform_entry(binding: u32, visibility: wgpu::ShaderStages, dynamic: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: dynamic,
            min_binding_size: None,
        },
        count: None,
    }
}

/// A filterable 2D-array texture read by the fragment stage (material and billboard arrays).
#[must_use]
pub fn texture_array_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    texture_entry(binding, wgpu::TextureViewDimension::D2Array)
}

/// A filterable texture of `dimension` read by the fragment stage.
#[must_use]
pub fn texture_entry(binding: u32, dimension: wgpu::TextureViewDimension) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::FRAGMENT,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable: true },
            view_dimension: dimension,
            multisampled: false,
        },
        count: None,
    }
}

/// A filtering sampler for the fragment stage.
#[must_use]
pub fn sampler_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::FRAGMENT,
        ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
        count: None,
    }
}

impl SharedLayouts {
    /// Creates the layouts.
    #[must_use]
    pub fn new(device: &wgpu::Device) -> Self {
        let view = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("view"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::VERTEX_FRAGMENT | wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: true },
                        has_dynamic_offset: false,
                        min_binding_size: wgpu::BufferSize::new(std::mem::size_of::<ViewUniform>() as u64),
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Depth,
                        view_dimension: wgpu::TextureViewDimension::D2Array,
                        multisampled: false,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 2,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Comparison),
                    count: None,
                },
            ],
        });
        let v = wgpu::ShaderStages::VERTEX;
        let instances = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("instances"),
            entries: &[
                storage(0, v, true),
                storage(1, v, true),
                storage(2, v, true),
                storage(3, wgpu::ShaderStages::VERTEX_FRAGMENT, true),
            ],
        });
        let draw = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("draw params"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: true,
                    min_binding_size: wgpu::BufferSize::new(std::mem::size_of::<DrawParams>() as u64),
                },
                count: None,
            }],
        });
        let no_shadow_map = shadow_map(device, 1, 1).create_view(&wgpu::TextureViewDescriptor {
            label: Some("no shadow map"),
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
        let shadow_sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("shadow map"),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            compare: Some(wgpu::CompareFunction::GreaterEqual),
            ..Default::default()
        });
        Self { view, instances, draw, no_shadow_map, shadow_sampler }
    }

    /// Group 0 for a view buffer (STORAGE usage), without shadows.
    #[must_use]
    pub fn view_group(&self, device: &wgpu::Device, buffer: &wgpu::Buffer) -> wgpu::BindGroup {
        self.view_group_at(device, buffer, 0, None)
    }

    /// Group 0 for the view at byte `offset` of `buffer`, with the shadow map
    /// `shadows` (a depth array view) or none.
    #[must_use]
    pub fn view_group_at(
        &self,
        device: &wgpu::Device,
        buffer: &wgpu::Buffer,
        offset: u64,
        shadows: Option<&wgpu::TextureView>,
    ) -> wgpu::BindGroup {
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("view"),
            layout: &self.view,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer,
                        offset,
                        size: wgpu::BufferSize::new(std::mem::size_of::<ViewUniform>() as u64),
                    }),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(shadows.unwrap_or(&self.no_shadow_map)),
                },
                wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::Sampler(&self.shadow_sampler) },
            ],
        })
    }

    /// Group 2 over the batch, instance and draw-item buffers and the styles
    /// (the cull control buffer from [`super::gpu_data::STYLE_OFFSET_BYTES`]).
    #[must_use]
    pub fn instance_group(
        &self,
        device: &wgpu::Device,
        batches: &wgpu::Buffer,
        instances: &wgpu::Buffer,
        items: &wgpu::Buffer,
        control: &wgpu::Buffer,
    ) -> wgpu::BindGroup {
        let styles = wgpu::BufferBinding { buffer: control, offset: super::gpu_data::STYLE_OFFSET_BYTES, size: None };
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("instances"),
            layout: &self.instances,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: batches.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: instances.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: items.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 3, resource: wgpu::BindingResource::Buffer(styles) },
            ],
        })
    }

    /// Group 3 over a buffer of 256-byte `DrawParams` records (bound at a dynamic offset).
    #[must_use]
    pub fn draw_group(&self, device: &wgpu::Device, buffer: &wgpu::Buffer) -> wgpu::BindGroup {
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("draw params"),
            layout: &self.draw,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer,
                    offset: 0,
                    size: wgpu::BufferSize::new(std::mem::size_of::<DrawParams>() as u64),
                }),
            }],
        })
    }
}

/// What a vertex-pulling pipeline draws into.
#[derive(Debug, Clone)]
pub struct PullingTarget {
    /// Topology and culling.
    pub primitive: wgpu::PrimitiveState,
    /// Depth test and writes.
    pub depth_stencil: Option<wgpu::DepthStencilState>,
    /// Colour target format.
    pub format: wgpu::TextureFormat,
}

/// A [`pulling_pipeline`] built the first time it is asked for (a viewer
/// that never needs it never compiles it).
pub struct LazyPulling {
    label: String,
    fragment: &'static str,
    module: wgpu::ShaderModule,
    layout: wgpu::PipelineLayout,
    target: PullingTarget,
    pipeline: std::sync::OnceLock<wgpu::RenderPipeline>,
}

impl LazyPulling {
    /// `module`'s `vs_main` and `fragment` under `layout` into `target`; not built yet.
    #[must_use]
    pub fn new(
        label: &str,
        module: &wgpu::ShaderModule,
        layout: &wgpu::PipelineLayout,
        fragment: &'static str,
        target: &PullingTarget,
    ) -> Self {
        Self {
            label: format!("{label} {fragment}"),
            fragment,
            module: module.clone(),
            layout: layout.clone(),
            target: target.clone(),
            pipeline: std::sync::OnceLock::new(),
        }
    }

    /// Builds the pipeline if it is not yet.
    pub fn build(&self, device: &wgpu::Device) {
        self.pipeline.get_or_init(|| {
            pulling_pipeline(device, &self.label, &self.module, &self.layout, self.fragment, &self.target)
        });
    }

    /// The pipeline, once built.
    #[must_use]
    pub fn get(&self) -> Option<&wgpu::RenderPipeline> {
        self.pipeline.get()
    }
}

/// A render pipeline whose vertex shader `vs_main` reads its data from storage
/// buffers (no vertex buffers) and whose fragment entry is `fragment`: the
/// billboard and cluster passes, the sky and the overlays.
#[must_use]
pub fn pulling_pipeline(
    device: &wgpu::Device,
    label: &str,
    module: &wgpu::ShaderModule,
    layout: &wgpu::PipelineLayout,
    fragment: &str,
    target: &PullingTarget,
) -> wgpu::RenderPipeline {
    let stages = Stages { module, layout, buffers: &[], fragment };
    render_pipeline(
        device,
        label,
        &stages,
        target.primitive,
        target.depth_stencil.clone(),
        &[Some(target.format.into())],
    )
}

/// [`pulling_pipeline`] with `blend` on the colour target (`fs_main`).
#[must_use]
pub fn pulling_pipeline_blended(
    device: &wgpu::Device,
    label: &str,
    module: &wgpu::ShaderModule,
    layout: &wgpu::PipelineLayout,
    target: &PullingTarget,
    blend: wgpu::BlendState,
) -> wgpu::RenderPipeline {
    let stages = Stages { module, layout, buffers: &[], fragment: "fs_main" };
    let color =
        wgpu::ColorTargetState { format: target.format, blend: Some(blend), write_mask: wgpu::ColorWrites::ALL };
    render_pipeline(device, label, &stages, target.primitive, target.depth_stencil.clone(), &[Some(color)])
}

/// The depth-only pipeline a pass draws shadow casters with: vertex stage
/// `vs_main` (reading `buffers`), fragment stage `fs_shadow` (alpha tests,
/// exact depths), no colour targets, the cascade's reversed-Z depth.
#[must_use]
pub fn shadow_caster_pipeline(
    device: &wgpu::Device,
    label: &str,
    module: &wgpu::ShaderModule,
    layout: &wgpu::PipelineLayout,
    buffers: &[Option<wgpu::VertexBufferLayout<'_>>],
) -> wgpu::RenderPipeline {
    let stages = Stages { module, layout, buffers, fragment: "fs_shadow" };
    let primitive = wgpu::PrimitiveState { cull_mode: None, ..Default::default() };
    render_pipeline(device, label, &stages, primitive, depth_state(true, wgpu::CompareFunction::Greater), &[])
}

/// A module's `vs_main` (reading `buffers`) and `fragment` entry points under `layout`.
struct Stages<'a> {
    module: &'a wgpu::ShaderModule,
    layout: &'a wgpu::PipelineLayout,
    buffers: &'a [Option<wgpu::VertexBufferLayout<'a>>],
    fragment: &'a str,
}

fn render_pipeline(
    device: &wgpu::Device,
    label: &str,
    stages: &Stages<'_>,
    primitive: wgpu::PrimitiveState,
    depth_stencil: Option<wgpu::DepthStencilState>,
    targets: &[Option<wgpu::ColorTargetState>],
) -> wgpu::RenderPipeline {
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(label),
        layout: Some(stages.layout),
        vertex: wgpu::VertexState {
            module: stages.module,
            entry_point: Some("vs_main"),
            compilation_options: Default::default(),
            buffers: stages.buffers,
        },
        primitive,
        depth_stencil,
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module: stages.module,
            entry_point: Some(stages.fragment),
            compilation_options: Default::default(),
            targets,
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// The id pass's colour format: the pool instance + 1 of the tree a pixel
/// shows (0: none).
pub const ID_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Uint;

/// A pass's id pipeline (picking): its module's `vs_main` and `fs_id` into an
/// [`ID_FORMAT`] target with the reversed-Z depth, built the first time a
/// pick asks for it (a viewer nobody clicks never compiles it).
pub struct IdPipeline {
    label: String,
    fragment: &'static str,
    module: wgpu::ShaderModule,
    layout: wgpu::PipelineLayout,
    buffers: Vec<Option<wgpu::VertexBufferLayout<'static>>>,
    primitive: wgpu::PrimitiveState,
    pipeline: std::sync::OnceLock<wgpu::RenderPipeline>,
}

impl IdPipeline {
    /// The id pipeline of `module` under `layout`, reading `buffers`, fragment
    /// entry `fs_id`; not built yet.
    #[must_use]
    pub fn new(
        label: &str,
        module: &wgpu::ShaderModule,
        layout: &wgpu::PipelineLayout,
        buffers: &[Option<wgpu::VertexBufferLayout<'static>>],
        primitive: wgpu::PrimitiveState,
    ) -> Self {
        Self::with_fragment(label, "fs_id", module, layout, buffers, primitive)
    }

    /// As [`Self::new`] with another fragment entry.
    #[must_use]
    pub fn with_fragment(
        label: &str,
        fragment: &'static str,
        module: &wgpu::ShaderModule,
        layout: &wgpu::PipelineLayout,
        buffers: &[Option<wgpu::VertexBufferLayout<'static>>],
        primitive: wgpu::PrimitiveState,
    ) -> Self {
        Self {
            label: format!("{label} {fragment}"),
            fragment,
            module: module.clone(),
            layout: layout.clone(),
            buffers: buffers.to_vec(),
            primitive,
            pipeline: std::sync::OnceLock::new(),
        }
    }

    /// Builds the pipeline if it is not yet.
    pub fn build(&self, device: &wgpu::Device) {
        self.pipeline.get_or_init(|| {
            let stages =
                Stages { module: &self.module, layout: &self.layout, buffers: &self.buffers, fragment: self.fragment };
            render_pipeline(
                device,
                &self.label,
                &stages,
                self.primitive,
                depth_state(true, wgpu::CompareFunction::Greater),
                &[Some(ID_FORMAT.into())],
            )
        });
    }

    /// The pipeline, once [`Self::build`] has run.
    #[must_use]
    pub fn get(&self) -> Option<&wgpu::RenderPipeline> {
        self.pipeline.get()
    }
}
