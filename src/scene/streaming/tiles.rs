//! Tiles and index nodes: the walk of the index for the view, tiles requested
//! nearest first (whole, or the prefix levels a far view draws), arrivals
//! decoded and made resident, eviction and trimming when the pools fill.

use super::*;

/// The first guess of the prefix levels (of `levels.count`, 1..=count) a
/// view drawing with `thin` needs of a tile, before its batches are known:
/// the thinned fraction (`thinning` in `shaders/select.wgsl`) of its tallest
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
/// hold what every batch in view keeps (`thinning` in `shaders/select.wgsl`:
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

pub(super) fn tile_distance(b: &crate::format::Bounds, eye: Vec3) -> f32 {
    let lo = Vec3::from(b.min) - eye;
    let hi = Vec3::from(b.max) - eye;
    let (c, h) = ((lo + hi) * 0.5, (hi - lo) * 0.5);
    (c.abs() - h).max(Vec3::ZERO).length()
}

impl<F: Fetcher> SceneStream<F> {
    pub(super) fn on_node(&mut self, n: usize, result: Result<Vec<u8>, FetchError>, now_s: f64) {
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

    pub(super) fn on_tile(
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
                let prefix = Box::new(Prefix::held(&held, if keep_bytes { bytes } else { Vec::new() }));
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
    pub(super) fn on_tile_more(
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
                **prefix = Prefix::held(&held, if keep_bytes { bytes } else { Vec::new() });
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
    pub(super) fn shorten_reach(&mut self, t: usize, url: String, what: &str, view: &ViewData) {
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
    pub(super) fn evict_one(
        &mut self,
        residency: &mut impl Residency,
        view: &ViewData,
        keep: Option<usize>,
        trim: bool,
    ) -> bool {
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
    pub(super) fn trim_one(&mut self, residency: &mut impl Residency, view: &ViewData, keep: Option<usize>) -> bool {
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
    pub(super) fn request_tiles(&mut self, view: &ViewData, draw_distance_m: f32, now_s: f64) {
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
    pub(super) fn walk(&mut self, view: &ViewData, draw_distance_m: f32) {
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
