//! The forest renderer: the frame composed from long-lived passes over shared
//! resident data. [`ForestRenderer::prepare`] writes the frame's uniforms and
//! returns its [`FrameData`]; the passes consume it:
//!
//! 1. the cull pass ([`super::cull`]): batches, then trees, into draw items and
//!    indirect arguments;
//! 2. the draw pass: the sky ([`super::overlay`]), the species draws
//!    ([`super::species`], at most one indirect draw per species ×
//!    representation), the batch-bounds overlay when asked for.
//!
//! A new pass (terrain, shadows, ids) is a module with its pipelines and one
//! call in [`ForestRenderer::encode_draw`] or the frame ([`super::frame`]).
//! Residency lives in [`super::pools`] (tiles) and [`super::species`] (packs);
//! the streamer reaches it through [`crate::scene::Residency`] ([`GpuResidency`]).
//!
//! CPU work per frame is O(species): write the view uniform, record five
//! dispatches and at most `species × REPR_COUNT` draws. Tiles are uploaded once
//! when they arrive; nothing per tree is touched by the CPU after that.

use super::counters::CullCounters;
use super::cull::CullPipelines;
use super::gpu_data::{CullControl, DrawArgs, GpuSpecies, ViewUniform, REPR_COUNT, VIEW_STRIDE};
use super::layouts::SharedLayouts;
use super::layouts::DEPTH_FORMAT;
use super::overlay::{BoundsPass, SkyPass};
pub use super::pass::FrameData;
use super::pass::{DrawPass, PassContext, SpeciesFrame};
pub use super::pools::PoolConfig;
use super::pools::{buffer, PoolLayouts, Pools};
use super::reach::Reach;
pub use super::settings::{CullingMode, RenderSettings, Representations, DEFAULT_CLUSTER_MIN_PX, DEFAULT_THIN_PX};
use super::shadow::{ShadowMaps, MAX_CASCADES};
use super::species::Species;
use super::terrain::TerrainPass;
use crate::camera::ViewData;
use crate::format::pack::PACK_PARTS;
use crate::format::{Pack, PackMeta, Tile};
use crate::scene::{PoolError, Residency, TileSlot};

/// What the sky's uniform depends on.
#[derive(Debug, Clone, Copy, PartialEq)]
struct SkyKey {
    light: [[f32; 3]; 3],
    parts: u32,
    turbidity: f32,
}

/// The GPU-driven forest renderer (see the module docs).
pub struct ForestRenderer {
    /// Shared bind group layouts.
    pub shared: SharedLayouts,
    cull: CullPipelines,
    sky: SkyPass,
    terrain: TerrainPass,
    canopy: super::canopy::CanopyPass,
    /// This frame's canopy cross-fade (`ViewUniform::canopy`; zeros: off).
    canopy_px: [f32; 2],
    bounds: BoundsPass,
    pools: Pools,
    species: Species,
    reach: Reach,
    /// The camera's view, then one per shadow cascade, [`VIEW_STRIDE`] apart.
    view_buffer: wgpu::Buffer,
    /// Group 0 of the camera's view (with the shadow map).
    view_group: wgpu::BindGroup,
    /// Group 0 of each cascade's view (without: it draws into the map).
    cascade_groups: Vec<wgpu::BindGroup>,
    shadow_maps: Option<ShadowMaps>,
    /// Each cascade's draw arguments after its cull pass (for the stats).
    shadow_args: Option<wgpu::Buffer>,
    /// How far apart the scene's lowest ground and highest tree top are (m):
    /// how far towards the sun a cascade's casters can stand.
    height_span_m: f32,
    last_view: ViewUniform,
    last_cascades: Vec<ViewUniform>,
    /// The sky's uniform and what it was worked out for (the SH projection
    /// runs once per change of the light, not per frame).
    sky_cache: Option<(SkyKey, super::gpu_data::SkyUniform)>,
    styles_epoch: u64,
}

impl ForestRenderer {
    /// Creates pipelines and pools for `color_format` targets.
    #[must_use]
    pub fn new(device: &wgpu::Device, color_format: wgpu::TextureFormat, config: PoolConfig) -> Self {
        use wgpu::BufferUsages as U;
        let shared = SharedLayouts::new(device);
        let cull = CullPipelines::new(device, &shared);
        let sky = SkyPass::new(device, &shared, color_format);
        let terrain = TerrainPass::new(device, &shared, color_format);
        let canopy = super::canopy::CanopyPass::new(device, &shared, color_format);
        let bounds = BoundsPass::new(device, &shared, color_format);
        let pools = Pools::new(
            device,
            config,
            &PoolLayouts {
                shared: &shared,
                cull: &cull.layout,
                cull_dispatch: &cull.dispatch_layout,
                bounds: &bounds.layout,
            },
        );
        let views = VIEW_STRIDE * (1 + MAX_CASCADES as u64);
        let view_buffer = buffer(device, "views", views, U::STORAGE | U::COPY_DST);
        let view_group = shared.view_group(device, &view_buffer);
        let cascade_groups = (1..=MAX_CASCADES as u64)
            .map(|i| shared.view_group_at(device, &view_buffer, i * VIEW_STRIDE, None))
            .collect();
        Self {
            shared,
            cull,
            sky,
            terrain,
            canopy,
            canopy_px: [0.0; 2],
            bounds,
            pools,
            species: Species::new(color_format),
            reach: Reach::default(),
            view_buffer,
            view_group,
            cascade_groups,
            shadow_maps: None,
            shadow_args: None,
            height_span_m: 60.0,
            last_view: bytemuck::Zeroable::zeroed(),
            last_cascades: Vec::new(),
            sky_cache: None,
            styles_epoch: 0,
        }
    }

    /// The pool configuration.
    #[must_use]
    pub fn config(&self) -> PoolConfig {
        self.pools.config()
    }

    /// Re-creates the pools at `config` cut to the device's limits (when it
    /// differs from the current one). Only while nothing is resident: call it
    /// when a scene's manifest arrives, with [`PoolConfig::for_scene`], so a small
    /// scene does not hold memory for millions of trees.
    pub fn fit_pools(&mut self, device: &wgpu::Device, config: PoolConfig) {
        let layouts = PoolLayouts {
            shared: &self.shared,
            cull: &self.cull.layout,
            cull_dispatch: &self.cull.dispatch_layout,
            bounds: &self.bounds.layout,
        };
        if self.pools.fit(device, config, &layouts) {
            self.species.mark_dirty();
            self.styles_epoch += 1;
        }
    }

    /// Room for a style byte per pool instance, or none (see [`Pools::set_styles`]).
    /// Returns whether the buffer was re-created (its header and bytes cleared).
    pub fn set_styles(&mut self, device: &wgpu::Device, on: bool, growth: bool) -> bool {
        let layouts = PoolLayouts {
            shared: &self.shared,
            cull: &self.cull.layout,
            cull_dispatch: &self.cull.dispatch_layout,
            bounds: &self.bounds.layout,
        };
        let changed = self.pools.set_styles(device, on, growth, &layouts);
        self.styles_epoch += u64::from(changed);
        changed
    }

    /// Changes whenever the styles' buffer is re-created (the pools re-fitted,
    /// or room for style bytes made or given back): its contents are gone.
    #[must_use]
    pub fn styles_epoch(&self) -> u64 {
        self.styles_epoch
    }

    /// Writes the styles' header (palette and flags).
    pub fn write_style_header(&self, queue: &wgpu::Queue, header: &[u32]) {
        self.pools.write_style_header(queue, header);
    }

    /// Writes style bytes of pool instances from `first` (a multiple of 4).
    pub fn write_style_bytes(&self, queue: &wgpu::Queue, first: u32, bytes: &[u8]) {
        self.pools.write_style_bytes(queue, first, bytes);
    }

    /// Writes growth bytes of pool instances from `first` (a multiple of 4).
    pub fn write_growth_bytes(&self, queue: &wgpu::Queue, first: u32, bytes: &[u8]) {
        self.pools.write_growth_bytes(queue, first, bytes);
    }

    /// Whether the pools were cut down to the device's limits (reported in stats).
    #[must_use]
    pub fn pools_limited_by_device(&self) -> bool {
        self.pools.limited_by_device()
    }

    /// Sets the scene's species count (from the manifest). Drops loaded packs.
    ///
    /// # Panics
    /// If `count` exceeds the configured species capacity.
    pub fn set_species_count(&mut self, count: u32) {
        let capacity = self.pools.config().species;
        assert!(count <= capacity, "{count} species exceed the renderer's {capacity}");
        self.pools.set_species_count(count);
        self.species.set_count(count);
    }

    /// Whether species `i`'s pack is on the GPU.
    #[must_use]
    pub fn has_pack(&self, i: u32) -> bool {
        self.species.has_pack(i)
    }

    /// Uploads a decoded pack as species `index`.
    pub fn upload_pack(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, index: u32, pack: &Pack<'_>) {
        self.species.upload_pack(device, queue, &self.shared, index, pack);
    }

    /// Makes a tile resident (see [`Pools::upload_tile`]).
    ///
    /// # Errors
    /// [`PoolError::Full`] when there is no room (nothing is changed), or
    /// [`PoolError::UnknownSpecies`].
    pub fn upload_tile(&mut self, queue: &wgpu::Queue, tile: &Tile) -> Result<TileSlot, PoolError> {
        let slot = self.pools.upload_tile(queue, tile)?;
        self.species.mark_dirty();
        Ok(slot)
    }

    /// Evicts a resident tile (see [`Pools::evict_tile`]).
    pub fn evict_tile(&mut self, queue: &wgpu::Queue, slot: TileSlot) {
        self.pools.evict_tile(queue, slot);
        self.species.mark_dirty();
    }

    /// Resident instances in total.
    #[must_use]
    pub fn resident_instances(&self) -> u64 {
        self.pools.resident_instances()
    }

    /// Free instance slots.
    #[must_use]
    pub fn free_instances(&self) -> u32 {
        self.pools.free_instances()
    }

    /// Which parts of species `s`'s pack the resident trees within reach can need
    /// (see [`Reach::parts_needed`]), from the last [`Self::measure_reach`].
    #[must_use]
    pub fn parts_needed(&self, s: usize, meta: &PackMeta) -> [bool; PACK_PARTS] {
        self.reach.parts_needed(s, meta)
    }

    /// Each species' bound on the projected height (px) of its resident trees
    /// within reach, from the last [`Self::measure_reach`].
    #[must_use]
    pub fn species_max_px(&self) -> &[f32] {
        self.reach.species_max_px()
    }

    /// Which draw pipelines have been built (meshes, clusters, billboards): each
    /// only once a pack holding that representation arrived.
    #[must_use]
    pub fn pipelines_built(&self) -> [bool; 3] {
        self.species.pipelines_built()
    }

    /// GPU bytes: pools plus uploaded packs, terrain and the shadow map.
    #[must_use]
    pub fn gpu_bytes(&self) -> u64 {
        // (The pools' figure counts the control buffer without styles: add what styles hold.)
        let styles = self.pools.buffers.control.size() - super::gpu_data::control_buffer_bytes(0, false);
        let passes: u64 = self.passes().iter().map(|p| p.gpu_bytes()).sum();
        self.pools.config().bytes() + styles + passes + self.shadow_bytes()
    }

    /// GPU bytes of the shadow map (0 until shadows are first drawn).
    #[must_use]
    pub fn shadow_bytes(&self) -> u64 {
        self.shadow_maps.as_ref().map_or(0, |m| m.config.bytes())
    }

    /// Tells the shadows how far apart the scene's lowest ground and highest
    /// tree top are (m; from the manifest).
    pub fn set_height_span(&mut self, span_m: f32) {
        if span_m.is_finite() && span_m > 0.0 {
            self.height_span_m = span_m;
        }
    }

    /// The shadow map for `config`, made (and the camera's view group rebound)
    /// when the quality changed.
    fn ensure_shadow_maps(&mut self, device: &wgpu::Device, config: super::shadow::ShadowConfig) {
        if self.shadow_maps.as_ref().is_some_and(|m| m.requested == config) {
            return;
        }
        let maps = ShadowMaps::new(device, config);
        self.view_group = self.shared.view_group_at(device, &self.view_buffer, 0, Some(&maps.array));
        self.shadow_maps = Some(maps);
    }

    /// Bounds each species' projected tree height for `view` from the resident
    /// tiles' boxes (see [`Reach`]): what [`Self::prepare`] skips draws by and
    /// [`Self::parts_needed`] decides fetches by. Measured again only when the
    /// view, the settings or the residency changed.
    pub fn measure_reach(&mut self, view: &ViewData, settings: &RenderSettings) {
        let (tiles, generation) = (self.pools.tile_bounds(), self.pools.generation());
        self.reach.measure(tiles, generation, self.species.count() as usize, view, settings);
    }

    /// Writes the frame's uniforms (and the species table if residency or the
    /// representation settings changed; the shadow map if the shadow quality
    /// did) and returns what the passes draw.
    pub fn prepare(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        view: &ViewData,
        settings: &RenderSettings,
    ) -> FrameData {
        self.measure_reach(view, settings);
        self.species.update_table(queue, &self.pools, settings);
        if settings.moving_impostors {
            self.species.build_moving_pipelines(device);
        }
        let l = &settings.lighting;
        let uniform = ViewUniform {
            clip_from_eye: view.clip_from_eye.to_cols_array_2d(),
            // w: the mesh leaves' alpha test (`surface` in mesh.wgsl): 1 at the
            // textures' full resolution (the accuracy reference), 2 adaptive, 0 plain.
            eye_hi: view
                .eye_hi
                .extend(if settings.full_res_alpha {
                    1.0
                } else if settings.adaptive_alpha {
                    2.0
                } else {
                    0.0
                })
                .to_array(),
            // w: the cross-fade dither's shift (`fade_keeps` in select.wgsl).
            eye_lo: view.eye_lo.extend(settings.refine_seed as f32).to_array(),
            frustum: view.frustum.map(|p| p.to_array()),
            sun_dir: l.sun_dir.extend(0.0).to_array(),
            sun_color: l.sun_color.extend(0.0).to_array(),
            // w: the trees' own baked occlusion on (1) or off (0), `own_ao` in light.wgsl.
            ambient: l.ambient.extend(f32::from(u8::from(settings.ao))).to_array(),
            lod: [
                view.px_per_m_at_1m * settings.quality,
                settings.draw_distance_m,
                settings.fade_band,
                match settings.culling {
                    CullingMode::Batches => 0.0,
                    CullingMode::PerTree => 1.0,
                    CullingMode::None => 2.0,
                },
            ],
            params: [0, self.pools.batch_high_water(), u32::from(settings.debug_lod), self.species.count()],
            eye_from_clip: view.clip_from_eye.inverse().to_cols_array_2d(),
            viewport: [view.viewport[0] as f32, view.viewport[1] as f32, settings.thin_px, 0.0],
            shadow_from_eye: [[[0.0; 4]; 4]; super::gpu_data::MAX_CASCADES],
            shadow_texel: [0.0; 4],
            shadow: [0.0; 4],
            canopy: [self.canopy_px[0], self.canopy_px[1], 0.0, 0.0],
            sky: self.sky_uniform(settings),
        };
        let mut uniform = uniform;
        self.last_cascades.clear();
        // Shadows while the sun is up (and lights anything).
        let sun_up = l.sun_dir.z > 0.01 && l.sun_color.max_element() > 1e-3;
        if let (Some(config), true) = (settings.shadows.config(), sun_up) {
            self.ensure_shadow_maps(device, config.fitted(view.viewport));
            let config = self.shadow_maps.as_ref().map_or(config, |m| m.config);
            let eye = view.eye_hi.as_dvec3() + view.eye_lo.as_dvec3();
            // Casters stand up to the height span above a receiver: that far up
            // the sun's ray, within reason at a low sun.
            let reach = (self.height_span_m / l.sun_dir.z.max(0.05)).clamp(self.height_span_m, 4000.0);
            let distance = config.distance_m.min(settings.draw_distance_m);
            let cascades = super::shadow::cascades(view.clip_from_eye, eye, l.sun_dir, &config, distance, reach);
            for (i, c) in cascades.iter().enumerate() {
                let mut v = super::shadow::cascade_view(&uniform, c, config.size);
                v.lod[0] *= settings.quality * config.cascade_lod_scale(i);
                queue.write_buffer(&self.view_buffer, (1 + i as u64) * VIEW_STRIDE, bytemuck::bytes_of(&v));
                self.last_cascades.push(v);
            }
            super::shadow::apply_to_view(&mut uniform, &cascades, &config);
        } else if settings.shadows.config().is_none() && self.shadow_maps.is_some() {
            // Shadows turned off: give the map's memory back.
            self.shadow_maps = None;
            self.view_group = self.shared.view_group(device, &self.view_buffer);
        }
        queue.write_buffer(&self.view_buffer, 0, bytemuck::bytes_of(&uniform));
        self.last_view = uniform;
        FrameData {
            view: uniform,
            species: SpeciesFrame {
                fade_band: settings.fade_band,
                cluster_exact_depth: settings.cluster_exact_depth,
                moving_impostors: settings.moving_impostors,
            },
            debug_bounds: settings.debug_bounds,
            clear: settings.clear,
            sky: settings.sky,
            cascades: self.last_cascades.len() as u32,
        }
    }

    /// Records the shadow cascades of a prepared frame: for each, the cull
    /// pass with the cascade's view, then its casters depth-only into its
    /// layer of the shadow map. Returns the draw calls recorded (0 without
    /// shadows). Submit it before the camera's cull pass: the two share the
    /// draw items.
    /// With `timestamps`, the first cascade's cull pass writes index 4 at its
    /// beginning and the last cascade's draw index 5 at its end.
    pub fn encode_shadows(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        frame: &FrameData,
        timestamps: Option<&wgpu::QuerySet>,
    ) -> u32 {
        let Some(maps) = self.shadow_maps.as_ref().filter(|_| frame.cascades > 0) else { return 0 };
        let slots = self.slot_count();
        let slot_bytes = u64::from(slots) * size_of::<DrawArgs>() as u64;
        let part = CullCounters::cascade_bytes(slots);
        let need = part * MAX_CASCADES as u64;
        if self.shadow_args.as_ref().is_none_or(|b| b.size() < need) {
            use wgpu::BufferUsages as U;
            self.shadow_args = Some(buffer(device, "shadow casters", need, U::COPY_DST | U::COPY_SRC));
        }
        let mut draws = 0;
        let last = frame.cascades as usize - 1;
        for (i, layer) in maps.layers.iter().enumerate().take(frame.cascades as usize) {
            let group = &self.cascade_groups[i];
            let begin = timestamps.filter(|_| i == 0).map(|query_set| wgpu::ComputePassTimestampWrites {
                query_set,
                beginning_of_pass_write_index: Some(4),
                end_of_pass_write_index: None,
            });
            self.cull.encode(encoder, group, &self.pools, slots, begin);
            // Its counters (control words, then slots) for the stats, as
            // `CullCounters` reads them after the camera's.
            if let Some(out) = &self.shadow_args {
                let control = size_of::<CullControl>() as u64;
                encoder.copy_buffer_to_buffer(&self.pools.buffers.control, 0, out, i as u64 * part, control);
                if slot_bytes > 0 {
                    encoder.copy_buffer_to_buffer(
                        &self.pools.buffers.args,
                        0,
                        out,
                        i as u64 * part + control,
                        slot_bytes,
                    );
                }
            }
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("shadow cascade"),
                color_attachments: &[],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: layer,
                    depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(0.0), store: wgpu::StoreOp::Store }),
                    stencil_ops: None,
                }),
                timestamp_writes: timestamps.filter(|_| i == last).map(|query_set| wgpu::RenderPassTimestampWrites {
                    query_set,
                    beginning_of_pass_write_index: None,
                    end_of_pass_write_index: Some(5),
                }),
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_bind_group(0, group, &[]);
            let texels_per_m = self.last_cascades[i].lod[0];
            draws +=
                self.species.draw_shadow(&mut pass, &self.pools, &self.reach, texels_per_m, frame.species.fade_band);
        }
        draws
    }

    /// Records the cull pass of the last frame's shadow cascade `i` alone (tests).
    ///
    /// # Panics
    /// If the last frame had no cascade `i`.
    pub fn encode_cascade_cull(&self, encoder: &mut wgpu::CommandEncoder, i: usize) {
        assert!(i < self.last_cascades.len(), "the last frame had {} cascades", self.last_cascades.len());
        self.cull.encode(encoder, &self.cascade_groups[i], &self.pools, self.slot_count(), None);
    }

    /// The view uniforms of the last frame's shadow cascades (for the CPU
    /// oracle and tests).
    #[must_use]
    pub fn last_cascades(&self) -> &[ViewUniform] {
        &self.last_cascades
    }

    /// Uploads what the terrain pass draws this frame: `draws` is the stream's
    /// selection at `threshold_px`.
    pub fn prepare_terrain(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        draws: &[crate::scene::terrain::TerrainDraw],
        threshold_px: f32,
        flags: u32,
    ) {
        self.terrain.prepare(device, queue, draws, threshold_px, flags);
    }

    /// Uploads what the canopy pass draws this frame (the stream's selection)
    /// in `season` and sets the trees' cross-fade with it (`px`:
    /// [`super::settings::CANOPY_PX`]; None: no canopy, trees at every size).
    pub fn prepare_canopy(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        draws: &[crate::scene::canopy::CanopyDraw],
        px: Option<[f32; 2]>,
        season: super::settings::Season,
    ) {
        self.canopy.prepare(device, queue, if px.is_some() { draws } else { &[] }, season);
        // A raster the pool could not hold would leave its trees drawn by nothing:
        // then trees at every size this frame.
        self.canopy_px = px.filter(|_| self.canopy.dropped == 0).unwrap_or([0.0; 2]);
    }

    /// The canopy pass (rasters drawn, uploads, GPU bytes).
    #[must_use]
    pub fn canopy(&self) -> &super::canopy::CanopyPass {
        &self.canopy
    }

    /// Sizes the terrain pool for a scene's terrain (see [`TerrainPass::reserve`]).
    pub fn reserve_terrain(&mut self, device: &wgpu::Device, grid: u16, tiles: u64, images: u64) {
        self.terrain.reserve(device, grid, tiles);
        if images > 0 {
            self.terrain.reserve_images(device, images);
        }
    }

    /// The terrain pass (tiles drawn, uploads, GPU bytes).
    #[must_use]
    pub fn terrain(&self) -> &TerrainPass {
        &self.terrain
    }

    /// Records the cull pass (after [`Self::prepare`]).
    /// With `timestamps`, the pass writes its begin and end at indices 0 and 1.
    pub fn encode_cull(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        _frame: &FrameData,
        timestamps: Option<&wgpu::QuerySet>,
    ) {
        let writes = timestamps.map(|query_set| wgpu::ComputePassTimestampWrites {
            query_set,
            beginning_of_pass_write_index: Some(0),
            end_of_pass_write_index: Some(1),
        });
        self.cull.encode(encoder, &self.view_group, &self.pools, self.slot_count(), writes);
    }

    /// Records the draw pass: sky, terrain, species draws, overlays. Returns the number of
    /// draw calls recorded. With `timestamps`, the pass writes its begin and end at
    /// indices 2 and 3.
    pub fn encode_draw(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        frame: &FrameData,
        timestamps: Option<&wgpu::QuerySet>,
    ) -> u32 {
        let clear = frame.clear;
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("forest"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: color,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color { r: clear[0], g: clear[1], b: clear[2], a: clear[3] }),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: depth,
                depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(0.0), store: wgpu::StoreOp::Discard }),
                stencil_ops: None,
            }),
            timestamp_writes: timestamps.map(|query_set| wgpu::RenderPassTimestampWrites {
                query_set,
                beginning_of_pass_write_index: Some(2),
                end_of_pass_write_index: Some(3),
            }),
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_bind_group(0, &self.view_group, &[]);
        let cx = PassContext { pools: &self.pools, reach: &self.reach, frame };
        let mut draws = 0;
        for p in self.passes() {
            if p.enabled(frame) {
                draws += p.draw(&mut pass, &cx);
            }
        }
        draws
    }

    /// The draw passes in the order the frame records them: sky, terrain,
    /// trees, canopy rasters (blended over the trees), the bounds overlay.
    fn passes(&self) -> [&dyn DrawPass; 5] {
        [&self.sky, &self.terrain, &self.species, &self.canopy, &self.bounds]
    }

    /// Records the id pass of a prepared frame whose cull pass ran (picking):
    /// terrain and trees as [`Self::encode_draw`] draws them (the same
    /// representations, alpha tests and cross-fades), each tree writing its
    /// pool instance + 1 into `ids` ([`super::layouts::ID_FORMAT`]), only
    /// within `rect` (x, y, width, height). Builds the id pipelines the first time.
    #[allow(clippy::too_many_arguments)]
    pub fn encode_ids(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        ids: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        frame: &FrameData,
        rect: [u32; 4],
    ) -> u32 {
        for p in self.passes() {
            p.build_ids(device);
        }
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("tree ids"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: ids,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: depth,
                depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(0.0), store: wgpu::StoreOp::Discard }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_scissor_rect(rect[0], rect[1], rect[2], rect[3]);
        pass.set_bind_group(0, &self.view_group, &[]);
        let cx = PassContext { pools: &self.pools, reach: &self.reach, frame };
        self.passes().iter().filter(|p| p.enabled(frame)).map(|p| p.draw_ids(&mut pass, &cx)).sum()
    }

    /// The sky's uniform for `settings`' light (worked out again only when it changed).
    fn sky_uniform(&mut self, settings: &RenderSettings) -> super::gpu_data::SkyUniform {
        let l = &settings.lighting;
        let key = SkyKey {
            light: [l.sun_dir.to_array(), l.sun_color.to_array(), l.ambient.to_array()],
            parts: settings.light_parts.0,
            turbidity: settings.turbidity,
        };
        if let Some((k, u)) = &self.sky_cache {
            if *k == key {
                return *u;
            }
        }
        use super::sky_light::{SkyLight, LEAF_TRANSMIT};
        let u = SkyLight::new(l, settings.turbidity).uniform(settings.light_parts, LEAF_TRANSMIT);
        self.sky_cache = Some((key, u));
        u
    }

    /// The last frame's view uniform (for the CPU oracle and tests).
    #[must_use]
    pub fn last_view(&self) -> &ViewUniform {
        &self.last_view
    }

    /// The species table as last uploaded.
    #[must_use]
    pub fn species_table(&self) -> &[GpuSpecies] {
        self.species.table()
    }

    /// Batch slots the cull pass tests (the high-water mark of the batch pool).
    #[must_use]
    pub fn batch_slots(&self) -> u32 {
        self.pools.batch_high_water()
    }

    /// Copies the cull counters and draw arguments into `readback` (laid out as
    /// [`super::counters::CullCounters`] reads them): the camera's, then those of
    /// the frame's `cascades` shadow cascades.
    pub fn copy_counters(&self, encoder: &mut wgpu::CommandEncoder, readback: &wgpu::Buffer, cascades: u32) {
        let control = size_of::<CullControl>() as u64;
        encoder.copy_buffer_to_buffer(&self.pools.buffers.control, 0, readback, 0, control);
        let slots = u64::from(self.slot_count()) * size_of::<DrawArgs>() as u64;
        if slots > 0 {
            encoder.copy_buffer_to_buffer(&self.pools.buffers.args, 0, readback, control, slots);
        }
        if let (Some(args), true) = (&self.shadow_args, cascades > 0) {
            let bytes = CullCounters::cascade_bytes(self.slot_count()) * u64::from(cascades);
            encoder.copy_buffer_to_buffer(args, 0, readback, control + slots, bytes);
        }
    }

    /// The buffers stats and tests read back: (control, args, items).
    #[must_use]
    pub fn readback_buffers(&self) -> (&wgpu::Buffer, &wgpu::Buffer, &wgpu::Buffer) {
        let b = &self.pools.buffers;
        (&b.control, &b.args, &b.items)
    }

    /// The batch and instance pools (for tests that check the GPU against the CPU oracle).
    #[must_use]
    pub fn pool_buffers(&self) -> (&wgpu::Buffer, &wgpu::Buffer) {
        (&self.pools.buffers.batches, &self.pools.buffers.instances)
    }

    /// Number of draw slots in use.
    #[must_use]
    pub fn slot_count(&self) -> u32 {
        self.species.count() * REPR_COUNT
    }
}

/// The renderer as the streamer's [`Residency`]: tiles and packs go to the GPU
/// through `device` and `queue`.
pub struct GpuResidency<'a> {
    /// The renderer holding the pools and packs.
    pub renderer: &'a mut ForestRenderer,
    /// Its device.
    pub device: &'a wgpu::Device,
    /// Its queue.
    pub queue: &'a wgpu::Queue,
}

impl Residency for GpuResidency<'_> {
    fn species_capacity(&self) -> u32 {
        self.renderer.config().species
    }

    fn begin_scene(&mut self, trees: u64, batches: u64, species: u32) {
        let fitted = self.renderer.config().for_scene(trees, batches, species);
        self.renderer.fit_pools(self.device, fitted);
        self.renderer.set_species_count(species);
    }

    fn upload_tile(&mut self, tile: &Tile) -> Result<TileSlot, PoolError> {
        self.renderer.upload_tile(self.queue, tile)
    }

    fn evict_tile(&mut self, slot: TileSlot) {
        self.renderer.evict_tile(self.queue, slot);
    }

    fn upload_pack(&mut self, species: u32, pack: &Pack<'_>) {
        self.renderer.upload_pack(self.device, self.queue, species, pack);
    }

    fn parts_needed(&self, species: usize, meta: &PackMeta) -> [bool; PACK_PARTS] {
        self.renderer.parts_needed(species, meta)
    }

    fn instance_room(&self) -> (u32, u32) {
        (self.renderer.free_instances(), self.renderer.config().instances)
    }

    fn bytes(&self) -> u64 {
        self.renderer.gpu_bytes()
    }

    fn limited_by_device(&self) -> bool {
        self.renderer.pools_limited_by_device()
    }
}

/// Creates the depth texture every Sylva target needs.
#[must_use]
pub fn depth_texture(device: &wgpu::Device, width: u32, height: u32) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some("depth"),
        size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: DEPTH_FORMAT,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
        view_formats: &[],
    })
}
