//! The path tracer's pass (issue 48): `shaders/path_trace.wgsl` over a
//! [`TraceScene`] placed relative to the eye — the sun as a disk of its true
//! angular size sampled at every path vertex, the sky as an environment,
//! two-sided leaves that reflect and transmit, bark and a ground plane that
//! reflect, `bounces` bounces; samples accumulate on the GPU. One code path
//! for `sylva render --path-trace` ([`PathTracer::render`]) and the browser's
//! `setRenderer('path-trace')` (a dispatch a frame while the camera rests,
//! shown by [`PathDisplay`]).

use glam::Vec3;
use wgpu::util::DeviceExt;

use super::layouts::{storage_entry, uniform_entry};
use super::shaders;
use super::sky_light::{sky_scale, LightParts, SkyLight, DEFAULT_TURBIDITY, LEAF_TRANSMIT};
use crate::trace::scene::TraceScene;

/// The sun's angular radius, radians (0.2666°: its mean apparent size).
pub const SUN_ANGULAR_RADIUS: f32 = 0.004_653;

/// The pass's uniform. Must match `PathParams` in `shaders/path_trace.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct PathParams {
    /// Camera forward (unit).
    pub forward: [f32; 4],
    /// Camera right × tan(fov/2) × aspect.
    pub right: [f32; 4],
    /// Camera up × tan(fov/2).
    pub up: [f32; 4],
    /// Towards the sun (unit); w: the cosine of its angular radius.
    pub sun_dir: [f32; 4],
    /// The sun's irradiance at normal incidence over π (the raster's `sun_color`).
    pub sun_color: [f32; 4],
    /// Sky radiance at the zenith.
    pub sky_zenith: [f32; 4],
    /// Sky radiance at the horizon.
    pub sky_horizon: [f32; 4],
    /// Ground albedo (rgb) and the ground plane's height relative to the eye (w; −1e30: none).
    pub ground: [f32; 4],
    /// The raster's ambient light, for the simple light.
    pub ambient: [f32; 4],
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// The dispatch's first sample.
    pub sample: u32,
    /// Samples it adds per pixel.
    pub samples: u32,
    /// Bounces after the first hit.
    pub bounces: u32,
    /// 1: the raster's light (its `shade()` without shadows: the sun with a
    /// leaf's wrap, the sky's hemisphere light, its haze and background).
    pub simple: u32,
    /// Share of a leaf's albedo transmitted.
    pub leaf_transmit: f32,
    /// The eye's height above the scene origin (the raster's haze).
    pub eye_z: f32,
    /// The eye relative to the point the scene was placed around (xyz; the
    /// browser keeps a view's scene while the camera moves near it).
    pub origin: [f32; 4],
    /// x: 1 with an HDR environment bound (the sky and the sun then; set by
    /// [`PathTracer::dispatch`] from the upload); y: its radiance's scale.
    pub env: [f32; 4],
    /// x: 1 to jitter each sample within its pixel (anti-aliasing), 0 for
    /// rays through pixel centres as a rasteriser samples (coverage comparisons).
    pub sampling: [f32; 4],
    /// The clear sky (Preetham et al. 1999), the air and the raster light's
    /// parts, as the raster's view has them ([`super::sky_light`]): under the
    /// physical light `LIGHT_SKY` draws the clear sky (else the gradient) and
    /// `LIGHT_AERIAL` puts the air between the eye and the first hit; the
    /// simple light mirrors the raster's parts.
    pub sky: super::gpu_data::SkyUniform,
}

/// How a frame is traced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathOptions {
    /// Samples per pixel.
    pub spp: u32,
    /// The first sample's index in the pixels' random sequences (another
    /// start: independent samples, e.g. for a reference beside a run).
    pub first_sample: u32,
    /// Bounces after the first hit (at least 2 for the reference).
    pub bounces: u32,
    /// The raster's simple light instead (to split light error from geometry error).
    pub simple: bool,
    /// Share of a leaf's albedo it transmits (the rest it reflects): 0.3,
    /// about what a broad leaf transmits in the green (Jacquemoud & Baret's
    /// PROSPECT leaves transmit 0.2–0.4 of what they scatter in the visible).
    pub leaf_transmit: f32,
    /// The ground plane's height, scene frame (metres); `None`: no ground.
    pub ground_z: Option<f32>,
    /// Ground albedo, linear.
    pub ground_albedo: Vec3,
    /// The scale of an HDR environment's radiance (where one is uploaded).
    pub environment_scale: f32,
    /// Jitter samples within their pixels (anti-aliased; the default), or
    /// send every ray through its pixel's centre, where a rasteriser's one
    /// sample lies (the coverage check against the raster).
    pub jitter: bool,
}

impl Default for PathOptions {
    fn default() -> Self {
        Self {
            spp: 64,
            first_sample: 0,
            bounces: 2,
            simple: false,
            leaf_transmit: LEAF_TRANSMIT,
            ground_z: Some(0.0),
            ground_albedo: super::sky_light::GROUND_ALBEDO,
            environment_scale: 1.0,
            jitter: true,
        }
    }
}

/// The camera and light of a traced frame, in the scene frame (the scene's
/// instances are placed relative to `eye`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathView {
    /// The eye, scene frame (metres from the origin).
    pub eye: Vec3,
    /// View direction (unit).
    pub forward: Vec3,
    /// Vertical field of view, radians.
    pub fov_y: f32,
    /// Towards the sun (unit).
    pub sun_dir: Vec3,
    /// The sun's colour × intensity, as the raster's `Lighting::sun_color`.
    pub sun_color: Vec3,
    /// The sky's colour at the zenith (linear radiance).
    pub sky_zenith: Vec3,
    /// The sky's colour at the horizon.
    pub sky_horizon: Vec3,
    /// The raster's ambient light (`Lighting::ambient`), for the simple light.
    pub ambient: Vec3,
    /// The clear sky (Preetham et al. 1999), the air and the light's parts
    /// ([`PathParams::sky`]; parts 0: the raster's gradient, no air).
    pub sky: super::gpu_data::SkyUniform,
}

/// The raster's sky at the zenith and at the horizon (`shaders/sky.wgsl`'s
/// `SKY_ZENITH`, `SKY_HORIZON`; linear), and its ground below the horizon.
pub const RASTER_SKY_ZENITH: Vec3 = Vec3::new(0.23, 0.42, 0.72);
/// See [`RASTER_SKY_ZENITH`].
pub const RASTER_SKY_HORIZON: Vec3 = Vec3::new(0.62, 0.74, 0.86);

impl PathView {
    /// A view from `eye` along `forward` (unit) under the raster's `lighting`:
    /// its sun, its sky colours scaled as `sky_scale` in `shaders/light.wgsl`
    /// scales them (the sky's brightness follows the ambient light), and a
    /// clear sky of `turbidity` for the physical light (`None`: the gradient).
    #[must_use]
    pub fn under(lighting: &super::Lighting, eye: Vec3, forward: Vec3, fov_y: f32, turbidity: Option<f32>) -> Self {
        let parts = if turbidity.is_some() { LightParts::ALL } else { LightParts::NONE };
        Self::under_parts(lighting, eye, forward, fov_y, turbidity.unwrap_or(DEFAULT_TURBIDITY), parts)
    }

    /// [`Self::under`] with the light's `parts` (the simple light then
    /// mirrors a raster frame drawn with them) through air of `turbidity`.
    #[must_use]
    pub fn under_parts(
        lighting: &super::Lighting,
        eye: Vec3,
        forward: Vec3,
        fov_y: f32,
        turbidity: f32,
        parts: LightParts,
    ) -> Self {
        let scale = sky_scale(lighting);
        Self {
            eye,
            forward,
            fov_y,
            sun_dir: lighting.sun_dir,
            sun_color: lighting.sun_color,
            sky_zenith: RASTER_SKY_ZENITH * scale,
            sky_horizon: RASTER_SKY_HORIZON * scale,
            ambient: lighting.ambient,
            sky: SkyLight::new(lighting, turbidity).uniform(parts, LEAF_TRANSMIT),
        }
    }
}

/// The scene walk's uniform. Must match `TraceParams` in `shaders/trace_scene.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuTraceParams {
    /// Where the top level starts in the nodes.
    pub top_base: u32,
    /// Instances in the top level.
    pub instance_count: u32,
    /// Padding (0).
    pub pad0: u32,
    /// Padding (0).
    pub pad1: u32,
}

/// `v`, or one default record where it is empty: a binding may not be empty.
pub(crate) fn non_empty<T: Default>(mut v: Vec<T>) -> Vec<T> {
    if v.is_empty() {
        v.push(T::default());
    }
    v
}

/// A storage buffer holding `contents`.
pub(crate) fn storage(device: &wgpu::Device, label: &str, contents: &[u8]) -> wgpu::Buffer {
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents,
        usage: wgpu::BufferUsages::STORAGE,
    })
}

/// The pass's pipeline (its image shown on a canvas by [`PathDisplay`]).
pub struct PathTracer {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
    top: super::top_level::TopLevel,
}

/// A scene on the GPU with an image's accumulation, for one size: uploaded
/// once for a view (the top level for a view, not for the whole scene),
/// traced a dispatch at a time while the camera rests, restarted when it moves.
pub struct PathScene {
    group: wgpu::BindGroup,
    params: wgpu::Buffer,
    accum: wgpu::Buffer,
    /// The walk's uniform and the scene's arrays (bindings 0, 2–7, 9).
    trace_params: wgpu::Buffer,
    arrays: Vec<wgpu::Buffer>,
    /// Whether an environment is bound.
    environment: bool,
    /// The top level's build on the GPU, recorded before the first samples.
    top_job: Option<super::top_level::TopJob>,
    size: (u32, u32),
    /// Samples accumulated per pixel since the last restart.
    pub samples: u32,
    /// Bytes it holds on the GPU (the scene's arrays and the accumulation).
    pub bytes: u64,
}

impl PathScene {
    /// The image's size.
    #[must_use]
    pub fn size(&self) -> (u32, u32) {
        self.size
    }

    /// The accumulation: per pixel (row-major, top row first) the sum of its
    /// samples' linear radiance (rgb) and their count (a).
    #[must_use]
    pub fn accum(&self) -> &wgpu::Buffer {
        &self.accum
    }

    /// Starts the image over (the camera or the light changed).
    pub fn restart(&mut self, encoder: &mut wgpu::CommandEncoder) {
        encoder.clear_buffer(&self.accum, 0, None);
        self.samples = 0;
    }
}

/// Samples one dispatch adds per pixel at most (a dispatch stays short on a slow device).
pub const SAMPLES_PER_DISPATCH: u32 = 4;

impl PathTracer {
    /// Creates the pipeline.
    #[must_use]
    pub fn new(device: &wgpu::Device) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("path_trace.wgsl"),
            source: wgpu::ShaderSource::Wgsl(shaders::PATH_TRACE.source().into()),
        });
        let c = wgpu::ShaderStages::COMPUTE;
        let mut entries = vec![uniform_entry(0, c, false), uniform_entry(1, c, false)];
        entries.extend((2..8).map(|b| storage_entry(b, c, true)));
        entries.push(storage_entry(8, c, false));
        entries.push(storage_entry(9, c, true));
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("path trace"),
            entries: &entries,
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("path trace"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("path_trace"),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("path_trace"),
            compilation_options: Default::default(),
            cache: None,
        });
        Self { layout, pipeline, top: super::top_level::TopLevel::new(device) }
    }

    /// Uploads `scene` (placed relative to the eye) and, where given, an HDR
    /// environment (the sky and the sun then) with a zeroed `width`×`height`
    /// accumulation.
    ///
    /// # Errors
    /// The image or the scene's arrays larger than a storage buffer the
    /// device binds (say which and by how much).
    pub fn upload(
        &self,
        device: &wgpu::Device,
        scene: &TraceScene,
        environment: Option<&crate::trace::environment::Environment>,
        (width, height): (u32, u32),
    ) -> Result<PathScene, String> {
        let a = scene.arrays();
        let env = environment.map_or_else(|| vec![0.0f32; 4], crate::trace::environment::Environment::gpu_array);
        // Trees without a top level get theirs built on the GPU (2n − 1 nodes
        // after the species'), recorded before the first samples.
        let count = scene.instances.len() as u32;
        let gpu_top = scene.top_level_trees().filter(|_| scene.top.is_empty());
        let mut nodes = a.nodes;
        if let Some((trees, ground)) = gpu_top {
            let top = super::top_level::top_nodes(trees, ground);
            // (Its root empty until built: a walk before the build meets nothing.)
            let empty = crate::trace::bvh::BvhNode { min: [3e38; 3], max: [-3e38; 3], ..Default::default() };
            nodes.resize((a.top_base + top) as usize, empty);
        }
        let limit = device.limits().max_storage_buffer_binding_size;
        let pixels = u64::from(width) * u64::from(height);
        for (what, bytes) in [
            ("the image's accumulation (16 bytes a pixel)", pixels * 16),
            ("the BVH nodes (32 bytes each)", std::mem::size_of_val(&nodes[..]) as u64),
            ("the species' triangles (64 bytes each)", std::mem::size_of_val(&a.triangles[..]) as u64),
            ("the material textures' texels", a.texels.len() as u64 * 4),
            ("the trees", std::mem::size_of_val(&scene.instances[..]) as u64),
            ("the environment map", std::mem::size_of_val(&env[..]) as u64),
        ] {
            if bytes > limit {
                return Err(format!(
                    "{what} take {:.1} MB, more than this GPU binds in one buffer ({:.1} MB): trace a smaller image or fewer trees (a shorter reach)",
                    bytes as f64 / 1e6,
                    limit as f64 / 1e6
                ));
            }
        }
        let trace_params = GpuTraceParams { top_base: a.top_base, instance_count: count, pad0: 0, pad1: 0 };
        let trace_params = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("trace params"),
            contents: bytemuck::bytes_of(&trace_params),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("path params"),
            size: std::mem::size_of::<PathParams>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        // (A binding may not be empty: an empty scene binds one zeroed record.)
        let instances = non_empty(scene.instances.clone());
        let arrays = vec![
            storage(device, "bvh nodes", bytemuck::cast_slice(&non_empty(nodes))),
            storage(device, "bvh triangles", bytemuck::cast_slice(&non_empty(a.triangles))),
            storage(device, "trace species", bytemuck::cast_slice(&non_empty(a.species))),
            storage(device, "trace instances", bytemuck::cast_slice(&instances)),
            storage(device, "trace materials", bytemuck::cast_slice(&non_empty(a.materials))),
            storage(device, "trace texels", bytemuck::cast_slice(&non_empty(a.texels))),
            storage(device, "environment", bytemuck::cast_slice(&env)),
        ];
        let top_job = gpu_top.map(|(trees, ground)| {
            let source = storage(device, "trees as loaded", bytemuck::cast_slice(&scene.instances));
            self.top.prepare(device, &arrays[0], &arrays[2], &source, &arrays[3], trees, a.top_base, ground)
        });
        let (accum, group) = self.image(device, &trace_params, &params, &arrays, (width, height));
        let bytes = arrays.iter().map(wgpu::Buffer::size).sum::<u64>() + accum.size();
        Ok(PathScene {
            group,
            params,
            accum,
            trace_params,
            arrays,
            environment: environment.is_some(),
            top_job,
            size: (width, height),
            samples: 0,
            bytes,
        })
    }

    /// A new zeroed accumulation of `size` for `scene` (the canvas resized):
    /// the scene's arrays stay.
    ///
    /// # Errors
    /// The image larger than a storage buffer the device binds.
    pub fn resize(
        &self,
        device: &wgpu::Device,
        scene: &mut PathScene,
        (width, height): (u32, u32),
    ) -> Result<(), String> {
        let bytes = u64::from(width) * u64::from(height) * 16;
        let limit = device.limits().max_storage_buffer_binding_size;
        if bytes > limit {
            return Err(format!(
                "the image's accumulation (16 bytes a pixel) takes {:.1} MB, more than this GPU binds in one buffer ({:.1} MB)",
                bytes as f64 / 1e6,
                limit as f64 / 1e6
            ));
        }
        let (accum, group) = self.image(device, &scene.trace_params, &scene.params, &scene.arrays, (width, height));
        scene.bytes = scene.bytes - scene.accum.size() + accum.size();
        scene.accum = accum;
        scene.group = group;
        scene.size = (width, height);
        scene.samples = 0;
        Ok(())
    }

    /// A zeroed accumulation of `size` and the pass's bindings over it.
    fn image(
        &self,
        device: &wgpu::Device,
        trace_params: &wgpu::Buffer,
        params: &wgpu::Buffer,
        arrays: &[wgpu::Buffer],
        (width, height): (u32, u32),
    ) -> (wgpu::Buffer, wgpu::BindGroup) {
        // Zeroed at creation (wgpu clears new buffers).
        let accum = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("path accum"),
            size: (u64::from(width) * u64::from(height)).max(1) * 16,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut entries = vec![
            wgpu::BindGroupEntry { binding: 0, resource: trace_params.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 1, resource: params.as_entire_binding() },
        ];
        // (Bindings 2–7 the scene, 8 the image, 9 the environment.)
        for (i, b) in arrays.iter().enumerate() {
            let binding = if i < 6 { 2 + i as u32 } else { 9 };
            entries.push(wgpu::BindGroupEntry { binding, resource: b.as_entire_binding() });
        }
        entries.push(wgpu::BindGroupEntry { binding: 8, resource: accum.as_entire_binding() });
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("path trace"),
            layout: &self.layout,
            entries: &entries,
        });
        (accum, group)
    }

    /// Records the build of `target`'s top level on the GPU, if it waits for
    /// one (the first [`Self::dispatch`] records it otherwise).
    pub fn build_top(&self, encoder: &mut wgpu::CommandEncoder, target: &mut PathScene) {
        if let Some(job) = target.top_job.take() {
            self.top.encode(encoder, &job);
        }
    }

    /// Records one dispatch adding `samples` (at most
    /// [`SAMPLES_PER_DISPATCH`]) samples a pixel to `target` with `params`
    /// ([`path_params`]; its sample index is set here). One dispatch per
    /// submission: the parameters are written through the queue.
    pub fn dispatch(
        &self,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        target: &mut PathScene,
        params: &PathParams,
        first_sample: u32,
        samples: u32,
    ) {
        let samples = samples.clamp(1, SAMPLES_PER_DISPATCH);
        let mut params = PathParams { sample: first_sample.wrapping_add(target.samples), samples, ..*params };
        params.env[0] = if target.environment { 1.0 } else { 0.0 };
        queue.write_buffer(&target.params, 0, bytemuck::bytes_of(&params));
        self.build_top(encoder, target);
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &target.group, &[]);
        pass.dispatch_workgroups(target.size.0.div_ceil(8), target.size.1.div_ceil(8), 1);
        target.samples += samples;
    }

    /// Traces `scene` (placed relative to `view.eye`), lit by `environment`
    /// where given (else the view's sun and sky), into a `width`×`height`
    /// image of linear radiance (rgb, row-major, top row first), `options.spp`
    /// samples per pixel, waiting for the GPU; `progress(samples done)` after
    /// the top level's build (0: its own submission, so it can be timed) and
    /// after each dispatch.
    ///
    /// # Errors
    /// See [`Self::upload`].
    #[cfg(not(target_arch = "wasm32"))]
    #[allow(clippy::too_many_arguments)]
    pub fn render(
        &self,
        ctx: &super::GpuContext,
        scene: &TraceScene,
        environment: Option<&crate::trace::environment::Environment>,
        view: &PathView,
        (width, height): (u32, u32),
        options: &PathOptions,
        progress: &mut dyn FnMut(u32),
    ) -> Result<Vec<[f32; 3]>, String> {
        let mut target = self.upload(&ctx.device, scene, environment, (width, height))?;
        let params = path_params(view, options, (width, height), view.eye);
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        self.build_top(&mut encoder, &mut target);
        ctx.queue.submit([encoder.finish()]);
        ctx.device.poll(wgpu::PollType::wait_indefinitely()).expect("wait for the GPU");
        progress(0);
        while target.samples < options.spp.max(1) {
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            let samples = SAMPLES_PER_DISPATCH.min(options.spp.max(1) - target.samples);
            self.dispatch(&ctx.queue, &mut encoder, &mut target, &params, options.first_sample, samples);
            ctx.queue.submit([encoder.finish()]);
            ctx.device.poll(wgpu::PollType::wait_indefinitely()).expect("wait for the GPU");
            progress(target.samples);
        }
        let pixels = (u64::from(width) * u64::from(height)) as usize;
        let sums: Vec<[f32; 4]> = read_back(ctx, &target.accum, (pixels * 16) as u64);
        let image = sums.iter().map(|s| {
            let n = s[3].max(1.0);
            [s[0] / n, s[1] / n, s[2] / n]
        });
        Ok(image.collect())
    }
}

/// The pass's uniform for `view` and `options` at `size`, the scene placed
/// around `scene_origin` (scene frame; `view.eye` where it was placed for
/// this view), its sample index and count set per dispatch.
#[must_use]
pub fn path_params(
    view: &PathView,
    options: &PathOptions,
    (width, height): (u32, u32),
    scene_origin: Vec3,
) -> PathParams {
    let f = view.forward.normalize();
    let up_ref = if f.cross(Vec3::Z).length_squared() < 1e-8 { Vec3::Y } else { Vec3::Z };
    let right = f.cross(up_ref).normalize();
    let up = right.cross(f);
    let tan_half = (view.fov_y * 0.5).tan();
    let aspect = width.max(1) as f32 / height.max(1) as f32;
    let v4 = |v: Vec3, w: f32| [v.x, v.y, v.z, w];
    let mut params = PathParams {
        forward: v4(f, 0.0),
        right: v4(right * tan_half * aspect, 0.0),
        up: v4(up * tan_half, 0.0),
        sun_dir: v4(view.sun_dir.normalize(), SUN_ANGULAR_RADIUS.cos()),
        sun_color: v4(view.sun_color, 0.0),
        sky_zenith: v4(view.sky_zenith, 0.0),
        sky_horizon: v4(view.sky_horizon, 0.0),
        ground: v4(options.ground_albedo, options.ground_z.map_or(-1e30, |z| z - scene_origin.z)),
        ambient: v4(view.ambient, 0.0),
        width,
        height,
        sample: 0,
        samples: 0,
        bounces: options.bounces,
        simple: u32::from(options.simple),
        leaf_transmit: options.leaf_transmit.clamp(0.0, 1.0),
        eye_z: view.eye.z,
        origin: v4(view.eye - scene_origin, 0.0),
        env: [0.0, options.environment_scale, 0.0, 0.0],
        sampling: [if options.jitter { 1.0 } else { 0.0 }, 0.0, 0.0, 0.0],
        sky: view.sky,
    };
    params.sky.sun[3] = options.leaf_transmit.clamp(0.0, 1.0);
    params
}

/// The accumulation's display on a colour target (the browser's canvas):
/// each pixel its samples' mean, clamped as [`to_srgb8`] clamps.
pub struct PathDisplay {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::RenderPipeline,
    size: wgpu::Buffer,
}

impl PathDisplay {
    /// Creates the pipeline for targets of `format` (an sRGB one: the image is linear).
    #[must_use]
    pub fn new(device: &wgpu::Device, format: wgpu::TextureFormat) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("path_display.wgsl"),
            source: wgpu::ShaderSource::Wgsl(shaders::PATH_DISPLAY.source().into()),
        });
        let f = wgpu::ShaderStages::FRAGMENT;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("path display"),
            entries: &[uniform_entry(0, f, false), storage_entry(1, f, true)],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("path display"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("path_display"),
            layout: Some(&pipeline_layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("display_vs"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("display_fs"),
                compilation_options: Default::default(),
                targets: &[Some(format.into())],
            }),
            primitive: Default::default(),
            depth_stencil: None,
            multisample: Default::default(),
            multiview_mask: None,
            cache: None,
        });
        let size = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("path display size"),
            size: 16,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Self { layout, pipeline, size }
    }

    /// Records the display of `scene`'s accumulation on `target`.
    pub fn draw(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        scene: &PathScene,
        target: &wgpu::TextureView,
    ) {
        queue.write_buffer(&self.size, 0, bytemuck::cast_slice(&[scene.size.0, scene.size.1, 0, 0]));
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("path display"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: self.size.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: scene.accum.as_entire_binding() },
            ],
        });
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("path display"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: target,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations { load: wgpu::LoadOp::Clear(wgpu::Color::BLACK), store: wgpu::StoreOp::Store },
            })],
            ..Default::default()
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &group, &[]);
        pass.draw(0..3, 0..1);
    }
}

#[cfg(not(target_arch = "wasm32"))]
/// The first `size` bytes of `buffer` (made with `COPY_SRC`) read back once
/// the GPU is done with what was submitted.
pub(crate) fn read_back<T: bytemuck::Pod>(ctx: &super::GpuContext, buffer: &wgpu::Buffer, size: u64) -> Vec<T> {
    bytemuck::pod_collect_to_vec(&super::readback::read_buffer(ctx, buffer, size)[..size as usize])
}

/// Linear radiance to 8-bit sRGB (clamped), as the raster's sRGB target stores it.
#[must_use]
pub fn to_srgb8(image: &[[f32; 3]]) -> Vec<u8> {
    let enc = super::mips::linear_to_srgb;
    image.iter().flat_map(|p| [enc(p[0]), enc(p[1]), enc(p[2]), 255]).collect()
}
