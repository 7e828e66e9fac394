//! The terrain pass: the tiles the stream selected (`scene::terrain`) drawn in
//! one instanced draw before the trees. Heights live in a pool of fixed slots
//! on the GPU (a tile is uploaded once, when first drawn, and stays until its
//! slot is needed by a tile drawn later); each frame writes only the small
//! per-tile draw records. Ground images (`scene::imagery`) live in a texture
//! array of [`IMAGE_LAYERS`] mipmapped layers, kept the same way; a tile whose
//! image finds no free layer is drawn with the ground material.
//! Shader: `shaders/terrain.wgsl`.

use std::collections::HashMap;

use super::layouts::{depth_state, DEPTH_FORMAT};
use super::layouts::{sampler_entry, storage_entry, texture_array_entry, SharedLayouts};
use crate::scene::imagery::IMAGE_PX;
use crate::scene::terrain::{TerrainDraw, TerrainKey};

/// An sRGB RGBA8 2D-array texture of `layers` layers of `px`², `mips` levels.
fn image_texture(device: &wgpu::Device, px: u32, layers: u32, mips: u32) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some("terrain images"),
        size: wgpu::Extent3d { width: px, height: px, depth_or_array_layers: layers },
        mip_level_count: mips,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba8UnormSrgb,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    })
}

fn image_group(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    texture: &wgpu::Texture,
    sampler: &wgpu::Sampler,
) -> wgpu::BindGroup {
    let view = texture.create_view(&wgpu::TextureViewDescriptor {
        dimension: Some(wgpu::TextureViewDimension::D2Array),
        ..Default::default()
    });
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("terrain images"),
        layout,
        entries: &[
            wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(&view) },
            wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::Sampler(sampler) },
        ],
    })
}

/// Writes an image and its mip chain (2 × 2 box averages, premultiplied by
/// coverage so uncovered pixels do not darken the edge) into `layer`.
fn upload_mips(queue: &wgpu::Queue, texture: &wgpu::Texture, layer: u32, rgba: &[u8]) {
    let mut level = rgba.to_vec();
    let mut px = IMAGE_PX;
    for mip in 0..IMAGE_MIPS {
        queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture,
                mip_level: mip,
                origin: wgpu::Origin3d { x: 0, y: 0, z: layer },
                aspect: wgpu::TextureAspect::All,
            },
            &level,
            wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(px * 4), rows_per_image: Some(px) },
            wgpu::Extent3d { width: px, height: px, depth_or_array_layers: 1 },
        );
        if px == 1 {
            break;
        }
        let half = px / 2;
        let mut next = vec![0u8; (half * half * 4) as usize];
        for j in 0..half as usize {
            for i in 0..half as usize {
                let mut sum = [0u32; 4];
                for (di, dj) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let at = ((2 * j + dj) * px as usize + 2 * i + di) * 4;
                    let a = u32::from(level[at + 3]);
                    for k in 0..3 {
                        sum[k] += u32::from(level[at + k]) * a;
                    }
                    sum[3] += a;
                }
                let at = (j * half as usize + i) * 4;
                for k in 0..3 {
                    next[at + k] = sum[k].checked_div(sum[3]).unwrap_or(0) as u8;
                }
                next[at + 3] = (sum[3] / 4) as u8;
            }
        }
        level = next;
        px = half;
    }
}

/// Most height slots in the pool (a 64-cell tile is 8.5 KB: 8.7 MB at most);
/// a scene with fewer terrain tiles gets one slot per tile.
pub const TERRAIN_SLOTS: usize = 1024;
/// Layers of the ground-image array (256² RGBA8 with mipmaps: 350 KB each).
pub const IMAGE_LAYERS: u32 = 96;
/// Mip levels of a ground image (256 down to 1).
const IMAGE_MIPS: u32 = IMAGE_PX.ilog2() + 1;
/// `TerrainParams::debug` bit: colour tiles by level.
pub const TERRAIN_LEVEL_COLOURS: u32 = 1;
/// `TerrainParams::debug` bit: no geomorphing (comparisons only).
pub const TERRAIN_NO_MORPH: u32 = 2;
/// `TerrainParams::debug` bit: colour the ground by the shadow cascade that
/// holds it (red, green, blue, white for the first four; black: none).
pub const TERRAIN_CASCADE_COLOURS: u32 = 4;
/// `TerrainParams::debug` bit, with [`TERRAIN_CASCADE_COLOURS`]: the ground
/// the first cascade holds is shaded by the second instead (the two compared).
pub const TERRAIN_NEXT_CASCADE: u32 = 8;
/// `GpuTerrainDraw::layer` of a tile without an image.
pub const NO_IMAGE: u32 = u32::MAX;

/// A slot of a pool whose slots hold `(what, frame last drawn)`: a free one,
/// else the one drawn longest ago (not in `frame`); None when every slot is
/// drawn this frame. (The terrain's heights and images, the canopy's rasters.)
pub(crate) fn free_or_oldest<K: Copy>(slots: &[Option<(K, u64)>], frame: u64) -> Option<usize> {
    slots.iter().position(Option::is_none).or_else(|| {
        slots
            .iter()
            .enumerate()
            .filter(|(_, s)| s.is_some_and(|(_, used)| used < frame))
            .min_by_key(|(_, s)| s.map_or(0, |(_, used)| used))
            .map(|(i, _)| i)
    })
}

/// Links each drawn tile to the neighbours of its level drawn beside it
/// ([`GpuTerrainDraw::across_x`], `across_y`), found by key and placed by
/// their corners (west/east, south/north). Draws past 65,535 link none.
fn link_neighbours(records: &mut [GpuTerrainDraw], keys: &[TerrainKey]) {
    // (A scan of every pair: a frame draws a few hundred tiles at most, and
    // a map's code would cost the browser's wasm more than the scan its time.)
    let n = records.len().min(keys.len()).min(0xffff);
    for k in 0..n {
        let (level, x, y) = keys[k];
        let me = records[k];
        let mut across = [0u32; 4]; // west, east, south, north
        for o in 0..n {
            let (l, ox, oy) = keys[o];
            if l != level || ox.abs_diff(x) + oy.abs_diff(y) != 1 {
                continue;
            }
            let other = records[o];
            if (other.size_m - me.size_m).abs() > 1e-3 * me.size_m {
                continue;
            }
            let (ex, ey) =
                ((other.origin_m[0] - me.origin_m[0]) / me.size_m, (other.origin_m[1] - me.origin_m[1]) / me.size_m);
            let side = match (ex.round() as i32, ey.round() as i32) {
                (-1, 0) => 0,
                (1, 0) => 1,
                (0, -1) => 2,
                (0, 1) => 3,
                _ => continue,
            };
            across[side] = o as u32 + 1;
        }
        records[k].across_x = across[0] | across[1] << 16;
        records[k].across_y = across[2] | across[3] << 16;
        // Their images, where another than this tile's: the place one tile
        // west (east, south, north) of this one's in the neighbour's.
        const SHIFT: [[f32; 2]; 4] = [[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]];
        for side in 0..4 {
            records[k].image_across[side] = [0.0, 0.0, 0.0, -1.0];
            let Some(o) = across[side].checked_sub(1).map(|o| records[o as usize]) else { continue };
            if o.layer == NO_IMAGE || o.layer == me.layer {
                continue;
            }
            let [ox, oy, s, _] = o.image_uv;
            // Where the shared edge lies inside the neighbour's image (it
            // drapes an ancestor's, its own not there yet), that side shows
            // its image on across the edge unblended: this side then takes it
            // whole at the edge (the scale negated says so), not half.
            let edge = [ox + s, ox, oy + s, oy][side];
            let inside = edge > 1e-6 && edge < 1.0 - 1e-6;
            records[k].image_across[side] =
                [ox + SHIFT[side][0] * s, oy + SHIFT[side][1] * s, if inside { -s } else { s }, o.layer as f32];
        }
    }
}

/// A ground image's identity: (source generation, terrain tile it covers).
type ImageKey = (u32, TerrainKey);

/// One drawn tile. Must match `TerrainDraw` in `shaders/terrain.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuTerrainDraw {
    /// South-west corner (metres relative to the scene origin) and lowest height.
    pub origin_m: [f32; 3],
    /// Pool slot of the heights.
    pub slot: u32,
    /// Side of the square, metres.
    pub size_m: f32,
    /// Highest minus lowest height.
    pub range_m: f32,
    /// Morph from the parent's surface (0) to the tile's own (1).
    pub morph: f32,
    /// Skirt depth below the edge, metres.
    pub skirt_m: f32,
    /// Where this tile lies in its image: uv offset (x, y) and scale (z, w).
    pub image_uv: [f32; 4],
    /// Layer of the image in the array, [`NO_IMAGE`] for none.
    pub layer: u32,
    /// The draws (index + 1; 0: none) of the neighbours of the same level
    /// drawn this frame, west in bits 0–15 and east in 16–31: the normals
    /// along an edge reach across it, so both sides shade alike (no seam).
    pub across_x: u32,
    /// South (bits 0–15) and north (16–31), as [`Self::across_x`].
    pub across_y: u32,
    /// Padding to 16 bytes.
    pub pad2: u32,
    /// The images of the neighbours in [`Self::across_x`], `across_y` (west,
    /// east, south, north) that drape another image than this tile's: where
    /// this tile's place (0–1, east and north) lies in it, `offset + place ×
    /// scale`, carried across the edge (x, y the offset, z the scale, negated
    /// where the edge lies inside that image) and its layer (w; −1: none). The fragments near an image's edge blend its
    /// edge texels in (`photo_across`: no seam between images).
    pub image_across: [[f32; 4]; 4],
}

/// Pass constants. Must match `TerrainParams` in `shaders/terrain.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct TerrainParams {
    /// Cells per tile side.
    pub grid: u32,
    /// Words per pool slot.
    pub words: u32,
    /// Selection threshold, pixels.
    pub threshold_px: f32,
    /// Bits: [`TERRAIN_LEVEL_COLOURS`], [`TERRAIN_NO_MORPH`], [`TERRAIN_CASCADE_COLOURS`], [`TERRAIN_NEXT_CASCADE`].
    pub debug: u32,
}

/// GPU buffers for one grid size.
struct Pool {
    grid: u16,
    /// Slots (and draw records) the pool holds.
    capacity: usize,
    words: u32,
    heights: wgpu::Buffer,
    draws: wgpu::Buffer,
    params: wgpu::Buffer,
    indices: wgpu::Buffer,
    index_count: u32,
    group: wgpu::BindGroup,
    /// Tile in each slot and the frame it was last drawn.
    slots: Vec<Option<(TerrainKey, u64)>>,
    by_key: HashMap<TerrainKey, u32>,
}

/// The ground images on the GPU.
struct Images {
    texture: wgpu::Texture,
    group: wgpu::BindGroup,
    /// Image in each layer and the frame it was last drawn.
    layers: Vec<Option<(ImageKey, u64)>>,
    by_key: HashMap<ImageKey, u32>,
}

/// The terrain pass.
pub struct TerrainPass {
    pipeline: wgpu::RenderPipeline,
    /// The id pass's (picking: the ground hides trees, and is none).
    pub id: super::layouts::IdPipeline,
    layout: wgpu::BindGroupLayout,
    image_layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
    /// A 1×1 array bound while there are no images.
    no_images: wgpu::BindGroup,
    images: Option<Images>,
    /// Images uploaded since the start.
    pub image_uploads: u64,
    /// Tiles drawn with an image this frame.
    pub imaged: u32,
    pool: Option<Pool>,
    frame: u64,
    /// Tiles drawn this frame.
    count: u32,
    /// Tiles selected but not drawn (more than the pool holds).
    pub dropped: u32,
    /// Tiles uploaded since the start (for stats and tests).
    pub uploads: u64,
    /// This frame's draw records (kept between frames: no allocation in steady state).
    records: Vec<GpuTerrainDraw>,
    /// This frame's image layer per draw (kept between frames too).
    layers: Vec<u32>,
    /// This frame's distinct images (kept between frames too).
    image_keys: Vec<ImageKey>,
}

impl TerrainPass {
    /// The pipeline for `format` targets.
    #[must_use]
    pub fn new(device: &wgpu::Device, shared: &SharedLayouts, format: wgpu::TextureFormat) -> Self {
        let vertex = wgpu::ShaderStages::VERTEX;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("terrain"),
            entries: &[
                storage_entry(0, vertex, true),
                storage_entry(1, vertex, true),
                wgpu::BindGroupLayoutEntry {
                    binding: 2,
                    visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
            ],
        });
        let image_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("terrain images"),
            entries: &[texture_array_entry(0), sampler_entry(1)],
        });
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("terrain images"),
            address_mode_u: wgpu::AddressMode::ClampToEdge,
            address_mode_v: wgpu::AddressMode::ClampToEdge,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            mipmap_filter: wgpu::MipmapFilterMode::Linear,
            anisotropy_clamp: 4,
            ..Default::default()
        });
        let blank = image_texture(device, 1, 1, 1);
        let no_images = image_group(device, &image_layout, &blank, &sampler);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("terrain"),
            source: wgpu::ShaderSource::Wgsl(super::shaders::TERRAIN.source().into()),
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("terrain"),
            bind_group_layouts: &[Some(&shared.view), Some(&layout), Some(&image_layout)],
            immediate_size: 0,
        });
        let target = super::layouts::PullingTarget {
            primitive: wgpu::PrimitiveState { cull_mode: None, ..Default::default() },
            depth_stencil: depth_state(true, wgpu::CompareFunction::Greater),
            format,
        };
        let _ = DEPTH_FORMAT;
        let pipeline =
            super::layouts::pulling_pipeline(device, "terrain", &module, &pipeline_layout, "fs_main", &target);
        let id = super::layouts::IdPipeline::new("terrain", &module, &pipeline_layout, &[], target.primitive);
        Self {
            pipeline,
            id,
            layout,
            image_layout,
            sampler,
            no_images,
            images: None,
            image_uploads: 0,
            imaged: 0,
            pool: None,
            frame: 0,
            count: 0,
            dropped: 0,
            uploads: 0,
            records: Vec::new(),
            layers: Vec::new(),
            image_keys: Vec::new(),
        }
    }

    /// The layer holding the image of `d` (uploaded now if it is new), or
    /// [`NO_IMAGE`] when it has none or every layer is drawn this frame.
    fn image_layer(&mut self, queue: &wgpu::Queue, d: &TerrainDraw) -> u32 {
        let Some(img) = &d.imagery else { return NO_IMAGE };
        if img.tile.px != IMAGE_PX || img.tile.rgba.len() != (IMAGE_PX * IMAGE_PX * 4) as usize {
            return NO_IMAGE;
        }
        let Some(images) = self.images.as_mut() else { return NO_IMAGE };
        if let Some(&layer) = images.by_key.get(&img.key) {
            images.layers[layer as usize] = Some((img.key, self.frame));
            return layer;
        }
        let Some(free) = free_or_oldest(&images.layers, self.frame) else { return NO_IMAGE };
        if let Some((old, _)) = images.layers[free] {
            images.by_key.remove(&old);
        }
        upload_mips(queue, &images.texture, free as u32, &img.tile.rgba);
        self.image_uploads += 1;
        images.layers[free] = Some((img.key, self.frame));
        images.by_key.insert(img.key, free as u32);
        free as u32
    }

    /// Sizes the image array for `layers` images (at most [`IMAGE_LAYERS`];
    /// when a baked scene's manifest arrives, so budgets count it). A larger
    /// array replaces the former (its images are uploaded again when drawn).
    pub fn reserve_images(&mut self, device: &wgpu::Device, layers: u64) {
        let layers = layers.clamp(1, u64::from(IMAGE_LAYERS)) as u32;
        if self.images.as_ref().is_some_and(|i| i.layers.len() as u32 >= layers) {
            return;
        }
        let texture = image_texture(device, IMAGE_PX, layers, IMAGE_MIPS);
        let group = image_group(device, &self.image_layout, &texture, &self.sampler);
        self.images = Some(Images { texture, group, layers: vec![None; layers as usize], by_key: HashMap::new() });
    }

    /// Bytes of GPU memory held.
    #[must_use]
    pub fn gpu_bytes(&self) -> u64 {
        let images = self.images.as_ref().map_or(0, |i| {
            // The mip chain adds a third.
            u64::from(IMAGE_PX) * u64::from(IMAGE_PX) * 4 * i.layers.len() as u64 * 4 / 3
        });
        self.pool.as_ref().map_or(0, |p| p.heights.size() + p.draws.size() + p.indices.size()) + images
    }

    /// Tiles drawn by the last prepared frame.
    #[must_use]
    pub fn drawn(&self) -> u32 {
        self.count
    }

    /// Uploads the heights of newly drawn tiles and writes this frame's draw
    /// records for `draws` (the stream's selection).
    pub fn prepare(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        draws: &[TerrainDraw],
        threshold_px: f32,
        flags: u32,
    ) {
        self.frame += 1;
        self.count = 0;
        self.dropped = 0;
        self.imaged = 0;
        let Some(first) = draws.first() else { return };
        let grid = first.tile.grid;
        if self.pool.as_ref().is_none_or(|p| p.grid != grid) {
            self.reserve(device, grid, TERRAIN_SLOTS as u64);
        }
        // Images first (their layers), then the heights. The array grows (up to
        // IMAGE_LAYERS) when this frame drapes more images than it holds.
        let mut keys = std::mem::take(&mut self.image_keys);
        keys.clear();
        keys.extend(draws.iter().filter_map(|d| d.imagery.as_ref().map(|i| i.key)));
        keys.sort_unstable();
        keys.dedup();
        let held = self.images.as_ref().map_or(0, |i| i.layers.len());
        if keys.len() > held && held < IMAGE_LAYERS as usize {
            self.reserve_images(device, (keys.len() as u64).next_power_of_two().max(16));
        }
        self.image_keys = keys;
        let mut layers = std::mem::take(&mut self.layers);
        layers.clear();
        for d in draws {
            let layer = self.image_layer(queue, d);
            layers.push(layer);
        }
        let Some(pool) = self.pool.as_mut() else { return };
        queue.write_buffer(
            &pool.params,
            0,
            bytemuck::bytes_of(&TerrainParams { grid: u32::from(grid), words: pool.words, threshold_px, debug: flags }),
        );
        let mut records = std::mem::take(&mut self.records);
        records.clear();
        let mut keys: Vec<TerrainKey> = Vec::with_capacity(draws.len());
        for (d, &layer) in draws.iter().zip(&layers) {
            if d.tile.grid != grid {
                self.dropped += 1;
                continue;
            }
            let slot = match pool.by_key.get(&d.key) {
                Some(&s) => s,
                None => {
                    let Some(free) = free_or_oldest(&pool.slots, self.frame) else {
                        self.dropped += 1;
                        continue;
                    };
                    if let Some((old, _)) = pool.slots[free] {
                        pool.by_key.remove(&old);
                    }
                    let mut words: Vec<u32> = d
                        .tile
                        .heights
                        .chunks(2)
                        .map(|p| u32::from(p[0]) | u32::from(*p.get(1).unwrap_or(&0)) << 16)
                        .collect();
                    words.resize(pool.words as usize, 0);
                    queue.write_buffer(
                        &pool.heights,
                        u64::from(pool.words) * 4 * free as u64,
                        bytemuck::cast_slice(&words),
                    );
                    self.uploads += 1;
                    pool.by_key.insert(d.key, free as u32);
                    free as u32
                }
            };
            pool.slots[slot as usize] = Some((d.key, self.frame));
            let cell = d.size_m / f64::from(grid);
            self.imaged += u32::from(layer != NO_IMAGE);
            records.push(GpuTerrainDraw {
                origin_m: [d.origin_m[0] as f32, d.origin_m[1] as f32, d.tile.min_m],
                slot,
                size_m: d.size_m as f32,
                range_m: d.tile.max_m - d.tile.min_m,
                morph: d.morph,
                // Deep enough to hide the largest step a coarser neighbour can leave.
                skirt_m: (2.0 * d.parent_error_m.min(d.tile.max_m - d.tile.min_m) + 0.5 * cell as f32).max(0.5),
                image_uv: d.imagery.as_ref().map_or([0.0, 0.0, 1.0, 1.0], |i| i.uv),
                layer,
                across_x: 0,
                across_y: 0,
                pad2: 0,
                image_across: [[0.0, 0.0, 0.0, -1.0]; 4],
            });
            keys.push(d.key);
        }
        link_neighbours(&mut records, &keys);
        if !records.is_empty() {
            queue.write_buffer(&pool.draws, 0, bytemuck::cast_slice(&records));
        }
        self.count = records.len() as u32;
        self.records = records;
        self.layers = layers;
    }

    /// Sizes the pool for a scene's terrain of `tiles` tiles of `grid` cells
    /// (when its manifest arrives, so the GPU memory it takes is known before
    /// anything is drawn: budgets count it).
    pub fn reserve(&mut self, device: &wgpu::Device, grid: u16, tiles: u64) {
        // At most what one storage binding of the device holds.
        let side = u64::from(grid) + 1;
        let slot_bytes = (side * side).div_ceil(2) * 4;
        let fits = device.limits().max_storage_buffer_binding_size / slot_bytes.max(1);
        let capacity = tiles.clamp(1, (TERRAIN_SLOTS as u64).min(fits.max(1))) as usize;
        if self.pool.as_ref().is_none_or(|p| p.grid != grid || p.capacity != capacity) {
            self.pool = Some(self.make_pool(device, grid, capacity));
        }
    }

    fn make_pool(&self, device: &wgpu::Device, grid: u16, capacity: usize) -> Pool {
        let side = u32::from(grid) + 1;
        let words = (side * side).div_ceil(2);
        let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let heights = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("terrain heights"),
            size: u64::from(words) * 4 * capacity as u64,
            usage: storage,
            mapped_at_creation: false,
        });
        let draws = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("terrain draws"),
            size: (std::mem::size_of::<GpuTerrainDraw>() * capacity) as u64,
            usage: storage,
            mapped_at_creation: false,
        });
        let params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("terrain params"),
            size: std::mem::size_of::<TerrainParams>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        // A (grid + 3)² vertex grid: the tile's vertices and the skirt ring.
        let ring = u32::from(grid) + 3;
        let mut index: Vec<u32> = Vec::with_capacity(((ring - 1) * (ring - 1) * 6) as usize);
        for b in 0..ring - 1 {
            for a in 0..ring - 1 {
                let v = b * ring + a;
                index.extend_from_slice(&[v, v + 1, v + ring + 1, v, v + ring + 1, v + ring]);
            }
        }
        let indices = wgpu::util::DeviceExt::create_buffer_init(
            device,
            &wgpu::util::BufferInitDescriptor {
                label: Some("terrain indices"),
                contents: bytemuck::cast_slice(&index),
                usage: wgpu::BufferUsages::INDEX,
            },
        );
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("terrain"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: heights.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: draws.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: params.as_entire_binding() },
            ],
        });
        Pool {
            grid,
            capacity,
            words,
            heights,
            draws,
            params,
            indices,
            index_count: index.len() as u32,
            group,
            slots: vec![None; capacity],
            by_key: HashMap::new(),
        }
    }

    /// Draws the prepared tiles (view bound at group 0); returns the draw calls (0 or 1).
    pub fn draw(&self, pass: &mut wgpu::RenderPass<'_>) -> u32 {
        self.draw_with(pass, &self.pipeline)
    }

    /// Draws the prepared tiles into the id pass (its pipeline built).
    pub fn draw_ids(&self, pass: &mut wgpu::RenderPass<'_>) -> u32 {
        self.id.get().map_or(0, |p| self.draw_with(pass, p))
    }

    fn draw_with(&self, pass: &mut wgpu::RenderPass<'_>, pipeline: &wgpu::RenderPipeline) -> u32 {
        let Some(pool) = &self.pool else { return 0 };
        if self.count == 0 {
            return 0;
        }
        pass.set_pipeline(pipeline);
        pass.set_bind_group(1, &pool.group, &[]);
        pass.set_bind_group(2, self.images.as_ref().map_or(&self.no_images, |i| &i.group), &[]);
        pass.set_index_buffer(pool.indices.slice(..), wgpu::IndexFormat::Uint32);
        pass.draw_indexed(0..pool.index_count, 0, 0..self.count);
        1
    }
}

impl super::pass::DrawPass for TerrainPass {
    fn draw<'p>(&'p self, pass: &mut wgpu::RenderPass<'p>, _cx: &super::pass::PassContext<'p>) -> u32 {
        TerrainPass::draw(self, pass)
    }

    fn draw_ids<'p>(&'p self, pass: &mut wgpu::RenderPass<'p>, _cx: &super::pass::PassContext<'p>) -> u32 {
        TerrainPass::draw_ids(self, pass)
    }

    fn build_ids(&self, device: &wgpu::Device) {
        self.id.build(device);
    }

    fn gpu_bytes(&self) -> u64 {
        TerrainPass::gpu_bytes(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn draw(x: u32, y: u32, image_uv: [f32; 4], layer: u32) -> GpuTerrainDraw {
        GpuTerrainDraw {
            origin_m: [x as f32 * 256.0, y as f32 * 256.0, 0.0],
            size_m: 256.0,
            image_uv,
            layer,
            image_across: [[0.0; 4]; 4],
            ..bytemuck::Zeroable::zeroed()
        }
    }

    #[test]
    fn neighbours_name_their_images_carried_across_the_edge() {
        // A tile with its own image; west of it one draping its parent's
        // image (its east edge inside it), east one with its own, north one
        // draping the same image as the middle one.
        let keys = [(2, 1, 1), (2, 0, 1), (2, 2, 1), (2, 1, 2)];
        let mut records = [
            draw(1, 1, [0.0, 0.0, 1.0, 1.0], 5),
            draw(0, 1, [0.0, 0.5, 0.5, 0.5], 7),
            draw(2, 1, [0.0, 0.0, 1.0, 1.0], 6),
            draw(1, 2, [0.0, 0.0, 1.0, 1.0], 5),
        ];
        link_neighbours(&mut records, &keys);
        let t = records[0];
        assert_eq!((t.across_x, t.across_y), (2 | 3 << 16, 4 << 16));
        // West: this tile's place one tile east in the parent's image, the
        // edge at its middle (inside: the scale negated).
        assert_eq!(t.image_across[0], [0.5, 0.5, -0.5, 7.0]);
        // East: one tile west in the neighbour's own image, its edge at 0.
        assert_eq!(t.image_across[1], [-1.0, 0.0, 1.0, 6.0]);
        // South: nothing drawn; north: the same image, nothing to blend.
        assert_eq!(t.image_across[2][3], -1.0);
        assert_eq!(t.image_across[3][3], -1.0);
        // The western tile sees this one's image from its east, one tile
        // west of it there, at this image's edge.
        assert_eq!(records[1].image_across[1], [-1.0, 0.0, 1.0, 5.0]);
    }
}
