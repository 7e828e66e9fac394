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

/// What a budget or device limit currently holds back (all false: nothing).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Degraded {
    /// The GPU pools are full of wanted tiles: the draw distance for new tiles is
    /// shortened to `reach_m`.
    pub pools_full: bool,
    /// Pack parts (finer levels) are held back by the GPU budget.
    pub gpu_budget: bool,
    /// Requests wait for the download budget.
    pub bandwidth: bool,
    /// The GPU pools were cut down to the device's limits (largest storage binding).
    pub device_limit: bool,
    /// The distance up to which tiles are requested (the draw distance unless the
    /// pools are full).
    pub reach_m: f32,
}

/// A file given up on (not found, corrupt, or failed every retry): what the
/// view lacks. Listed in the frame stats as `failed`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LoadFailure {
    /// The URL.
    pub url: String,
    /// What went wrong.
    pub message: String,
}

/// Most failures kept in the list (the count in [`StreamStats::broken`] goes on).
pub const MAX_LISTED_FAILURES: usize = 64;

/// Something a user should hear about.
#[derive(Debug, Clone, PartialEq)]
pub enum StreamEvent {
    /// The manifest is loaded.
    ManifestLoaded {
        /// Trees in the scene.
        trees: u64,
    },
    /// A fetch or decode failed; `retrying` says whether it will be tried again.
    Failed {
        /// The URL.
        url: String,
        /// What went wrong.
        message: String,
        /// Whether another attempt is scheduled.
        retrying: bool,
    },
    /// The manifest could not be loaded: nothing can be drawn.
    Fatal {
        /// What went wrong.
        message: String,
    },
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

/// The first guess of the prefix levels (of `levels.count`, 1..=count) a
/// view drawing with `thin` needs of a tile, before its batches are known:
/// the thinned fraction (`thinning` in `shaders/common.wgsl`) of its tallest
/// tree (`levels.tallest_m`) at the nearest point of the tile the view sees
/// (sampled). All of them without thinning. [`batch_levels_wanted`] decides
/// once the head is in.
#[must_use]
pub fn first_levels_wanted(
    view: &ViewData,
    bounds: &crate::format::Bounds,
    levels: &Levels,
    thin: Option<PrefixView>,
) -> u32 {
    let (height_m, levels_count) = (levels.tallest_m, levels.count);
    let Some(thin) = thin.filter(|t| t.thin_px > 0.0) else { return levels_count };
    let eye = view.eye_hi + view.eye_lo;
    let (lo, hi) = (Vec3::from(bounds.min) - eye, Vec3::from(bounds.max) - eye);
    let inside = |p: Vec3| view.frustum.iter().all(|f| f.truncate().dot(p) + f.w >= 0.0);
    let mut d = f32::INFINITY;
    if lo.cmple(Vec3::ZERO).all() && hi.cmpge(Vec3::ZERO).all() {
        d = 0.0;
    }
    for i in 0..5 {
        for j in 0..5 {
            for k in 0..3 {
                let p = lo + (hi - lo) * Vec3::new(i as f32 / 4.0, j as f32 / 4.0, k as f32 / 2.0);
                if inside(p) {
                    d = d.min(p.length());
                }
            }
        }
    }
    if d == f32::INFINITY {
        d = tile_distance(bounds, eye);
    }
    let h = height_m * view.px_per_m_at_1m * thin.lod_scale / (d * 0.99).max(1e-3);
    if h >= thin.thin_px || h.is_nan() {
        return levels_count;
    }
    let mut f = (h * h) / (thin.thin_px * thin.thin_px);
    // The canopy's share comes off the tail of those.
    if let Some(band) = thin.canopy {
        f *= canopy_share(h, band);
    }
    levels.covering(f)
}

/// The prefix levels (of `scheme.count`, 1..=count) a view drawing with
/// `thin` needs of a tile whose whole batches are `batches`: the fewest that
/// hold what every batch in view keeps (`thinning` in `shaders/common.wgsl`:
/// its tallest tree at its nearest point, 1 % nearer against float noise).
/// All of them without thinning.
#[must_use]
pub fn batch_levels_wanted(view: &ViewData, batches: &[GpuBatch], scheme: &Levels, thin: Option<PrefixView>) -> u32 {
    let levels = scheme.count;
    let Some(thin) = thin.filter(|t| t.thin_px > 0.0) else { return levels };
    let eye = view.eye_hi + view.eye_lo;
    let mut want = 1;
    for b in batches {
        let (c, half) = (Vec3::from(b.center_m) - eye, Vec3::from(b.half_extent_m));
        let seen = view.frustum.iter().all(|p| p.truncate().dot(c) + p.w + p.truncate().abs().dot(half) >= 0.0);
        if b.instance_count == 0 || !seen {
            continue;
        }
        let d = ((c.abs() - half).max(Vec3::ZERO).length() * 0.99).max(1e-3);
        let h = b.max_height_m * view.px_per_m_at_1m * thin.lod_scale / d;
        let mut need = if h < thin.thin_px {
            let f = ((h * h) / (thin.thin_px * thin.thin_px)).clamp(1.0 / 64.0, 1.0);
            (b.instance_count as f32 * f).max(1.0).ceil() as u32
        } else {
            b.instance_count
        };
        // The canopy's share comes off the tail of those (its tallest tree's share: the most kept).
        if let Some(band) = thin.canopy {
            need = canopy_keeps(h, need, band);
        }
        let l = (0..levels).find(|&l| scheme.prefix(b, l) >= need).unwrap_or(levels - 1) + 1;
        want = want.max(l);
        if want == levels {
            break;
        }
    }
    want
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

/// Counters for stats.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StreamStats {
    /// Bytes received.
    pub bytes_fetched: u64,
    /// Of them, bytes of tiles (whole or prefix levels).
    pub tile_bytes_fetched: u64,
    /// Tiles in the GPU pools.
    pub tiles_resident: u64,
    /// Requests in flight.
    pub loading: u64,
    /// Tiles or packs given up on.
    pub broken: u64,
    /// Tiles the view wants.
    pub tiles_wanted: u64,
    /// Tiles known (listed by the manifest or by index nodes read so far).
    pub tiles_known: u64,
    /// Index nodes read (0 for a flat manifest).
    pub index_nodes_loaded: u64,
    /// Index nodes in the scene (0 for a flat manifest).
    pub index_nodes_total: u64,
    /// Requests started, of every kind.
    pub requests: u64,
    /// What budgets or limits hold back now.
    pub degraded: Degraded,
    /// Terrain tiles decoded and kept.
    pub terrain_resident: u64,
    /// Terrain tiles drawn by the current view.
    pub terrain_drawn: u64,
    /// Ground imagery images decoded and kept.
    pub imagery_resident: u64,
    /// Terrain tiles drawn with an image this frame.
    pub imagery_drawn: u64,
    /// Canopy rasters decoded and kept.
    pub canopy_resident: u64,
    /// Canopy rasters drawn by the current view.
    pub canopy_drawn: u64,
    /// Bytes of canopy rasters received.
    pub canopy_bytes_fetched: u64,
    /// Times a resident tile was trimmed to fewer prefix levels to make room
    /// (eviction by prefix).
    pub tiles_trimmed: u64,
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

/// Asks for the tiles a quadtree layer waits for, nearest first, within the
/// in-flight budget (the same for every layer: terrain, canopy rasters).
fn request_layer<L: QuadLayer, F: Fetcher>(
    layer: &mut L,
    fetcher: &mut F,
    base: &str,
    max_in_flight: usize,
    requests: &mut HashMap<RequestId, Target>,
    stats: &mut StreamStats,
    target: fn(QuadKey) -> Target,
) {
    let wanted = std::mem::take(&mut layer.residency_mut().wanted);
    for &(_, key) in &wanted {
        if fetcher.in_flight() >= max_in_flight {
            break;
        }
        if !layer.residency().is_unknown(key) {
            continue;
        }
        let id = fetcher.start(&join(base, &layer.url(key)));
        stats.requests += 1;
        requests.insert(id, target(key));
        layer.residency_mut().mark_loading(key);
    }
    layer.residency_mut().wanted = wanted;
}

/// A tile of a quadtree layer arrived or failed: kept, retried with backoff
/// (a failure a retry may mend; it stays asked for until then) or given up on
/// (its parent stands in). Returns the failure to tell: (url, message, retried).
fn layer_arrived<L: QuadLayer>(
    layer: &mut L,
    base: &str,
    key: QuadKey,
    result: Result<Vec<u8>, FetchError>,
    policy: RetryPolicy,
    now_s: f64,
) -> Option<(String, String, bool)> {
    let url = join(base, &layer.url(key));
    let outcome = result
        .map_err(|e| (e.to_string(), e.retryable()))
        .and_then(|bytes| layer.decode(&url, key, &bytes).map_err(|e| (e, false)));
    match outcome {
        Ok(tile) => {
            layer.residency_mut().insert(key, tile);
            None
        }
        Err((message, retryable)) => {
            let retrying = layer.residency_mut().failed(key, retryable, policy, now_s);
            Some((url, message, retrying))
        }
    }
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
            if let Ok(bytes) = &result {
                self.stats.bytes_fetched += bytes.len() as u64;
                if self.config.max_bytes_per_s > 0.0 {
                    self.recent.push_back((now_s, bytes.len() as u64));
                }
            }
            match target {
                Target::Manifest => self.on_manifest(residency, result, now_s),
                Target::Node(n) => self.on_node(n, result, now_s),
                Target::Tile(t) => self.on_tile(residency, t, result, view, now_s),
                Target::TileMore(t, have) => self.on_tile_more(residency, t, have, result, view, now_s),
                Target::PackHead(s) => self.on_pack_head(residency, s, result, now_s),
                Target::PackPart(s, part) => self.on_pack_part(residency, s, part, result, now_s),
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

    /// Picks the canopy rasters the view draws and the ones it waits for, and
    /// the index walk's gate (where the canopy alone draws the trees).
    fn select_canopy(&mut self, view: &ViewData) {
        if let Some(c) = &mut self.canopy {
            c.res.wanted.clear();
        }
        if self.canopy_view.is_some() && self.canopy.is_some() {
            self.collect_canopy_gaps();
        }
        let (Some(cv), Some(tree)) = (self.canopy_view, self.canopy.as_mut()) else {
            self.canopy_draws.clear();
            self.canopy_gate = None;
            return;
        };
        let px_per_m = view.px_per_m_at_1m * cv.lod_scale;
        let eye = view.eye_hi.as_dvec3() + view.eye_lo.as_dvec3();
        // Cut coarser while the view would draw more rasters than the GPU pool holds.
        let mut cell_px = cv.cell_px;
        for _ in 0..8 {
            tree.select(view, eye, px_per_m, cell_px, cv.px_hi, &self.canopy_gaps, &mut self.canopy_draws);
            if self.canopy_draws.len() <= super::canopy::MAX_CANOPY_DRAWS {
                break;
            }
            cell_px *= 2.0;
        }
        self.canopy_gate = tree.ready().then_some(CanopyGate { px_per_m, px_lo: cv.px_lo });
    }

    /// Where trees the view wants cannot be drawn yet, into `canopy_gaps`.
    fn collect_canopy_gaps(&mut self) {
        // Gaps (from the last walk): wanted tiles not resident, or with a species
        // whose billboards are still on their way, or none of whose species can
        // be drawn (a tile with one species given up on and others drawn is not
        // one: the canopy would darken the drawn trees twice); index nodes in
        // view not read. As squares of the tile grid the bake sorts trunks by
        // (the trees' bounds reach past them by the crowns, into the
        // neighbouring rasters).
        let Some(m) = &self.manifest else { return };
        let tile_m = m.cell_size_m * m.tile_cells as f32;
        let square = |x: i32, y: i32| {
            let (x, y) = (x as f32, y as f32);
            [x * tile_m, y * tile_m, (x + 1.0) * tile_m, (y + 1.0) * tile_m]
        };
        // A node's trunk squares: its bounds rounded to the grid (crowns reach
        // less than half a tile past their trunks' squares).
        let snap = |b: &crate::format::Bounds| {
            let r = |v: f32| (v / tile_m).round() * tile_m;
            [r(b.min[0]), r(b.min[1]), r(b.max[0]), r(b.max[1])]
        };
        let mut gaps = std::mem::take(&mut self.canopy_gaps);
        gaps.clear();
        for &(_, t) in &self.walk_tiles {
            let gap = match self.tiles.get(t) {
                Some(TileState::Resident { species, .. }) => {
                    // (No allocation: the steady-state frame allocates nothing.)
                    let state = |k: &u32| self.species_drawable(*k as usize);
                    species.iter().any(|k| state(k).1) || species.iter().all(|k| !state(k).0)
                }
                _ => true,
            };
            if gap {
                let e = &self.index.tiles[t];
                gaps.push(square(e.x, e.y));
            }
        }
        for &(_, n) in &self.walk_nodes {
            gaps.push(snap(&self.index.nodes[n].bounds));
        }
        self.canopy_gaps = gaps;
    }

    /// A canopy raster arrived (or failed): kept, retried or given up on (its
    /// parent's is drawn instead; the rest of the scene goes on).
    fn on_canopy(&mut self, key: CanopyKey, result: Result<Vec<u8>, FetchError>, now_s: f64) {
        let Some(tree) = &mut self.canopy else { return };
        if let Ok(bytes) = &result {
            self.stats.canopy_bytes_fetched += bytes.len() as u64;
        }
        let failed = layer_arrived(tree, &self.base, key, result, self.config.retry(), now_s);
        self.report(failed);
    }

    /// A failed file of a quadtree layer: given up on (listed) unless it is
    /// retried, and told as an event either way.
    fn report(&mut self, failed: Option<(String, String, bool)>) {
        if let Some((url, message, retrying)) = failed {
            if !retrying {
                self.give_up(&url, &message);
            }
            self.events.push(StreamEvent::Failed { url, message, retrying });
        }
    }

    /// Fetch the ids (`ids`) and attributes (`attributes`, for scenes with
    /// them) of resident tiles' trees, as a style needs them; neither: stop
    /// and forget them.
    pub fn set_tree_data(&mut self, ids: bool, attributes: bool) {
        let wanted = (ids || attributes, attributes);
        if self.tree_data == wanted {
            return;
        }
        // Attributes newly wanted: tiles read without them are read again.
        let again = !wanted.0 || (wanted.1 && !self.tree_data.1);
        self.tree_data = wanted;
        if again {
            for t in &mut self.tiles {
                if let TileState::Resident { data, .. } = t {
                    *data = TreeDataLoad::None;
                }
            }
        }
    }

    /// Every resident tile: its number, its range in the instance pool and its
    /// trees' ids and attributes once they arrived (with [`Self::set_tree_data`]).
    #[allow(clippy::type_complexity)]
    pub fn resident_tree_data(
        &self,
    ) -> impl Iterator<Item = (usize, std::ops::Range<u32>, &[[u32; 3]], TreeDataState<'_>)> + '_ {
        self.tiles.iter().enumerate().filter_map(|(t, state)| match state {
            TileState::Resident { slot, data, prefix, .. } => {
                let state = match data {
                    TreeDataLoad::Ready(d) => TreeDataState::Ready(d),
                    TreeDataLoad::Broken => TreeDataState::Broken,
                    _ => TreeDataState::Pending,
                };
                Some((t, slot.instances.clone(), prefix.runs.as_slice(), state))
            }
            TileState::NotResident(_) => None,
        })
    }

    /// Requests the ids and attributes of resident tiles that lack them, the
    /// wanted (nearest) tiles first, within the in-flight budget.
    fn request_tree_data(&mut self) {
        if !self.tree_data.0 {
            return;
        }
        let attributes = self.tree_data.1 && self.manifest.as_ref().is_some_and(|m| m.attributes.is_some());
        let due = |d: &TreeDataLoad| matches!(d, TreeDataLoad::None | TreeDataLoad::Failed(_));
        let order: Vec<usize> = self
            .wanted
            .iter()
            .copied()
            .chain(0..self.tiles.len())
            .filter(|&t| matches!(&self.tiles[t], TileState::Resident { data, .. } if due(data)))
            .collect();
        for t in order {
            if self.fetcher.in_flight() + 2 > self.config.max_in_flight.max(2) {
                break;
            }
            let TileState::Resident { data, .. } = &mut self.tiles[t] else { continue };
            let attempt = match data {
                TreeDataLoad::None => 0,
                TreeDataLoad::Failed(n) => *n,
                _ => continue,
            };
            *data = TreeDataLoad::Loading { attempt, ids: None, codes: if attributes { None } else { Some(None) } };
            let entry = &self.index.tiles[t];
            let ids_url = join(&self.base, &entry.ids_url);
            let attr_url = join(&self.base, &crate::format::attributes::attributes_url(&entry.url));
            let id = self.fetcher.start(&ids_url);
            self.requests.insert(id, Target::TreeData(t, false));
            self.stats.requests += 1;
            if attributes {
                let id = self.fetcher.start(&attr_url);
                self.requests.insert(id, Target::TreeData(t, true));
                self.stats.requests += 1;
            }
        }
    }

    fn on_tree_data(&mut self, t: usize, attributes: bool, result: Result<Vec<u8>, FetchError>) {
        let Some(m) = &self.manifest else { return };
        let entry = &self.index.tiles[t];
        let url = if attributes {
            join(&self.base, &crate::format::attributes::attributes_url(&entry.url))
        } else {
            join(&self.base, &entry.ids_url)
        };
        let TileState::Resident { slot, data, prefix, .. } = &mut self.tiles[t] else { return };
        let TreeDataLoad::Loading { attempt, ids, codes } = data else { return };
        let attempt = *attempt;
        // The sidecars hold every tree of the tile, also when only a prefix is resident.
        let count = if prefix.batches.is_empty() {
            slot.instances.len()
        } else {
            prefix.batches.iter().map(|b| b.instance_count as usize).sum()
        };
        let decoded = result.map_err(|e| e.to_string()).and_then(|bytes| {
            if attributes {
                let schema = m.attributes.as_ref().ok_or("the scene has no attributes")?;
                let c = crate::format::attributes::decode_attributes(&url, &bytes, schema, count)
                    .map_err(|e| e.to_string())?;
                *codes = Some(Some(c));
            } else {
                let v = crate::format::decode_tree_ids(&url, &bytes).map_err(|e| e.to_string())?;
                if v.numbers.len() != count {
                    return Err(format!("{url}: {} ids for {count} trees", v.numbers.len()));
                }
                *ids = Some(v);
            }
            Ok(())
        });
        match decoded {
            Err(message) => {
                // (The other sidecar's answer, if still to come, finds the tile no longer loading.)
                let retrying = attempt + 1 < TREE_DATA_ATTEMPTS;
                *data = if retrying { TreeDataLoad::Failed(attempt + 1) } else { TreeDataLoad::Broken };
                if !retrying {
                    self.give_up(&url, &message);
                }
                self.events.push(StreamEvent::Failed { url, message, retrying });
            }
            Ok(()) => {
                if let TreeDataLoad::Loading { ids: Some(_), codes: Some(_), .. } = data {
                    if let TreeDataLoad::Loading { ids: Some(ids), codes: Some(codes), .. } = std::mem::take(data) {
                        *data = TreeDataLoad::Ready(std::sync::Arc::new(TreeData { ids, codes }));
                    }
                }
            }
        }
    }

    /// Requests the images the drawn terrain wants, within the in-flight budget.
    fn request_imagery(&mut self) {
        let Some(t) = &self.terrain else { return };
        if !self.config.terrain {
            return;
        }
        let generation = self.imagery.generation();
        for &key in &self.imagery_wanted {
            if self.fetcher.in_flight() >= self.config.max_in_flight {
                break;
            }
            for fetch in self.imagery.start(t.entry(), self.geo.as_ref(), key) {
                let (url, target) = match fetch {
                    ImageryFetch::Baked(k, rel) => (join(&self.base, &rel), Target::Image(generation, k)),
                    ImageryFetch::Source(tile, url) => (url, Target::ImageSource(generation, tile)),
                };
                let id = self.fetcher.start(&url);
                self.stats.requests += 1;
                self.requests.insert(id, target);
            }
        }
    }

    /// A baked image arrived or failed: kept, retried with backoff (server
    /// errors, broken connections) or given up on (the tile then drapes its
    /// ancestor's image). Answers for a former imagery source are dropped.
    fn on_image(&mut self, generation: u32, key: TerrainKey, result: Result<Vec<u8>, FetchError>, now_s: f64) {
        if generation != self.imagery.generation() {
            return;
        }
        let Some(t) = &self.terrain else { return };
        let Some(i) = &t.entry().imagery else { return };
        let url = join(&self.base, &i.tile_url(key.0, key.1, key.2));
        let (outcome, retrying) = match &result {
            Ok(bytes) => (self.imagery.on_baked(t.entry(), key, &url, Some(bytes)), false),
            Err(e) if e.retryable() => {
                let retrying = self.imagery.retry_later(key, now_s, self.config.retry());
                (Err(e.to_string()), retrying)
            }
            Err(e) => {
                let _ = self.imagery.on_baked(t.entry(), key, &url, None);
                (Err(e.to_string()), false)
            }
        };
        if let Err(message) = outcome {
            if !retrying {
                self.give_up(&url, &message);
            }
            self.events.push(StreamEvent::Failed { url, message, retrying });
        }
    }

    /// A tile of the XYZ/WMTS source arrived or failed (missing tiles leave
    /// their part without imagery; only undecodable ones are reported).
    fn on_image_source(&mut self, generation: u32, tile: (u8, u32, u32), result: Result<Vec<u8>, FetchError>) {
        if generation != self.imagery.generation() {
            return;
        }
        let url = match self.imagery.choice() {
            ImageryChoice::Xyz(src) => src.url(tile.0, tile.1, tile.2),
            _ => String::new(),
        };
        let outcome = self.imagery.on_source(tile, &url, result.as_deref().ok());
        let failure = match (outcome, result) {
            (Err(message), _) => Some(message),
            (Ok(()), Err(e)) if !matches!(e, FetchError::NotFound { .. }) => Some(e.to_string()),
            _ => None,
        };
        if let Some(message) = failure {
            self.events.push(StreamEvent::Failed { url, message, retrying: false });
        }
    }

    /// Picks the terrain tiles the view draws and the ones it waits for.
    fn select_terrain(&mut self, view: &ViewData) {
        self.imagery_wanted.clear();
        let Some(t) = &mut self.terrain else { return };
        if !self.config.terrain {
            t.res.wanted.clear();
            self.terrain_draws.clear();
            return;
        }
        let eye = view.eye_hi.as_dvec3() + view.eye_lo.as_dvec3();
        t.select(view, eye, self.config.terrain_error_px, &mut self.terrain_draws);
        let draws = self.terrain_draws.iter_mut().map(|d| (d.key, &mut d.imagery));
        self.imagery.attach(t.entry(), self.geo.as_ref(), draws, &mut self.imagery_wanted);
    }

    /// A terrain tile arrived (or failed): kept, retried or given up on (its
    /// parent is drawn instead; the rest of the scene goes on).
    fn on_terrain(&mut self, key: TerrainKey, result: Result<Vec<u8>, FetchError>, now_s: f64) {
        let Some(t) = &mut self.terrain else { return };
        let failed = layer_arrived(t, &self.base, key, result, self.config.retry(), now_s);
        self.report(failed);
    }

    fn on_node(&mut self, n: usize, result: Result<Vec<u8>, FetchError>, now_s: f64) {
        let url = join(&self.base, self.index.node_url(n));
        let attempt = self.node_loads[n].attempt();
        let loaded = result
            .map_err(|e| (e.to_string(), e.retryable()))
            .and_then(|bytes| self.index.load_node(n, &url, &bytes).map_err(|e| (e, true)));
        match loaded {
            Ok(new_tiles) => {
                self.node_loads[n] = Load::Idle;
                self.tiles.extend(new_tiles.map(|_| TileState::NotResident(Load::Idle)));
                let nodes = self.index.nodes.len();
                self.node_loads.resize(nodes, Load::Idle);
            }
            Err((message, retryable)) => self.node_loads[n] = self.fail(url, &message, attempt, retryable, now_s),
        }
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
                self.geo = GeoFrame::new(&m.crs.proj4, m.origin_m).ok();
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

    fn on_tile(
        &mut self,
        residency: &mut impl Residency,
        t: usize,
        result: Result<Vec<u8>, FetchError>,
        view: &ViewData,
        now_s: f64,
    ) {
        let Some(m) = &self.manifest else { return };
        let entry = &self.index.tiles[t];
        let url = join(&self.base, &entry.url);
        let attempt = match &self.tiles[t] {
            TileState::NotResident(Load::Requested { attempt }) => *attempt,
            _ => 0,
        };
        let species_count = m.species.len() as u32;
        if let Ok(bytes) = &result {
            self.stats.tile_bytes_fetched += bytes.len() as u64;
        }
        let decoded = result
            .map_err(|e| (e.to_string(), e.retryable()))
            // A corrupt tile may be a truncated transfer: worth one more try.
            .and_then(|bytes| {
                Tile::decode_prefix(&url, &bytes, species_count).map(|p| (p, bytes)).map_err(|e| (e.to_string(), true))
            });
        let (held, bytes) = match decoded {
            Ok(held) => held,
            Err((message, retryable)) => {
                let load = self.fail(url, &message, attempt, retryable, now_s);
                self.tiles[t] = TileState::NotResident(load);
                return;
            }
        };
        let tile = &held.tile;
        let mut result = residency.upload_tile(tile);
        // Full pools: evict resident tiles the view does not want, farthest first.
        while let Err(PoolError::Full(what)) = result {
            if !self.evict_one(residency, view, None, what == "instances") {
                break;
            }
            result = residency.upload_tile(tile);
        }
        // Bytes kept for more or fewer levels (a tile whose entry lists its levels).
        let keep_bytes = held.of > 1 && self.index.tiles[t].levels.is_some();
        match result {
            Ok(slot) => {
                let prefix = Box::new(Prefix {
                    levels: held.levels,
                    runs: std::sync::Arc::new(held.runs()),
                    batches: held.whole_batches(),
                    scheme: held.scheme,
                    bytes: if keep_bytes { bytes } else { Vec::new() },
                    more: Load::Idle,
                });
                let species = slot.species_counts.iter().map(|(s, _)| *s).collect();
                let cells = tile
                    .batches
                    .iter()
                    .map(|b| {
                        let side = b.xy_step_m * 65535.0;
                        [b.origin_m[0], b.origin_m[1], b.origin_m[0] + side, b.origin_m[1] + side, b.origin_m[2]]
                    })
                    .collect();
                self.tiles[t] = TileState::Resident { slot, species, cells, data: TreeDataLoad::None, prefix };
            }
            Err(PoolError::Full(what)) => {
                // No room even after evicting everything unwanted: the view wants more
                // than the pools hold.
                self.shorten_reach(t, url, what, view);
                self.tiles[t] = TileState::NotResident(Load::Waiting { attempt, retry_at_s: now_s + 1.0 });
            }
            Err(e) => {
                self.give_up(&url, &e.to_string());
                self.events.push(StreamEvent::Failed { url, message: e.to_string(), retrying: false });
                self.tiles[t] = TileState::NotResident(Load::Broken);
            }
        }
    }

    /// More levels of resident tile `t` (which held `have`) arrived: the tile is
    /// uploaded again with them and its old room given back. On failure the
    /// tile keeps what it holds.
    fn on_tile_more(
        &mut self,
        residency: &mut impl Residency,
        t: usize,
        have: u32,
        result: Result<Vec<u8>, FetchError>,
        view: &ViewData,
        now_s: f64,
    ) {
        let Some(m) = &self.manifest else { return };
        let species_count = m.species.len() as u32;
        let url = join(&self.base, &self.index.tiles[t].url);
        let whole = self.index.tiles[t].bytes;
        let TileState::Resident { prefix, .. } = &mut self.tiles[t] else { return };
        if prefix.levels != have {
            return;
        }
        let attempt = prefix.more.attempt();
        let decoded = result.map_err(|e| (e.to_string(), e.retryable())).and_then(|more| {
            self.stats.tile_bytes_fetched += more.len() as u64;
            // A server that ignores ranges answers with the whole file (a range is shorter).
            let bytes = if more.len() as u64 == whole {
                more
            } else {
                let mut bytes = Vec::with_capacity(prefix.bytes.len() + more.len());
                bytes.extend_from_slice(&prefix.bytes);
                bytes.extend_from_slice(&more);
                bytes
            };
            Tile::decode_prefix(&url, &bytes, species_count).map(|p| (p, bytes)).map_err(|e| (e.to_string(), true))
        });
        let decoded = decoded.and_then(|(p, bytes)| {
            if p.levels > have {
                Ok((p, bytes))
            } else {
                Err(("the bytes fetched add no level to the tile".to_string(), false))
            }
        });
        let (held, bytes) = match decoded {
            Ok(d) => d,
            Err((message, retryable)) => {
                let load = self.fail(url, &message, attempt, retryable, now_s);
                if let TileState::Resident { prefix, .. } = &mut self.tiles[t] {
                    prefix.more = load;
                }
                return;
            }
        };
        let mut result = residency.upload_tile(&held.tile);
        while let Err(PoolError::Full(what)) = result {
            if !self.evict_one(residency, view, Some(t), what == "instances") {
                break;
            }
            result = residency.upload_tile(&held.tile);
        }
        let keep_bytes = held.of > 1 && self.index.tiles[t].levels.is_some();
        let TileState::Resident { slot, prefix, .. } = &mut self.tiles[t] else { return };
        // Room for one copy only: the old one's room first, and back if the new does not fit.
        let mut replaced = false;
        if matches!(result, Err(PoolError::Full(_))) {
            residency.evict_tile(slot.clone());
            result = residency.upload_tile(&held.tile);
            replaced = true;
            if result.is_err() {
                let old = Tile::decode_prefix(&url, &prefix.bytes, species_count).map_err(|e| e.to_string());
                match old.and_then(|old| residency.upload_tile(&old.tile).map_err(|e| e.to_string())) {
                    Ok(back) => *slot = back,
                    Err(message) => {
                        // Not even the old copy fits again (cannot happen with one
                        // tile's room freed): fetched anew later.
                        self.events.push(StreamEvent::Failed { url, message, retrying: true });
                        self.tiles[t] = TileState::NotResident(Load::Idle);
                        return;
                    }
                }
            }
        }
        match result {
            Ok(new_slot) => {
                let old = std::mem::replace(slot, new_slot);
                if !replaced {
                    residency.evict_tile(old);
                }
                **prefix = Prefix {
                    levels: held.levels,
                    runs: std::sync::Arc::new(held.runs()),
                    batches: held.whole_batches(),
                    scheme: held.scheme,
                    bytes: if keep_bytes { bytes } else { Vec::new() },
                    more: Load::Idle,
                };
            }
            // No room for the bigger tile: it keeps what it holds, and (as for a new
            // tile) tiles are requested only up to a little less than its distance.
            Err(PoolError::Full(what)) => {
                prefix.more = Load::Waiting { attempt: attempt + 1, retry_at_s: now_s + 1.0 };
                self.shorten_reach(t, url, what, view);
            }
            Err(e) => {
                let message = e.to_string();
                prefix.more = Load::Broken;
                self.give_up(&url, &message);
                self.events.push(StreamEvent::Failed { url, message, retrying: false });
            }
        }
    }

    /// The pools are full of what the view wants: degrade by requesting tiles only
    /// up to a little less than tile `t`'s distance (nearer tiles came first), and say so.
    fn shorten_reach(&mut self, t: usize, url: String, what: &str, view: &ViewData) {
        let d = tile_distance(&self.index.tiles[t].bounds, view.eye_hi + view.eye_lo);
        let reach = (d * 0.9).min(self.reach_m);
        if reach < self.reach_m {
            self.events.push(StreamEvent::Failed {
                url,
                message: format!(
                    "the GPU pools are full ({what}): tiles are requested up to {reach:.0} m instead of the draw distance"
                ),
                retrying: true,
            });
            self.reach_m = reach;
        }
    }

    /// Evicts the farthest resident tile the view does not want (never `keep`);
    /// with none left and `trim` (the instance pool is what is full), trims a
    /// wanted one to the levels the view draws ([`Self::trim_one`]).
    fn evict_one(&mut self, residency: &mut impl Residency, view: &ViewData, keep: Option<usize>, trim: bool) -> bool {
        let eye = view.eye_hi + view.eye_lo;
        let victim = self
            .tiles
            .iter()
            .enumerate()
            .filter(|(i, t)| matches!(t, TileState::Resident { .. }) && !self.wanted.contains(i) && Some(*i) != keep)
            .max_by(|(a, _), (b, _)| {
                let d = |i: usize| tile_distance(&self.index.tiles[i].bounds, eye);
                d(*a).total_cmp(&d(*b))
            })
            .map(|(i, _)| i);
        // (A trim keeps every batch: it makes room for instances only.)
        let Some(v) = victim else { return trim && self.trim_one(residency, view, keep) };
        if let TileState::Resident { slot, .. } =
            std::mem::replace(&mut self.tiles[v], TileState::NotResident(Load::Idle))
        {
            residency.evict_tile(slot);
        }
        true
    }

    /// Eviction by prefix: trims the farthest resident tile (never `keep`) that
    /// holds more prefix levels than the view draws of it down to the levels it
    /// draws. Its kept bytes are decoded again up to that level's end and
    /// uploaded in place of the old copy (whose room is given back first); the
    /// bytes beyond are dropped, so the tile grows again by range from there.
    /// False when no tile holds more than the view draws.
    fn trim_one(&mut self, residency: &mut impl Residency, view: &ViewData, keep: Option<usize>) -> bool {
        let Some(thin) = self.prefix_view else { return false };
        let thin = PrefixView { canopy: self.canopy_band(), ..thin };
        let Some(m) = &self.manifest else { return false };
        let species_count = m.species.len() as u32;
        let eye = view.eye_hi + view.eye_lo;
        let mut victim: Option<(f32, usize, u32)> = None;
        for (i, state) in self.tiles.iter().enumerate() {
            let TileState::Resident { prefix, .. } = state else { continue };
            let Some(ends) = self.index.tiles[i].levels.as_ref().map(|l| &l.bytes) else { continue };
            // Only a tile whose bytes are all kept (a file with other levels than its entry lists is not).
            if Some(i) == keep
                || prefix.levels < 2
                || ends.get(prefix.levels as usize - 1) != Some(&(prefix.bytes.len() as u64))
            {
                continue;
            }
            // (Levels may end at the same byte: a trim must free some.)
            let want = batch_levels_wanted(view, &prefix.batches, &prefix.scheme, Some(thin));
            if want >= prefix.levels || ends[want as usize - 1] >= prefix.bytes.len() as u64 {
                continue;
            }
            let d = tile_distance(&self.index.tiles[i].bounds, eye);
            if victim.is_none_or(|(far, _, _)| d > far) {
                victim = Some((d, i, want));
            }
        }
        let Some((_, t, want)) = victim else { return false };
        let url = join(&self.base, &self.index.tiles[t].url);
        let end = self.index.tiles[t].levels.as_ref().map_or(0, |l| l.bytes[want as usize - 1]) as usize;
        let TileState::Resident { slot, prefix, .. } = &mut self.tiles[t] else { return false };
        residency.evict_tile(slot.clone());
        let trimmed = Tile::decode_prefix(&url, &prefix.bytes[..end], species_count).map_err(|e| e.to_string());
        match trimmed.and_then(|held| residency.upload_tile(&held.tile).map(|s| (held, s)).map_err(|e| e.to_string())) {
            Ok((held, new_slot)) => {
                *slot = new_slot;
                prefix.bytes.truncate(end);
                prefix.bytes.shrink_to_fit();
                prefix.levels = held.levels;
                prefix.runs = std::sync::Arc::new(held.runs());
                if prefix.more != Load::Broken {
                    prefix.more = Load::Idle;
                }
            }
            // Cannot happen (a prefix of bytes that decoded, into the room of a
            // bigger copy): the tile is fetched anew later.
            Err(message) => {
                self.events.push(StreamEvent::Failed { url, message, retrying: true });
                self.tiles[t] = TileState::NotResident(Load::Idle);
            }
        }
        self.stats.tiles_trimmed += 1;
        true
    }

    /// Requests index nodes and tiles of the view up to the draw distance; tiles
    /// only up to `reach_m` (shorter while the pools are full). Tiles beyond the
    /// reach stay wanted (their species' packs are needed, they are not evicted
    /// for farther ones) but are not fetched.
    fn request_tiles(&mut self, view: &ViewData, draw_distance_m: f32, now_s: f64) {
        if self.manifest.is_none() {
            return;
        }
        self.walk(view, draw_distance_m);
        self.pending_nodes = 0;
        let (wanted, nodes) = (std::mem::take(&mut self.walk_tiles), std::mem::take(&mut self.walk_nodes));
        // Index nodes first: they unlock the tiles below them.
        for &(_, n) in &nodes {
            let due = match self.node_loads[n] {
                Load::Idle => Some(0),
                Load::Waiting { attempt, retry_at_s } if now_s >= retry_at_s => Some(attempt),
                _ => None,
            };
            if self.node_loads[n] != Load::Broken {
                self.pending_nodes += 1;
            }
            if let Some(attempt) = due {
                if self.fetcher.in_flight() >= self.config.max_in_flight {
                    continue;
                }
                let id = self.fetcher.start(&join(&self.base, self.index.node_url(n)));
                self.stats.requests += 1;
                self.requests.insert(id, Target::Node(n));
                self.node_loads[n] = Load::Requested { attempt };
            }
        }
        let mut short = 0;
        let canopy = self.canopy_band();
        for &(_, i) in &wanted[..self.within_reach] {
            let entry = &self.index.tiles[i];
            let thin = self.prefix_view.map(|t| PrefixView { canopy, ..t });
            let room = self.fetcher.in_flight() < self.config.max_in_flight;
            match &mut self.tiles[i] {
                TileState::NotResident(load) => {
                    let attempt = match load {
                        Load::Idle => 0,
                        Load::Waiting { attempt, retry_at_s } if now_s >= *retry_at_s => *attempt,
                        _ => continue,
                    };
                    if !room {
                        continue;
                    }
                    // The prefix the view draws of a tile in levels (without levels: whole).
                    let range = entry.levels.as_ref().and_then(|l| {
                        let want = first_levels_wanted(view, &entry.bounds, &l.scheme(), thin);
                        (want < l.bytes.len() as u32).then(|| (0, l.bytes[want as usize - 1]))
                    });
                    let id = self.fetcher.start_range(&join(&self.base, &entry.url), range);
                    self.stats.requests += 1;
                    self.requests.insert(id, Target::Tile(i));
                    *load = Load::Requested { attempt };
                }
                TileState::Resident { prefix, .. } => {
                    let Some(ends) = entry.levels.as_ref().map(|l| &l.bytes) else { continue };
                    let have = prefix.levels as usize;
                    if have >= ends.len() {
                        continue;
                    }
                    let want = batch_levels_wanted(view, &prefix.batches, &prefix.scheme, thin) as usize;
                    // A file with other levels than its entry lists cannot be fetched on by range.
                    if want <= have
                        || prefix.more == Load::Broken
                        || ends.get(have - 1) != Some(&(prefix.bytes.len() as u64))
                    {
                        continue;
                    }
                    short += 1;
                    let attempt = match prefix.more {
                        Load::Idle => 0,
                        Load::Waiting { attempt, retry_at_s } if now_s >= retry_at_s => attempt,
                        _ => continue,
                    };
                    if !room {
                        continue;
                    }
                    let range = (ends[have - 1], ends[want.min(ends.len()) - 1]);
                    let id = self.fetcher.start_range(&join(&self.base, &entry.url), Some(range));
                    self.stats.requests += 1;
                    self.requests.insert(id, Target::TileMore(i, prefix.levels));
                    prefix.more = Load::Requested { attempt };
                }
            }
        }
        self.levels_short = short;
        (self.walk_tiles, self.walk_nodes) = (wanted, nodes);
    }

    /// Walks the index for the view into the reused buffers: `walk_tiles`,
    /// `walk_nodes`, `wanted` and `within_reach`.
    fn walk(&mut self, view: &ViewData, draw_distance_m: f32) {
        self.index.walk_into(
            view,
            draw_distance_m,
            self.canopy_gate.as_ref(),
            &mut self.walk_tiles,
            &mut self.walk_nodes,
            &mut self.walk_stack,
        );
        self.within_reach = self.walk_tiles.iter().take_while(|(d, _)| *d <= self.reach_m).count();
        self.wanted.clear();
        self.wanted.extend(self.walk_tiles.iter().map(|(_, i)| *i));
    }
}

fn tile_distance(b: &crate::format::Bounds, eye: Vec3) -> f32 {
    let lo = Vec3::from(b.min) - eye;
    let hi = Vec3::from(b.max) - eye;
    let (c, h) = ((lo + hi) * 0.5, (hi - lo) * 0.5);
    (c.abs() - h).max(Vec3::ZERO).length()
}

#[path = "stream_packs.rs"]
mod packs;

#[cfg(test)]
#[path = "streaming_tests.rs"]
mod tests;
