//! The path tracer on the GPU (issue 48), first part: a species' BVH
//! ([`crate::trace::bvh::Bvh`]) uploaded as it is built, and a probe that
//! traces a list of rays through it (`shaders/trace_probe.wgsl` over
//! `shaders/trace.wgsl`): the WGSL walk's test against its CPU twin, and the
//! measure of rays per second.

use wgpu::util::DeviceExt;

use super::layouts::storage_entry;
use super::shaders;
use super::GpuContext;
use crate::trace::bvh::Bvh;
use crate::trace::{Hit, Ray};

/// A ray as the probe reads it. Must match `ProbeRay` in `shaders/trace_probe.wgsl`.
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
}

impl GpuHit {
    /// The hit, or `None` for a miss.
    #[must_use]
    pub fn hit(&self) -> Option<Hit> {
        (self.t >= 0.0).then_some(Hit { t: self.t, triangle: self.triangle, u: self.u, v: self.v })
    }
}

/// Rays per dispatch (64 per workgroup, within WebGPU's 65,535 workgroups).
const RAYS_PER_DISPATCH: usize = 64 * 65_535;

/// The probe's pipeline.
pub struct TraceProbe {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

impl TraceProbe {
    /// Creates the pipeline.
    #[must_use]
    pub fn new(device: &wgpu::Device) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("trace_probe.wgsl"),
            source: wgpu::ShaderSource::Wgsl(shaders::TRACE_PROBE.source().into()),
        });
        let c = wgpu::ShaderStages::COMPUTE;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("trace probe"),
            entries: &[
                storage_entry(0, c, true),
                storage_entry(1, c, true),
                storage_entry(2, c, true),
                storage_entry(3, c, false),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("trace probe"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("trace_probe"),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("trace_probe"),
            compilation_options: Default::default(),
            cache: None,
        });
        Self { layout, pipeline }
    }

    /// Traces `rays` through `bvh` on the GPU and waits for the hits (one per
    /// ray, in order). An empty hierarchy misses everything.
    #[must_use]
    pub fn trace(&self, ctx: &GpuContext, bvh: &Bvh, rays: &[Ray]) -> Vec<Option<Hit>> {
        if bvh.nodes.is_empty() || rays.is_empty() {
            return vec![None; rays.len()];
        }
        let device = &ctx.device;
        let storage = |label, contents: &[u8]| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let nodes = storage("bvh nodes", bytemuck::cast_slice(&bvh.nodes));
        let tris = storage("bvh triangles", bytemuck::cast_slice(&bvh.triangles));
        let mut out = Vec::with_capacity(rays.len());
        for chunk in rays.chunks(RAYS_PER_DISPATCH) {
            let probe: Vec<ProbeRay> = chunk
                .iter()
                .map(|r| ProbeRay { origin: r.origin.into(), t_max: r.t_max, dir: r.dir.into(), pad: 0.0 })
                .collect();
            let ray_buf = storage("probe rays", bytemuck::cast_slice(&probe));
            let size = (chunk.len() * std::mem::size_of::<GpuHit>()) as u64;
            let hits = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("probe hits"),
                size,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            let read = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("probe hits readback"),
                size,
                usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                mapped_at_creation: false,
            });
            let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("trace probe"),
                layout: &self.layout,
                entries: &[
                    wgpu::BindGroupEntry { binding: 0, resource: nodes.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 1, resource: tris.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 2, resource: ray_buf.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 3, resource: hits.as_entire_binding() },
                ],
            });
            let mut encoder = device.create_command_encoder(&Default::default());
            {
                let mut pass = encoder.begin_compute_pass(&Default::default());
                pass.set_pipeline(&self.pipeline);
                pass.set_bind_group(0, &group, &[]);
                pass.dispatch_workgroups(chunk.len().div_ceil(64) as u32, 1, 1);
            }
            encoder.copy_buffer_to_buffer(&hits, 0, &read, 0, size);
            ctx.queue.submit([encoder.finish()]);
            let slice = read.slice(..);
            slice.map_async(wgpu::MapMode::Read, |r| r.expect("map the probe's hits"));
            device.poll(wgpu::PollType::wait_indefinitely()).expect("wait for the GPU");
            let mapped = slice.get_mapped_range().expect("mapped range");
            out.extend(bytemuck::cast_slice::<u8, GpuHit>(&mapped).iter().map(GpuHit::hit));
            drop(mapped);
            read.unmap();
        }
        out
    }
}
