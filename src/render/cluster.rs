//! Cluster pass: clustered ellipsoids and lines (Clasen et al. 2010, §5), ray-cast per
//! pixel with correct depth, one indirect draw per species × cluster tier.
//! Shader: `shaders/cluster.wgsl`. The noise cube maps are made here.

use std::sync::OnceLock;

use super::gpu_data::DrawParams;
use super::layouts::{sampler_entry, storage_entry, texture_entry, SharedLayouts};
use super::shaders;
use crate::format::cluster::{ClusterLevelMeta, ClusterMeta};
use crate::format::pack::{kind, AoFieldRef, TextureArrayMeta};
use crate::format::Pack;

/// How far out along its normal (in field cells) an ellipsoid or a line looks
/// up its occlusion: a cluster's surface lies inside the leaves it stands for,
/// whose outermost ones are the ones seen.
pub const AO_LIFT_CELLS: f32 = 1.5;

/// Vertices per primitive (a two-triangle proxy).
pub const CLUSTER_VERTICES: u32 = 6;

/// log2 of the noise cube side: 64² texels a face, so noise levels up to 6
/// (clusters of up to 2^11 leaves) have their own mip; coarser clusters share mip 0.
pub const NOISE_SIZE_LOG2: u32 = 6;

/// The cluster pipeline, its group-1 layout and the shared noise textures.
pub struct ClusterPipeline {
    /// Group 1: records, alpha noise cube, normal noise cube, sampler, occlusion field (3D).
    pub layout: wgpu::BindGroupLayout,
    pipeline: wgpu::RenderPipeline,
    proxy_depth: wgpu::RenderPipeline,
    shadow: wgpu::RenderPipeline,
    /// The id pass's (picking), with the exact depth.
    pub id: super::layouts::IdPipeline,
    /// The id pass's with the proxy's depth (as the lit pass draws without exact depth).
    pub id_proxy: super::layouts::IdPipeline,
    sampler: wgpu::Sampler,
    noise: OnceLock<(wgpu::TextureView, wgpu::TextureView)>,
}

impl ClusterPipeline {
    /// Creates the pipeline for `color_format` targets.
    #[must_use]
    pub fn new(device: &wgpu::Device, shared: &SharedLayouts, color_format: wgpu::TextureFormat) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("cluster.wgsl"),
            source: wgpu::ShaderSource::Wgsl(shaders::CLUSTER.source().into()),
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("cluster level"),
            entries: &[
                storage_entry(0, wgpu::ShaderStages::VERTEX, true),
                texture_entry(1, wgpu::TextureViewDimension::Cube),
                texture_entry(2, wgpu::TextureViewDimension::Cube),
                sampler_entry(3),
                texture_entry(4, wgpu::TextureViewDimension::D3),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("cluster"),
            bind_group_layouts: &[Some(&shared.view), Some(&layout), Some(&shared.instances), Some(&shared.draw)],
            immediate_size: 0,
        });
        let target = super::layouts::PullingTarget {
            primitive: wgpu::PrimitiveState { cull_mode: None, ..Default::default() },
            depth_stencil: super::layouts::depth_state(true, wgpu::CompareFunction::Greater),
            format: color_format,
        };
        let make =
            |entry: &str| super::layouts::pulling_pipeline(device, entry, &module, &pipeline_layout, entry, &target);
        let pipeline = make("fs_main");
        let proxy_depth = make("fs_proxy_depth");
        let shadow = super::layouts::shadow_caster_pipeline(device, "cluster shadow", &module, &pipeline_layout, &[]);
        let id = super::layouts::IdPipeline::new("cluster", &module, &pipeline_layout, &[], target.primitive);
        let id_proxy = super::layouts::IdPipeline::with_fragment(
            "cluster",
            "fs_id_proxy_depth",
            &module,
            &pipeline_layout,
            &[],
            target.primitive,
        );
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("cluster noise"),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            mipmap_filter: wgpu::MipmapFilterMode::Linear,
            ..Default::default()
        });
        Self { layout, pipeline, proxy_depth, shadow, id, id_proxy, sampler, noise: OnceLock::new() }
    }

    /// The pipeline: exact per-pixel depth, or (benchmarks) the proxy's depth.
    #[must_use]
    pub fn pipeline(&self, exact_depth: bool) -> &wgpu::RenderPipeline {
        if exact_depth {
            &self.pipeline
        } else {
            &self.proxy_depth
        }
    }

    /// The shadow casters' pipeline (depth only, exact ray-cast depth).
    #[must_use]
    pub fn shadow_pipeline(&self) -> &wgpu::RenderPipeline {
        &self.shadow
    }

    fn noise(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> &(wgpu::TextureView, wgpu::TextureView) {
        self.noise.get_or_init(|| {
            let (alpha, normal) = noise_cubes(NOISE_SIZE_LOG2);
            let meta = TextureArrayMeta::plain(1 << NOISE_SIZE_LOG2, 6, NOISE_SIZE_LOG2 + 1);
            let view = |t: wgpu::Texture| {
                t.create_view(&wgpu::TextureViewDescriptor {
                    dimension: Some(wgpu::TextureViewDimension::Cube),
                    ..Default::default()
                })
            };
            let fmt = wgpu::TextureFormat::Rgba8Unorm;
            let a = super::mesh::upload_texture_array(device, queue, "noise alpha", &meta, &alpha, fmt);
            let n = super::mesh::upload_texture_array(device, queue, "noise normal", &meta, &normal, fmt);
            (view(a), view(n))
        })
    }
}

/// The two noise cube maps, mip-major (all faces of mip 0, then mip 1, …), RGBA8:
/// white noise in R (alpha holes) and random unit vectors in RGB (normals).
/// Every mip is its own white noise (not a blur of the finer one), so a
/// threshold t removes the same fraction t of the surface at every level; mip m
/// has 2^(L−m) texels a side, the features of a cluster of noise level L − m.
#[must_use]
pub fn noise_cubes(size_log2: u32) -> (Vec<u8>, Vec<u8>) {
    let mut state = 0x5eed_u64;
    let mut next = move || {
        state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    };
    let (mut alpha, mut normal) = (Vec::new(), Vec::new());
    for m in 0..=size_log2 {
        let side = 1usize << (size_log2 - m);
        for _ in 0..6 * side * side {
            let r = next();
            let v = (r & 0xff) as u8;
            alpha.extend_from_slice(&[v, v, v, 255]);
            // A uniform direction from two random numbers.
            let z = ((r >> 8) & 0xffff) as f32 / 65535.0 * 2.0 - 1.0;
            let phi = ((r >> 24) & 0xffff) as f32 / 65535.0 * std::f32::consts::TAU;
            let s = (1.0 - z * z).max(0.0).sqrt();
            let d = [s * phi.cos(), s * phi.sin(), z];
            normal.extend(d.iter().map(|c| ((c * 0.5 + 0.5) * 255.0).round() as u8));
            normal.push(255);
        }
    }
    (alpha, normal)
}

/// Where one level's records sit in the species' record buffer.
#[derive(Debug, Clone, PartialEq)]
pub struct ClusterLevelGpu {
    /// First word of the level's ellipsoids.
    pub ellipsoid_word: u32,
    /// Ellipsoids.
    pub ellipsoids: u32,
    /// First word of the matching line level.
    pub line_word: u32,
    /// Lines.
    pub lines: u32,
    /// The ellipsoid level's metadata.
    pub meta: ClusterLevelMeta,
}

/// One species' cluster levels on the GPU.
pub struct ClusterGpu {
    /// Group 1 of the cluster pipeline.
    pub bind_group: wgpu::BindGroup,
    /// Levels, finest first.
    pub levels: Vec<ClusterLevelGpu>,
    /// Quantisation box (min, extent).
    pub bounds: ([f32; 3], [f32; 3]),
    /// Linear RGB of the lines.
    pub line_color: [f32; 3],
    /// The occlusion field's box (min, size; model space at scale 1), if baked.
    pub ao_box: Option<([f32; 3], [f32; 3])>,
    /// Its cell side (0 without one).
    pub ao_cell: f32,
    /// Bytes uploaded.
    pub bytes: u64,
}

impl ClusterGpu {
    /// Uploads the cluster levels of `pack`, if it has any.
    #[must_use]
    pub fn upload(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        pipeline: &ClusterPipeline,
        pack: &Pack<'_>,
    ) -> Option<Self> {
        let meta: &ClusterMeta = pack.meta.clusters.as_ref()?;
        if meta.ellipsoid_levels.is_empty() {
            return None;
        }
        let mut words: Vec<u8> = Vec::new();
        let mut ell_words = Vec::new();
        for l in 0..meta.ellipsoid_levels.len() {
            ell_words.push((words.len() / 4) as u32);
            words.extend_from_slice(pack.section(kind::ELLIPSOIDS, l as u32)?);
        }
        let mut line_words = Vec::new();
        for l in 0..meta.line_levels.len() {
            line_words.push((words.len() / 4) as u32);
            words.extend_from_slice(pack.section(kind::LINES, l as u32)?);
        }

        let levels = meta
            .ellipsoid_levels
            .iter()
            .enumerate()
            .map(|(l, m)| {
                // Level l draws line level l (or the coarsest there is).
                let line = l.min(meta.line_levels.len().saturating_sub(1));
                let lines = meta.line_levels.get(line).map_or(0, |x| x.count);
                ClusterLevelGpu {
                    ellipsoid_word: ell_words[l],
                    ellipsoids: m.count,
                    line_word: line_words.get(line).copied().unwrap_or(0),
                    lines,
                    meta: m.clone(),
                }
            })
            .collect();
        let lo = pack.meta.bounds_min;
        let hi = pack.meta.bounds_max;
        Some(Self::new(
            device,
            queue,
            pipeline,
            words,
            levels,
            (lo, [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]]),
            meta.line_color,
            pack.ao_field(),
        ))
    }

    /// Encodes `ellipsoids` and `lines` over the bounds `lo..hi` and uploads them
    /// as a single level (the bake's candidate levels, tests).
    #[must_use]
    #[allow(clippy::too_many_arguments)]
    pub fn from_level(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        pipeline: &ClusterPipeline,
        ellipsoids: &[crate::format::cluster::Ellipsoid],
        lines: &[crate::format::cluster::Line],
        (lo, hi): (glam::Vec3, glam::Vec3),
        noise: (f32, f32),
        line_color: [f32; 3],
        ao_field: Option<AoFieldRef<'_>>,
    ) -> Self {
        use crate::format::cluster::{PackedEllipsoid, PackedLine};
        let mut words: Vec<u8> = Vec::new();
        for e in ellipsoids {
            words.extend_from_slice(bytemuck::bytes_of(&PackedEllipsoid::encode(e, lo, hi)));
        }
        let line_word = (words.len() / 4) as u32;
        for l in lines {
            words.extend_from_slice(bytemuck::bytes_of(&PackedLine::encode(l, lo, hi)));
        }
        let level = ClusterLevelGpu {
            ellipsoid_word: 0,
            ellipsoids: ellipsoids.len() as u32,
            line_word,
            lines: lines.len() as u32,
            meta: ClusterLevelMeta {
                count: ellipsoids.len() as u32,
                select_px: 0.0,
                error: 0.0,
                noise_threshold: noise.0,
                normal_blend: noise.1,
                pareto_error: None,
                pareto_cost: None,
            },
        };
        Self::new(
            device,
            queue,
            pipeline,
            words,
            vec![level],
            (lo.to_array(), (hi - lo).to_array()),
            line_color,
            ao_field,
        )
    }

    /// Uploads records (`words`: ellipsoid and line records, little endian) laid
    /// out as `levels` say, quantised over `bounds` (min, extent), with the
    /// tree's own occlusion field (an open one where there is none).
    #[must_use]
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        pipeline: &ClusterPipeline,
        mut words: Vec<u8>,
        levels: Vec<ClusterLevelGpu>,
        bounds: ([f32; 3], [f32; 3]),
        line_color: [f32; 3],
        ao_field: Option<AoFieldRef<'_>>,
    ) -> Self {
        words.resize(words.len().max(16), 0);
        // The field as a 3D texture; texel centres are cell centres, so the box
        // runs from half a cell before the first centre over dims × cell.
        let (dims, cells, ao_box) = match ao_field {
            Some(f) => {
                let min = std::array::from_fn(|i| f.origin[i] - 0.5 * f.cell);
                let size = std::array::from_fn(|i| f.cell * f.dims[i] as f32);
                (f.dims, f.cells, Some((min, size)))
            }
            None => ([1, 1, 1], &[255u8][..], None),
        };
        let field = wgpu::util::DeviceExt::create_texture_with_data(
            device,
            queue,
            &wgpu::TextureDescriptor {
                label: Some("occlusion field"),
                size: wgpu::Extent3d { width: dims[0], height: dims[1], depth_or_array_layers: dims[2] },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D3,
                format: wgpu::TextureFormat::R8Unorm,
                usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                view_formats: &[],
            },
            wgpu::util::TextureDataOrder::LayerMajor,
            cells,
        );
        let field_view = field.create_view(&wgpu::TextureViewDescriptor::default());
        let buffer = wgpu::util::DeviceExt::create_buffer_init(
            device,
            &wgpu::util::BufferInitDescriptor {
                label: Some("cluster records"),
                contents: &words,
                usage: wgpu::BufferUsages::STORAGE,
            },
        );
        let (alpha, normal) = pipeline.noise(device, queue);
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("cluster level"),
            layout: &pipeline.layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: buffer.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(alpha) },
                wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::TextureView(normal) },
                wgpu::BindGroupEntry { binding: 3, resource: wgpu::BindingResource::Sampler(&pipeline.sampler) },
                wgpu::BindGroupEntry { binding: 4, resource: wgpu::BindingResource::TextureView(&field_view) },
            ],
        });
        let bytes = (words.len() + cells.len()) as u64;
        let ao_cell = ao_field.map_or(0.0, |f| f.cell);
        Self { bind_group, levels, bounds, line_color, ao_box, ao_cell, bytes }
    }

    /// Fills the cluster fields of a draw's parameters for level `level`.
    pub fn draw_params(&self, level: usize, d: &mut DrawParams) {
        let Some(l) = self.levels.get(level) else { return };
        d.cluster = [l.ellipsoid_word, l.ellipsoids, l.line_word, l.lines];
        d.cluster_noise = [l.meta.noise_threshold, l.meta.normal_blend, NOISE_SIZE_LOG2 as f32, 0.0];
        d.bounds_min = [self.bounds.0[0], self.bounds.0[1], self.bounds.0[2], 0.0];
        d.bounds_extent = [self.bounds.1[0], self.bounds.1[1], self.bounds.1[2], 0.0];
        d.line_color = [self.line_color[0], self.line_color[1], self.line_color[2], 1.0];
        // Without a field the 1×1×1 white texture answers open everywhere.
        let (min, size) = self.ao_box.unwrap_or(([0.0; 3], [1.0; 3]));
        d.ao_field_min = [min[0], min[1], min[2], AO_LIFT_CELLS * self.ao_cell];
        d.ao_field_size = [size[0], size[1], size[2], 0.0];
    }

    /// Vertices per tree of level `level`.
    #[must_use]
    pub fn vertices(&self, level: usize) -> u32 {
        self.levels.get(level).map_or(0, |l| (l.ellipsoids + l.lines) * CLUSTER_VERTICES)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_mips_are_white_at_every_level() {
        let (alpha, normal) = noise_cubes(4);
        let texels: usize = (0..=4).map(|m| 6 * (1usize << (4 - m)).pow(2)).sum();
        assert_eq!(alpha.len(), texels * 4);
        assert_eq!(normal.len(), texels * 4);
        // Mip 0: about half the texels below 128.
        let n0 = 6 * 16 * 16;
        let below = alpha.chunks(4).take(n0).filter(|t| t[0] < 128).count();
        assert!((below as f32 / n0 as f32 - 0.5).abs() < 0.06, "{below} of {n0}");
    }
}
