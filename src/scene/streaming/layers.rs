//! The quadtree layers of the stream: terrain tiles, their ground images and
//! the canopy rasters, each selected for the view, requested nearest first and
//! kept, retried or given up on through the one residency (`super::super::quadtree`).

use super::*;

/// Asks for the tiles a quadtree layer waits for, nearest first, within the
/// in-flight budget (the same for every layer: terrain, canopy rasters).
pub(super) fn request_layer<L: QuadLayer, F: Fetcher>(
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

impl<F: Fetcher> SceneStream<F> {
    /// Picks the canopy rasters the view draws and the ones it waits for, and
    /// the index walk's gate (where the canopy alone draws the trees).
    pub(super) fn select_canopy(&mut self, view: &ViewData) {
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
            if self.canopy_draws.len() <= crate::scene::canopy::MAX_CANOPY_DRAWS {
                break;
            }
            cell_px *= 2.0;
        }
        self.canopy_gate = tree.ready().then_some(CanopyGate { px_per_m, px_lo: cv.px_lo });
    }

    /// Where trees the view wants cannot be drawn yet, into `canopy_gaps`.
    pub(super) fn collect_canopy_gaps(&mut self) {
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
    pub(super) fn on_canopy(&mut self, key: CanopyKey, result: Result<Vec<u8>, FetchError>, now_s: f64) {
        let Some(tree) = &mut self.canopy else { return };
        if let Ok(bytes) = &result {
            self.stats.canopy_bytes_fetched += bytes.len() as u64;
        }
        let failed = layer_arrived(tree, &self.base, key, result, self.config.retry(), now_s);
        self.report(failed);
    }

    /// A failed file of a quadtree layer: given up on (listed) unless it is
    /// retried, and told as an event either way.
    pub(super) fn report(&mut self, failed: Option<(String, String, bool)>) {
        if let Some((url, message, retrying)) = failed {
            if !retrying {
                self.give_up(&url, &message);
            }
            self.events.push(StreamEvent::Failed { url, message, retrying });
        }
    }

    /// Requests the images the drawn terrain wants, within the in-flight budget.
    pub(super) fn request_imagery(&mut self) {
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
    pub(super) fn on_image(
        &mut self,
        generation: u32,
        key: TerrainKey,
        result: Result<Vec<u8>, FetchError>,
        now_s: f64,
    ) {
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
    pub(super) fn on_image_source(
        &mut self,
        generation: u32,
        tile: (u8, u32, u32),
        result: Result<Vec<u8>, FetchError>,
    ) {
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
    pub(super) fn select_terrain(&mut self, view: &ViewData) {
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
    pub(super) fn on_terrain(&mut self, key: TerrainKey, result: Result<Vec<u8>, FetchError>, now_s: f64) {
        let Some(t) = &mut self.terrain else { return };
        let failed = layer_arrived(t, &self.base, key, result, self.config.retry(), now_s);
        self.report(failed);
    }
}
