//! The tracer's top level built on the GPU (issue 48; `shaders/top_level.wgsl`):
//! a linear BVH over the trees of a view (Lauterbach et al. 2009, §3; Karras
//! 2012, §3–4) recorded in the command buffer that traces the view's first
//! samples, so the CPU hands over the trees as loaded and never orders them.
//! The layout is the walks' (an inner node's children side by side; a leaf a
//! tree), 2n − 1 nodes for n instances after the species' nodes (the ground
//! beside the trees at the root). The CPU's
//! binned-SAH top level (`TraceScene::build`) stays the twin the tests walk.

use wgpu::util::DeviceExt;

use super::layouts::{storage_entry, uniform_entry};
use super::shaders;

/// The build's uniform. Must match `TopBuild` in `shaders/top_level.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct TopBuild {
    /// Trees.
    pub count: u32,
    /// The sort's length: the power of two at or above `count` (at least 2).
    pub padded: u32,
    /// Where the top level starts in the nodes.
    pub top_base: u32,
    /// 1: instance `count` is the ground, beside the trees at the root.
    pub ground: u32,
}

/// The build's pipelines, one per pass.
pub struct TopLevel {
    layout: wgpu::BindGroupLayout,
    /// bounds, codes, sort, gather, split, refit, join.
    passes: Vec<wgpu::ComputePipeline>,
}

/// A build ready to record: its scratch buffers and bindings.
pub struct TopJob {
    group: wgpu::BindGroup,
    build: TopBuild,
    /// Bitonic steps, each a `SortStep` (k, j) at `stride` in the steps uniform.
    steps: u32,
    stride: u32,
}

/// The bitonic merge's (k, j) steps for `padded` keys (Batcher 1968): for
/// each merged length k = 2, 4, … padded, compare distances k/2 … 1.
#[must_use]
pub fn sort_steps(padded: u32) -> Vec<[u32; 4]> {
    let mut steps = Vec::new();
    let mut k = 2;
    while k <= padded {
        let mut j = k / 2;
        while j > 0 {
            steps.push([k, j, 0, 0]);
            j /= 2;
        }
        k *= 2;
    }
    steps
}

/// Times `top_refit` runs for `count` trees: the tree's depth bound (each
/// level of Karras' hierarchy splits at a longer common prefix of its keys:
/// 30 bits of Morton code, then the bits of the trees' indices that break ties).
#[must_use]
pub fn refit_levels(count: u32) -> u32 {
    31 + (32 - count.saturating_sub(1).leading_zeros())
}

const ENTRIES: [&str; 7] = ["top_bounds", "top_codes", "top_sort", "top_gather", "top_split", "top_refit", "top_join"];

/// Nodes of the top level over `trees` trees, with or without the ground
/// beside them at the root.
#[must_use]
pub fn top_nodes(trees: u32, ground: bool) -> u32 {
    (2 * trees).saturating_sub(1) + 2 * u32::from(ground)
}

impl TopLevel {
    /// Creates the pipelines.
    #[must_use]
    pub fn new(device: &wgpu::Device) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("top_level.wgsl"),
            source: wgpu::ShaderSource::Wgsl(shaders::TOP_LEVEL.source().into()),
        });
        let c = wgpu::ShaderStages::COMPUTE;
        let mut entries = vec![uniform_entry(0, c, false), uniform_entry(1, c, true)];
        // (2 nodes, 3 species, 4 the trees as loaded, 5 in curve order, 6 codes, 7 parents, 8 the centres' box.)
        entries.extend((2..9).map(|b| storage_entry(b, c, b == 3 || b == 4)));
        let layout = device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some("top level"), entries: &entries });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("top level"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let passes = ENTRIES
            .iter()
            .map(|entry| {
                device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(entry),
                    layout: Some(&pipeline_layout),
                    module: &module,
                    entry_point: Some(entry),
                    compilation_options: Default::default(),
                    cache: None,
                })
            })
            .collect();
        Self { layout, passes }
    }

    /// A build of the top level over the `count` trees in `source` into
    /// `nodes` (from `top_base`, [`top_nodes`] of them) and `instances` (the
    /// trees in the leaves' order), with `species` (whose roots give each
    /// tree's box). With `ground`, instance `count` (after the trees; already
    /// in `instances` at that place) is the ground: a leaf beside the trees'
    /// hierarchy at the root. Every tree's species must have nodes
    /// (`TraceScene::place` leaves out the others). `count` ≥ 1.
    #[allow(clippy::too_many_arguments)]
    #[must_use]
    pub fn prepare(
        &self,
        device: &wgpu::Device,
        nodes: &wgpu::Buffer,
        species: &wgpu::Buffer,
        source: &wgpu::Buffer,
        instances: &wgpu::Buffer,
        count: u32,
        top_base: u32,
        ground: bool,
    ) -> TopJob {
        let padded = count.max(2).next_power_of_two();
        let build = TopBuild { count, padded, top_base, ground: u32::from(ground) };
        let stride = device.limits().min_uniform_buffer_offset_alignment.max(16);
        let steps = sort_steps(padded);
        let mut step_bytes = vec![0u8; steps.len() * stride as usize];
        for (i, s) in steps.iter().enumerate() {
            let at = i * stride as usize;
            step_bytes[at..at + 16].copy_from_slice(bytemuck::bytes_of(s));
        }
        let init = |label, contents: &[u8], usage| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents, usage })
        };
        let (u, s) = (wgpu::BufferUsages::UNIFORM, wgpu::BufferUsages::STORAGE);
        let build_buf = init("top build", bytemuck::bytes_of(&build), u);
        let step_buf = init("top sort steps", &step_bytes, u);
        let scratch = |label, size: u64| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage: s,
                mapped_at_creation: false,
            })
        };
        let codes = scratch("top codes", u64::from(padded) * 8);
        let parents = scratch("top parents", u64::from(count.max(1)) * 4);
        let centre_box = init("top centres' box", bytemuck::cast_slice(&[u32::MAX, u32::MAX, u32::MAX, 0, 0, 0]), s);
        let step_binding = wgpu::BufferBinding { buffer: &step_buf, offset: 0, size: wgpu::BufferSize::new(16) };
        let resources = [
            build_buf.as_entire_binding(),
            wgpu::BindingResource::Buffer(step_binding),
            nodes.as_entire_binding(),
            species.as_entire_binding(),
            source.as_entire_binding(),
            instances.as_entire_binding(),
            codes.as_entire_binding(),
            parents.as_entire_binding(),
            centre_box.as_entire_binding(),
        ];
        let entries: Vec<_> = resources
            .into_iter()
            .enumerate()
            .map(|(b, resource)| wgpu::BindGroupEntry { binding: b as u32, resource })
            .collect();
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("top level"),
            layout: &self.layout,
            entries: &entries,
        });
        TopJob { group, build, steps: steps.len() as u32, stride }
    }

    /// Records `job`'s passes on `encoder` (the buffers it was prepared
    /// over are then built when the encoder's commands run).
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, job: &TopJob) {
        let TopBuild { count, padded, .. } = job.build;
        let mut pass = encoder
            .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("top level"), timestamp_writes: None });
        let run = |pass: &mut wgpu::ComputePass<'_>, which: usize, threads: u32, step: u32| {
            pass.set_pipeline(&self.passes[which]);
            pass.set_bind_group(0, &job.group, &[step * job.stride]);
            let (x, y) = groups(threads);
            pass.dispatch_workgroups(x, y, 1);
        };
        run(&mut pass, 0, count, 0);
        run(&mut pass, 1, padded, 0);
        for step in 0..job.steps {
            run(&mut pass, 2, padded, step);
        }
        run(&mut pass, 3, count, 0);
        run(&mut pass, 4, count.saturating_sub(1).max(1), 0);
        if count > 1 {
            for _ in 0..refit_levels(count) {
                run(&mut pass, 5, count - 1, 0);
            }
        }
        if job.build.ground == 1 {
            pass.set_pipeline(&self.passes[6]);
            pass.set_bind_group(0, &job.group, &[0]);
            pass.dispatch_workgroups(1, 1, 1);
        }
    }
}

/// 64-thread groups for `threads`, as a 2D grid where one row of 65,535
/// groups is not enough (the shader's `thread()` flattens it).
fn groups(threads: u32) -> (u32, u32) {
    let n = threads.div_ceil(64).max(1);
    if n <= 65_535 {
        (n, 1)
    } else {
        (65_535, n.div_ceil(65_535))
    }
}

#[cfg(not(target_arch = "wasm32"))]
impl TopLevel {
    /// `scene` with its top level built on the GPU and read back (its
    /// trees in the leaves' order): what the tracer walks, for tests and
    /// figures. A scene of no instances comes back as it is.
    #[must_use]
    pub fn built(
        &self,
        ctx: &super::GpuContext,
        scene: &crate::trace::scene::TraceScene,
    ) -> crate::trace::scene::TraceScene {
        use crate::trace::bvh::BvhNode;
        let Some((count, ground)) = scene.top_level_trees() else { return scene.clone() };
        let a = scene.arrays();
        let top_base = a.top_base;
        let mut nodes = a.nodes;
        nodes.truncate(top_base as usize);
        nodes.resize((top_base + top_nodes(count, ground)) as usize, BvhNode::default());
        let rw = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
        let init = |label, contents: &[u8], usage| {
            ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents, usage })
        };
        let nodes_buf = init("bvh nodes", bytemuck::cast_slice(&nodes), rw);
        let species = init("trace species", bytemuck::cast_slice(&a.species), wgpu::BufferUsages::STORAGE);
        let source = init("trees as loaded", bytemuck::cast_slice(&scene.instances), wgpu::BufferUsages::STORAGE);
        let instances = init("trees", bytemuck::cast_slice(&scene.instances), rw);
        let job = self.prepare(&ctx.device, &nodes_buf, &species, &source, &instances, count, top_base, ground);
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        self.encode(&mut encoder, &job);
        ctx.queue.submit([encoder.finish()]);
        let read = |b: &wgpu::Buffer| super::readback::read_buffer(ctx, b, b.size());
        let nodes: Vec<BvhNode> = bytemuck::pod_collect_to_vec(&read(&nodes_buf));
        let mut out = scene.clone();
        out.top = nodes[top_base as usize..].to_vec();
        out.instances = bytemuck::pod_collect_to_vec(&read(&instances));
        out
    }
}
