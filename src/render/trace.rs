//! The path tracer on the GPU (issue 48), first part: a species' BVH
//! ([`crate::trace::bvh::Bvh`]) uploaded as it is built, and a probe that
//! traces a list of rays through it (`shaders/trace_probe.wgsl` over
//! `shaders/trace.wgsl`): the WGSL walk's test against its CPU twin, and the
//! measure of rays per second.

use wgpu::util::DeviceExt;

use super::layouts::storage_entry;
use super::path_trace::{non_empty, read_back, storage};
use super::shaders;
use super::GpuContext;
use crate::trace::bvh::Bvh;
use crate::trace::scene::{SceneHit, TraceScene};
use crate::trace::{Hit, Ray};

/// A ray as the probe reads it. Must match `ProbeRay` in `shaders/trace_probe_ray.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ProbeRay {
    /// Where it starts.
    pub origin: [f32; 3],
    /// Hits at or beyond this distance do not count.
    pub t_max: f32,
    /// Its direction.
    pub dir: [f32; 3],
    /// Padding (0).
    pub pad: f32,
}

/// A nearest hit as the GPU writes it (`t < 0`: none). Must match `TraceHit`
/// in `shaders/trace.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuHit {
    /// Distance along the ray; negative for a miss.
    pub t: f32,
    /// The triangle's index in the mesh.
    pub triangle: u32,
    /// Barycentric weight of the second corner.
    pub u: f32,
    /// Barycentric weight of the third corner.
    pub v: f32,
    /// The triangle's place in the concatenated triangles.
    pub index: u32,
}

impl GpuHit {
    /// The hit, or `None` for a miss.
    #[must_use]
    pub fn hit(&self) -> Option<Hit> {
        (self.t >= 0.0).then_some(Hit { t: self.t, triangle: self.triangle, u: self.u, v: self.v, index: self.index })
    }
}

/// A scene's nearest hit as the GPU writes it. Must match `SceneHit` in
/// `shaders/trace_scene.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuSceneHit {
    /// The instance's id (its index in the list the scene was built from).
    pub instance: u32,
    /// Its place in the top level's order (`TraceScene::instances`).
    pub slot: u32,
    /// The hit on its species' mesh.
    pub hit: GpuHit,
}

pub use super::path_trace::GpuTraceParams;

/// Rays per dispatch (64 per workgroup, within WebGPU's 65,535 workgroups).
const RAYS_PER_DISPATCH: usize = 64 * 65_535;

/// The probes' pipelines: one species' hierarchy, and a scene's two levels.
pub struct TraceProbe {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
    scene_layout: wgpu::BindGroupLayout,
    scene_pipeline: wgpu::ComputePipeline,
}

impl TraceProbe {
    /// Creates the pipelines.
    #[must_use]
    pub fn new(device: &wgpu::Device) -> Self {
        let make = |name: &str, shader: &shaders::Shader, uniform: bool, buffers: u32| {
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(name),
                source: wgpu::ShaderSource::Wgsl(shader.source().into()),
            });
            let c = wgpu::ShaderStages::COMPUTE;
            // A uniform first where asked for, then storage buffers, every one
            // read but the last (the hits).
            let first = u32::from(uniform);
            let mut entries: Vec<_> =
                (first..first + buffers).map(|b| storage_entry(b, c, b + 1 < first + buffers)).collect();
            if uniform {
                entries.insert(
                    0,
                    wgpu::BindGroupLayoutEntry {
                        binding: 0,
                        visibility: c,
                        ty: wgpu::BindingType::Buffer {
                            ty: wgpu::BufferBindingType::Uniform,
                            has_dynamic_offset: false,
                            min_binding_size: None,
                        },
                        count: None,
                    },
                );
            }
            let layout = device
                .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(name), entries: &entries });
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some(name),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
            let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(name),
                layout: Some(&pipeline_layout),
                module: &module,
                entry_point: Some(name),
                compilation_options: Default::default(),
                cache: None,
            });
            (layout, pipeline)
        };
        let (layout, pipeline) = make("trace_probe", &shaders::TRACE_PROBE, false, 4);
        let (scene_layout, scene_pipeline) = make("trace_scene_probe", &shaders::TRACE_SCENE_PROBE, true, 8);
        Self { layout, pipeline, scene_layout, scene_pipeline }
    }

    /// Traces `rays` through `bvh` on the GPU and waits for the hits (one per
    /// ray, in order). An empty hierarchy misses everything.
    #[must_use]
    pub fn trace(&self, ctx: &GpuContext, bvh: &Bvh, rays: &[Ray]) -> Vec<Option<Hit>> {
        if bvh.nodes.is_empty() || rays.is_empty() {
            return vec![None; rays.len()];
        }
        let nodes = storage(&ctx.device, "bvh nodes", bytemuck::cast_slice(&bvh.nodes));
        let tris = storage(&ctx.device, "bvh triangles", bytemuck::cast_slice(&bvh.triangles));
        let hits: Vec<GpuHit> = self.dispatch(ctx, &self.layout, &self.pipeline, &[&nodes, &tris], rays);
        hits.iter().map(GpuHit::hit).collect()
    }

    /// Traces `rays` through `scene`'s two levels on the GPU and waits for the
    /// hits (one per ray, in order).
    #[must_use]
    pub fn trace_scene(&self, ctx: &GpuContext, scene: &TraceScene, rays: &[Ray]) -> Vec<Option<SceneHit>> {
        let a = scene.arrays();
        if scene.instances.is_empty() || a.triangles.is_empty() || rays.is_empty() {
            return vec![None; rays.len()];
        }
        let params =
            GpuTraceParams { top_base: a.top_base, instance_count: scene.instances.len() as u32, pad0: 0, pad1: 0 };
        let params = ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("trace params"),
            contents: bytemuck::bytes_of(&params),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let texels = non_empty(a.texels);
        let buffers = [
            params,
            storage(&ctx.device, "bvh nodes", bytemuck::cast_slice(&a.nodes)),
            storage(&ctx.device, "bvh triangles", bytemuck::cast_slice(&a.triangles)),
            storage(&ctx.device, "trace species", bytemuck::cast_slice(&a.species)),
            storage(&ctx.device, "trace instances", bytemuck::cast_slice(&scene.instances)),
            storage(&ctx.device, "trace materials", bytemuck::cast_slice(&a.materials)),
            storage(&ctx.device, "trace texels", bytemuck::cast_slice(&texels)),
        ];
        let inputs: Vec<&wgpu::Buffer> = buffers.iter().collect();
        let hits: Vec<GpuSceneHit> = self.dispatch(ctx, &self.scene_layout, &self.scene_pipeline, &inputs, rays);
        hits.iter().map(|h| h.hit.hit().map(|hit| SceneHit { instance: h.instance, slot: h.slot, hit })).collect()
    }

    /// One probe's dispatches over `rays` (in chunks WebGPU's workgroup
    /// limit allows), bound after `inputs`; the hits read back.
    fn dispatch<H: bytemuck::Pod>(
        &self,
        ctx: &GpuContext,
        layout: &wgpu::BindGroupLayout,
        pipeline: &wgpu::ComputePipeline,
        inputs: &[&wgpu::Buffer],
        rays: &[Ray],
    ) -> Vec<H> {
        let device = &ctx.device;
        let mut out = Vec::with_capacity(rays.len());
        for chunk in rays.chunks(RAYS_PER_DISPATCH) {
            let probe: Vec<ProbeRay> = chunk
                .iter()
                .map(|r| ProbeRay { origin: r.origin.into(), t_max: r.t_max, dir: r.dir.into(), pad: 0.0 })
                .collect();
            let ray_buf = storage(&ctx.device, "probe rays", bytemuck::cast_slice(&probe));
            let size = (chunk.len() * std::mem::size_of::<H>()) as u64;
            let hits = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("probe hits"),
                size,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            let mut entries: Vec<wgpu::BindGroupEntry> = inputs
                .iter()
                .enumerate()
                .map(|(i, b)| wgpu::BindGroupEntry { binding: i as u32, resource: b.as_entire_binding() })
                .collect();
            let n = inputs.len() as u32;
            entries.push(wgpu::BindGroupEntry { binding: n, resource: ray_buf.as_entire_binding() });
            entries.push(wgpu::BindGroupEntry { binding: n + 1, resource: hits.as_entire_binding() });
            let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("trace probe"),
                layout,
                entries: &entries,
            });
            let mut encoder = device.create_command_encoder(&Default::default());
            {
                let mut pass = encoder.begin_compute_pass(&Default::default());
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, &group, &[]);
                pass.dispatch_workgroups(chunk.len().div_ceil(64) as u32, 1, 1);
            }
            ctx.queue.submit([encoder.finish()]);
            out.extend(read_back::<H>(ctx, &hits, size));
        }
        out
    }
}
