//! Streaming: what the view needs is fetched, decoded, validated and made
//! resident; what is far and unseen is evicted when the pools fill up.
//!
//! Each frame [`SceneStream::update`] (non-blocking) handles finished requests,
//! then requests the tiles inside the frustum and draw distance, nearest first,
//! with a bounded number in flight, and the packs of species that resident
//! visible tiles use. Failures are retried with exponential backoff (server
//! errors, broken connections, corrupt bytes) or given up (404), and reported
//! as [`StreamEvent`]s; the rest of the scene keeps rendering.

use std::collections::HashMap;

use glam::Vec3;

use super::canopy::{CanopyDraw, CanopyTree};
use super::fetch::{join, scene_locations, FetchError, Fetcher, RequestId};
use super::imagery::{Imagery, ImageryChoice, ImageryFetch};
use super::index_walk::CanopyGate;
use super::index_walk::IndexWalk;
use super::quadtree::{QuadKey, QuadLayer, RetryPolicy};
use super::residency::{PoolError, Residency, TileSlot};
use super::terrain::{TerrainDraw, TerrainKey, TerrainTree};
use crate::camera::ViewData;
use crate::format::attributes::AttributeCodes;
use crate::format::canopy::CanopyKey;
use crate::format::tile::Levels;
use crate::format::{DecodeError, GpuBatch, Manifest, Tile};
use crate::geo::GeoFrame;
use crate::lod::select::{canopy_keeps, canopy_share};
use packs::PackLoad;

mod layers;
mod packs;
mod report;
#[cfg(test)]
mod tests;
mod tiles;
mod tree_data;

use layers::request_layer;
pub use report::{Degraded, LoadFailure, StreamEvent, StreamStats, MAX_LISTED_FAILURES};
pub use tiles::{batch_levels_wanted, first_levels_wanted};

/// Limits of the streamer: the budgets a viewer degrades gracefully within.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StreamConfig {
    /// Requests in flight at once.
    pub max_in_flight: usize,
    /// Attempts per file before giving up (retryable failures only).
    pub max_attempts: u32,
    /// First retry delay in seconds (doubles per attempt).
    pub retry_base_s: f64,
    /// GPU memory budget in bytes for pools and packs (0: none). Pack parts that
    /// would exceed it are not fetched: trees draw with the coarser parts held.
    pub gpu_budget_bytes: u64,
    /// Download budget in bytes per second, averaged over a second (0: none).
    pub max_bytes_per_s: f64,
    /// Terrain level selection: a tile is refined while its geometric error
    /// projects to more than this many pixels.
    pub terrain_error_px: f32,
    /// Stream (and select) the terrain at all; off, no terrain tile is fetched.
    pub terrain: bool,
}

impl StreamConfig {
    /// The retries of failed files: `retry_base_s` doubling, `max_attempts` in all.
    #[must_use]
    pub fn retry(&self) -> RetryPolicy {
        RetryPolicy { base_s: self.retry_base_s, max_attempts: self.max_attempts }
    }
}

impl Default for StreamConfig {
    fn default() -> Self {
        Self {
            max_in_flight: 6,
            max_attempts: 4,
            retry_base_s: 0.25,
            gpu_budget_bytes: 0,
            max_bytes_per_s: 0.0,
            terrain_error_px: 2.0,
            terrain: true,
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
enum Load {
    Idle,
    Requested { attempt: u32 },
    Waiting { attempt: u32, retry_at_s: f64 },
    Broken,
}

impl Load {
    /// The attempt of a request in flight (0 otherwise).
    fn attempt(&self) -> u32 {
        match self {
            Load::Requested { attempt } => *attempt,
            _ => 0,
        }
    }
}

enum TileState {
    NotResident(Load),
    /// In the pools; `cells` keeps each batch's cell rectangle and lowest ground
    /// (x0, y0, x1, y1, z) for ground-height queries; `data` its trees' ids and
    /// attributes while a style wants them ([`SceneStream::set_tree_data`]).
    Resident {
        slot: TileSlot,
        species: Vec<u32>,
        cells: Vec<[f32; 5]>,
        data: TreeDataLoad,
        prefix: Box<Prefix>,
    },
}

/// How much of a resident tile's file is held (its prefix levels) and the
/// request for more.
struct Prefix {
    /// Levels held.
    levels: u32,
    /// The file's bytes up to the levels held, kept while the tile is resident
    /// (a file in levels): more levels are appended (never fetched again), and
    /// eviction by prefix decodes fewer levels from them.
    bytes: Vec<u8>,
    /// [`crate::format::tile::TilePrefix::runs`]: resident instance → index in the tile.
    runs: std::sync::Arc<Vec<[u32; 3]>>,
    /// The tile's whole batches (what decides the levels a view wants; empty
    /// for a file without levels).
    batches: Vec<GpuBatch>,
    /// How the file's levels split them.
    scheme: Levels,
    /// The request for the next levels.
    more: Load,
}

impl Prefix {
    /// What a decoded prefix holds, with the file's `bytes` kept (or none), no
    /// request for more yet.
    fn held(held: &crate::format::tile::TilePrefix, bytes: Vec<u8>) -> Self {
        Self {
            levels: held.levels,
            runs: std::sync::Arc::new(held.runs()),
            batches: held.whole_batches(),
            scheme: held.scheme,
            bytes,
            more: Load::Idle,
        }
    }
}

/// What prefix thinning keeps of far trees (the renderer's settings), so the
/// stream fetches only that prefix of a tile ([`SceneStream::set_prefix_view`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrefixView {
    /// The thinning threshold in pixels (`RenderSettings::thin_px`; > 0).
    pub thin_px: f32,
    /// The factor on pixels per metre the cull pass uses (the quality).
    pub lod_scale: f32,
    /// The canopy cross-fade's band (px: `CANOPY_PX`) while the canopy stands
    /// in for trees: the cull keeps only the head `1 − w(h)` of each batch's
    /// kept trees (`canopy_drops`). Filled in by the stream from
    /// [`SceneStream::canopy_active`]; callers give None.
    pub canopy: Option<[f32; 2]>,
}

/// The ids and attribute codes of a resident tile's trees, in instance order.
#[derive(Debug, Clone, PartialEq)]
pub struct TreeData {
    /// Tree ids (the `.ids` sidecar: numbers, and text ids where given).
    pub ids: crate::format::TreeIds,
    /// Attribute codes (the `.attr` sidecar; None for a scene without attributes).
    pub codes: Option<AttributeCodes>,
}

/// Where a resident tile's [`TreeData`] is.
#[derive(Debug, Clone, Default)]
enum TreeDataLoad {
    /// Not asked for.
    #[default]
    None,
    /// Requested: what arrived so far (ids; codes, `Some(None)` for none to come).
    Loading {
        attempt: u32,
        ids: Option<crate::format::TreeIds>,
        codes: Option<Option<AttributeCodes>>,
    },
    Ready(std::sync::Arc<TreeData>),
    /// A sidecar failed this many times: asked for again (up to 3 attempts).
    Failed(u32),
    /// A sidecar failed for good (said as an event); the tile's trees keep their own look.
    Broken,
}

/// What a resident tile's [`TreeData`] is (for styles).
#[derive(Debug, Clone, Copy)]
pub enum TreeDataState<'a> {
    /// Asked for or not yet.
    Pending,
    /// In.
    Ready(&'a std::sync::Arc<TreeData>),
    /// Failed for good.
    Broken,
}

/// Attempts at a tile's sidecars before giving up.
const TREE_DATA_ATTEMPTS: u32 = 3;

#[derive(Debug, Clone, Copy)]
enum Target {
    Manifest,
    Node(usize),
    Tile(usize),
    /// The pack's head (or the whole pack, for manifests without `head_bytes`).
    PackHead(usize),
    /// One part of a pack, by byte range.
    PackPart(usize, usize),
    /// One part of a stored pack being inflated (not a request: its bytes
    /// were counted when fetched).
    PackInflate(usize, usize),
    /// A terrain tile.
    Terrain(TerrainKey),
    /// A baked imagery image (source generation, terrain tile).
    Image(u32, TerrainKey),
    /// A tile of an XYZ/WMTS imagery source (source generation, z/x/y).
    ImageSource(u32, (u8, u32, u32)),
    /// A resident tile's ids (`false`) or attributes (`true`) sidecar.
    TreeData(usize, bool),
    /// More prefix levels of a resident tile holding this many.
    TileMore(usize, u32),
    /// A canopy raster.
    Canopy(CanopyKey),
}

/// Where a picked tree's data is: its tile's files and its index in the tile.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LocatedTree {
    /// The tile (absolute, or relative to the working directory for a local scene).
    pub tile_url: String,
    /// The tile's tree ids.
    pub ids_url: String,
    /// The tile's attribute sidecar (scenes with attributes).
    pub attributes_url: String,
    /// The tree's instance in the tile.
    pub index: u32,
}

/// The tree of pool instance `instance` in a snapshot of [`SceneStream::tile_locations`].
#[must_use]
pub fn locate(tiles: &[(std::ops::Range<u32>, LocatedTree)], instance: u32) -> Option<LocatedTree> {
    tiles
        .iter()
        .find(|(range, _)| range.contains(&instance))
        .map(|(range, t)| LocatedTree { index: t.index + (instance - range.start), ..t.clone() })
}

/// A scene being streamed into a [`Residency`] (the renderer's GPU pools).
pub struct SceneStream<F: Fetcher> {
    base: String,
    manifest_url: String,
    manifest: Option<Manifest>,
    manifest_load: Load,
    index: IndexWalk,
    node_loads: Vec<Load>,
    tiles: Vec<TileState>,
    packs: Vec<PackLoad>,
    requests: HashMap<RequestId, Target>,
    fetcher: F,
    config: StreamConfig,
    stats: StreamStats,
    events: Vec<StreamEvent>,
    failures: Vec<LoadFailure>,
    wanted: Vec<usize>,
    /// Unread index nodes the view meets (not given up on).
    pending_nodes: usize,
    /// Tiles are requested up to this distance (shortened when pools are full).
    reach_m: f32,
    /// How many of `wanted` (nearest first) lie within `reach_m`.
    within_reach: usize,
    /// Buffers reused every frame (no allocation in steady state).
    walk_tiles: Vec<(f32, usize)>,
    walk_nodes: Vec<(f32, usize)>,
    walk_stack: Vec<usize>,
    needed: Vec<usize>,
    /// (time, bytes) of responses in the last second, for the download budget.
    recent: std::collections::VecDeque<(f64, u64)>,
    /// The terrain, if the scene has one, what the view draws of it and the
    /// tiles it waits for (and their failed attempts).
    terrain: Option<TerrainTree>,
    terrain_draws: Vec<TerrainDraw>,
    /// Ground imagery for the terrain and the images the view waits for.
    imagery: Imagery,
    imagery_wanted: Vec<TerrainKey>,
    /// The scene CRS ↔ lon/lat (for imagery sources in Web Mercator), once the manifest is in.
    geo: Option<GeoFrame>,
    /// Block encodings the device samples, best first: a species' pack
    /// variant of one of them is fetched instead of its pack.
    texture_encodings: Vec<crate::format::pack::TexelEncoding>,
    /// Resident tiles' ids (and, with the second, attributes) are fetched (a style uses them).
    tree_data: (bool, bool),
    /// Fetch tiles' prefixes only (None: whole tiles).
    prefix_view: Option<PrefixView>,
    /// Wanted tiles within reach holding fewer levels than the view needs.
    levels_short: usize,
    /// Canopy rasters (scene version 8): the view's cross-fade (None: off),
    /// the resident ones, what the view draws and waits for, failed attempts.
    canopy_view: Option<CanopyView>,
    canopy_gate: Option<CanopyGate>,
    canopy: Option<CanopyTree>,
    canopy_draws: Vec<CanopyDraw>,
    /// Where trees the view wants are not resident (`[x0, y0, x1, y1]`): the
    /// canopy stands in there.
    canopy_gaps: Vec<[f32; 4]>,
    /// When the stream first waited for the root canopy raster.
    canopy_wait_from: Option<f64>,
}

/// Longest wait for the root canopy raster before tiles are fetched anyway (s).
const CANOPY_WAIT_S: f64 = 2.0;

/// Where a view hands far trees over to the canopy rasters
/// ([`SceneStream::set_canopy_view`]; the cull pass's `canopy_weight`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CanopyView {
    /// Projected tree height (px, × quality) below which the canopy stands in for every tree.
    pub px_lo: f32,
    /// … and from which trees begin to give way to it.
    pub px_hi: f32,
    /// Rasters are refined while their cells project above this (px).
    pub cell_px: f32,
    /// The factor on pixels per metre (the quality).
    pub lod_scale: f32,
}

impl<F: Fetcher> SceneStream<F> {
    /// The resident tile holding pool instance `instance` (what a pick's id
    /// pass returns), with the URLs of its tile and sidecars and the
    /// instance's index in the tile. None when no resident tile holds it.
    #[must_use]
    pub fn locate_instance(&self, instance: u32) -> Option<LocatedTree> {
        locate(&self.tile_locations(), instance)
    }

    /// Every resident tile's instance range in the pools, with its files and
    /// the tile index of the range's first instance (one range per batch for a
    /// tile holding a prefix): a snapshot a pick answered later can be located
    /// in ([`locate`]), whatever streamed in or out meanwhile.
    #[must_use]
    pub fn tile_locations(&self) -> Vec<(std::ops::Range<u32>, LocatedTree)> {
        self.tiles
            .iter()
            .enumerate()
            .filter_map(|(t, state)| match state {
                TileState::Resident { slot, prefix, .. } => {
                    let entry = self.index.tiles.get(t)?;
                    let tree = LocatedTree {
                        tile_url: join(&self.base, &entry.url),
                        ids_url: join(&self.base, &entry.ids_url),
                        attributes_url: join(&self.base, &crate::format::attributes::attributes_url(&entry.url)),
                        index: 0,
                    };
                    if prefix.runs.is_empty() {
                        return Some(vec![(slot.instances.clone(), tree)]);
                    }
                    let at = slot.instances.start;
                    Some(
                        prefix
                            .runs
                            .iter()
                            .filter(|r| r[1] > 0)
                            .map(|r| (at + r[0]..at + r[0] + r[1], LocatedTree { index: r[2], ..tree.clone() }))
                            .collect(),
                    )
                }
                TileState::NotResident(_) => None,
            })
            .flatten()
            .collect()
    }

    /// The block encodings of texture arrays the device samples, best first
    /// (`render::mesh::block_formats`; empty: plain packs only). Each
    /// species' pack is chosen by it, so it holds from the manifest's arrival
    /// on: a later call changes nothing (set it before streaming starts).
    pub fn set_texture_encodings(&mut self, encodings: Vec<crate::format::pack::TexelEncoding>) {
        if self.manifest.is_none() {
            self.texture_encodings = encodings;
        }
    }

    /// The pack species `s` is fetched from: its variant in an encoding the
    /// device samples, else its plain pack.
    pub(crate) fn pack_choice<'a>(
        m: &'a Manifest,
        encodings: &[crate::format::pack::TexelEncoding],
        s: usize,
    ) -> crate::format::manifest::PackChoice<'a> {
        m.species[s].pack_for(encodings)
    }

    /// The encodings species `s` may be fetched in: those the device samples,
    /// less those whose variant failed for good (the next, or the plain pack,
    /// then).
    fn encodings_for(&self, s: usize) -> Vec<crate::format::pack::TexelEncoding> {
        let failed = self.packs.get(s).map_or(&[][..], |p| &p.failed[..]);
        self.texture_encodings.iter().copied().filter(|e| !failed.contains(e)).collect()
    }

    /// The block encoding the scene's textures are fetched in (`None`: plain
    /// texels): the first the device samples that a species has a variant of.
    #[must_use]
    pub fn textures_in_use(&self) -> Option<crate::format::pack::TexelEncoding> {
        let m = self.manifest.as_ref()?;
        (0..m.species.len()).find_map(|s| m.species[s].pack_for(&self.encodings_for(s)).encoding)
    }

    /// Starts streaming the scene at `scene` (directory, `scene.json` path or URL).
    pub fn new(scene: &str, fetcher: F, config: StreamConfig) -> Self {
        let (base, manifest_url) = scene_locations(scene);
        Self {
            base,
            manifest_url,
            manifest: None,
            manifest_load: Load::Idle,
            index: IndexWalk::default(),
            node_loads: Vec::new(),
            tiles: Vec::new(),
            packs: Vec::new(),
            requests: HashMap::new(),
            fetcher,
            config,
            stats: StreamStats::default(),
            events: Vec::new(),
            failures: Vec::new(),
            wanted: Vec::new(),
            pending_nodes: 0,
            reach_m: f32::INFINITY,
            within_reach: 0,
            walk_tiles: Vec::new(),
            walk_nodes: Vec::new(),
            walk_stack: Vec::new(),
            needed: Vec::new(),
            recent: std::collections::VecDeque::new(),
            terrain: None,
            terrain_draws: Vec::new(),
            imagery: Imagery::new(),
            imagery_wanted: Vec::new(),
            geo: None,
            texture_encodings: Vec::new(),
            tree_data: (false, false),
            prefix_view: None,
            levels_short: 0,
            canopy_view: None,
            canopy_gate: None,
            canopy: None,
            canopy_draws: Vec::new(),
            canopy_gaps: Vec::new(),
            canopy_wait_from: None,
        }
    }

    /// Let the canopy rasters stand in for far trees (None: trees at every
    /// size, no raster fetched).
    pub fn set_canopy_view(&mut self, view: Option<CanopyView>) {
        self.canopy_view = view;
        if view.is_none() {
            self.canopy_draws.clear();
            if let Some(c) = &mut self.canopy {
                c.res.wanted.clear();
            }
            self.canopy_gate = None;
        }
    }

    /// The canopy rasters the current view draws.
    #[must_use]
    pub fn canopy_draws(&self) -> &[CanopyDraw] {
        &self.canopy_draws
    }

    /// Whether the canopy stands in for far trees now: asked for, and the
    /// scene's root raster is resident (until then trees are drawn at every size).
    #[must_use]
    pub fn canopy_active(&self) -> Option<CanopyView> {
        self.canopy_view.filter(|_| self.canopy.as_ref().is_some_and(CanopyTree::ready))
    }

    /// The canopy's cross-fade band (px) while it stands in for trees.
    fn canopy_band(&self) -> Option<[f32; 2]> {
        self.canopy_active().map(|c| [c.px_lo, c.px_hi])
    }

    /// Fetch only the prefix of each tile that a view drawing with this
    /// thinning draws (None: whole tiles, as before prefix levels).
    pub fn set_prefix_view(&mut self, thin: Option<PrefixView>) {
        self.prefix_view = thin;
    }

    /// Where ground imagery comes from (the scene's own by default).
    pub fn set_imagery(&mut self, choice: ImageryChoice) {
        self.imagery.set_choice(choice);
    }

    /// The ground imagery held.
    #[must_use]
    pub fn imagery(&self) -> &Imagery {
        &self.imagery
    }

    /// The terrain tiles the current view draws (empty without terrain).
    #[must_use]
    pub fn terrain_draws(&self) -> &[TerrainDraw] {
        &self.terrain_draws
    }

    /// The scene's terrain, if it has one.
    #[must_use]
    pub fn terrain(&self) -> Option<&TerrainTree> {
        self.terrain.as_ref()
    }

    /// The files given up on so far (at most [`MAX_LISTED_FAILURES`]).
    #[must_use]
    pub fn failures(&self) -> &[LoadFailure] {
        &self.failures
    }

    /// Records a file given up on.
    fn give_up(&mut self, url: &str, message: &str) {
        self.stats.broken += 1;
        if self.failures.len() < MAX_LISTED_FAILURES {
            self.failures.push(LoadFailure { url: url.to_string(), message: message.to_string() });
        }
    }

    /// The manifest, once loaded.
    #[must_use]
    pub fn manifest(&self) -> Option<&Manifest> {
        self.manifest.as_ref()
    }

    /// Changes the budgets (takes effect from the next update).
    pub fn set_config(&mut self, config: StreamConfig) {
        self.config = config;
    }

    /// The budgets.
    #[must_use]
    pub fn config(&self) -> StreamConfig {
        self.config
    }

    /// Counters.
    #[must_use]
    pub fn stats(&self) -> StreamStats {
        self.stats
    }

    /// Events since the last call.
    pub fn drain_events(&mut self) -> Vec<StreamEvent> {
        std::mem::take(&mut self.events)
    }

    /// Whether everything the current view wants is resident (or given up on) and
    /// nothing is in flight or waiting for a retry.
    #[must_use]
    pub fn is_settled(&self) -> bool {
        let manifest_done = self.manifest.is_some() || self.manifest_load == Load::Broken;
        let nodes_done = !self.node_loads.iter().any(|l| matches!(l, Load::Requested { .. } | Load::Waiting { .. }))
            && self.pending_nodes == 0;
        let tiles_done = self.wanted[..self.within_reach].iter().all(|&t| match &self.tiles[t] {
            TileState::Resident { .. } => true,
            TileState::NotResident(l) => *l == Load::Broken,
        });
        let packs_done = self.needed.iter().all(|&s| self.packs[s].done());
        let terrain_done = self.terrain.as_ref().is_none_or(|t| t.res.settled())
            && self.imagery_wanted.is_empty()
            && !self.imagery.retries_pending();
        let canopy_done = self.canopy.as_ref().is_none_or(|c| c.res.settled());
        // Trees' ids and attributes a style waits for and not yet asked for (the
        // fetcher was busy): their tiles are drawn unstyled until they come.
        let data_done = !self.tree_data.0
            || self.wanted[..self.within_reach].iter().all(|&t| {
                !matches!(
                    &self.tiles[t],
                    TileState::Resident { data: TreeDataLoad::None | TreeDataLoad::Failed(_), .. }
                )
            });
        manifest_done
            && nodes_done
            && tiles_done
            && self.levels_short == 0
            && packs_done
            && terrain_done
            && canopy_done
            && data_done
            && self.requests.is_empty()
    }

    /// The ground height at `(x, y)` (metres relative to the scene origin): the
    /// terrain's where it has data, else the lowest tree base of the resident
    /// batch cell nearest within 200 m (a ground estimate without a DEM).
    #[must_use]
    pub fn ground_height_at(&self, x: f32, y: f32) -> Option<f32> {
        if let Some(h) = self.terrain.as_ref().and_then(|t| t.height_at(f64::from(x), f64::from(y))) {
            return Some(h);
        }
        let distance = |c: &[f32; 5]| ((c[0] - x).max(x - c[2]).max(0.0)).hypot((c[1] - y).max(y - c[3]).max(0.0));
        self.tiles
            .iter()
            .filter_map(|t| match t {
                TileState::Resident { cells, .. } => Some(cells),
                TileState::NotResident(_) => None,
            })
            .flatten()
            .map(|c| (distance(c), c[4]))
            .filter(|(d, _)| *d <= 200.0)
            .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)))
            .map(|(_, z)| z)
    }

    /// Species of the wanted resident tiles, into `self.needed` (no allocation
    /// in steady state).
    fn collect_needed_species(&mut self) {
        let mut needed = std::mem::take(&mut self.needed);
        needed.clear();
        for &t in &self.wanted {
            if let TileState::Resident { species, .. } = &self.tiles[t] {
                for &s in species {
                    if !needed.contains(&(s as usize)) {
                        needed.push(s as usize);
                    }
                }
            }
        }
        self.needed = needed;
    }

    fn fail(&mut self, url: String, err: &str, attempt: u32, retryable: bool, now_s: f64) -> Load {
        let retrying = retryable && attempt + 1 < self.config.max_attempts;
        if !retrying {
            self.give_up(&url, err);
        }
        self.events.push(StreamEvent::Failed { url, message: err.to_string(), retrying });
        if retrying {
            Load::Waiting {
                attempt: attempt + 1,
                retry_at_s: now_s + self.config.retry_base_s * 2f64.powi(attempt as i32),
            }
        } else {
            Load::Broken
        }
    }

    /// One non-blocking step: handle finished requests, then request what the view
    /// needs. `now_s` is a monotonic clock in seconds (for retry backoff).
    pub fn update(&mut self, residency: &mut impl Residency, view: &ViewData, draw_distance_m: f32, now_s: f64) {
        for (id, result) in self.fetcher.poll() {
            let Some(target) = self.requests.remove(&id) else { continue };
            let fetched = !matches!(target, Target::PackInflate(..));
            if let (Ok(bytes), true) = (&result, fetched) {
                // (An image the browser decoded counts its encoded bytes.)
                let n = crate::format::imagery::fetched_bytes(bytes);
                self.stats.bytes_fetched += n;
                if self.config.max_bytes_per_s > 0.0 {
                    self.recent.push_back((now_s, n));
                }
            }
            match target {
                Target::Manifest => self.on_manifest(residency, result, now_s),
                Target::Node(n) => self.on_node(n, result, now_s),
                Target::Tile(t) => self.on_tile(residency, t, result, view, now_s),
                Target::TileMore(t, have) => self.on_tile_more(residency, t, have, result, view, now_s),
                Target::PackHead(s) => self.on_pack_head(residency, s, result, now_s),
                Target::PackPart(s, part) => self.on_pack_part(residency, s, part, result, false, now_s),
                Target::PackInflate(s, part) => self.on_pack_part(residency, s, part, result, true, now_s),
                Target::Terrain(key) => self.on_terrain(key, result, now_s),
                Target::Image(generation, key) => self.on_image(generation, key, result, now_s),
                Target::ImageSource(generation, tile) => self.on_image_source(generation, tile, result),
                Target::TreeData(t, attributes) => self.on_tree_data(t, attributes, result),
                Target::Canopy(n) => self.on_canopy(n, result, now_s),
            }
        }
        if self.manifest.is_none() {
            let due = match self.manifest_load {
                Load::Idle => Some(0),
                Load::Waiting { attempt, retry_at_s } if now_s >= retry_at_s => Some(attempt),
                _ => None,
            };
            if let Some(attempt) = due {
                let id = self.fetcher.start(&self.manifest_url);
                self.stats.requests += 1;
                self.requests.insert(id, Target::Manifest);
                self.manifest_load = Load::Requested { attempt };
            }
        } else {
            // Pools with room again: widen the reach step by step.
            // (Half free, so that a reach just shortened does not grow back at once.)
            let (free, total) = residency.instance_room();
            if self.reach_m < draw_distance_m && free > total / 2 {
                self.reach_m = (self.reach_m * 1.1).max(1.0);
                // Past the farthest tile the view wants: nothing is held back any more.
                if self.walk_tiles.last().is_none_or(|&(d, _)| d < self.reach_m) {
                    self.reach_m = draw_distance_m;
                }
            }
            self.reach_m = self.reach_m.min(draw_distance_m);
            while self.recent.front().is_some_and(|(t, _)| *t < now_s - 1.0) {
                self.recent.pop_front();
            }
            let rate: u64 = self.recent.iter().map(|(_, b)| b).sum();
            let over_rate = self.config.max_bytes_per_s > 0.0 && rate as f64 >= self.config.max_bytes_per_s;
            self.stats.degraded.bandwidth = over_rate;
            if let Some(t) = &mut self.terrain {
                t.res.retry_due(now_s);
            }
            if let Some(c) = &mut self.canopy {
                c.res.retry_due(now_s);
            }
            self.imagery.retry_due(now_s);
            self.select_terrain(view);
            self.select_canopy(view);
            // While the scene's root canopy raster loads, index nodes and tiles
            // wait (it decides which trees a far view needs at all) — for at most
            // CANOPY_WAIT_S, and not after it failed once.
            let root_loading = self.canopy_view.is_some()
                && self.canopy.as_ref().is_some_and(|c| c.root_loading() && !c.res.has_failed((0, 0, 0)));
            let since = *self.canopy_wait_from.get_or_insert(now_s);
            let canopy_first = root_loading && now_s - since < CANOPY_WAIT_S;
            if !over_rate {
                if let Some(c) = &mut self.canopy {
                    let (fetcher, requests, stats) = (&mut self.fetcher, &mut self.requests, &mut self.stats);
                    request_layer(c, fetcher, &self.base, self.config.max_in_flight, requests, stats, Target::Canopy);
                }
                if canopy_first {
                    self.walk(view, draw_distance_m);
                } else {
                    self.request_tiles(view, draw_distance_m, now_s);
                }
                self.request_packs(residency, now_s);
                if let Some(t) = &mut self.terrain {
                    let (fetcher, requests, stats) = (&mut self.fetcher, &mut self.requests, &mut self.stats);
                    request_layer(t, fetcher, &self.base, self.config.max_in_flight, requests, stats, Target::Terrain);
                }
                self.request_imagery();
                self.request_tree_data();
            } else {
                // Still decide what the view wants (for is_settled and eviction).
                self.walk(view, draw_distance_m);
            }
            self.stats.degraded.pools_full = self.reach_m < draw_distance_m;
            self.stats.degraded.device_limit = residency.limited_by_device();
            self.stats.degraded.reach_m = self.reach_m;
        }
        self.stats.loading = self.requests.len() as u64;
        self.stats.tiles_resident =
            self.tiles.iter().filter(|t| matches!(t, TileState::Resident { .. })).count() as u64;
        self.stats.tiles_wanted = self.wanted.len() as u64;
        self.stats.tiles_known = self.index.tiles.len() as u64;
        self.stats.index_nodes_loaded = self.index.nodes_loaded();
        self.stats.index_nodes_total = self.index.nodes_declared();
        self.stats.terrain_resident = self.terrain.as_ref().map_or(0, |t| t.resident() as u64);
        self.stats.terrain_drawn = self.terrain_draws.len() as u64;
        self.stats.imagery_resident = self.imagery.resident() as u64;
        self.stats.imagery_drawn = self.terrain_draws.iter().filter(|d| d.imagery.is_some()).count() as u64;
        self.stats.canopy_resident = self.canopy.as_ref().map_or(0, |c| c.resident() as u64);
        self.stats.canopy_drawn = self.canopy_draws.len() as u64;
    }

    fn on_manifest(&mut self, residency: &mut impl Residency, result: Result<Vec<u8>, FetchError>, now_s: f64) {
        let attempt = self.manifest_load.attempt();
        let parsed = result.map_err(|e| (e.to_string(), e.retryable())).and_then(|bytes| {
            Manifest::decode(&self.manifest_url, &bytes).map_err(|e: DecodeError| (e.to_string(), false))
        });
        match parsed {
            Ok(m) if m.shard.is_some() => {
                self.manifest_load = Load::Broken;
                let s = m.shard.unwrap_or(crate::format::ShardStamp { index: 0, count: 0 });
                self.events.push(StreamEvent::Fatal {
                    message: format!(
                        "{} is shard {} of {} of a sharded bake, not a whole scene: join the shards with `sylva-bake merge`",
                        self.manifest_url, s.index, s.count
                    ),
                });
            }
            Ok(m) if m.species.len() as u32 <= residency.species_capacity() => {
                // Pools no bigger than the scene can fill (and within the device's limits).
                residency.begin_scene(m.counts.trees, m.counts.batches, m.species.len() as u32);
                self.index = IndexWalk::new(&m);
                self.node_loads = vec![Load::Idle; self.index.nodes.len()];
                self.tiles = self.index.tiles.iter().map(|_| TileState::NotResident(Load::Idle)).collect();
                self.packs = (0..m.species.len()).map(|_| PackLoad::new()).collect();
                self.terrain = m.terrain.clone().map(TerrainTree::new);
                self.canopy = m.canopy.clone().map(CanopyTree::new);
                self.geo = GeoFrame::for_scene(&m.crs, m.origin_m).ok();
                self.events.push(StreamEvent::ManifestLoaded { trees: m.counts.trees });
                self.manifest = Some(m);
            }
            Ok(m) => {
                self.manifest_load = Load::Broken;
                self.events.push(StreamEvent::Fatal {
                    message: format!(
                        "{}: {} species exceed this viewer's {}",
                        self.manifest_url,
                        m.species.len(),
                        residency.species_capacity()
                    ),
                });
            }
            Err((message, retryable)) => {
                let url = self.manifest_url.clone();
                self.manifest_load = self.fail(url, &message, attempt, retryable, now_s);
                if self.manifest_load == Load::Broken {
                    self.events.push(StreamEvent::Fatal { message });
                }
            }
        }
    }
}
