//! Species packs in the stream: a pack is fetched whole, or as a head (header,
//! section table, metadata) and then by byte range only the parts the view
//! needs ([`PackPart`]: the far tier drawn (billboards or impostors), clusters,
//! coarse meshes, the full mesh, a deciduous species' bare far tier in
//! leaf-off), within the GPU budget. A stored pack's part comes deflated and
//! is inflated off the frame ([`crate::scene::Fetcher::start_inflate`]). Part
//! of [`super::SceneStream`]'s update.

use super::{join, Load, SceneStream, Target};
use crate::format::decode_pack;
use crate::format::pack::{PackHead, PackPart, FAR_PARTS, PACK_PARTS};
use crate::format::stored::unstore;
use crate::scene::fetch::{FetchError, Fetcher};
use crate::scene::residency::Residency;

/// A species pack, fetched whole or as a head and then the parts views need.
pub(super) struct PackLoad {
    /// The head (or the whole pack).
    head: Load,
    /// The decoded head, once fetched.
    parsed: Option<PackHead>,
    /// Per part ([`PackPart::ALL`] order).
    parts: [Load; PACK_PARTS],
    /// Parts held: (file offset, bytes).
    held: Vec<(u64, Vec<u8>)>,
    have: [bool; PACK_PARTS],
    /// The parts the view wanted at the last update.
    wants: [bool; PACK_PARTS],
    /// Parts held back by the GPU budget at the last update.
    blocked: [bool; PACK_PARTS],
    /// The whole pack is uploaded: nothing more to fetch.
    whole: bool,
    /// The encodings whose variant failed for good (missing, corrupt, in
    /// blocks the device does not sample): the next the device samples, or
    /// the plain pack, instead.
    pub(super) failed: Vec<crate::format::pack::TexelEncoding>,
}

impl PackLoad {
    pub(super) fn new() -> Self {
        Self {
            head: Load::Idle,
            parsed: None,
            parts: std::array::from_fn(|_| Load::Idle),
            held: Vec::new(),
            have: [false; PACK_PARTS],
            wants: [false; PACK_PARTS],
            blocked: [false; PACK_PARTS],
            whole: false,
            failed: Vec::new(),
        }
    }

    /// Nothing more the view wants of it is due.
    pub(super) fn done(&self) -> bool {
        if self.whole || self.head == Load::Broken {
            return true;
        }
        let Some(head) = &self.parsed else { return false };
        PackPart::ALL.iter().enumerate().all(|(i, p)| {
            !self.wants[i]
                || self.have[i]
                || self.blocked[i]
                || self.parts[i] == Load::Broken
                || head.part_range(*p).is_none()
        })
    }
}

/// Whether any of a pack's load is on the GPU.
fn load_drawn(load: &PackLoad) -> bool {
    load.whole || load.have.contains(&true)
}

/// Refuses a pack whose textures are in a block encoding the device does not
/// sample (a plain pack that is not plain, a variant listed under another
/// name, a file changed on the server): it could not be uploaded.
fn sampled(
    url: &str,
    meta: &crate::format::pack::PackMeta,
    encodings: &[crate::format::pack::TexelEncoding],
) -> Result<(), (String, bool)> {
    match meta.unsampled(encodings) {
        Some(e) => Err((format!("{url}: its textures are {} blocks, which this GPU does not sample", e.name()), false)),
        None => Ok(()),
    }
}

impl<F: Fetcher> SceneStream<F> {
    pub(super) fn on_pack_head(
        &mut self,
        residency: &mut impl Residency,
        s: usize,
        result: Result<Vec<u8>, FetchError>,
        now_s: f64,
    ) {
        let Some(m) = &self.manifest else { return };
        let entry = Self::pack_choice(m, &self.encodings_for(s), s);
        let variant = entry.encoding;
        let url = join(&self.base, entry.pack);
        let attempt = self.packs[s].head.attempt();
        let pack_bytes = entry.bytes;
        let ranged = entry.head_bytes.is_some();
        let encodings = &self.texture_encodings;
        let sampled = |meta: &crate::format::pack::PackMeta| sampled(&url, meta, encodings);
        let outcome = result.map_err(|e| (e.to_string(), e.retryable())).and_then(|bytes| {
            // No head size in the manifest, or a server that ignores ranges: the whole pack.
            if !ranged || bytes.len() as u64 == pack_bytes && pack_bytes > entry.head_bytes.unwrap_or(0) {
                // (A stored pack that does not inflate whole will not next time either.)
                let bytes = unstore(&url, bytes).map_err(|e| (e.to_string(), false))?;
                let pack = decode_pack(&url, &bytes).map_err(|e| (e.to_string(), true))?;
                sampled(&pack.meta)?;
                residency.upload_pack(s as u32, &pack);
                Ok(None)
            } else {
                let head = PackHead::decode(&url, &bytes).map_err(|e| (e.to_string(), true))?;
                sampled(&head.meta)?;
                Ok(Some(head))
            }
        });
        let load = &mut self.packs[s];
        match outcome {
            Ok(None) => {
                load.head = Load::Idle;
                load.whole = true;
            }
            Ok(Some(head)) => {
                load.head = Load::Idle;
                load.parsed = Some(head);
            }
            Err((message, retryable)) => {
                let given_up = self.fail(url.clone(), &message, attempt, retryable, now_s);
                if let (Some(e), Load::Broken) = (variant, &given_up) {
                    self.give_up_variant(s, e, &url);
                } else {
                    self.packs[s].head = given_up;
                }
            }
        }
    }

    /// A part's bytes: as fetched (`inflated` false; a stored pack's block
    /// then goes on to be inflated) or inflated.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn on_pack_part(
        &mut self,
        residency: &mut impl Residency,
        s: usize,
        part: usize,
        result: Result<Vec<u8>, FetchError>,
        inflated: bool,
        now_s: f64,
    ) {
        let Some(m) = &self.manifest else { return };
        let choice = Self::pack_choice(m, &self.encodings_for(s), s);
        let url = join(&self.base, choice.pack);
        let file_bytes = choice.bytes;
        let variant = choice.encoding;
        let encodings = &self.texture_encodings;
        let load = &mut self.packs[s];
        let attempt = load.parts[part].attempt();
        let Some(head) = &load.parsed else { return };
        let Some((start, end)) = head.part_range(PackPart::ALL[part]) else { return };
        let Some(fetch) = head.fetch_of(PackPart::ALL[part]) else { return };
        let mut inflate = None;
        let outcome = result.map_err(|e| (e.to_string(), e.retryable())).and_then(|bytes| {
            let len = bytes.len() as u64;
            let (a, b) = fetch.range;
            if !inflated && len == file_bytes && len != b - a {
                // The server sent the whole file instead of the range.
                let bytes = unstore(&url, bytes).map_err(|e| (e.to_string(), false))?;
                let pack = decode_pack(&url, &bytes).map_err(|e| (e.to_string(), true))?;
                sampled(&url, &pack.meta, encodings)?;
                residency.upload_pack(s as u32, &pack);
                return Ok(true);
            }
            let expected = if inflated { end - start } else { b - a };
            if len != expected {
                return Err((format!("{url}: asked for bytes {a}..{b}, got {len} bytes"), true));
            }
            if let (false, Some(n)) = (inflated, fetch.inflated) {
                inflate = Some((bytes, n));
                return Ok(false);
            }
            load.held.push((start, bytes));
            match head.assemble(&url, &load.held) {
                Ok(pack) => {
                    residency.upload_pack(s as u32, &pack);
                    Ok(false)
                }
                Err(e) => {
                    load.held.pop();
                    Err((e.to_string(), true))
                }
            }
        });
        if let (Some((deflated, n)), Ok(_)) = (inflate, &outcome) {
            // Still requested until inflated.
            let id = self.fetcher.start_inflate(&url, deflated, n);
            self.requests.insert(id, Target::PackInflate(s, part));
            return;
        }
        match outcome {
            Ok(whole) => {
                load.parts[part] = Load::Idle;
                load.have[part] = true;
                load.whole |= whole;
                let held_or_absent = |h: &PackHead, i: usize| load.have[i] || h.part_range(PackPart::ALL[i]).is_none();
                // Every part on the GPU: nothing more to fetch.
                let complete = load.parsed.as_ref().is_some_and(|h| (0..PACK_PARTS).all(|i| held_or_absent(h, i)));
                // A far tier and every finer part: the CPU copies kept for
                // re-assembly can go (another far tier, should it come, uploads
                // alone and joins what is on the GPU: `Species::upload_pack`).
                let all_but_a_far_state = load.parsed.as_ref().is_some_and(|h| {
                    let far =
                        FAR_PARTS.iter().any(|&i| load.have[i]) || FAR_PARTS.iter().all(|&i| held_or_absent(h, i));
                    far && (0..PACK_PARTS).filter(|i| !PackPart::ALL[*i].is_far()).all(|i| held_or_absent(h, i))
                });
                load.whole |= complete;
                if load.whole || all_but_a_far_state {
                    load.held = Vec::new();
                }
            }
            Err((message, retryable)) => {
                let given_up = self.fail(url.clone(), &message, attempt, retryable, now_s);
                let nothing_drawn = !load_drawn(&self.packs[s]);
                match (variant, &given_up) {
                    // A variant's part broken before any of it is on the GPU:
                    // the species starts again from the next pack.
                    (Some(e), Load::Broken) if nothing_drawn => self.give_up_variant(s, e, &url),
                    _ => self.packs[s].parts[part] = given_up,
                }
            }
        }
    }

    /// Species `s`'s variant in encoding `e` (at `url`) failed for good: the
    /// species starts again from the next pack the device samples, or the
    /// plain one, so the image lacks nothing (the event said what failed; it
    /// is not counted among the broken files).
    fn give_up_variant(&mut self, s: usize, e: crate::format::pack::TexelEncoding, url: &str) {
        let failed = std::mem::take(&mut self.packs[s].failed);
        self.packs[s] = PackLoad::new();
        self.packs[s].failed = failed;
        self.packs[s].failed.push(e);
        // Whatever of the variant is still on its way is dropped when it comes.
        self.requests.retain(
            |_, t| !matches!(t, Target::PackHead(x) | Target::PackPart(x, _) | Target::PackInflate(x, _) if *x == s),
        );
        self.failures.retain(|f| f.url != url);
        self.stats.broken = self.stats.broken.saturating_sub(1);
    }

    /// Whether trees of species `s` can be drawn (its billboards, or the whole
    /// pack, are on the GPU; for a view without a far tier, any part it wants)
    /// and, if not, whether they may still come (not
    /// given up on).
    pub(super) fn species_drawable(&self, s: usize) -> (bool, bool) {
        // The far parts: either tier, leaf-on or bare. Any far tier draws
        // (`Species` draws the other where the wanted one is missing; leaf-off
        // draws the leafy one's wood).
        let far_wanted = |l: &PackLoad| FAR_PARTS.iter().any(|&i| l.wants[i]);
        match self.packs.get(s) {
            Some(l) if l.whole || FAR_PARTS.iter().any(|&i| l.have[i]) => (true, false),
            // A view that draws no far tier (meshes only): drawable with the
            // parts it wants that have come.
            Some(l) if !far_wanted(l) && l.wants.iter().zip(&l.have).any(|(w, h)| *w && *h) => (true, false),
            // Not yet: it may come while its head and a part the view wants
            // (a far tier, or else any) are not given up on.
            Some(l) if l.wants.contains(&true) => {
                let coming = if far_wanted(l) {
                    FAR_PARTS.iter().any(|&i| l.wants[i] && l.parts[i] != Load::Broken)
                } else {
                    l.wants.iter().zip(&l.parts).any(|(w, p)| *w && *p != Load::Broken)
                };
                (false, l.head != Load::Broken && coming)
            }
            // (Only the far parts the pack has: an evergreen has no bare ones.)
            Some(l) => {
                let has = |i: usize| l.parsed.as_ref().is_none_or(|h| h.part_range(PackPart::ALL[i]).is_some());
                (false, l.head != Load::Broken && FAR_PARTS.iter().any(|&i| has(i) && l.parts[i] != Load::Broken))
            }
            None => (false, false),
        }
    }

    pub(super) fn request_packs(&mut self, residency: &impl Residency, now_s: f64) {
        self.collect_needed_species();
        let needed = std::mem::take(&mut self.needed);
        let mut over_budget = false;
        // What each needed species' view wants, from its head.
        for &s in &needed {
            let load = &mut self.packs[s];
            let Some(head) = &load.parsed else { continue };
            let asked = residency.parts_needed(s, &head.meta);
            let mut wants = asked;
            let usable = |j: usize| head.part_range(PackPart::ALL[j]).is_some() && load.parts[j] != Load::Broken;
            // The bare state where asked for and the pack has it (and it is not
            // given up on); else its leafy one (drawn without its leaf texels in
            // leaf-off).
            for i in FAR_PARTS.into_iter().filter(|&i| PackPart::ALL[i].is_bare()) {
                let leafy = PackPart::ALL[i].other_state().map_or(i, PackPart::index);
                if wants[i] && !usable(i) {
                    (wants[i], wants[leafy]) = (false, true);
                }
            }
            // A far tier the pack lacks or that was given up on: another one.
            let far = |w: &[bool; PACK_PARTS]| FAR_PARTS.iter().any(|&i| w[i] && usable(i));
            if FAR_PARTS.iter().any(|&i| asked[i]) && !far(&wants) {
                for i in FAR_PARTS {
                    wants[i] = false;
                }
                // (The season asked for first: bare billboards before leafy impostors in leaf-off.)
                let bare_asked = FAR_PARTS.iter().any(|&i| asked[i] && PackPart::ALL[i].is_bare());
                let mut order = FAR_PARTS;
                order.sort_by_key(|&j| PackPart::ALL[j].is_bare() != bare_asked);
                if let Some(&j) = order.iter().find(|&&j| usable(j)) {
                    wants[j] = true;
                }
            }
            load.wants = wants;
        }
        // GPU bytes held plus parts on their way.
        let mut committed = residency.bytes();
        for (s, load) in self.packs.iter().enumerate() {
            let Some(head) = &load.parsed else { continue };
            for (i, part) in PackPart::ALL.iter().enumerate() {
                // Far tiers of needed species are fetched whatever the budget:
                // reserve them before anything finer.
                let due_far = part.is_far() && load.wants[i] && !load.have[i] && needed.contains(&s);
                if matches!(load.parts[i], Load::Requested { .. }) || due_far {
                    committed += head.part_bytes(*part);
                }
            }
        }
        // Far tiers are reserved only once a head tells their size: finer parts
        // wait until every needed species' head is known, or a late head's
        // far tier would push the total over the budget.
        let heads_pending = self.config.gpu_budget_bytes > 0
            && needed.iter().any(|&s| {
                let l = &self.packs[s];
                l.parsed.is_none() && !l.whole && l.head != Load::Broken
            });
        let Some(m) = &self.manifest else { return };
        let due = |l: &Load| match *l {
            Load::Idle => Some(0),
            Load::Waiting { attempt, retry_at_s } if now_s >= retry_at_s => Some(attempt),
            _ => None,
        };
        for &s in &needed {
            let choice = Self::pack_choice(m, &self.encodings_for(s), s);
            let load = &mut self.packs[s];
            if load.whole || self.fetcher.in_flight() >= self.config.max_in_flight {
                continue;
            }
            let url = || join(&self.base, choice.pack);
            let Some(head) = &load.parsed else {
                if let Some(attempt) = due(&load.head) {
                    let range = choice.head_bytes.map(|h| (0, h));
                    let id = self.fetcher.start_range(&url(), range);
                    self.stats.requests += 1;
                    self.requests.insert(id, Target::PackHead(s));
                    load.head = Load::Requested { attempt };
                }
                continue;
            };
            for i in PackPart::FETCH_ORDER {
                let part = &PackPart::ALL[i];
                if !load.wants[i] || load.have[i] || self.fetcher.in_flight() >= self.config.max_in_flight {
                    continue;
                }
                if heads_pending && !part.is_far() {
                    continue;
                }
                let (Some(fetch), Some(attempt)) = (head.fetch_of(*part), due(&load.parts[i])) else { continue };
                // The GPU budget: finer parts wait (trees draw with coarser ones);
                // the far field is always fetched.
                let budget = self.config.gpu_budget_bytes;
                let gpu_bytes = head.part_bytes(*part);
                let blocked = budget > 0 && !part.is_far() && committed + gpu_bytes > budget;
                load.blocked[i] = blocked;
                if blocked {
                    over_budget = true;
                    continue;
                }
                let id = self.fetcher.start_range(&url(), Some(fetch.range));
                if !part.is_far() {
                    committed += gpu_bytes; // far tiers are reserved above
                }
                self.stats.requests += 1;
                self.requests.insert(id, Target::PackPart(s, i));
                load.parts[i] = Load::Requested { attempt };
            }
        }
        self.stats.degraded.gpu_budget = over_budget;
        self.needed = needed;
    }
}
