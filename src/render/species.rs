//! The species on the GPU: each species' pack (mesh levels, billboards,
//! clusters), the draw pipelines (built when the first pack needing one
//! arrives: a scene or view that never needs one never compiles it), the
//! species table the cull pass reads (per representation: lower threshold,
//! segment of the draw items, count) and the draw params, and the species draws
//! of the frame: at most one indirect draw per species × representation.

use glam::Vec3;

use super::billboard::{BillboardGpu, BillboardPipeline, BILLBOARD_VERTICES};
use super::cluster::{ClusterGpu, ClusterPipeline};
use super::gpu_data::{DrawArgs, DrawParams, GpuSpecies, RenderMode, Repr, REPR_COUNT};
use super::impostor::{ImpostorGpu, ImpostorPipeline, IMPOSTOR_VERTICES};
use super::layouts::SharedLayouts;
use super::mesh::{MeshGpu, MeshPipelines};
use super::pools::Pools;
use super::reach::Reach;
use super::settings::{FarTier, RenderSettings, Representations, Season};
use crate::format::Pack;
use crate::lod::bands::{bands, cluster_tiers, MeshOffer, Offer};
use crate::lod::policy::policy_keeps;

/// Segment capacity of the full mesh level per species: only trees hundreds of
/// pixels tall use it, a few hundred at most on any screen.
pub const MESH0_CAPACITY: u32 = 1 << 15;
/// Segment capacity of the simplified mesh level per species.
pub const MESH1_CAPACITY: u32 = 1 << 18;
/// Segment capacity of each cluster tier per species.
pub const CLUSTER_CAPACITY: u32 = 1 << 18;

struct SpeciesGpu {
    mesh: MeshGpu,
    billboard: Option<BillboardGpu>,
    impostor: Option<ImpostorGpu>,
    /// The bare wood's billboards and impostors (a deciduous species' leaf-off
    /// far tiers), when on the GPU.
    billboard_bare: Option<BillboardGpu>,
    impostor_bare: Option<ImpostorGpu>,
    /// The far-tier slot draws the impostors (set by `rebuild_table`).
    far_impostor: bool,
    /// The far-tier slot draws the bare captures (set by `rebuild_table`).
    far_bare: bool,
    /// The pack's seasons (none: evergreen).
    season: Option<crate::format::pack::SeasonMeta>,
    cluster: Option<ClusterGpu>,
    /// Cluster level of each cluster tier in use (set by `rebuild_table`).
    tiers: Vec<usize>,
    sphere: [f32; 4],
    height_m: f32,
    select_px: [f32; 2],
    index_counts: [u32; 2],
    /// Mesh levels 0 and 1 on the GPU.
    has_level: [bool; 2],
    /// The bake's LoD policy threshold of each mesh level, when measured.
    policy_px: [Option<f32>; 2],
    /// The billboard cloud's threshold and index count, when on the GPU.
    cloud: Option<(f32, u32)>,
    /// The bake's LoD policy keeps the cloud as a default tier.
    cloud_kept: bool,
    /// The pack has a far tier (impostors or billboards), resident or not.
    has_far: bool,
    bytes: u64,
}

/// Which pipelines a species draw uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Pipeline {
    /// The lit ones: ellipsoids with their exact depth or not, impostors as
    /// a moving frame draws them or not.
    Lit { exact_depth: bool, moving: bool },
    /// The shadow casters' (depth only).
    Shadow,
    /// The id pass's (picking; ellipsoids with their exact depth or not, as lit).
    Id(bool),
}

impl Pipeline {
    /// The mesh pipelines' mode.
    fn mesh_mode(self) -> RenderMode {
        match self {
            Pipeline::Lit { .. } => RenderMode::Lit,
            Pipeline::Shadow => RenderMode::Shadow,
            Pipeline::Id(_) => RenderMode::Id,
        }
    }

    /// A far tier's pipeline (the id pass's only once built).
    fn far_tier(self, p: &super::billboard::FarTierPipeline) -> Option<&wgpu::RenderPipeline> {
        match self {
            Pipeline::Lit { moving: true, .. } => Some(p.moving_pipeline().unwrap_or(p.pipeline())),
            Pipeline::Lit { .. } => Some(p.pipeline()),
            Pipeline::Shadow => Some(p.shadow_pipeline()),
            Pipeline::Id(_) => p.id.get(),
        }
    }
}

pub use super::pass::SpeciesFrame;

/// Every species of the scene on the GPU, and the table over them.
pub struct Species {
    color_format: wgpu::TextureFormat,
    mesh: Option<MeshPipelines>,
    billboard: Option<BillboardPipeline>,
    impostor: Option<ImpostorPipeline>,
    cluster: Option<ClusterPipeline>,
    packs: Vec<Option<SpeciesGpu>>,
    table: Vec<GpuSpecies>,
    /// The table no longer matches packs, residency or settings.
    dirty: bool,
    /// The settings the table was built with.
    cluster_min_px: f32,
    representations: Representations,
    far_tier: FarTier,
    lod_policy: bool,
    season: Season,
    /// The date the seasons follow, if any (`RenderSettings::date`).
    date: Option<super::settings::SeasonDate>,
}

impl Species {
    /// No species yet; pipelines for `color_format` targets.
    #[must_use]
    pub fn new(color_format: wgpu::TextureFormat) -> Self {
        Self {
            color_format,
            mesh: None,
            billboard: None,
            impostor: None,
            cluster: None,
            packs: Vec::new(),
            table: Vec::new(),
            dirty: true,
            cluster_min_px: super::settings::DEFAULT_CLUSTER_MIN_PX,
            representations: Representations::default(),
            far_tier: FarTier::Impostors,
            lod_policy: true,
            season: Season::LeafOn,
            date: None,
        }
    }

    /// Starts a scene of `count` species: loaded packs are dropped.
    pub fn set_count(&mut self, count: u32) {
        self.packs = (0..count).map(|_| None).collect();
        self.dirty = true;
    }

    /// Species in the scene.
    #[must_use]
    pub fn count(&self) -> u32 {
        self.packs.len() as u32
    }

    /// Whether species `i`'s pack is on the GPU.
    #[must_use]
    pub fn has_pack(&self, i: u32) -> bool {
        self.packs.get(i as usize).is_some_and(Option::is_some)
    }

    /// Residency changed: the table's counts must follow.
    pub fn mark_dirty(&mut self) {
        self.dirty = true;
    }

    /// Uploads a decoded pack as species `index`.
    pub fn upload_pack(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        shared: &SharedLayouts,
        index: u32,
        pack: &Pack<'_>,
    ) {
        if self.packs.get(index as usize).is_none() {
            return;
        }
        let m = &pack.meta;
        use crate::format::pack::kind;
        let format = self.color_format;
        let any_level = (0..m.mesh_levels.len() as u32).any(|l| pack.section(kind::MESH_VERTICES, l).is_some())
            || pack.section(kind::CLOUD_VERTICES, 0).is_some();
        let mesh = if any_level {
            let pipelines = self.mesh.get_or_insert_with(|| MeshPipelines::new(device, shared, format));
            MeshGpu::upload(device, queue, pipelines, pack)
        } else {
            MeshGpu { levels: Vec::new(), cloud: None }
        };
        // Far tiers of each state held: leaf-on (0) and a deciduous species' bare wood (1).
        let mut billboards = [0, 1].map(|state| {
            if m.billboards.is_some() && pack.section(kind::BILLBOARD_COLOR, state).is_some() {
                let pipeline =
                    self.billboard.get_or_insert_with(|| BillboardPipeline::billboard(device, shared, format));
                BillboardGpu::upload(device, queue, state, pipeline, pack)
            } else {
                None
            }
        });
        let mut impostors = [0, 1].map(|state| {
            if m.impostors.is_some() && pack.section(kind::IMPOSTOR_COLOR, state).is_some() {
                let pipeline =
                    self.impostor.get_or_insert_with(|| super::impostor::impostor_pipeline(device, shared, format));
                ImpostorGpu::upload(device, queue, state, pipeline, pack)
            } else {
                None
            }
        });
        let cluster = if m.clusters.is_some() && pack.section(kind::ELLIPSOIDS, 0).is_some() {
            let pipeline = self.cluster.get_or_insert_with(|| ClusterPipeline::new(device, shared, format));
            ClusterGpu::upload(device, queue, pipeline, pack)
        } else {
            None
        };
        let Some(slot) = self.packs.get_mut(index as usize) else { return };
        // A part that comes after the stream dropped its copies of the others
        // (the other season's far tier) is uploaded alone: what the pack held
        // before stays on the GPU beside it.
        let mut mesh = mesh;
        let mut cluster = cluster;
        // (Its bytes then count too: the new pack holds only its own sections.)
        let mut carried = 0u64;
        if let Some(old) = slot.take() {
            let mut kept = false;
            let empty = |m: &MeshGpu| m.levels.iter().all(Option::is_none) && m.cloud.is_none();
            if empty(&mesh) && !empty(&old.mesh) {
                mesh = old.mesh;
                kept = true;
            }
            for (new, old) in billboards.iter_mut().zip([old.billboard, old.billboard_bare]) {
                if new.is_none() && old.is_some() {
                    (*new, kept) = (old, true);
                }
            }
            for (new, old) in impostors.iter_mut().zip([old.impostor, old.impostor_bare]) {
                if new.is_none() && old.is_some() {
                    (*new, kept) = (old, true);
                }
            }
            if cluster.is_none() && old.cluster.is_some() {
                (cluster, kept) = (old.cluster, true);
            }
            if kept {
                carried = old.bytes;
            }
        }
        let lo = Vec3::from(m.bounds_min);
        let hi = Vec3::from(m.bounds_max);
        let c = (lo + hi) * 0.5;
        let level = |l: usize| m.mesh_levels.get(l);
        // What goes to the GPU: every section but the JSON metadata.
        let bytes = carried
            + pack
                .sections
                .iter()
                .filter(|(e, _)| e.kind != crate::format::pack::kind::META)
                .map(|(e, _)| e.bytes)
                .sum::<u64>();
        *slot = Some(SpeciesGpu {
            sphere: [c.x, c.y, c.z, ((hi - lo) * 0.5).length()],
            height_m: m.height_m,
            select_px: [level(0).map_or(0.0, |l| l.select_px), level(1).map_or(0.0, |l| l.select_px)],
            index_counts: [level(0).map_or(0, |l| l.index_count), level(1).map_or(0, |l| l.index_count)],
            has_level: [mesh.has_level(0), mesh.has_level(1)],
            policy_px: [level(0).and_then(|l| l.policy_px), level(1).and_then(|l| l.policy_px)],
            cloud: m.cloud.as_ref().filter(|_| mesh.cloud.is_some()).map(|c| (c.select_px, c.mesh.index_count)),
            cloud_kept: m.cloud.as_ref().is_some_and(|c| policy_keeps(c.pareto_error, c.pareto_cost, false)),
            has_far: m.billboards.is_some() || m.impostors.is_some(),
            mesh,
            billboard: billboards[0].take(),
            impostor: impostors[0].take(),
            billboard_bare: billboards[1].take(),
            impostor_bare: impostors[1].take(),
            far_impostor: false,
            far_bare: false,
            season: m.season.clone(),
            cluster,
            tiers: Vec::new(),
            bytes,
        });
        self.dirty = true;
    }

    /// Rebuilds the species table and draw params when packs, residency or the
    /// representation settings changed since the last frame.
    pub fn update_table(&mut self, queue: &wgpu::Queue, pools: &Pools, settings: &RenderSettings) {
        if settings.cluster_min_px != self.cluster_min_px
            || settings.representations != self.representations
            || settings.far_tier != self.far_tier
            || settings.lod_policy != self.lod_policy
            || settings.season != self.season
            || settings.date != self.date
        {
            self.season = settings.season;
            self.date = settings.date;
            self.cluster_min_px = settings.cluster_min_px;
            self.representations = settings.representations;
            self.far_tier = settings.far_tier;
            self.lod_policy = settings.lod_policy;
            self.dirty = true;
        }
        if self.dirty {
            self.rebuild_table(queue, pools);
        }
    }

    fn rebuild_table(&mut self, queue: &wgpu::Queue, pools: &Pools) {
        let mut base = 0u32;
        let count = self.packs.len();
        let mut table = Vec::with_capacity(count);
        let mut params = Vec::with_capacity(count * REPR_COUNT as usize);
        let budget = pools.config().items;
        let allow = self.representations;
        for (i, pack) in self.packs.iter_mut().enumerate() {
            let resident = pools.resident(i).min(u64::from(u32::MAX)) as u32;
            let mut s = GpuSpecies::default();
            let mut draw: Vec<DrawParams> = Repr::ALL
                .iter()
                .map(|r| DrawParams { ids: [0, *r as u32, i as u32, 0], ..Default::default() })
                .collect();
            if let Some(p) = pack {
                let species_season = super::settings::season_at(p.season.as_ref(), self.season, self.date);
                let season = super::settings::season_params_at(p.season.as_ref(), self.season, self.date);
                for d in &mut draw {
                    d.season = season;
                }
                s.sphere = p.sphere;
                s.select = [p.height_m, 0.0, 0.0, 0.0];
                let mut want = [0u32; REPR_COUNT as usize];
                let mut lower = [0f32; REPR_COUNT as usize];
                // What is resident, banded by the shared rule.
                let mesh = |l: usize| {
                    p.has_level[l].then_some(MeshOffer { select_px: p.select_px[l], policy_px: p.policy_px[l] })
                };
                let offer = Offer {
                    meshes: [mesh(0), mesh(1)],
                    cloud: p.cloud.map(|(px, _)| (px, p.cloud_kept)),
                    clusters: p.cluster.is_some(),
                    far: p.has_far,
                };
                let levels = p.cluster.iter().flat_map(|c| c.levels.iter().map(|l| &l.meta));
                let b = bands(&offer, allow, self.lod_policy, self.cluster_min_px, levels);
                for (l, (repr, capacity)) in
                    [(Repr::Mesh0, MESH0_CAPACITY), (Repr::Mesh1, MESH1_CAPACITY)].into_iter().enumerate()
                {
                    if let Some(px) = b.mesh[l] {
                        want[repr as usize] = resident.min(capacity);
                        lower[repr as usize] = px;
                        s.index_count[repr as usize] = p.index_counts[l];
                    }
                }
                // The billboard cloud, below the meshes.
                if let (Some(px), Some((_, indices))) = (b.cloud, p.cloud) {
                    want[Repr::Cloud as usize] = resident.min(MESH1_CAPACITY);
                    lower[Repr::Cloud as usize] = px;
                    s.index_count[Repr::Cloud as usize] = indices;
                }
                // Cluster tiers: the levels whose size band meets the cluster band.
                p.tiers.clear();
                if let (Some(c), Some(min_px)) = (p.cluster.as_ref(), b.clusters) {
                    let tiers = cluster_tiers(c.levels.iter().map(|l| &l.meta), min_px, b.floor);
                    for (tier, (level, lo)) in tiers.into_iter().enumerate() {
                        let r = Repr::CLUSTERS[tier] as usize;
                        want[r] = resident.min(CLUSTER_CAPACITY);
                        lower[r] = lo;
                        s.index_count[r] = c.vertices(level);
                        c.draw_params(level, &mut draw[r]);
                        p.tiers.push(level);
                    }
                }
                // The far tier: impostors or billboards (settings.far_tier where both).
                // In leaf-off, a deciduous species' bare captures where they have
                // come (until then the leafy ones, their leaf texels dropped);
                // in the other seasons the leafy ones, or the bare ones until
                // those come (after a leaf-off view: bare trees rather than none).
                let bare = p.impostor_bare.is_some() || p.billboard_bare.is_some();
                let leafy = p.impostor.is_some() || p.billboard.is_some();
                p.far_bare = bare && p.season.is_some() && (species_season == Season::LeafOff || !leafy);
                let (impostor, billboard) =
                    if p.far_bare { (&p.impostor_bare, &p.billboard_bare) } else { (&p.impostor, &p.billboard) };
                p.far_impostor = impostor.is_some() && (self.far_tier == FarTier::Impostors || billboard.is_none());
                let r = Repr::Billboard as usize;
                match (impostor, billboard) {
                    (Some(imp), _) if p.far_impostor && b.far => {
                        want[r] = resident;
                        s.index_count[r] = IMPOSTOR_VERTICES;
                        imp.draw_params(&mut draw[r]);
                    }
                    (_, Some(bb)) if b.far => {
                        want[r] = resident;
                        s.index_count[r] = BILLBOARD_VERTICES;
                        draw[r].ids[3] = bb.meta.angles | (bb.meta.azimuths << 16);
                        draw[r].bb_center =
                            [bb.meta.center[0], bb.meta.center[1], bb.meta.center[2], bb.meta.half_width];
                        draw[r].bb_size = [bb.meta.half_height, bb.meta.variants.unwrap_or(1) as f32, 0.0, 0.0];
                    }
                    _ => {}
                }
                // Billboards first: the far field must never starve for items.
                let order = std::iter::once(Repr::Billboard as usize).chain(0..Repr::Billboard as usize);
                for r in order {
                    let cap = want[r].min(budget.saturating_sub(base));
                    s.slot_base[r] = base;
                    s.slot_cap[r] = cap;
                    s.lower_px[r] = lower[r];
                    base += cap;
                }
            }
            for (r, d) in draw.iter_mut().enumerate() {
                d.ids[0] = s.slot_base[r];
            }
            params.extend(draw);
            table.push(s);
        }
        if !table.is_empty() {
            queue.write_buffer(&pools.buffers.species, 0, bytemuck::cast_slice(&table));
            queue.write_buffer(&pools.buffers.draw_params, 0, bytemuck::cast_slice(&params));
        }
        self.table = table;
        self.dirty = false;
    }

    /// The species table as last uploaded.
    #[must_use]
    pub fn table(&self) -> &[GpuSpecies] {
        &self.table
    }

    /// Which draw pipelines have been built (meshes, clusters, billboards).
    #[must_use]
    pub fn pipelines_built(&self) -> [bool; 3] {
        [self.mesh.is_some(), self.cluster.is_some(), self.billboard.is_some() || self.impostor.is_some()]
    }

    /// GPU bytes of the uploaded packs.
    #[must_use]
    pub fn bytes(&self) -> u64 {
        self.packs.iter().flatten().map(|p| p.bytes).sum()
    }

    /// Records the species draws into `pass` (view bound at group 0): per species
    /// and representation one indirect draw, skipped where no resident tree within
    /// reach can need it. Returns the draws recorded.
    pub fn draw<'p>(
        &'p self,
        pass: &mut wgpu::RenderPass<'p>,
        pools: &'p Pools,
        reach: &Reach,
        frame: SpeciesFrame,
    ) -> u32 {
        self.draw_with(
            pass,
            pools,
            reach,
            frame,
            Pipeline::Lit { exact_depth: frame.cluster_exact_depth, moving: frame.moving_impostors },
        )
    }

    /// Builds the pipelines a moving frame draws with (`RenderSettings::moving_impostors`).
    pub fn build_moving_pipelines(&self, device: &wgpu::Device) {
        if let Some(i) = &self.impostor {
            i.build_moving(device);
        }
    }

    /// Builds the id pipelines (picking) of the passes built so far.
    pub fn build_id_pipelines(&self, device: &wgpu::Device) {
        if let Some(m) = &self.mesh {
            m.build_id(device);
        }
        if let Some(c) = &self.cluster {
            c.id.build(device);
            c.id_proxy.build(device);
        }
        for far in [&self.billboard, &self.impostor].into_iter().flatten() {
            far.id.build(device);
        }
    }

    /// Records the species draws of the id pass (picking): as [`Self::draw`],
    /// each tree writing its pool instance + 1 ([`Self::build_id_pipelines`] first).
    pub fn draw_ids<'p>(
        &'p self,
        pass: &mut wgpu::RenderPass<'p>,
        pools: &'p Pools,
        reach: &Reach,
        frame: SpeciesFrame,
    ) -> u32 {
        self.draw_with(pass, pools, reach, frame, Pipeline::Id(frame.cluster_exact_depth))
    }

    fn draw_with<'p>(
        &'p self,
        pass: &mut wgpu::RenderPass<'p>,
        pools: &'p Pools,
        reach: &Reach,
        frame: SpeciesFrame,
        pipeline: Pipeline,
    ) -> u32 {
        self.draw_reaching(pass, pools, |i| reach.max_px(i), frame.fade_band, pipeline)
    }

    /// Per ready species × representation one indirect draw with `pipeline`,
    /// skipped where the species' largest tree (`max_px(species)`, px or
    /// texels) is below the representation's band (fade band `fade_band`
    /// included; the coarsest reaches down to 0). Returns the draws recorded.
    fn draw_reaching<'p>(
        &'p self,
        pass: &mut wgpu::RenderPass<'p>,
        pools: &'p Pools,
        max_px: impl Fn(usize) -> f32,
        fade_band: f32,
        pipeline: Pipeline,
    ) -> u32 {
        pass.set_bind_group(2, &pools.groups.instance, &[]);
        let mut draws = 0;
        for (i, p) in self.packs.iter().enumerate() {
            let (Some(p), Some(s)) = (p, self.table.get(i)) else { continue };
            let max_px = max_px(i);
            let coarsest = Repr::ALL.iter().rposition(|r| s.slot_cap[*r as usize] > 0);
            for (k, repr) in Repr::ALL.into_iter().enumerate() {
                if s.slot_cap[repr as usize] == 0 {
                    continue;
                }
                // Nothing of the species within reach, or no tree tall enough on screen
                // for this representation (fade bands included): skip the draw.
                let lower = if Some(k) == coarsest { 0.0 } else { s.lower_px[repr as usize] * (1.0 - fade_band) };
                if max_px <= 0.0 || lower > max_px {
                    continue;
                }
                let slot = i as u32 * REPR_COUNT + repr as u32;
                draws += u32::from(self.draw_slot(pass, pools, p, repr, slot, pipeline));
            }
        }
        draws
    }

    /// Records species `p`'s draw of `repr` (draw slot `slot`) with the lit or
    /// the shadow casters' pipeline; false where nothing of it is on the GPU.
    fn draw_slot<'p>(
        &'p self,
        pass: &mut wgpu::RenderPass<'p>,
        pools: &'p Pools,
        p: &'p SpeciesGpu,
        repr: Repr,
        slot: u32,
        pipeline: Pipeline,
    ) -> bool {
        pass.set_bind_group(3, &pools.groups.draw, &[slot * size_of::<DrawParams>() as u32]);
        let args_offset = u64::from(slot) * size_of::<DrawArgs>() as u64;
        match repr {
            Repr::Mesh0 | Repr::Mesh1 => {
                let Some(pipelines) = &self.mesh else { return false };
                let mode = pipeline.mesh_mode();
                if p.mesh.bind_level(pass, pipelines, mode, repr as usize) == 0 {
                    return false;
                }
                pass.draw_indexed_indirect(&pools.buffers.args, args_offset);
            }
            Repr::Cloud => {
                let Some(pipelines) = &self.mesh else { return false };
                let mode = pipeline.mesh_mode();
                if p.mesh.bind_cloud(pass, pipelines, mode) == 0 {
                    return false;
                }
                pass.draw_indexed_indirect(&pools.buffers.args, args_offset);
            }
            Repr::Cluster0 | Repr::Cluster1 | Repr::Cluster2 | Repr::Cluster3 => {
                let (Some(c), Some(cluster)) = (&p.cluster, &self.cluster) else { return false };
                let Some(pipe) = (match pipeline {
                    Pipeline::Lit { exact_depth, .. } => Some(cluster.pipeline(exact_depth)),
                    Pipeline::Shadow => Some(cluster.shadow_pipeline()),
                    Pipeline::Id(true) => cluster.id.get(),
                    Pipeline::Id(false) => cluster.id_proxy.get(),
                }) else {
                    return false;
                };
                pass.set_pipeline(pipe);
                pass.set_bind_group(1, &c.bind_group, &[]);
                pass.draw_indirect(&pools.buffers.args, args_offset);
            }
            Repr::Billboard if p.far_impostor => {
                let imp = if p.far_bare { &p.impostor_bare } else { &p.impostor };
                let (Some(imp), Some(impostor)) = (imp, &self.impostor) else { return false };
                let Some(pipe) = pipeline.far_tier(impostor) else { return false };
                pass.set_pipeline(pipe);
                pass.set_bind_group(1, &imp.bind_group, &[]);
                pass.draw_indirect(&pools.buffers.args, args_offset);
            }
            Repr::Billboard => {
                let bb = if p.far_bare { &p.billboard_bare } else { &p.billboard };
                let (Some(bb), Some(billboard)) = (bb, &self.billboard) else { return false };
                let Some(pipe) = pipeline.far_tier(billboard) else { return false };
                pass.set_pipeline(pipe);
                pass.set_bind_group(1, &bb.bind_group, &[]);
                pass.draw_indirect(&pools.buffers.args, args_offset);
            }
        }
        true
    }

    /// Records the species draws of a shadow cascade into `pass` (the
    /// cascade's view bound at group 0, its cull pass run): the depth-only
    /// pipelines, one indirect draw per ready species × representation that
    /// the species' tallest resident tree can reach at the cascade's
    /// `texels_per_m` (anywhere: the camera's reach says nothing about what
    /// shades its view). Returns the draws recorded.
    pub fn draw_shadow<'p>(
        &'p self,
        pass: &mut wgpu::RenderPass<'p>,
        pools: &'p Pools,
        reach: &Reach,
        texels_per_m: f32,
        fade_band: f32,
    ) -> u32 {
        self.draw_reaching(pass, pools, |i| reach.tallest_m(i) * texels_per_m, fade_band, Pipeline::Shadow)
    }
}

impl super::pass::DrawPass for Species {
    fn draw<'p>(&'p self, pass: &mut wgpu::RenderPass<'p>, cx: &super::pass::PassContext<'p>) -> u32 {
        Species::draw(self, pass, cx.pools, cx.reach, cx.frame.species)
    }

    fn draw_ids<'p>(&'p self, pass: &mut wgpu::RenderPass<'p>, cx: &super::pass::PassContext<'p>) -> u32 {
        Species::draw_ids(self, pass, cx.pools, cx.reach, cx.frame.species)
    }

    fn build_ids(&self, device: &wgpu::Device) {
        self.build_id_pipelines(device);
    }

    fn gpu_bytes(&self) -> u64 {
        self.bytes()
    }
}
