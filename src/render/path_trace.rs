//! The path tracer's pass (issue 48): `shaders/path_trace.wgsl` over a
//! [`TraceScene`] placed relative to the eye — the sun as a disk of its true
//! angular size sampled at every path vertex, the sky as an environment,
//! two-sided leaves that reflect and transmit, bark and a ground plane that
//! reflect, `bounces` bounces; samples accumulate on the GPU. Native for now
//! (`sylva render --path-trace`); the browser's control comes with the
//! refinement machinery.

use glam::Vec3;
use wgpu::util::DeviceExt;

use super::layouts::storage_entry;
use super::shaders;
use super::trace::{non_empty, read_back, storage, GpuTraceParams};
use super::GpuContext;
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
    /// Preetham et al. 1999's Perez coefficient A for (Y, x, y).
    pub perez_a: [f32; 4],
    /// Coefficient B.
    pub perez_b: [f32; 4],
    /// Coefficient C.
    pub perez_c: [f32; 4],
    /// Coefficient D.
    pub perez_d: [f32; 4],
    /// Coefficient E.
    pub perez_e: [f32; 4],
    /// The zenith's (Y, x, y) over their distribution; w: render units per kcd/m².
    pub sky_zenith_yxy: [f32; 4],
    /// The sun as the sky's fit saw it; w: 1 for the clear sky, 0 for the raster's gradient.
    pub sky_sun: [f32; 4],
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
}

impl Default for PathOptions {
    fn default() -> Self {
        Self {
            spp: 64,
            first_sample: 0,
            bounces: 2,
            simple: false,
            leaf_transmit: 0.3,
            ground_z: Some(0.0),
            ground_albedo: Vec3::new(0.16, 0.15, 0.08),
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
    /// A clear sky (Preetham et al. 1999) instead of the raster's gradient
    /// (`sky_zenith`, `sky_horizon`) for the physical light.
    pub sky: Option<crate::trace::sky::PreethamSky>,
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
        let scale = (lighting.ambient.dot(Vec3::new(0.2126, 0.7152, 0.0722)) / 0.4573).clamp(0.15, 1.5);
        Self {
            eye,
            forward,
            fov_y,
            sun_dir: lighting.sun_dir,
            sun_color: lighting.sun_color,
            sky_zenith: RASTER_SKY_ZENITH * scale,
            sky_horizon: RASTER_SKY_HORIZON * scale,
            ambient: lighting.ambient,
            sky: turbidity.map(|t| crate::trace::sky::PreethamSky::new(lighting.sun_dir, t)),
        }
    }
}

/// The pass's pipeline.
pub struct PathTracer {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

/// Samples one dispatch adds per pixel (a dispatch stays short on a slow device).
const SAMPLES_PER_DISPATCH: u32 = 4;

impl PathTracer {
    /// Creates the pipeline.
    #[must_use]
    pub fn new(device: &wgpu::Device) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("path_trace.wgsl"),
            source: wgpu::ShaderSource::Wgsl(shaders::PATH_TRACE.source().into()),
        });
        let c = wgpu::ShaderStages::COMPUTE;
        let uniform = |binding| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: c,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let mut entries = vec![uniform(0), uniform(1)];
        entries.extend((2..8).map(|b| storage_entry(b, c, true)));
        entries.push(storage_entry(8, c, false));
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
        Self { layout, pipeline }
    }

    /// Traces `scene` (placed relative to `view.eye`) into a `width`×`height`
    /// image of linear radiance (rgb, row-major, top row first), `options.spp`
    /// samples per pixel, waiting for the GPU; `progress(samples done)` after
    /// each dispatch.
    ///
    /// # Errors
    /// The image or the scene's arrays larger than a storage buffer the
    /// device binds (say which and by how much).
    pub fn render(
        &self,
        ctx: &GpuContext,
        scene: &TraceScene,
        view: &PathView,
        (width, height): (u32, u32),
        options: &PathOptions,
        progress: &mut dyn FnMut(u32),
    ) -> Result<Vec<[f32; 3]>, String> {
        let device = &ctx.device;
        let a = scene.arrays();
        let limit = device.limits().max_storage_buffer_binding_size;
        let pixels = u64::from(width) * u64::from(height);
        for (what, bytes) in [
            ("the image's accumulation (16 bytes a pixel)", pixels * 16),
            ("the species' BVH nodes", std::mem::size_of_val(&a.nodes[..]) as u64),
            ("the species' triangles (64 bytes each)", std::mem::size_of_val(&a.triangles[..]) as u64),
            ("the material textures' texels", a.texels.len() as u64 * 4),
            ("the trees", std::mem::size_of_val(&scene.instances[..]) as u64),
        ] {
            if bytes > limit {
                return Err(format!(
                    "{what} take {:.1} MB, more than this GPU binds in one buffer ({:.1} MB): trace a smaller image or fewer trees (--reach)",
                    bytes as f64 / 1e6,
                    limit as f64 / 1e6
                ));
            }
        }
        let trace_params = GpuTraceParams {
            top_base: a.top_base,
            instance_count: if scene.top.is_empty() { 0 } else { scene.instances.len() as u32 },
            pad0: 0,
            pad1: 0,
        };
        let trace_params = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("trace params"),
            contents: bytemuck::bytes_of(&trace_params),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let path_buf = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("path params"),
            size: std::mem::size_of::<PathParams>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let pixels = pixels as usize;
        // Zeroed at creation (wgpu clears new buffers).
        let accum = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("path accum"),
            size: (pixels * 16) as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        // (A binding may not be empty: an empty scene binds one zeroed record.)
        let instances = non_empty(scene.instances.clone());
        let buffers = [
            storage(ctx, "bvh nodes", bytemuck::cast_slice(&non_empty(a.nodes))),
            storage(ctx, "bvh triangles", bytemuck::cast_slice(&non_empty(a.triangles))),
            storage(ctx, "trace species", bytemuck::cast_slice(&non_empty(a.species))),
            storage(ctx, "trace instances", bytemuck::cast_slice(&instances)),
            storage(ctx, "trace materials", bytemuck::cast_slice(&non_empty(a.materials))),
            storage(ctx, "trace texels", bytemuck::cast_slice(&non_empty(a.texels))),
        ];
        let mut entries = vec![
            wgpu::BindGroupEntry { binding: 0, resource: trace_params.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 1, resource: path_buf.as_entire_binding() },
        ];
        for (i, b) in buffers.iter().enumerate() {
            entries.push(wgpu::BindGroupEntry { binding: 2 + i as u32, resource: b.as_entire_binding() });
        }
        entries.push(wgpu::BindGroupEntry { binding: 8, resource: accum.as_entire_binding() });
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("path trace"),
            layout: &self.layout,
            entries: &entries,
        });
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
            ground: v4(options.ground_albedo, options.ground_z.map_or(-1e30, |z| z - view.eye.z)),
            ambient: v4(view.ambient, 0.0),
            width,
            height,
            sample: 0,
            samples: 0,
            bounces: options.bounces,
            simple: u32::from(options.simple),
            leaf_transmit: options.leaf_transmit.clamp(0.0, 1.0),
            eye_z: view.eye.z,
            perez_a: [0.0; 4],
            perez_b: [0.0; 4],
            perez_c: [0.0; 4],
            perez_d: [0.0; 4],
            perez_e: [0.0; 4],
            sky_zenith_yxy: [0.0; 4],
            sky_sun: [0.0; 4],
        };
        if let (Some(sky), false) = (view.sky, options.simple) {
            let letter = |k: usize| [sky.perez[0][k], sky.perez[1][k], sky.perez[2][k], 0.0];
            params.perez_a = letter(0);
            params.perez_b = letter(1);
            params.perez_c = letter(2);
            params.perez_d = letter(3);
            params.perez_e = letter(4);
            params.sky_zenith_yxy = [sky.zenith[0], sky.zenith[1], sky.zenith[2], crate::trace::sky::UNITS_PER_KCD];
            let fitted = sky.fitted_sun();
            params.sky_sun = [fitted.x, fitted.y, fitted.z, 1.0];
        }
        let mut done = 0;
        while done < options.spp.max(1) {
            params.sample = options.first_sample.wrapping_add(done);
            params.samples = SAMPLES_PER_DISPATCH.min(options.spp.max(1) - done);
            ctx.queue.write_buffer(&path_buf, 0, bytemuck::bytes_of(&params));
            let mut encoder = device.create_command_encoder(&Default::default());
            {
                let mut pass = encoder.begin_compute_pass(&Default::default());
                pass.set_pipeline(&self.pipeline);
                pass.set_bind_group(0, &group, &[]);
                pass.dispatch_workgroups(width.div_ceil(8), height.div_ceil(8), 1);
            }
            ctx.queue.submit([encoder.finish()]);
            device.poll(wgpu::PollType::wait_indefinitely()).expect("wait for the GPU");
            done += params.samples;
            progress(done);
        }
        let sums: Vec<[f32; 4]> = read_back(ctx, &accum, (pixels * 16) as u64);
        let image = sums.iter().map(|s| {
            let n = s[3].max(1.0);
            [s[0] / n, s[1] / n, s[2] / n]
        });
        Ok(image.collect())
    }
}

/// Linear radiance to 8-bit sRGB (clamped), as the raster's sRGB target stores it.
#[must_use]
pub fn to_srgb8(image: &[[f32; 3]]) -> Vec<u8> {
    let enc = |c: f32| {
        let c = c.clamp(0.0, 1.0);
        let s = if c <= 0.003_130_8 { c * 12.92 } else { 1.055 * c.powf(1.0 / 2.4) - 0.055 };
        (s * 255.0 + 0.5) as u8
    };
    image.iter().flat_map(|p| [enc(p[0]), enc(p[1]), enc(p[2]), 255]).collect()
}
