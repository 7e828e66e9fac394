//! Headless renders of one species pack: the bake's view-angle billboard
//! capture (Eichner 2024, §3.3, alg. 3.1) and `sylva render --pack` previews.
//! Native only: both block on the GPU.

use glam::{Mat4, Vec3};
use wgpu::util::DeviceExt;

use super::billboard::{BillboardGpu, BillboardPipeline, BILLBOARD_VERTICES};
use super::cluster::{ClusterGpu, ClusterPipeline};
use super::context::{read_texture_rgba8, GpuContext};
use super::gpu_data::{DrawParams, RenderMode, Repr, ViewUniform};
use super::impostor::{ImpostorGpu, ImpostorPipeline, IMPOSTOR_VERTICES};
use super::layouts::SharedLayouts;
use super::layouts::DEPTH_FORMAT;
use super::mesh::{MeshGpu, MeshPipelines, CAPTURE_ALBEDO_FORMAT, CAPTURE_AO_FORMAT, CAPTURE_NORMAL_FORMAT};
use super::settings::Season;
use super::Lighting;
use crate::format::tile::{GpuBatch, PackedInstance};
use crate::format::Pack;

/// The box a billboard covers: a vertical cylinder around the tree (model space,
/// metres at scale 1). Chosen so every elevation angle fits one quad size.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BillboardFrame {
    /// Centre of the cylinder (x, y at the crown axis, z at mid height).
    pub center: Vec3,
    /// Cylinder radius = quad half width.
    pub half_width: f32,
    /// Quad half height: the largest projected half height over 0–90°.
    pub half_height: f32,
}

impl BillboardFrame {
    /// The frame of a model with bounds `min..max`.
    #[must_use]
    pub fn from_bounds(min: Vec3, max: Vec3) -> Self {
        let center = (min + max) * 0.5;
        let half = (max - min) * 0.5;
        let radius = half.x.hypot(half.y).max(1e-3);
        // Projected half height of the cylinder at elevation θ is
        // h cos θ + r sin θ, whose maximum over θ is sqrt(h² + r²).
        let half_height = half.z.hypot(radius).max(1e-3);
        Self { center, half_width: radius, half_height }
    }

    /// Camera direction (from the tree towards the eye) for elevation `elevation_rad`
    /// and azimuth `azimuth_rad`, and the camera's up vector.
    #[must_use]
    pub fn view_axes(elevation_rad: f32, azimuth_rad: f32) -> (Vec3, Vec3) {
        let (se, ce) = elevation_rad.sin_cos();
        let (sa, ca) = azimuth_rad.sin_cos();
        let dir = Vec3::new(ce * ca, ce * sa, se);
        // Tangent in the elevation direction: continuous up to the top view.
        let up = Vec3::new(-se * ca, -se * sa, ce);
        (dir, up)
    }

    /// Clip-from-model transform of the orthographic capture (reversed Z).
    #[must_use]
    pub fn clip_from_model(&self, elevation_rad: f32, azimuth_rad: f32) -> Mat4 {
        let (dir, up) = Self::view_axes(elevation_rad, azimuth_rad);
        let reach = self.half_width.hypot(self.half_height) * 1.01;
        let eye = self.center + dir * (reach * 2.0);
        let view = glam::camera::rh::view::look_at_mat4(eye, self.center, up);
        // near and far swapped: reversed Z, like every other pass.
        let proj = glam::camera::rh::proj::directx::orthographic(
            -self.half_width,
            self.half_width,
            -self.half_height,
            self.half_height,
            reach * 3.0,
            reach,
        );
        proj * view
    }
}

/// Raw billboard layers as rendered (before mips): per layer `size²` RGBA8 texels.
#[derive(Default)]
pub struct CapturedBillboards {
    /// Albedo (sRGB) + coverage alpha, one `Vec` per layer.
    pub color: Vec<Vec<u8>>,
    /// Normal * 0.5 + 0.5 and leaf flag, one `Vec` per layer.
    pub normal: Vec<Vec<u8>>,
    /// The vertices' baked sky visibility in r, g, b (255 where the mesh has
    /// none, and on the background).
    pub ao: Vec<Vec<u8>>,
    /// Reversed-Z depth (1 near … 0 far; 0 on the background), one `Vec` per layer.
    pub depth: Vec<Vec<f32>>,
}

impl CapturedBillboards {
    /// Adds `other`'s layers after these (another mesh variant's).
    pub fn append(&mut self, other: CapturedBillboards) {
        self.color.extend(other.color);
        self.normal.extend(other.normal);
        self.ao.extend(other.ao);
        self.depth.extend(other.depth);
    }
}

/// A render target that can be read back.
fn target(ctx: &GpuContext, width: u32, height: u32, format: wgpu::TextureFormat) -> wgpu::Texture {
    ctx.device.create_texture(&wgpu::TextureDescriptor {
        label: Some("target"),
        size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    })
}

/// Groups 2 and 3 for drawing one tree: a batch at the scene origin, one
/// instance at its origin with yaw 0 and scale 1, one draw item. The view
/// uniform's eye places the camera.
struct SingleTree {
    instances: wgpu::BindGroup,
    draw: wgpu::BindGroup,
    params: wgpu::Buffer,
    /// The one instance (its variation chooses the mesh variant).
    instance: wgpu::Buffer,
}

impl SingleTree {
    fn new(ctx: &GpuContext, shared: &SharedLayouts) -> Self {
        let origin = Vec3::ZERO;
        let batch = GpuBatch {
            origin_m: origin.to_array(),
            instance_offset: 0,
            center_m: origin.to_array(),
            radius_m: 1.0,
            half_extent_m: [1.0; 3],
            instance_count: 1,
            species: 0,
            xy_step_m: 0.01,
            z_step_m: 0.01,
            scale_min: 1.0,
            scale_log2_step: 0.0,
            max_height_m: 1.0,
            flags: 0,
            crown: 0,
        };
        // Variation 15 of 0–31 is the neutral tint.
        let instance = PackedInstance::new(0, 0, 0, 0, 0, 15);
        let init = |label, contents: &[u8], usage| {
            ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents, usage })
        };
        let s = wgpu::BufferUsages::STORAGE;
        let batches = init("batch", bytemuck::bytes_of(&batch), s);
        let instances = init("instance", bytemuck::bytes_of(&instance), s | wgpu::BufferUsages::COPY_DST);
        let items = init("item", bytemuck::cast_slice(&[0u32, 0u32]), s);
        // No style: a zeroed control buffer (control words and styles' header).
        let control_bytes = super::gpu_data::control_buffer_bytes(0, false) as usize;
        let control = init("no styles", &vec![0u8; control_bytes], s);
        let params = init(
            "draw params",
            bytemuck::bytes_of(&DrawParams::default()),
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        );
        Self {
            instances: shared.instance_group(&ctx.device, &batches, &instances, &items, &control),
            draw: shared.draw_group(&ctx.device, &params),
            params,
            instance: instances,
        }
    }

    /// Draws mesh variant `variant` (0–31) of a pack that has it — a level
    /// with fewer draws `variant % (variants + 1)` — through the variation
    /// whose [`crate::format::pack::variant_of`] is `variant`.
    fn set_variant(&self, ctx: &GpuContext, variant: u32) {
        let instance = PackedInstance::new(0, 0, 0, 0, 0, variant.wrapping_add(15) & 31);
        ctx.queue.write_buffer(&self.instance, 0, bytemuck::bytes_of(&instance));
    }

    /// Draws leaves (false: the bare wood, as a leaf-off capture).
    fn set_leaves(&self, ctx: &GpuContext, leaves: bool) {
        let state = if leaves { Season::LeafOn } else { Season::LeafOff };
        let params = DrawParams { season: [0.0, 0.0, 0.0, state.code()], ..Default::default() };
        ctx.queue.write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
    }

    fn bind(&self, pass: &mut wgpu::RenderPass<'_>) {
        pass.set_bind_group(2, &self.instances, &[]);
        pass.set_bind_group(3, &self.draw, &[0]);
    }
}

/// The mesh pipelines with their shared layouts, for captures and previews.
pub struct CapturePipelines {
    shared: SharedLayouts,
    mesh: MeshPipelines,
}

impl CapturePipelines {
    /// Creates them; `color_format` is the lit preview's target format.
    #[must_use]
    pub fn new(device: &wgpu::Device, color_format: wgpu::TextureFormat) -> Self {
        let shared = SharedLayouts::new(device);
        let mesh = MeshPipelines::new(device, &shared, color_format);
        Self { shared, mesh }
    }
}

/// Renders mesh level 0 of `pack` orthographically from `angles` elevations evenly
/// spaced over 0–90° (alg. 3.1: angle k = 90°/(K−1)·k) times `azimuths` azimuths,
/// into `size`² albedo + normal layers. Layer = azimuth · angles + elevation.
/// `leaves` false: the bare wood (a deciduous tree's leaf-off state);
/// `variant`: the mesh variant captured (0–31, modulo the pack's).
#[must_use]
#[allow(clippy::too_many_arguments)]
pub fn capture_billboards(
    ctx: &GpuContext,
    pipelines: &CapturePipelines,
    pack: &Pack<'_>,
    frame: &BillboardFrame,
    angles: u32,
    azimuths: u32,
    size: u32,
    leaves: bool,
    variant: u32,
) -> CapturedBillboards {
    let mut views = Vec::new();
    for a in 0..azimuths {
        let azimuth = std::f32::consts::TAU * a as f32 / azimuths as f32;
        for k in 0..angles {
            let elevation = std::f32::consts::FRAC_PI_2 * k as f32 / (angles - 1).max(1) as f32;
            views.push(frame.clip_from_model(elevation, azimuth));
        }
    }
    capture_views(ctx, pipelines, pack, &views, size, leaves, variant)
}

/// Renders mesh level 0 of `pack` with each orthographic `views` transform
/// (clip from model, reversed Z) into `size`² layers: albedo, normal, occlusion
/// and depth, one layer per view; `leaves` false: the bare wood; `variant`:
/// the mesh variant captured (0–31, modulo the pack's).
#[must_use]
pub fn capture_views(
    ctx: &GpuContext,
    pipelines: &CapturePipelines,
    pack: &Pack<'_>,
    views: &[Mat4],
    size: u32,
    leaves: bool,
    variant: u32,
) -> CapturedBillboards {
    let mesh = MeshGpu::upload(&ctx.device, &ctx.queue, &pipelines.mesh, pack);
    let albedo = target(ctx, size, size, CAPTURE_ALBEDO_FORMAT);
    let normal = target(ctx, size, size, CAPTURE_NORMAL_FORMAT);
    let ao = target(ctx, size, size, CAPTURE_AO_FORMAT);
    let depth = target(ctx, size, size, DEPTH_FORMAT);
    let (albedo_view, normal_view, ao_view, depth_view) = (
        albedo.create_view(&Default::default()),
        normal.create_view(&Default::default()),
        ao.create_view(&Default::default()),
        depth.create_view(&Default::default()),
    );
    let view_buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("capture view"),
        size: std::mem::size_of::<ViewUniform>() as u64,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let view_group = pipelines.shared.view_group(&ctx.device, &view_buffer);
    // The capture works in model space: the eye is the model origin.
    let tree = SingleTree::new(ctx, &pipelines.shared);
    tree.set_leaves(ctx, leaves);
    if variant > 0 {
        tree.set_variant(ctx, variant);
    }
    let mut out = CapturedBillboards { color: Vec::new(), normal: Vec::new(), ao: Vec::new(), depth: Vec::new() };
    let light = Lighting::default();
    let sky = light.default_sky();
    for clip_from_model in views {
        let uniform = ViewUniform {
            clip_from_eye: clip_from_model.to_cols_array_2d(),
            params: [RenderMode::Capture as u32, 0, 0, 0],
            ..light.view_uniform_with(*clip_from_model, Vec3::ZERO, [size, size], sky)
        };
        ctx.queue.write_buffer(&view_buffer, 0, bytemuck::bytes_of(&uniform));
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        {
            let clear =
                wgpu::Operations { load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT), store: wgpu::StoreOp::Store };
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("view capture"),
                color_attachments: &[
                    Some(wgpu::RenderPassColorAttachment {
                        view: &albedo_view,
                        depth_slice: None,
                        resolve_target: None,
                        ops: clear,
                    }),
                    Some(wgpu::RenderPassColorAttachment {
                        view: &normal_view,
                        depth_slice: None,
                        resolve_target: None,
                        ops: clear,
                    }),
                    Some(wgpu::RenderPassColorAttachment {
                        view: &ao_view,
                        depth_slice: None,
                        resolve_target: None,
                        // Open where nothing is drawn: filtering at the silhouette
                        // must not mix "fully occluded" into the edge texels.
                        ops: wgpu::Operations {
                            load: wgpu::LoadOp::Clear(wgpu::Color { r: 1.0, g: 1.0, b: 1.0, a: 0.0 }),
                            store: wgpu::StoreOp::Store,
                        },
                    }),
                ],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &depth_view,
                    depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(0.0), store: wgpu::StoreOp::Store }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_bind_group(0, &view_group, &[]);
            tree.bind(&mut pass);
            let indices = mesh.bind_level(&mut pass, &pipelines.mesh, RenderMode::Capture, 0);
            pass.draw_indexed(0..indices, 0, 0..1);
        }
        ctx.queue.submit([encoder.finish()]);
        out.color.push(read_texture_rgba8(ctx, &albedo, 0, 0));
        out.normal.push(read_texture_rgba8(ctx, &normal, 0, 0));
        out.ao.push(read_texture_rgba8(ctx, &ao, 0, 0));
        // Depth32Float: four bytes per texel, as the RGBA8 readback copies them.
        let d = read_texture_rgba8(ctx, &depth, 0, 0);
        out.depth.push(d.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect());
    }
    out
}

/// Where `sylva render --pack` looks from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PackView {
    /// Horizontal, from the side.
    Side,
    /// 35° down.
    Oblique,
    /// Straight down.
    Top,
}

/// What [`TreeRenderer::render`] draws.
pub enum TreeDraw<'a> {
    /// A mesh level.
    Mesh(&'a MeshGpu, usize),
    /// A cluster level (ellipsoids + lines).
    Cluster(&'a ClusterGpu, usize),
    /// The billboards.
    Billboard(&'a BillboardGpu),
    /// The multi-view impostors.
    Impostor(&'a ImpostorGpu),
    /// The billboard cloud (García et al. 2007).
    Cloud(&'a MeshGpu),
}

/// Lit renders of one tree (scale 1, yaw 0, at the model origin) with any
/// representation, through the viewer's own pipelines: previews, the image
/// tests of the representations, and the bake's image-error calibration.
pub struct TreeRenderer {
    /// Mesh pipelines (for [`MeshGpu::upload`]).
    pub mesh: MeshPipelines,
    /// Cluster pipeline (for [`ClusterGpu::upload`] / [`ClusterGpu::new`]).
    pub cluster: ClusterPipeline,
    /// Billboard pipeline (for [`BillboardGpu::upload`]).
    pub billboard: BillboardPipeline,
    /// Impostor pipeline (for [`ImpostorGpu::upload`]).
    pub impostor: ImpostorPipeline,
    tree: SingleTree,
    view_buffer: wgpu::Buffer,
    view_group: wgpu::BindGroup,
    format: wgpu::TextureFormat,
    /// Draw with the trees' own baked occlusion (on by default).
    pub ao: bool,
    /// The light (the default daylight by default).
    pub lighting: Lighting,
    /// The share of a leaf's albedo it transmits
    /// ([`super::sky_light::LEAF_TRANSMIT`] by default).
    pub leaf_transmit: f32,
    /// The light's parts ([`super::sky_light::LightParts`]; the default's).
    pub light_parts: super::sky_light::LightParts,
    /// Alpha-test mesh leaves at their textures' full resolution (the accuracy
    /// reference's [`super::settings::RenderSettings::full_res_alpha`]).
    pub full_res_alpha: bool,
    /// The season drawn ([`Self::set_season`]) and its draw params.
    season: std::cell::Cell<(Season, [f32; 4])>,
    /// The sky of the last light drawn under (its SH projection is worked
    /// out once per light, not per image).
    sky: std::cell::Cell<Option<(Lighting, super::gpu_data::SkyUniform)>>,
}

/// What one capture sees: a camera (`clip_from_eye` at `eye`, model space)
/// and the image size.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shot {
    /// Clip transform of eye-relative positions.
    pub clip_from_eye: Mat4,
    /// The eye (model space).
    pub eye: Vec3,
    /// Image width and height (px).
    pub size: [u32; 2],
}

impl Shot {
    /// A `size`×`size` image from `eye`.
    #[must_use]
    pub fn square(clip_from_eye: Mat4, eye: Vec3, size: u32) -> Self {
        Self { clip_from_eye, eye, size: [size, size] }
    }
}

impl TreeRenderer {
    /// Pipelines for sRGB RGBA8 targets.
    #[must_use]
    pub fn new(ctx: &GpuContext) -> Self {
        let format = wgpu::TextureFormat::Rgba8UnormSrgb;
        let shared = SharedLayouts::new(&ctx.device);
        let mesh = MeshPipelines::new(&ctx.device, &shared, format);
        let cluster = ClusterPipeline::new(&ctx.device, &shared, format);
        let billboard = BillboardPipeline::billboard(&ctx.device, &shared, format);
        let impostor = super::impostor::impostor_pipeline(&ctx.device, &shared, format);
        let tree = SingleTree::new(ctx, &shared);
        let view_buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("tree view"),
            size: std::mem::size_of::<ViewUniform>() as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let view_group = shared.view_group(&ctx.device, &view_buffer);
        Self {
            mesh,
            cluster,
            billboard,
            impostor,
            tree,
            view_buffer,
            view_group,
            format,
            ao: true,
            lighting: Lighting::default(),
            leaf_transmit: super::sky_light::LEAF_TRANSMIT,
            light_parts: super::sky_light::LightParts::default(),
            full_res_alpha: false,
            season: std::cell::Cell::new((Season::LeafOn, [0.0; 4])),
            sky: std::cell::Cell::new(None),
        }
    }

    /// Draws from now on a tree with `meta`'s seasons (a pack's `season`;
    /// none: evergreen) in `season`. [`Self::render_pack`] then uploads the
    /// bare far tiers in leaf-off where the pack has them.
    pub fn set_season(&self, meta: Option<&crate::format::pack::SeasonMeta>, season: Season) {
        self.season.set((season, super::settings::season_params(meta, season)));
    }

    /// The far-tier state [`Self::render_pack`] uploads of `pack`: 1 (the
    /// bare wood) in leaf-off where the pack has it, else 0.
    fn far_state(&self, pack: &Pack<'_>) -> u32 {
        let bare = pack.meta.season.as_ref().is_some_and(|s| s.bare_far);
        u32::from(bare && self.season.get().0 == Season::LeafOff)
    }

    /// Draws mesh variant `variant` (0–31) from now on (0 by default; a level
    /// with fewer variants draws `variant` modulo their number): its one tree
    /// takes the variation that chooses it, tinted as that variation is.
    pub fn set_variant(&self, ctx: &GpuContext, variant: u32) {
        self.tree.set_variant(ctx, variant);
    }

    /// Renders `what` as `shot` sees it into an sRGB RGBA8 image over `background`.
    pub fn render(&self, ctx: &GpuContext, what: &TreeDraw<'_>, shot: &Shot, background: [f64; 4]) -> Vec<u8> {
        let (encoder, color) = self.encode(ctx, what, shot, background, None, 1);
        ctx.queue.submit([encoder.finish()]);
        read_texture_rgba8(ctx, &color, 0, 0)
    }

    /// The GPU work of drawing `what` as [`Self::render`] would: vertex and
    /// fragment shader invocations, counted by a pipeline-statistics query
    /// (deterministic, unlike a timer: the bake's LoD policy models time from
    /// it). `None` where the device lacks `PIPELINE_STATISTICS_QUERY`.
    #[cfg(not(target_arch = "wasm32"))]
    #[must_use]
    pub fn work(&self, ctx: &GpuContext, what: &TreeDraw<'_>, shot: &Shot) -> Option<Work> {
        if !ctx.device.features().contains(wgpu::Features::PIPELINE_STATISTICS_QUERY) {
            return None;
        }
        let query = ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("tree work"),
            ty: wgpu::QueryType::PipelineStatistics(
                wgpu::PipelineStatisticsTypes::VERTEX_SHADER_INVOCATIONS
                    | wgpu::PipelineStatisticsTypes::FRAGMENT_SHADER_INVOCATIONS,
            ),
            count: 1,
        });
        let resolve = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("tree work resolve"),
            size: 16,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let read = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("tree work read"),
            size: 16,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let (mut encoder, _color) = self.encode(ctx, what, shot, [0.0; 4], Some(&query), 1);
        encoder.resolve_query_set(&query, 0..1, &resolve, 0);
        encoder.copy_buffer_to_buffer(&resolve, 0, &read, 0, 16);
        ctx.queue.submit([encoder.finish()]);
        let slice = read.slice(..);
        slice.map_async(wgpu::MapMode::Read, |_| {});
        ctx.device.poll(wgpu::PollType::wait_indefinitely()).ok()?;
        let words: [u64; 2] = bytemuck::pod_read_unaligned(&slice.get_mapped_range().ok()?[..16]);
        Some(Work { vertices: words[0], fragments: words[1] })
    }

    /// Wall time (ms) of drawing `what` once at this size, net of an empty
    /// pass: the median of `runs` submissions of 8 passes each. For
    /// calibrating the LoD policy's cost model ([`Work`]); a timer, so not
    /// deterministic.
    #[cfg(not(target_arch = "wasm32"))]
    #[must_use]
    pub fn wall_ms(&self, ctx: &GpuContext, what: &TreeDraw<'_>, shot: &Shot, runs: usize) -> f64 {
        const PASSES: u32 = 8;
        let time = |draws: u32| {
            let mut samples: Vec<f64> = (0..runs.max(1))
                .map(|_| {
                    let encoders: Vec<_> =
                        (0..PASSES).map(|_| self.encode(ctx, what, shot, [0.0; 4], None, draws)).collect();
                    let _ = ctx.device.poll(wgpu::PollType::wait_indefinitely());
                    let start = std::time::Instant::now();
                    ctx.queue.submit(encoders.into_iter().map(|(e, _)| e.finish()));
                    let _ = ctx.device.poll(wgpu::PollType::wait_indefinitely());
                    start.elapsed().as_secs_f64() * 1e3 / f64::from(PASSES)
                })
                .collect();
            samples.sort_by(f64::total_cmp);
            samples[samples.len() / 2]
        };
        (time(1) - time(0)).max(0.0)
    }

    /// Draws `what` `draws` times into fresh targets: the encoder (not
    /// submitted) and the colour target. With `query`, the draws are inside a
    /// pipeline-statistics query at index 0.
    fn encode(
        &self,
        ctx: &GpuContext,
        what: &TreeDraw<'_>,
        shot: &Shot,
        background: [f64; 4],
        query: Option<&wgpu::QuerySet>,
        draws: u32,
    ) -> (wgpu::CommandEncoder, wgpu::Texture) {
        let Shot { clip_from_eye, eye, size: [width, height] } = *shot;
        let sky = match self.sky.get() {
            Some((light, sky)) if light == self.lighting => sky,
            _ => {
                let sky = self.lighting.default_sky();
                self.sky.set(Some((self.lighting, sky)));
                sky
            }
        };
        let mut uniform = self.lighting.view_uniform_with(clip_from_eye, eye, [width, height], sky);
        uniform.ambient[3] = f32::from(u8::from(self.ao));
        uniform.sky.sun[3] = self.leaf_transmit;
        uniform.sky.parts[0] = self.light_parts.0;
        uniform.eye_hi[3] = f32::from(u8::from(self.full_res_alpha));
        // Pixels per metre at 1 m, for the lines' minimum width.
        let row1 = Vec3::new(clip_from_eye.x_axis.y, clip_from_eye.y_axis.y, clip_from_eye.z_axis.y);
        uniform.lod[0] = 0.5 * height as f32 * row1.length();
        ctx.queue.write_buffer(&self.view_buffer, 0, bytemuck::bytes_of(&uniform));
        let mut params = DrawParams { season: self.season.get().1, ..Default::default() };
        match what {
            TreeDraw::Mesh(_, level) => params.ids[1] = (*level).min(1) as u32,
            TreeDraw::Cloud(_) => params.ids[1] = Repr::Cloud as u32,
            TreeDraw::Cluster(c, level) => {
                params.ids[1] = Repr::Cluster0 as u32;
                c.draw_params(*level, &mut params);
            }
            TreeDraw::Billboard(bb) => {
                params.ids[1] = Repr::Billboard as u32;
                params.ids[3] = bb.meta.angles | (bb.meta.azimuths << 16);
                params.bb_center = [bb.meta.center[0], bb.meta.center[1], bb.meta.center[2], bb.meta.half_width];
                params.bb_size = [bb.meta.half_height, bb.meta.variants.unwrap_or(1) as f32, 0.0, 0.0];
            }
            TreeDraw::Impostor(imp) => {
                params.ids[1] = Repr::Billboard as u32;
                imp.draw_params(&mut params);
            }
        }
        ctx.queue.write_buffer(&self.tree.params, 0, bytemuck::bytes_of(&params));
        let color = target(ctx, width, height, self.format);
        let depth = target(ctx, width, height, DEPTH_FORMAT);
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("tree"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &color.create_view(&Default::default()),
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color {
                            r: background[0],
                            g: background[1],
                            b: background[2],
                            a: background[3],
                        }),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &depth.create_view(&Default::default()),
                    depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(0.0), store: wgpu::StoreOp::Discard }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            if let Some(q) = query {
                pass.begin_pipeline_statistics_query(q, 0);
            }
            pass.set_bind_group(0, &self.view_group, &[]);
            self.tree.bind(&mut pass);
            for _ in 0..draws {
                match what {
                    TreeDraw::Mesh(mesh, level) => {
                        let indices = mesh.bind_level(&mut pass, &self.mesh, RenderMode::Lit, *level);
                        pass.draw_indexed(0..indices, 0, 0..1);
                    }
                    TreeDraw::Cloud(mesh) => {
                        let indices = mesh.bind_cloud(&mut pass, &self.mesh, RenderMode::Lit);
                        pass.draw_indexed(0..indices, 0, 0..1);
                    }
                    TreeDraw::Cluster(c, level) => {
                        pass.set_pipeline(self.cluster.pipeline(true));
                        pass.set_bind_group(1, &c.bind_group, &[]);
                        pass.draw(0..c.vertices(*level), 0..1);
                    }
                    TreeDraw::Billboard(bb) => {
                        pass.set_pipeline(self.billboard.pipeline());
                        pass.set_bind_group(1, &bb.bind_group, &[]);
                        pass.draw(0..BILLBOARD_VERTICES, 0..1);
                    }
                    TreeDraw::Impostor(imp) => {
                        pass.set_pipeline(self.impostor.pipeline());
                        pass.set_bind_group(1, &imp.bind_group, &[]);
                        pass.draw(0..IMPOSTOR_VERTICES, 0..1);
                    }
                }
            }
            if query.is_some() {
                pass.end_pipeline_statistics_query();
            }
        }
        (encoder, color)
    }
}

/// The GPU work of one draw ([`TreeRenderer::work`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Work {
    /// Vertex shader invocations.
    pub vertices: u64,
    /// Fragment shader invocations (2×2 quads included).
    pub fragments: u64,
}

/// A perspective camera framing a whole tree with bounds `min..max` from
/// `view`, for an image of `size` (width, height).
#[must_use]
pub fn preview_camera(min: Vec3, max: Vec3, view: PackView, size: [u32; 2]) -> Shot {
    let [width, height] = size;
    let center = (min + max) * 0.5;
    let radius = ((max - min) * 0.5).length().max(1e-3);
    let elevation: f32 = match view {
        PackView::Side => 0.0,
        PackView::Oblique => 35f32.to_radians(),
        PackView::Top => 89.9f32.to_radians(),
    };
    let fov_y = 40f32.to_radians();
    let aspect = width as f32 / height as f32;
    let fit = (fov_y * 0.5).tan().min((fov_y * 0.5).tan() * aspect);
    let distance = radius / fit * 1.05;
    let (dir, _) = BillboardFrame::view_axes(elevation, -std::f32::consts::FRAC_PI_2);
    let eye = center + dir * distance;
    // Camera-relative: rotation-only view matrix, the tree placed at (origin − eye).
    let eye_from_world = glam::camera::rh::view::look_to_mat4(Vec3::ZERO, -dir, Vec3::Z);
    let proj = glam::camera::rh::proj::directx::perspective_infinite_reverse(fov_y, aspect, distance * 0.01);
    Shot { clip_from_eye: proj * eye_from_world, eye, size }
}

/// Which representation of a pack [`render_pack_preview`] draws.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PackRepr {
    /// Mesh level n.
    Mesh(usize),
    /// Cluster level n (ellipsoids + lines).
    Cluster(usize),
    /// The billboards.
    Billboard,
    /// The multi-view impostors.
    Impostor,
    /// The billboard cloud.
    Cloud,
}

/// Renders one tree of `pack` lit, with a perspective camera framing the whole
/// tree, into an sRGB RGBA8 image of `size` (width, height), with the tree's
/// own baked occlusion when `ao`. `None` if the pack lacks the representation.
///
/// Sets up a [`TreeRenderer`] (every pipeline) for the one image: to render
/// several, make one and call [`TreeRenderer::render_pack`].
#[must_use]
pub fn render_pack_repr(
    ctx: &GpuContext,
    pack: &Pack<'_>,
    repr: PackRepr,
    view: PackView,
    size: [u32; 2],
    background: [f64; 4],
    ao: bool,
) -> Option<Vec<u8>> {
    let mut r = TreeRenderer::new(ctx);
    r.ao = ao;
    r.render_pack(ctx, pack, repr, view, size, background)
}

impl TreeRenderer {
    /// Renders one tree of `pack` lit, with a perspective camera framing the
    /// whole tree, into an sRGB RGBA8 image of `size` (with the tree's
    /// own occlusion when [`Self::ao`]). `None` if the pack lacks the
    /// representation. The pack is uploaded for the call; the pipelines are
    /// this renderer's (compiling them is most of a one-off image's time).
    #[must_use]
    pub fn render_pack(
        &self,
        ctx: &GpuContext,
        pack: &Pack<'_>,
        repr: PackRepr,
        view: PackView,
        size: [u32; 2],
        background: [f64; 4],
    ) -> Option<Vec<u8>> {
        let r = self;
        let shot = preview_camera(Vec3::from(pack.meta.bounds_min), Vec3::from(pack.meta.bounds_max), view, size);
        match repr {
            PackRepr::Mesh(level) => {
                let mesh = MeshGpu::upload(&ctx.device, &ctx.queue, &r.mesh, pack);
                mesh.has_level(level).then(|| r.render(ctx, &TreeDraw::Mesh(&mesh, level), &shot, background))
            }
            PackRepr::Cluster(level) => {
                let c = ClusterGpu::upload(&ctx.device, &ctx.queue, &r.cluster, pack)?;
                (level < c.levels.len()).then(|| r.render(ctx, &TreeDraw::Cluster(&c, level), &shot, background))
            }
            PackRepr::Billboard => {
                let bb = BillboardGpu::upload(&ctx.device, &ctx.queue, self.far_state(pack), &r.billboard, pack)?;
                Some(r.render(ctx, &TreeDraw::Billboard(&bb), &shot, background))
            }
            PackRepr::Impostor => {
                let imp = ImpostorGpu::upload(&ctx.device, &ctx.queue, self.far_state(pack), &r.impostor, pack)?;
                Some(r.render(ctx, &TreeDraw::Impostor(&imp), &shot, background))
            }
            PackRepr::Cloud => {
                let mesh = MeshGpu::upload(&ctx.device, &ctx.queue, &r.mesh, pack);
                mesh.cloud.is_some().then(|| r.render(ctx, &TreeDraw::Cloud(&mesh), &shot, background))
            }
        }
    }
}

/// Renders one tree of `pack` (mesh level `level`) lit, with a perspective camera
/// framing the whole tree, into an sRGB RGBA8 image of `size` (width, height).
#[must_use]
pub fn render_pack_preview(
    ctx: &GpuContext,
    pack: &Pack<'_>,
    level: usize,
    view: PackView,
    size: [u32; 2],
    background: [f64; 4],
) -> Vec<u8> {
    render_pack_repr(ctx, pack, PackRepr::Mesh(level), view, size, background, true)
        .unwrap_or_else(|| vec![0; (size[0] * size[1] * 4) as usize])
}
