//! The quadtree layers (terrain, its ground images, the canopy rasters):
//! their keys (a tile is `(level, x, y)`, level 0 the root, its four children
//! at `level + 1`, `2x + i`, `2y + j`), one residency for all of them
//! ([`QuadResidency`]) and what the streamer needs of a layer ([`QuadLayer`]).

use std::collections::HashMap;
use std::sync::Arc;

/// A tile's key: (level, x, y).
pub type QuadKey = (u8, u32, u32);

/// The ancestor of `key` at `level` (≤ its own).
#[must_use]
pub fn ancestor(key: QuadKey, level: u8) -> QuadKey {
    let d = key.0 - level.min(key.0);
    (key.0 - d, key.1 >> d, key.2 >> d)
}

/// Where tile `inner` lies in the uv square of its ancestor `outer`.
#[must_use]
pub fn uv_in(outer: QuadKey, inner: QuadKey) -> [f32; 4] {
    let d = inner.0 - outer.0;
    let scale = 1.0 / f64::from(1u32 << d);
    let (ox, oy) = (inner.1 - (outer.1 << d), inner.2 - (outer.2 << d));
    [(f64::from(ox) * scale) as f32, (f64::from(oy) * scale) as f32, scale as f32, scale as f32]
}

/// How failed fetches are retried: `base_s · 2^(attempt − 1)` seconds after
/// each failure that a retry may mend, up to `max_attempts` attempts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RetryPolicy {
    /// Wait after the first failure (s).
    pub base_s: f64,
    /// Attempts in all before a tile is given up on.
    pub max_attempts: u32,
}

/// Where one tile of a layer stands.
#[derive(Debug)]
enum Slot<T> {
    /// Requested, or waiting for a retry (its attempts say which).
    Loading,
    /// Given up on: drawn as its parent (or its ancestor's data).
    Broken,
    /// Decoded and kept; `used` the last frame that used it.
    Resident { data: Arc<T>, used: u64 },
}

/// The residency of one quadtree layer (terrain tiles, their ground images,
/// canopy rasters): which tiles are resident, asked for, waiting for a retry
/// or given up on; the tiles a view waits for, nearest first; failed
/// attempts with exponential backoff; least-recently-used eviction beyond a
/// budget, never the root, never a tile used this frame, and of one frame the
/// finest first (a child before its parent: a tile is reached through its
/// ancestors). The layer's own type decides what a view selects and draws.
#[derive(Debug)]
pub struct QuadResidency<T> {
    slots: HashMap<QuadKey, Slot<T>>,
    /// Failed attempts per tile and when the next is due (∞: asked again or not retried).
    attempts: HashMap<QuadKey, (u32, f64)>,
    frame: u64,
    /// The tiles the view waits for, nearest first (distance, key), as the
    /// layer's selection writes them.
    pub wanted: Vec<(f32, QuadKey)>,
    /// Most tiles kept decoded.
    pub max_resident: usize,
}

impl<T> QuadResidency<T> {
    /// Nothing resident; at most `max_resident` tiles kept.
    #[must_use]
    pub fn new(max_resident: usize) -> Self {
        Self { slots: HashMap::new(), attempts: HashMap::new(), frame: 0, wanted: Vec::new(), max_resident }
    }

    /// Starts a frame: tiles used from now on are this frame's.
    pub fn next_frame(&mut self) {
        self.frame += 1;
    }

    /// Tiles decoded and kept.
    #[must_use]
    pub fn resident(&self) -> usize {
        self.slots.values().filter(|s| matches!(s, Slot::Resident { .. })).count()
    }

    /// The resident data of `key`.
    #[must_use]
    pub fn get(&self, key: QuadKey) -> Option<&Arc<T>> {
        match self.slots.get(&key) {
            Some(Slot::Resident { data, .. }) => Some(data),
            _ => None,
        }
    }

    /// The resident data of `key`, marked used this frame (kept from eviction).
    pub fn use_now(&mut self, key: QuadKey) -> Option<Arc<T>> {
        match self.slots.get_mut(&key) {
            Some(Slot::Resident { data, used }) => {
                *used = self.frame;
                Some(Arc::clone(data))
            }
            _ => None,
        }
    }

    /// Whether `key` is neither resident, asked for nor given up on (it may be asked for).
    #[must_use]
    pub fn is_unknown(&self, key: QuadKey) -> bool {
        !self.slots.contains_key(&key)
    }

    /// Whether `key` was given up on.
    #[must_use]
    pub fn is_broken(&self, key: QuadKey) -> bool {
        matches!(self.slots.get(&key), Some(Slot::Broken))
    }

    /// Whether `key` is resident or given up on: nothing more will come of it.
    #[must_use]
    pub fn is_done(&self, key: QuadKey) -> bool {
        matches!(self.slots.get(&key), Some(Slot::Resident { .. } | Slot::Broken))
    }

    /// Whether a failed attempt at `key` waits for its retry.
    #[must_use]
    pub fn waiting(&self, key: QuadKey) -> bool {
        self.attempts.get(&key).is_some_and(|(_, due)| due.is_finite())
    }

    /// Whether some failed attempt waits for its retry.
    #[must_use]
    pub fn retries_pending(&self) -> bool {
        self.attempts.values().any(|(_, due)| due.is_finite())
    }

    /// Whether the view waits for nothing of this layer: no tile wanted, no retry pending.
    #[must_use]
    pub fn settled(&self) -> bool {
        self.wanted.is_empty() && !self.retries_pending()
    }

    /// Whether an attempt at `key` has failed (and it was not yet kept).
    #[must_use]
    pub fn has_failed(&self, key: QuadKey) -> bool {
        self.attempts.contains_key(&key)
    }

    /// Marks `key` as asked for.
    pub fn mark_loading(&mut self, key: QuadKey) {
        self.slots.insert(key, Slot::Loading);
    }

    /// Gives up on `key`.
    pub fn mark_broken(&mut self, key: QuadKey) {
        self.slots.insert(key, Slot::Broken);
    }

    /// Forgets everything (a new source).
    pub fn clear(&mut self) {
        self.slots.clear();
        self.attempts.clear();
        self.wanted.clear();
    }

    /// Keeps the decoded `data` of `key` (its failed attempts forgotten) and
    /// evicts beyond the budget.
    pub fn insert(&mut self, key: QuadKey, data: T) {
        self.attempts.remove(&key);
        self.slots.insert(key, Slot::Resident { data: Arc::new(data), used: self.frame });
        self.evict();
    }

    /// Counts a failed attempt at `key`: retried after the backoff when
    /// `retryable` and attempts are left (it stays asked for until then),
    /// else given up on. Returns whether it is retried.
    pub fn failed(&mut self, key: QuadKey, retryable: bool, policy: RetryPolicy, now_s: f64) -> bool {
        let (n, due) = self.attempts.entry(key).or_insert((0, f64::INFINITY));
        *n += 1;
        let retrying = retryable && *n < policy.max_attempts;
        if retrying {
            *due = now_s + policy.base_s * 2f64.powi(*n as i32 - 1);
            self.slots.insert(key, Slot::Loading);
        } else {
            *due = f64::INFINITY;
            self.slots.insert(key, Slot::Broken);
        }
        retrying
    }

    /// Tiles whose retry is due may be asked for again.
    pub fn retry_due(&mut self, now_s: f64) {
        for (key, (_, due)) in &mut self.attempts {
            if *due <= now_s {
                self.slots.remove(key);
                *due = f64::INFINITY;
            }
        }
    }

    /// Drops the least recently used tiles beyond [`Self::max_resident`].
    fn evict(&mut self) {
        let resident = self.resident();
        if resident <= self.max_resident {
            return;
        }
        let mut old: Vec<(u64, QuadKey)> = self
            .slots
            .iter()
            .filter_map(|(k, s)| match s {
                Slot::Resident { used, .. } if k.0 > 0 && *used < self.frame => Some((*used, *k)),
                _ => None,
            })
            .collect();
        old.sort_unstable_by_key(|&(used, k)| (used, std::cmp::Reverse(k.0), k.1, k.2));
        for (_, k) in old.into_iter().take(resident - self.max_resident) {
            self.slots.remove(&k);
        }
    }
}

/// A quadtree layer the streamer fetches: where its tiles are and how one
/// is decoded, checked against the key it was asked for, and kept. The
/// streamer's requests (nearest first, within the in-flight budget) and
/// arrivals (kept, retried with backoff, or given up on) are written once
/// for every layer (`SceneStream`'s `request_layer` and `layer_arrived`).
pub trait QuadLayer {
    /// The decoded tile.
    type Tile;
    /// The layer's residency.
    fn residency(&self) -> &QuadResidency<Self::Tile>;
    /// The layer's residency, to change.
    fn residency_mut(&mut self) -> &mut QuadResidency<Self::Tile>;
    /// The tile's file, relative to the scene.
    fn url(&self, key: QuadKey) -> String;
    /// Decodes the bytes fetched for `key` (from `url`) and checks they are that tile.
    ///
    /// # Errors
    /// Bytes that are no such tile, or another tile's (the message names `url`).
    fn decode(&self, url: &str, key: QuadKey, bytes: &[u8]) -> Result<Self::Tile, String>;
}

#[cfg(test)]
mod tests {
    use super::*;

    const POLICY: RetryPolicy = RetryPolicy { base_s: 0.5, max_attempts: 3 };

    #[test]
    fn eviction_drops_the_least_recently_used_finest_first_never_the_root_or_this_frame() {
        let mut r = QuadResidency::new(3);
        r.insert((0, 0, 0), "root");
        r.next_frame();
        r.insert((1, 0, 0), "a");
        r.insert((2, 0, 0), "a's child");
        r.next_frame();
        // Over the budget: of the oldest frame's, the finest goes first.
        r.insert((1, 1, 0), "b");
        assert_eq!(r.resident(), 3);
        assert!(r.get((2, 0, 0)).is_none(), "the child before its parent");
        assert!(r.get((1, 0, 0)).is_some() && r.get((0, 0, 0)).is_some());
        // A tile used this frame is kept, the root always.
        r.use_now((1, 0, 0));
        r.insert((1, 0, 1), "c");
        assert_eq!(r.resident(), 4, "nothing older than this frame but the root");
        r.next_frame();
        r.insert((1, 1, 1), "d");
        assert_eq!(r.resident(), 3);
        assert!(r.get((0, 0, 0)).is_some());
    }

    #[test]
    fn failures_are_retried_with_backoff_then_given_up_on() {
        let mut r: QuadResidency<u8> = QuadResidency::new(8);
        let k = (1, 0, 1);
        r.mark_loading(k);
        assert!(r.failed(k, true, POLICY, 10.0));
        assert!(r.waiting(k) && r.retries_pending() && !r.is_unknown(k), "waits, still asked for");
        r.retry_due(10.4);
        assert!(!r.is_unknown(k), "not before 0.5 s");
        r.retry_due(10.5);
        assert!(r.is_unknown(k) && !r.waiting(k), "asked again");
        r.mark_loading(k);
        assert!(r.failed(k, true, POLICY, 11.0));
        r.retry_due(11.9);
        assert!(!r.is_unknown(k), "the second wait is 1 s");
        r.retry_due(12.0);
        r.mark_loading(k);
        assert!(!r.failed(k, true, POLICY, 13.0), "three attempts in all");
        assert!(r.is_broken(k) && r.is_done(k) && !r.retries_pending());
        // What a retry cannot mend is given up on at once; a kept tile forgets its failures.
        let j = (1, 1, 1);
        assert!(!r.failed(j, false, POLICY, 0.0));
        assert!(r.is_broken(j));
        let m = (2, 3, 3);
        assert!(r.failed(m, true, POLICY, 0.0));
        r.insert(m, 7);
        assert!(!r.has_failed(m) && r.is_done(m) && r.get(m) == Some(&Arc::new(7)));
    }
}
