//! Mesh pass: draws the quantised mesh levels of LoD packs, alpha-tested and
//! lit, or (in capture mode) writes albedo + normals for the bake's billboards.
//!
//! [`MeshPipelines`] is the long-lived part (layouts, pipelines, sampler);
//! [`MeshGpu`] is one pack's uploaded mesh levels and material textures.

use wgpu::util::DeviceExt;

use super::gpu_data::{GpuMaterial, MeshUniform, RenderMode};
use super::layouts::{depth_state, sampler_entry, storage_entry, texture_array_entry, SharedLayouts};
use super::shaders;
use crate::format::pack::{kind, MaterialKind, MeshLevelMeta, TexelEncoding, TextureArrayMeta};
use crate::format::Pack;

/// Albedo target of the capture mode (sRGB-encoded, alpha = coverage).
pub const CAPTURE_ALBEDO_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
/// Normal target of the capture mode (n * 0.5 + 0.5, alpha = leaf flag).
pub const CAPTURE_NORMAL_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
/// Occlusion target of the capture mode (the baked sky visibility in r, g, b).
pub const CAPTURE_AO_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;

/// Layouts, pipelines and the sampler of the mesh pass.
pub struct MeshPipelines {
    /// Group 1: mesh level constants, materials, material textures.
    pub mesh_layout: wgpu::BindGroupLayout,
    lit: wgpu::RenderPipeline,
    capture: wgpu::RenderPipeline,
    shadow: wgpu::RenderPipeline,
    id: super::layouts::IdPipeline,
    sampler: wgpu::Sampler,
}

const VERTEX_ATTRIBUTES: [wgpu::VertexAttribute; 4] = wgpu::vertex_attr_array![
    0 => Uint16x4, 1 => Snorm8x4, 2 => Unorm16x2, 3 => Unorm8x4
];

impl MeshPipelines {
    /// Creates the pipelines; `color_format` is the lit pass's target.
    #[must_use]
    pub fn new(device: &wgpu::Device, shared: &SharedLayouts, color_format: wgpu::TextureFormat) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("mesh.wgsl"),
            source: wgpu::ShaderSource::Wgsl(shaders::MESH.source().into()),
        });
        let mesh_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("mesh level"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: wgpu::BufferSize::new(std::mem::size_of::<MeshUniform>() as u64),
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: true },
                        has_dynamic_offset: false,
                        min_binding_size: wgpu::BufferSize::new(std::mem::size_of::<GpuMaterial>() as u64),
                    },
                    count: None,
                },
                texture_array_entry(2),
                sampler_entry(3),
                wgpu::BindGroupLayoutEntry {
                    binding: 4,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: true },
                        has_dynamic_offset: false,
                        min_binding_size: wgpu::BufferSize::new(4),
                    },
                    count: None,
                },
                // The level's other variants (`MVAR`), 8 bytes a vertex.
                storage_entry(5, wgpu::ShaderStages::VERTEX, true),
            ],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("mesh"),
            bind_group_layouts: &[Some(&shared.view), Some(&mesh_layout), Some(&shared.instances), Some(&shared.draw)],
            immediate_size: 0,
        });
        let buffers = [Some(wgpu::VertexBufferLayout {
            array_stride: 20,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &VERTEX_ATTRIBUTES,
        })];
        let make = |label: &str, entry: &str, targets: &[Option<wgpu::ColorTargetState>]| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(label),
                layout: Some(&layout),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs_main"),
                    compilation_options: Default::default(),
                    buffers: &buffers,
                },
                primitive: wgpu::PrimitiveState {
                    // Leaves are double-sided; bark is closed, so culling would save
                    // little and per-material pipelines would double the draws.
                    cull_mode: None,
                    ..Default::default()
                },
                depth_stencil: depth_state(true, wgpu::CompareFunction::Greater),
                multisample: Default::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some(entry),
                    compilation_options: Default::default(),
                    targets,
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        let lit = make("mesh lit", "fs_lit", &[Some(color_format.into())]);
        let capture = make(
            "mesh capture",
            "fs_capture",
            &[Some(CAPTURE_ALBEDO_FORMAT.into()), Some(CAPTURE_NORMAL_FORMAT.into()), Some(CAPTURE_AO_FORMAT.into())],
        );
        let shadow = super::layouts::shadow_caster_pipeline(device, "mesh shadow", &module, &layout, &buffers);
        let primitive = wgpu::PrimitiveState { cull_mode: None, ..Default::default() };
        let id = super::layouts::IdPipeline::new("mesh", &module, &layout, &buffers, primitive);
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("material"),
            address_mode_u: wgpu::AddressMode::Repeat,
            address_mode_v: wgpu::AddressMode::Repeat,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            mipmap_filter: wgpu::MipmapFilterMode::Linear,
            ..Default::default()
        });
        Self { mesh_layout, lit, capture, shadow, id, sampler }
    }

    /// The pipeline for `mode` (the id pass's once [`Self::build_id`] ran).
    #[must_use]
    pub fn pipeline(&self, mode: RenderMode) -> Option<&wgpu::RenderPipeline> {
        match mode {
            RenderMode::Lit => Some(&self.lit),
            RenderMode::Capture => Some(&self.capture),
            RenderMode::Shadow => Some(&self.shadow),
            RenderMode::Id => self.id.get(),
        }
    }

    /// Builds the id pipeline (picking) if it is not yet.
    pub fn build_id(&self, device: &wgpu::Device) {
        self.id.build(device);
    }
}

/// One uploaded mesh level.
pub struct MeshLevelGpu {
    vertices: wgpu::Buffer,
    indices: wgpu::Buffer,
    index_count: u32,
    bind_group: wgpu::BindGroup,
}

/// A pack's mesh levels and material textures on the GPU.
pub struct MeshGpu {
    /// Levels, finest first; `None` for a level not (yet) fetched.
    pub levels: Vec<Option<MeshLevelGpu>>,
    /// The billboard cloud (García et al. 2007), when the pack has one and it is fetched.
    pub cloud: Option<MeshLevelGpu>,
}

impl MeshGpu {
    /// Uploads every mesh level of a decoded pack.
    #[must_use]
    pub fn upload(device: &wgpu::Device, queue: &wgpu::Queue, pipelines: &MeshPipelines, pack: &Pack<'_>) -> Self {
        let meta = &pack.meta;
        // Levels whose sections are held (a pack fetched in parts may hold some),
        // and only with their material textures when they are textured.
        let textures_held = meta.material_texture.is_none() || pack.section(kind::MATERIAL_TEXTURES, 0).is_some();
        let held: Vec<bool> = (0..meta.mesh_levels.len())
            .map(|l| {
                textures_held
                    && pack.section(kind::MESH_VERTICES, l as u32).is_some()
                    && pack.section(kind::MESH_INDICES, l as u32).is_some()
            })
            .collect();
        let cloud_held = textures_held
            && meta.cloud.is_some()
            && [kind::CLOUD_VERTICES, kind::CLOUD_INDICES, kind::CLOUD_DATA]
                .iter()
                .all(|k| pack.section(*k, 0).is_some());
        if !held.contains(&true) && !cloud_held {
            return Self { levels: Vec::new(), cloud: None };
        }
        let texture = match (meta.material_texture, pack.section(kind::MATERIAL_TEXTURES, 0)) {
            (Some(t), Some(data)) => {
                upload_texture_array(device, queue, "material textures", &t, data, wgpu::TextureFormat::Rgba8UnormSrgb)
            }
            _ => upload_texture_array(
                device,
                queue,
                "no material texture",
                &TextureArrayMeta::plain(1, 1, 1),
                &[255; 4],
                wgpu::TextureFormat::Rgba8UnormSrgb,
            ),
        };
        let texture_view = texture.create_view(&wgpu::TextureViewDescriptor {
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
        let texels = meta.material_texture.zip(pack.section(kind::MATERIAL_TEXTURES, 0));
        let mut materials: Vec<GpuMaterial> = meta
            .materials
            .iter()
            .map(|m| GpuMaterial {
                base_color: m.base_color,
                alpha_cutoff: m.alpha_cutoff,
                layer: m.texture_layer.map_or(-1, |l| l as i32),
                kind: match m.kind {
                    MaterialKind::Leaf => 0,
                    MaterialKind::Branch => 1,
                    MaterialKind::Cloud => 2,
                },
                // Block-encoded texels carry the bake's count (the viewer cannot count blocks).
                coverage: m.coverage.unwrap_or_else(|| match (m.texture_layer, texels) {
                    (Some(l), Some((t, data))) => layer_coverage(&t, data, l, m.alpha_cutoff),
                    _ => 0.0,
                }),
            })
            .collect();
        if materials.is_empty() {
            // A storage binding may not be empty.
            materials.push(GpuMaterial::zeroed_default());
        }
        let material_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("materials"),
            contents: bytemuck::cast_slice(&materials),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let placeholder = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("no billboard cloud"),
            contents: &[0; 4],
            usage: wgpu::BufferUsages::STORAGE,
        });
        let no_variants = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("no variants"),
            contents: &[0; 8],
            usage: wgpu::BufferUsages::STORAGE,
        });
        // One level: its dequantisation (and the cloud's record offsets), buffers, bind group.
        let make = |level: &MeshLevelMeta,
                    vtx: &[u8],
                    idx: &[u8],
                    var: Option<&[u8]>,
                    cloud: Option<(&wgpu::Buffer, [u32; 2])>| {
            let offsets = cloud.map_or([0, 0], |(_, o)| o);
            // Variants larger than the device's storage binding limit are left out.
            let var =
                var.filter(|v| !v.is_empty() && (v.len() as u64) <= device.limits().max_storage_buffer_binding_size);
            let variants = var.map(|v| {
                device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("mesh variants"),
                    contents: v,
                    usage: wgpu::BufferUsages::STORAGE,
                })
            });
            let uniform = MeshUniform {
                pos_min: [level.pos_min[0], level.pos_min[1], level.pos_min[2], 0.0],
                pos_extent: [
                    level.pos_max[0] - level.pos_min[0],
                    level.pos_max[1] - level.pos_min[1],
                    level.pos_max[2] - level.pos_min[2],
                    0.0,
                ],
                uv_min: level.uv_min,
                uv_extent: [level.uv_max[0] - level.uv_min[0], level.uv_max[1] - level.uv_min[1]],
                cloud: [
                    offsets[0],
                    offsets[1],
                    if variants.is_some() { level.variants } else { 0 },
                    level.vertex_count,
                ],
            };
            let uniform_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("mesh level"),
                contents: bytemuck::bytes_of(&uniform),
                usage: wgpu::BufferUsages::UNIFORM,
            });
            // Sections are 256-byte aligned in the file and validated: upload as they are.
            let vertices = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("mesh vertices"),
                contents: pad4(vtx).as_ref(),
                usage: wgpu::BufferUsages::VERTEX,
            });
            let indices = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("mesh indices"),
                contents: idx,
                usage: wgpu::BufferUsages::INDEX,
            });
            let records = cloud.map_or(&placeholder, |(b, _)| b);
            let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("mesh level"),
                layout: &pipelines.mesh_layout,
                entries: &[
                    wgpu::BindGroupEntry { binding: 0, resource: uniform_buffer.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 1, resource: material_buffer.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::TextureView(&texture_view) },
                    wgpu::BindGroupEntry { binding: 3, resource: wgpu::BindingResource::Sampler(&pipelines.sampler) },
                    wgpu::BindGroupEntry { binding: 4, resource: records.as_entire_binding() },
                    wgpu::BindGroupEntry {
                        binding: 5,
                        resource: variants.as_ref().unwrap_or(&no_variants).as_entire_binding(),
                    },
                ],
            });
            MeshLevelGpu { vertices, indices, index_count: level.index_count, bind_group }
        };
        let levels = meta
            .mesh_levels
            .iter()
            .enumerate()
            .map(|(l, level)| {
                if !held[l] {
                    return None;
                }
                let vtx = pack.section(kind::MESH_VERTICES, l as u32).unwrap_or_default();
                let idx = pack.section(kind::MESH_INDICES, l as u32).unwrap_or_default();
                let var = pack.section(kind::MESH_VARIANTS, l as u32);
                Some(make(level, vtx, idx, var, None))
            })
            .collect();
        // A cloud larger than the device's storage binding limit is left out.
        let fits =
            |c: &crate::format::cloud::CloudMeta| c.words() * 4 <= device.limits().max_storage_buffer_binding_size;
        let cloud = meta.cloud.as_ref().filter(|c| cloud_held && fits(c)).map(|c| {
            let data = pack.section(kind::CLOUD_DATA, 0).unwrap_or_default();
            let records = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("billboard cloud"),
                contents: pad4(data).as_ref(),
                usage: wgpu::BufferUsages::STORAGE,
            });
            let cells_at = c.planes * crate::format::cloud::PLANE_WORDS as u32;
            let fragments_at = cells_at + c.cells * crate::format::cloud::CELL_WORDS as u32;
            let vtx = pack.section(kind::CLOUD_VERTICES, 0).unwrap_or_default();
            let idx = pack.section(kind::CLOUD_INDICES, 0).unwrap_or_default();
            make(&c.mesh, vtx, idx, None, Some((&records, [cells_at, fragments_at])))
        });
        Self { levels, cloud }
    }

    /// Whether level `l` is on the GPU.
    #[must_use]
    pub fn has_level(&self, l: usize) -> bool {
        self.levels.get(l).is_some_and(Option::is_some)
    }

    /// Binds `level` (pipeline, group 1, buffers) for drawing; the caller has set
    /// groups 0, 2 and 3. Returns the level's index count, 0 when there is none.
    pub fn bind_level(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        pipelines: &MeshPipelines,
        mode: RenderMode,
        level: usize,
    ) -> u32 {
        Self::bind(self.levels.get(level).and_then(Option::as_ref), pass, pipelines, mode)
    }

    /// As [`Self::bind_level`], for the billboard cloud.
    pub fn bind_cloud(&self, pass: &mut wgpu::RenderPass<'_>, pipelines: &MeshPipelines, mode: RenderMode) -> u32 {
        Self::bind(self.cloud.as_ref(), pass, pipelines, mode)
    }

    fn bind(
        level: Option<&MeshLevelGpu>,
        pass: &mut wgpu::RenderPass<'_>,
        pipelines: &MeshPipelines,
        mode: RenderMode,
    ) -> u32 {
        let Some(level) = level else { return 0 };
        if level.index_count == 0 {
            return 0;
        }
        let Some(pipeline) = pipelines.pipeline(mode) else { return 0 };
        pass.set_pipeline(pipeline);
        pass.set_bind_group(1, &level.bind_group, &[]);
        pass.set_vertex_buffer(0, level.vertices.slice(..));
        pass.set_index_buffer(level.indices.slice(..), wgpu::IndexFormat::Uint32);
        level.index_count
    }
}

/// Share of layer `layer`'s full-resolution texels (mip 0 of a mip-major RGBA8
/// array) whose alpha passes `cutoff`: a leaf's coverage for adaptive
/// transparency (the material's and vertex alphas scale it in the shader,
/// exact where they are 1, as on leaves). 0 (no adaptive test) without a
/// cutoff or when the layer is not in `data`.
#[must_use]
pub fn layer_coverage(meta: &TextureArrayMeta, data: &[u8], layer: u32, cutoff: f32) -> f32 {
    if meta.encoding.is_some() {
        // Blocks, not texels (the bake writes a variant's coverage in META).
        return 0.0;
    }
    let texels = (meta.size as usize).pow(2);
    let start = meta.mip_offset(0, 4) as usize + layer as usize * texels * 4;
    match data.get(start..start + texels * 4) {
        Some(bytes) if cutoff > 0.0 => crate::render::mips::alpha_coverage(bytes, cutoff) as f32,
        _ => 0.0,
    }
}

impl GpuMaterial {
    fn zeroed_default() -> Self {
        bytemuck::Zeroable::zeroed()
    }
}

/// Vertex data is 20 bytes per vertex; buffers must be a multiple of 4 bytes (always true) —
/// kept as a check so a format change cannot silently break the upload.
fn pad4(bytes: &[u8]) -> std::borrow::Cow<'_, [u8]> {
    if bytes.len().is_multiple_of(4) {
        std::borrow::Cow::Borrowed(bytes)
    } else {
        let mut v = bytes.to_vec();
        v.resize(bytes.len().next_multiple_of(4), 0);
        std::borrow::Cow::Owned(v)
    }
}

/// Uploads a mip-major texture array (the pack layout) as it is: plain
/// texels of `format`, or a block-encoded array ([`TextureArrayMeta::encoding`])
/// in the block format `meta.encoding` names (BC7 or ETC2 RGBA8, sRGB kept as `format`'s), which the
/// device must support ([`block_formats`]).
#[must_use]
pub fn upload_texture_array(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    label: &str,
    meta: &TextureArrayMeta,
    data: &[u8],
    format: wgpu::TextureFormat,
) -> wgpu::Texture {
    // (A pack in an encoding the device does not sample is refused before
    // it gets here: `SceneStream` checks what it fetched, `sylva render --pack` the device.)
    let format = match (meta.encoding, format) {
        (Some(TexelEncoding::Bc7), wgpu::TextureFormat::Rgba8UnormSrgb) => wgpu::TextureFormat::Bc7RgbaUnormSrgb,
        (Some(TexelEncoding::Bc7), _) => wgpu::TextureFormat::Bc7RgbaUnorm,
        (Some(TexelEncoding::Etc2), wgpu::TextureFormat::Rgba8UnormSrgb) => wgpu::TextureFormat::Etc2Rgba8UnormSrgb,
        (Some(TexelEncoding::Etc2), _) => wgpu::TextureFormat::Etc2Rgba8Unorm,
        (None, f) => f,
    };
    let texel_bytes = format.block_copy_size(None).unwrap_or(4);
    let (block, _) = format.block_dimensions();
    let texture = device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d { width: meta.size, height: meta.size, depth_or_array_layers: meta.layers },
        mip_level_count: meta.mips,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    for mip in 0..meta.mips {
        // A mip smaller than a block is copied as the whole block it sits in.
        let size = (meta.size >> mip).max(1).next_multiple_of(block);
        let start = meta.mip_offset(mip, texel_bytes.into()) as usize;
        let len = (meta.mip_bytes(mip, texel_bytes.into()) * u64::from(meta.layers)) as usize;
        let Some(bytes) = data.get(start..start + len) else { break };
        queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &texture,
                mip_level: mip,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            bytes,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(size / block * texel_bytes),
                rows_per_image: Some(size / block),
            },
            wgpu::Extent3d { width: size, height: size, depth_or_array_layers: meta.layers },
        );
    }
    texture
}

/// The block encodings of texture arrays `device` samples (its features):
/// what a viewer may ask of a pack's block-compressed variants.
#[must_use]
pub fn block_formats(device: &wgpu::Device) -> Vec<TexelEncoding> {
    // Best first: BC7 keeps more of the texels than ETC2 where a GPU has both.
    let mut out = Vec::new();
    if device.features().contains(wgpu::Features::TEXTURE_COMPRESSION_BC) {
        out.push(TexelEncoding::Bc7);
    }
    if device.features().contains(wgpu::Features::TEXTURE_COMPRESSION_ETC2) {
        out.push(TexelEncoding::Etc2);
    }
    out
}
