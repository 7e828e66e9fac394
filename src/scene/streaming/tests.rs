//! The streamer without a GPU: the committed test scene (`tests/fixtures/forest-small`:
//! 16 tiles under a two-level index, three species packs with heads) served by a
//! fake fetcher that can hold requests back or fail them, into a fake residency
//! with a small instance capacity.

use std::collections::{HashMap, VecDeque};

use glam::DVec3;

use super::tiles::tile_distance;
use super::*;
use crate::camera::Camera;
use crate::format::pack::{PackHead, PackPart, PACK_PARTS};
use crate::scene::fetch::ByteRange;
use crate::scene::imagery::ImageryChoice;
use crate::scene::index_walk::tile_wanted;

fn fixture() -> String {
    concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/forest-small").to_string()
}

/// The heads of the fixture's packs: spruce, beech, birch.
fn fixture_heads() -> Vec<PackHead> {
    ["spruce", "beech", "birch"]
        .iter()
        .map(|n| PackHead::decode(n, &std::fs::read(format!("{}/species/{n}.pack", fixture())).unwrap()).unwrap())
        .collect()
}

/// The byte ranges fetched after a pack's head, from the `from`th request on: (url, range).
fn part_fetches(s: &SceneStream<FakeFetcher>, from: usize) -> Vec<(String, ByteRange)> {
    s.fetcher.log[from..].iter().filter_map(|(u, r)| r.filter(|r| r.0 > 0).map(|r| (u.clone(), r))).collect()
}

/// Serves files from disk; requests can be held back and failures scripted per
/// URL ending.
#[derive(Default)]
struct FakeFetcher {
    /// Started and not yet answered.
    queue: VecDeque<(RequestId, String, Option<ByteRange>)>,
    /// Inflations started and not yet answered (inflated at once).
    inflating: Vec<(RequestId, Result<Vec<u8>, FetchError>)>,
    /// Every request started, in order: (url, range).
    log: Vec<(String, Option<ByteRange>)>,
    /// While true, nothing is answered.
    hold: bool,
    /// Failures to answer with, in order, for URLs ending with `/` + the key.
    fail: HashMap<String, VecDeque<FetchError>>,
    /// Bytes served instead of the file, for URLs ending with `/` + the key.
    replace: HashMap<String, Vec<u8>>,
    next: RequestId,
}

impl Fetcher for FakeFetcher {
    fn start_range(&mut self, url: &str, range: Option<ByteRange>) -> RequestId {
        self.next += 1;
        self.queue.push_back((self.next, url.to_string(), range));
        self.log.push((url.to_string(), range));
        self.next
    }

    fn start_inflate(&mut self, url: &str, deflated: Vec<u8>, bytes: u64) -> RequestId {
        self.next += 1;
        let result = crate::format::stored::inflate_exact(&deflated, bytes)
            .map_err(|message| FetchError::Transport { url: url.into(), message });
        self.inflating.push((self.next, result));
        self.next
    }

    fn poll(&mut self) -> Vec<(RequestId, Result<Vec<u8>, FetchError>)> {
        if self.hold {
            return Vec::new();
        }
        let answers: Vec<_> = self.queue.drain(..).collect();
        let mut out = std::mem::take(&mut self.inflating);
        out.extend(self.answer(answers));
        out
    }

    fn in_flight(&self) -> usize {
        self.queue.len() + self.inflating.len()
    }
}

impl FakeFetcher {
    fn answer(
        &mut self,
        answers: Vec<(RequestId, String, Option<ByteRange>)>,
    ) -> Vec<(RequestId, Result<Vec<u8>, FetchError>)> {
        answers
            .into_iter()
            .map(|(id, url, range)| {
                let named = |k: &String| url.ends_with(&format!("/{k}"));
                let scripted = self.fail.iter_mut().find(|(k, _)| named(k)).and_then(|(_, f)| f.pop_front());
                if let Some(e) = scripted {
                    return (id, Err(e));
                }
                let bytes = match self.replace.iter().find(|(k, _)| named(k)) {
                    Some((_, b)) => Ok(b.clone()),
                    None => std::fs::read(&url).map_err(|_| FetchError::NotFound { url: url.clone() }),
                };
                let sliced = bytes.map(|b| match range {
                    Some((a, e)) => b[a as usize..(e as usize).min(b.len())].to_vec(),
                    None => b,
                });
                (id, sliced)
            })
            .collect()
    }
}

/// Holds up to `capacity` instances; records uploads, evictions and packs.
struct FakeResidency {
    /// The pack parts it asks for (every one a leaf-on view can by default).
    parts: [bool; PACK_PARTS],
    capacity: u32,
    used: u32,
    next: u32,
    species: u32,
    /// Resident tiles: slot start → (tile x, y).
    tiles: HashMap<u32, (i32, i32)>,
    evicted: Vec<(i32, i32)>,
    /// Uploads: (species, bytes of the pack as uploaded).
    packs: Vec<(u32, u64)>,
    pack_bytes: u64,
}

impl FakeResidency {
    fn new(capacity: u32) -> Self {
        Self {
            // Every part of a leaf-on view whose far tier is impostors (the default).
            parts: PackPart::ALL
                .map(|p| !matches!(p, PackPart::Billboards | PackPart::BareBillboards | PackPart::BareImpostors)),
            capacity,
            used: 0,
            next: 0,
            species: 0,
            tiles: HashMap::new(),
            evicted: Vec::new(),
            packs: Vec::new(),
            pack_bytes: 0,
        }
    }
}

impl Residency for FakeResidency {
    fn species_capacity(&self) -> u32 {
        8
    }
    fn begin_scene(&mut self, _trees: u64, _batches: u64, species: u32) {
        self.species = species;
    }
    fn upload_tile(&mut self, tile: &Tile) -> Result<TileSlot, PoolError> {
        let n = tile.instances.len() as u32;
        if self.used + n > self.capacity {
            return Err(PoolError::Full("instances"));
        }
        self.used += n;
        let start = self.next;
        self.next += n.max(1);
        self.tiles.insert(start, (tile.tile_x, tile.tile_y));
        let mut species_counts: Vec<(u32, u32)> = Vec::new();
        for b in &tile.batches {
            match species_counts.iter_mut().find(|(s, _)| *s == b.species) {
                Some(c) => c.1 += b.instance_count,
                None => species_counts.push((b.species, b.instance_count)),
            }
        }
        Ok(TileSlot { batches: start..start + 1, instances: start..start + n, species_counts })
    }
    fn evict_tile(&mut self, slot: TileSlot) {
        self.used -= slot.instances.len() as u32;
        let xy = self.tiles.remove(&slot.batches.start).expect("a resident tile");
        self.evicted.push(xy);
    }
    fn upload_pack(&mut self, species: u32, pack: &crate::format::Pack<'_>) {
        // A pack grows part by part: what is held is its latest upload.
        let bytes = pack.sections.iter().map(|(e, _)| e.bytes).sum::<u64>();
        self.packs.push((species, bytes));
        self.pack_bytes =
            (0..self.species).filter_map(|s| self.packs.iter().rev().find(|p| p.0 == s).map(|p| p.1)).sum();
    }
    fn parts_needed(&self, _species: usize, _meta: &crate::format::PackMeta) -> [bool; PACK_PARTS] {
        self.parts
    }
    fn instance_room(&self) -> (u32, u32) {
        (self.capacity - self.used, self.capacity)
    }
    fn bytes(&self) -> u64 {
        self.pack_bytes
    }
    fn limited_by_device(&self) -> bool {
        false
    }
}

const W: u32 = 640;
const H: u32 = 360;

/// From the south edge, looking north over the forest.
fn south_view() -> ViewData {
    Camera::look_at(DVec3::new(0.0, -420.0, 140.0), DVec3::new(0.0, 0.0, 20.0)).view_data(W, H)
}

fn stream(config: StreamConfig) -> SceneStream<FakeFetcher> {
    SceneStream::new(&fixture(), FakeFetcher::default(), config)
}

/// Runs `steps` updates `dt_s` apart from `t0`; returns the time after.
fn run(
    s: &mut SceneStream<FakeFetcher>,
    r: &mut FakeResidency,
    view: &ViewData,
    dd: f32,
    t0: f64,
    dt_s: f64,
    steps: usize,
) -> f64 {
    let mut t = t0;
    for _ in 0..steps {
        s.update(r, view, dd, t);
        t += dt_s;
    }
    t
}

fn tile_urls(f: &FakeFetcher) -> Vec<String> {
    f.log.iter().filter(|(u, _)| u.ends_with(".tile")).map(|(u, _)| u.clone()).collect()
}

fn eye(view: &ViewData) -> Vec3 {
    view.eye_hi + view.eye_lo
}

/// Distance from the eye of the tile whose URL is `url`.
fn distance(s: &SceneStream<FakeFetcher>, url: &str, eye: Vec3) -> f32 {
    let t = s.index.tiles.iter().find(|t| url.ends_with(&t.url)).expect("a known tile");
    tile_distance(&t.bounds, eye)
}

#[test]
fn loads_the_index_first_then_tiles_nearest_first_within_the_in_flight_bound() {
    let config = StreamConfig { max_in_flight: 2, ..StreamConfig::default() };
    let (mut s, mut r) = (stream(config), FakeResidency::new(1 << 20));
    let view = south_view();
    let mut most = 0;
    let mut t = 0.0;
    // Answer one step in two: requests pile up against the bound in between.
    for step in 0..400 {
        s.fetcher.hold = step % 2 == 1;
        s.update(&mut r, &view, 6000.0, t);
        most = most.max(s.fetcher.in_flight());
        assert!(s.fetcher.in_flight() <= 2, "step {step}: {} requests in flight", s.fetcher.in_flight());
        t += 0.01;
        if s.is_settled() {
            break;
        }
    }
    assert!(s.is_settled(), "the stream settles");
    assert_eq!(most, 2, "the bound is reached (the test would prove nothing otherwise)");
    let urls: Vec<&str> = s.fetcher.log.iter().map(|(u, _)| u.as_str()).collect();
    assert!(urls[0].ends_with("scene.json") && urls[1].ends_with("index/r.json"), "{urls:?}");
    let first_tile = urls.iter().position(|u| u.ends_with(".tile")).unwrap();
    assert!(urls[..first_tile].iter().filter(|u| u.contains("/index/r")).count() >= 2, "a node before its tiles");
    // Every tile once, all resident; tiles requested nearest first within each node's batch.
    let tiles = tile_urls(&s.fetcher);
    assert_eq!(tiles.len(), 16, "{tiles:?}");
    assert_eq!(r.tiles.len(), 16);
    assert_eq!(s.stats().index_nodes_loaded, 5);
    let e = eye(&view);
    let d: Vec<f32> = tiles.iter().map(|u| distance(&s, u, e)).collect();
    // The first tile asked for is the nearest of the scene.
    let nearest = s.index.tiles.iter().map(|t| tile_distance(&t.bounds, e)).fold(f32::MAX, f32::min);
    assert_eq!(d[0], nearest, "distances in request order: {d:?}");
    // Packs: heads by range first, then parts; every species uploaded.
    let heads = s.fetcher.log.iter().filter(|(u, r)| u.ends_with(".pack") && r.is_some_and(|r| r.0 == 0)).count();
    assert_eq!(heads, 3);
    let mut species: Vec<u32> = r.packs.iter().map(|p| p.0).collect();
    species.dedup();
    species.sort_unstable();
    species.dedup();
    assert_eq!(species, vec![0, 1, 2]);
}

#[test]
fn a_view_of_one_corner_reads_part_of_the_index() {
    let (mut s, mut r) = (stream(StreamConfig::default()), FakeResidency::new(1 << 20));
    // Straight down over the south-west quadrant, short draw distance.
    let view = Camera { eye_m: DVec3::new(-120.0, -120.0, 60.0), pitch_rad: -1.5, ..Camera::default() }.view_data(W, H);
    run(&mut s, &mut r, &view, 90.0, 0.0, 0.01, 100);
    assert!(s.is_settled());
    let loaded = s.stats().index_nodes_loaded;
    assert!((2..5).contains(&loaded), "{loaded} of 5 nodes read");
    let tiles = tile_urls(&s.fetcher);
    assert!(!tiles.is_empty() && tiles.len() < 16, "{tiles:?}");
}

#[test]
fn retries_with_backoff_and_gives_up_on_not_found() {
    let view = south_view();
    // Learn which tiles are asked for first, then script their failures.
    let mut probe = stream(StreamConfig::default());
    run(&mut probe, &mut FakeResidency::new(1 << 20), &view, 6000.0, 0.0, 0.0, 8);
    let order = tile_urls(&probe.fetcher);
    let (first, missing) = (order[0].clone(), order[1].clone());
    let file = |u: &str| u.rsplit('/').next().unwrap().to_string();
    let (name, missing_name) = (file(&first), file(&missing));
    let mut s = stream(StreamConfig::default());
    let mut r = FakeResidency::new(1 << 20);
    s.fetcher.fail.insert(name.clone(), VecDeque::from([FetchError::Status { url: first.clone(), status: 503 }]));
    s.fetcher.fail.insert(missing_name.clone(), VecDeque::from([FetchError::NotFound { url: missing.clone() }]));
    let asked = |s: &SceneStream<FakeFetcher>, n: &str| {
        s.fetcher.log.iter().filter(|(u, _)| u.ends_with(&format!("/{n}"))).count()
    };
    // Steps at t = 0 only: the 503 waits for its retry time (0.25 s).
    run(&mut s, &mut r, &view, 6000.0, 0.0, 0.0, 10);
    assert_eq!(asked(&s, &name), 1, "not retried before its time");
    let events = s.drain_events();
    assert!(events.iter().any(|e| matches!(e, StreamEvent::Failed { url, retrying: true, .. } if *url == first)));
    assert!(events.iter().any(|e| matches!(e, StreamEvent::Failed { url, retrying: false, .. } if *url == missing)));
    assert!(!s.is_settled(), "a retry is due");
    run(&mut s, &mut r, &view, 6000.0, 0.3, 0.01, 50);
    assert_eq!(asked(&s, &name), 2, "retried once after the backoff");
    assert_eq!(asked(&s, &missing_name), 1, "404 is not retried");
    assert!(s.is_settled(), "settled with the missing tile given up on");
    assert_eq!(r.tiles.len(), 15);
    assert_eq!(s.failures().len(), 1);
    assert!(s.failures()[0].url == missing && s.failures()[0].message.contains("not found"));
}

#[test]
fn gives_up_after_the_last_attempt() {
    let config = StreamConfig { max_attempts: 3, retry_base_s: 0.1, ..StreamConfig::default() };
    let (mut s, mut r) = (stream(config), FakeResidency::new(1 << 20));
    let down = |i| FetchError::Transport { url: format!("try {i}"), message: "connection reset".into() };
    s.fetcher.fail.insert("index/r0.json".into(), (0..10).map(down).collect());
    run(&mut s, &mut r, &south_view(), 6000.0, 0.0, 0.05, 200);
    let asked = s.fetcher.log.iter().filter(|(u, _)| u.ends_with("index/r0.json")).count();
    assert_eq!(asked, 3, "three attempts, then given up");
    assert!(s.is_settled());
    assert_eq!(s.stats().broken, 1);
    assert_eq!(r.tiles.len(), 12, "the other quadrants load");
}

#[test]
fn full_pools_evict_the_farthest_unwanted_tile_first() {
    let (mut s, mut r) = (stream(StreamConfig::default()), FakeResidency::new(1 << 20));
    let view = Camera::look_at(DVec3::new(0.0, 0.0, 900.0), DVec3::new(0.0, 0.0, 0.0)).view_data(W, H);
    run(&mut s, &mut r, &view, 6000.0, 0.0, 0.01, 100);
    assert_eq!(r.tiles.len(), 16, "everything resident from above");
    // Now full: a view of the north-east corner only must make room.
    r.capacity = r.used;
    let corner = Camera { eye_m: DVec3::new(150.0, 150.0, 40.0), pitch_rad: -1.5, ..Camera::default() };
    let corner_view = corner.view_data(W, H);
    // Forget the resident tiles' trees of the corner: they must be fetched again.
    let e = eye(&corner_view);
    let wanted_before = {
        s.walk(&corner_view, 60.0);
        s.wanted.clone()
    };
    assert!(!wanted_before.is_empty() && wanted_before.len() < 16);
    // Evict the wanted tiles by hand so they are fetched again and need room.
    for &t in &wanted_before {
        if let TileState::Resident { slot, .. } = std::mem::replace(&mut s.tiles[t], TileState::NotResident(Load::Idle))
        {
            r.evict_tile(slot);
        }
    }
    r.evicted.clear();
    r.capacity = r.used; // room for nothing more
    run(&mut s, &mut r, &corner_view, 60.0, 1.0, 0.01, 100);
    assert!(s.is_settled());
    assert!(!r.evicted.is_empty(), "tiles were evicted to make room");
    let d = |xy: &(i32, i32)| {
        let t = s.index.tiles.iter().find(|t| (t.x, t.y) == *xy).unwrap();
        tile_distance(&t.bounds, e)
    };
    let dist: Vec<f32> = r.evicted.iter().map(d).collect();
    assert!(dist.windows(2).all(|w| w[0] >= w[1]), "farthest first: {dist:?}");
    // The farthest resident tile went first.
    let farthest = s.index.tiles.iter().map(|t| tile_distance(&t.bounds, e)).fold(0.0, f32::max);
    assert_eq!(dist[0], farthest);
    for xy in &r.evicted {
        assert!(
            !wanted_before.iter().any(|&t| (s.index.tiles[t].x, s.index.tiles[t].y) == *xy),
            "a wanted tile evicted"
        );
    }
}

#[test]
fn pools_full_of_wanted_tiles_shorten_the_reach_and_say_so() {
    let (mut s, mut r) = (stream(StreamConfig::default()), FakeResidency::new(1000));
    let view = Camera::look_at(DVec3::new(0.0, 0.0, 900.0), DVec3::new(0.0, 0.0, 0.0)).view_data(W, H);
    run(&mut s, &mut r, &view, 6000.0, 0.0, 0.01, 300);
    let d = s.stats().degraded;
    assert!(d.pools_full, "{d:?}");
    assert!(d.reach_m < 6000.0, "{d:?}");
    assert!(r.used <= 1000);
    let events = s.drain_events();
    assert!(
        events.iter().any(|e| matches!(e, StreamEvent::Failed { message, .. } if message.contains("pools are full"))),
        "{events:?}"
    );
    // Room again: the reach grows back to the draw distance.
    r.capacity = 1 << 20;
    run(&mut s, &mut r, &view, 6000.0, 10.0, 0.05, 400);
    assert!(!s.stats().degraded.pools_full, "{:?}", s.stats().degraded);
    assert_eq!(r.tiles.len(), 16);
}

#[test]
fn the_gpu_budget_holds_back_finer_parts_but_never_the_far_tier() {
    let heads = fixture_heads();
    let size = |h: &PackHead, p: PackPart| h.part_range(p).map_or(0, |(a, b)| b - a);
    let billboards: u64 = heads.iter().map(|h| size(h, PackPart::Impostors)).sum();
    // (A leaf-on view drawing impostors: never the billboards or the bare far tiers.)
    let leaf_on = PackPart::ALL
        .iter()
        .filter(|p| !matches!(p, PackPart::Billboards | PackPart::BareBillboards | PackPart::BareImpostors));
    let everything: u64 = heads.iter().map(|h| leaf_on.clone().map(|p| size(h, *p)).sum::<u64>()).sum();
    // Room for the billboards and about half of the rest.
    let budget = billboards + (everything - billboards) / 2;
    let config = StreamConfig { gpu_budget_bytes: budget, ..StreamConfig::default() };
    let (mut s, mut r) = (stream(config), FakeResidency::new(1 << 20));
    run(&mut s, &mut r, &south_view(), 6000.0, 0.0, 0.01, 200);
    assert!(s.stats().degraded.gpu_budget, "{:?}", s.stats().degraded);
    assert!(s.is_settled(), "held-back parts do not keep the stream busy");
    let parts = part_fetches(&s, 0);
    let fetched: u64 = parts.iter().map(|(_, (a, b))| b - a).sum();
    assert!(fetched <= budget, "{fetched} bytes of parts fetched for a {budget} budget");
    assert!(fetched < everything, "something was held back");
    for (name, h) in ["spruce", "beech", "birch"].iter().zip(&heads) {
        let far = h.part_range(PackPart::Impostors).unwrap();
        assert!(parts.iter().any(|(u, r)| u.contains(name) && *r == far), "{name}'s far tier fetched");
    }
    // Without a budget, everything the view needs arrives.
    let held_back = r.pack_bytes;
    let (mut s, mut r) = (stream(StreamConfig::default()), FakeResidency::new(1 << 20));
    run(&mut s, &mut r, &south_view(), 6000.0, 0.0, 0.01, 200);
    assert!(!s.stats().degraded.gpu_budget);
    assert!(r.pack_bytes > held_back, "{} bytes without a budget, {held_back} with", r.pack_bytes);
}

#[test]
fn a_leaf_off_view_fetches_the_bare_far_tiers_instead() {
    // The fixture's beech and birch are deciduous (their packs hold the bare
    // wood's far tiers); the spruce is evergreen.
    let heads = fixture_heads();
    assert!(heads[0].part_range(PackPart::BareImpostors).is_none(), "an evergreen has one state");
    let (mut s, mut r) = (stream(StreamConfig::default()), FakeResidency::new(1 << 20));
    // A far view in leaf-off: what `Reach::parts_needed` asks of a deciduous pack.
    r.parts = PackPart::ALL.map(|p| p == PackPart::BareImpostors);
    run(&mut s, &mut r, &south_view(), 6000.0, 0.0, 0.01, 200);
    assert!(s.is_settled());
    let parts = part_fetches(&s, 0);
    for (name, h) in ["spruce", "beech", "birch"].iter().zip(&heads) {
        let fetched = |p: PackPart| parts.iter().any(|(u, x)| u.contains(name) && Some(*x) == h.part_range(p));
        if *name == "spruce" {
            // No bare state: its leafy far tiers.
            assert!(fetched(PackPart::Impostors), "{name}'s far tier fetched: {parts:?}");
        } else {
            assert!(fetched(PackPart::BareImpostors), "{name}'s bare far tier fetched: {parts:?}");
            assert!(!fetched(PackPart::Impostors), "{name}'s leafy far tier fetched too: {parts:?}");
        }
        // One far tier: never the billboards.
        assert!(!fetched(PackPart::Billboards) && !fetched(PackPart::BareBillboards), "{name}: {parts:?}");
    }
    // Every species drawable from what came.
    assert!((0..3).all(|i| s.species_drawable(i).0));
    // Back to leaf-on: the leafy far tiers come too, and the species stay drawable throughout.
    let fetched_before = s.fetcher.log.len();
    r.parts = PackPart::ALL.map(|p| p == PackPart::Impostors);
    let mut t = 10.0;
    for _ in 0..20 {
        t = run(&mut s, &mut r, &south_view(), 6000.0, t, 0.01, 10);
        assert!((0..3).all(|i| s.species_drawable(i).0), "a species undrawable while its leafy far tier comes");
    }
    let parts = part_fetches(&s, fetched_before);
    for (name, h) in ["beech", "birch"].iter().zip(&heads[1..]) {
        let leafy = h.part_range(PackPart::Impostors);
        assert!(parts.iter().any(|(u, x)| u.contains(name) && Some(*x) == leafy), "{name}'s leafy far tier: {parts:?}");
    }
    assert!(s.is_settled());
}

#[test]
fn a_missing_manifest_is_fatal_and_named() {
    let (mut s, mut r) = (stream(StreamConfig::default()), FakeResidency::new(1 << 20));
    s.fetcher.fail.insert("scene.json".into(), VecDeque::from([FetchError::NotFound { url: "scene.json".into() }]));
    run(&mut s, &mut r, &south_view(), 6000.0, 0.0, 0.01, 5);
    let events = s.drain_events();
    assert!(events.iter().any(|e| matches!(e, StreamEvent::Fatal { message } if message.contains("not found"))));
    assert!(s.is_settled() && s.manifest().is_none());
    assert_eq!(s.fetcher.log.len(), 1, "nothing else is asked for");
}

#[test]
fn one_shard_of_a_sharded_bake_is_refused_with_the_way_out() {
    let path = format!("{}/scene.json", fixture());
    let mut m: serde_json::Value = serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
    m["shard"] = serde_json::json!({"index": 1, "count": 3});
    let (mut s, mut r) = (stream(StreamConfig::default()), FakeResidency::new(1 << 20));
    s.fetcher.replace.insert("scene.json".into(), serde_json::to_vec(&m).unwrap());
    run(&mut s, &mut r, &south_view(), 6000.0, 0.0, 0.01, 5);
    let events = s.drain_events();
    let fatal = events.iter().find_map(|e| match e {
        StreamEvent::Fatal { message } => Some(message.clone()),
        _ => None,
    });
    let fatal = fatal.expect("a fatal event");
    assert!(fatal.contains("shard 1 of 3") && fatal.contains("sylva-bake merge"), "{fatal}");
    assert!(s.manifest().is_none() && r.species == 0, "nothing of the shard is used");
    assert_eq!(s.fetcher.log.len(), 1);
}

#[test]
fn terrain_tiles_stream_retry_with_backoff_and_a_lost_one_leaves_its_parent() {
    // The fixture has a terrain of a root and four children (the demo's hills).
    let view = south_view();
    let mut s = stream(StreamConfig { terrain_error_px: 0.01, ..StreamConfig::default() });
    let mut r = FakeResidency::new(1 << 20);
    // The root fails once with a 503; child 1/0_0 is missing.
    s.fetcher.fail.insert(
        "terrain/0/0_0.terr".into(),
        VecDeque::from([FetchError::Status { url: "terrain/0/0_0.terr".into(), status: 503 }]),
    );
    s.fetcher.fail.insert(
        "terrain/1/0_0.terr".into(),
        VecDeque::from([FetchError::NotFound { url: "terrain/1/0_0.terr".into() }]),
    );
    let asked = |s: &SceneStream<FakeFetcher>, n: &str| s.fetcher.log.iter().filter(|(u, _)| u.ends_with(n)).count();
    run(&mut s, &mut r, &view, 6000.0, 0.0, 0.0, 10);
    assert_eq!(asked(&s, "terrain/0/0_0.terr"), 1, "not retried before its time");
    assert!(!s.is_settled(), "a terrain retry is due");
    assert!(s.terrain_draws().is_empty());
    run(&mut s, &mut r, &view, 6000.0, 0.3, 0.01, 60);
    assert_eq!(asked(&s, "terrain/0/0_0.terr"), 2, "retried once after the backoff");
    assert_eq!(asked(&s, "terrain/1/0_0.terr"), 1, "404 is not retried");
    assert!(s.is_settled());
    // A child is lost, so the root is drawn instead of its four children.
    let keys: Vec<_> = s.terrain_draws().iter().map(|d| d.key).collect();
    assert_eq!(keys, vec![(0, 0, 0)], "{keys:?}");
    assert_eq!(s.stats().terrain_resident, 4, "the root and three children");
    assert!(s.failures().iter().any(|f| f.url.ends_with("terrain/1/0_0.terr")));
    // The ground is known where the terrain is.
    assert!(s.ground_height_at(0.0, 0.0).is_some_and(|h| (10.0..30.0).contains(&h)));
}

#[test]
fn ground_images_stream_retry_and_stop_with_the_terrain() {
    // The fixture's terrain carries its baked forest floor: images for levels 0 and 1.
    let view = south_view();
    let mut s = stream(StreamConfig { terrain_error_px: 0.01, ..StreamConfig::default() });
    let mut r = FakeResidency::new(1 << 20);
    // The root's image fails once with a 503; image 1/1_0 is missing.
    s.fetcher.fail.insert(
        "terrain/img/0/0_0.jpg".into(),
        VecDeque::from([FetchError::Status { url: "terrain/img/0/0_0.jpg".into(), status: 503 }]),
    );
    s.fetcher.fail.insert(
        "terrain/img/1/1_0.jpg".into(),
        VecDeque::from([FetchError::NotFound { url: "terrain/img/1/1_0.jpg".into() }]),
    );
    let asked = |s: &SceneStream<FakeFetcher>, n: &str| s.fetcher.log.iter().filter(|(u, _)| u.ends_with(n)).count();
    let images = |s: &SceneStream<FakeFetcher>| s.fetcher.log.iter().filter(|(u, _)| u.ends_with(".jpg")).count();
    let t = run(&mut s, &mut r, &view, 6000.0, 0.0, 0.0, 10);
    assert_eq!(asked(&s, "terrain/img/0/0_0.jpg"), 1, "not retried before its time");
    let t = run(&mut s, &mut r, &view, 6000.0, t + 0.3, 0.01, 80);
    assert_eq!(asked(&s, "terrain/img/0/0_0.jpg"), 2, "retried once after the backoff");
    assert_eq!(asked(&s, "terrain/img/1/1_0.jpg"), 1, "404 is not retried");
    assert!(s.is_settled());
    assert!(s.failures().iter().any(|f| f.url.ends_with("terrain/img/1/1_0.jpg")));
    // Every drawn tile drapes an image: its own level's, its level-1 ancestor's
    // or, under the missing one, the root's.
    let draws = s.terrain_draws();
    assert!(draws.len() > 4, "{} tiles drawn", draws.len());
    for d in draws {
        let img = d.imagery.as_ref().unwrap_or_else(|| panic!("tile {:?} has no image", d.key));
        let k = img.key.1;
        assert!(k.0 <= d.key.0 && (d.key.1 >> (d.key.0 - k.0), d.key.2 >> (d.key.0 - k.0)) == (k.1, k.2));
        let under_lost = d.key.0 >= 1 && (d.key.1 >> (d.key.0 - 1), d.key.2 >> (d.key.0 - 1)) == (1, 0);
        assert_eq!(k.0, if under_lost { 0 } else { 1 }, "tile {:?} drapes {k:?}", d.key);
        let scale = 1.0 / f32::from(1u16 << (d.key.0 - k.0));
        assert_eq!(img.uv[2], scale);
    }
    assert_eq!(s.stats().imagery_drawn as usize, draws.len());
    // Terrain off: nothing drawn, nothing more asked for, and the stream settles.
    let before = images(&s);
    s.set_config(StreamConfig { terrain: false, ..s.config() });
    run(&mut s, &mut r, &view, 6000.0, t, 0.01, 50);
    assert_eq!(images(&s), before, "no image is fetched again");
    assert!(s.is_settled());
    assert!(s.terrain_draws().is_empty());
    // Another source drops what was held; switching back fetches again.
    s.set_config(StreamConfig { terrain: true, ..s.config() });
    s.set_imagery(ImageryChoice::Off);
    run(&mut s, &mut r, &view, 6000.0, t + 1.0, 0.01, 5);
    assert!(s.terrain_draws().iter().all(|d| d.imagery.is_none()));
    assert_eq!(s.imagery().resident(), 0);
    assert!(s.is_settled());
    // Terrain off while images are on their way: they are not asked for again.
    let mut s = stream(StreamConfig { terrain_error_px: 0.01, ..StreamConfig::default() });
    let mut r = FakeResidency::new(1 << 20);
    let mut t = 0.0;
    while images(&s) == 0 && t < 1.0 {
        s.update(&mut r, &view, 6000.0, t);
        t += 0.01;
    }
    assert!(images(&s) > 0, "images were asked for");
    s.set_config(StreamConfig { terrain: false, ..s.config() });
    let before = images(&s);
    run(&mut s, &mut r, &view, 6000.0, t, 0.01, 50);
    assert_eq!(images(&s), before, "no image is asked for with the terrain off");
    assert!(s.is_settled());
}

/// Per batch of tile `entry` (decoded whole from disk) in view: the batch and
/// the trees the cull pass draws of it (`thinning` of the CPU oracle) for
/// `view` with `thin`.
fn oracle_counts(entry: &crate::format::TileEntry, view: &ViewData, thin: PrefixView) -> Vec<(GpuBatch, u32)> {
    let bytes = std::fs::read(format!("{}/{}", fixture(), entry.url)).unwrap();
    let tile = Tile::decode("t", &bytes, 3).unwrap();
    let mut u: crate::lod::shared::ViewUniform = bytemuck::Zeroable::zeroed();
    u.eye_hi = view.eye_hi.extend(0.0).to_array();
    u.eye_lo = view.eye_lo.extend(0.0).to_array();
    u.lod = [view.px_per_m_at_1m * thin.lod_scale, 1e9, 0.12, 0.0];
    u.viewport = [view.viewport[0] as f32, view.viewport[1] as f32, thin.thin_px, 0.0];
    let eye = eye(view);
    tile.batches
        .iter()
        .filter(|b| {
            let (c, h) = (Vec3::from(b.center_m) - eye, Vec3::from(b.half_extent_m));
            view.frustum.iter().all(|p| p.truncate().dot(c) + p.w + p.truncate().abs().dot(h) >= 0.0)
        })
        .map(|b| {
            let (kept, _, _) = crate::lod::select::thinning(b, &u);
            (*b, (kept.ceil() as u32).min(b.instance_count))
        })
        .collect()
}

#[test]
fn tiles_fetch_the_prefix_the_view_draws_and_no_byte_twice() {
    let thin = PrefixView { thin_px: 8.0, lod_scale: 1.0, canopy: None };
    let mut s = stream(StreamConfig::default());
    s.set_prefix_view(Some(thin));
    let mut r = FakeResidency::new(1 << 20);
    let mut t = 0.0;
    let total: u64 = 3000;
    let mut partial_seen = 0;
    // From far to near along one line, stopping at each camera until settled.
    for (k, d) in [8000.0, 4000.0, 2000.0, 1000.0, 500.0].into_iter().enumerate() {
        let view = Camera::look_at(DVec3::new(0.0, -d, d * 0.5), DVec3::new(0.0, 0.0, 20.0)).view_data(W, H);
        t = run(&mut s, &mut r, &view, 1e6, t, 0.1, 16);
        assert!(s.is_settled(), "settles at {d} m");
        for &i in &s.wanted[..s.within_reach] {
            let entry = s.index.tiles[i].clone();
            let TileState::Resident { prefix, .. } = &s.tiles[i] else { panic!("tile {i} resident at {d} m") };
            let levels = entry.levels.as_ref().expect("the fixture's tiles are in levels");
            let end = |l: u32| levels.bytes[l as usize - 1];
            let scheme = prefix.scheme;
            assert_eq!((scheme.version, scheme.count), (4, levels.bytes.len() as u32), "{}", entry.url);
            // The CPU oracle: every batch in view has what the cull pass draws of it.
            let drawn = oracle_counts(&entry, &view, thin);
            for (b, n) in &drawn {
                let held = scheme.prefix(b, prefix.levels - 1);
                assert!(*n <= held, "{}: a batch draws {n} of {} but {held} are held", entry.url, b.instance_count);
            }
            // No more than that on the first view: the levels the oracle needs,
            // or the first guess made before the tile's batches were known.
            if k == 0 {
                let exact =
                    (1..=scheme.count).find(|&l| drawn.iter().all(|(b, n)| *n <= scheme.prefix(b, l - 1))).unwrap();
                let guess = first_levels_wanted(&view, &entry.bounds, &levels.scheme(), Some(thin));
                assert_eq!(end(prefix.levels), end(exact.max(guess)), "{} at {d} m", entry.url);
            }
            partial_seen += usize::from(prefix.levels < scheme.count);
        }
        let resident = u64::from(r.used);
        if k == 0 {
            assert!(resident * 4 < total, "the far view holds {resident} of {total} trees");
        }
    }
    assert!(partial_seen > 0, "some tile was held in part");
    // No byte twice: each tile's ranges are disjoint, and all of them make at most the file.
    let mut by_url: HashMap<String, Vec<(u64, u64)>> = HashMap::new();
    for (url, range) in &s.fetcher.log {
        if url.ends_with(".tile") {
            let len = std::fs::metadata(url).unwrap().len();
            by_url.entry(url.clone()).or_default().push(range.unwrap_or((0, len)));
        }
    }
    assert!(by_url.len() >= 4);
    for (url, mut ranges) in by_url {
        ranges.sort_unstable();
        assert!(ranges.windows(2).all(|w| w[0].1 <= w[1].0), "{url} fetched twice: {ranges:?}");
        assert_eq!(ranges[0].0, 0, "{url} starts at its head");
    }
    assert!(s.requests.is_empty());
}

/// Tile index → prefix levels held, of every resident tile.
fn held_levels(s: &SceneStream<FakeFetcher>) -> HashMap<usize, u32> {
    (s.tiles.iter().enumerate())
        .filter_map(|(i, t)| match t {
            TileState::Resident { prefix, .. } => Some((i, prefix.levels)),
            TileState::NotResident(_) => None,
        })
        .collect()
}

#[test]
fn full_pools_trim_tiles_to_the_prefix_the_view_draws_and_they_grow_back_by_range() {
    let thin = PrefixView { thin_px: 8.0, lod_scale: 1.0, canopy: None };
    // A small screen, so trees thin across the fixture: the south view holds the
    // south tiles whole and the north ones in part, the north view the other way round.
    let near = Camera::look_at(DVec3::new(0.0, -300.0, 60.0), DVec3::new(0.0, 0.0, 20.0)).view_data(96, 54);
    let far = Camera::look_at(DVec3::new(0.0, 300.0, 60.0), DVec3::new(0.0, 0.0, 20.0)).view_data(96, 54);
    let held_alone = |view: &ViewData| {
        let mut s = stream(StreamConfig::default());
        s.set_prefix_view(Some(thin));
        let mut r = FakeResidency::new(1 << 20);
        run(&mut s, &mut r, view, 1e6, 0.0, 0.1, 16);
        assert!(s.is_settled() && s.within_reach == s.wanted.len());
        r.used
    };
    let (near_n, far_n) = (held_alone(&near), held_alone(&far));
    // Room for either view alone, not for the near view's tiles whole and the far view's prefixes.
    let cap = near_n.max(far_n) + 8;
    let mut s = stream(StreamConfig::default());
    s.set_prefix_view(Some(thin));
    let mut r = FakeResidency::new(cap);
    let mut t = run(&mut s, &mut r, &near, 1e6, 0.0, 0.1, 16);
    assert!(s.is_settled() && s.within_reach == s.wanted.len(), "the near view fits");
    let before = held_levels(&s);
    s.drain_events();
    t = run(&mut s, &mut r, &far, 1e6, t, 0.1, 24);
    assert!(s.is_settled(), "the far view settles");
    let events = s.drain_events();
    let full =
        events.iter().find(|e| matches!(e, StreamEvent::Failed { message, .. } if message.contains("pools are full")));
    assert!(full.is_none(), "trimming made room: {full:?}");
    assert_eq!(s.within_reach, s.wanted.len(), "every tile the far view wants is within reach");
    assert!(r.used <= cap);
    let after = held_levels(&s);
    let trimmed: Vec<usize> =
        after.iter().filter(|(i, l)| before.get(i).is_some_and(|b| *l < b)).map(|(i, _)| *i).collect();
    assert!(!trimmed.is_empty() && s.stats().tiles_trimmed >= trimmed.len() as u64, "{before:?} -> {after:?}");
    // What is held still covers what the cull pass draws of every wanted tile.
    for &i in &s.wanted {
        let entry = s.index.tiles[i].clone();
        let TileState::Resident { prefix, .. } = &s.tiles[i] else { panic!("{} resident", entry.url) };
        for (b, n) in oracle_counts(&entry, &far, thin) {
            let held = prefix.scheme.prefix(&b, prefix.levels - 1);
            assert!(
                n <= held,
                "{}: draws {n} of a batch, holds {held} ({} levels, wants {}, more {:?}, {}/{} used)",
                entry.url,
                prefix.levels,
                batch_levels_wanted(&far, &prefix.batches, &prefix.scheme, Some(thin)),
                prefix.more,
                r.used,
                cap
            );
        }
    }
    // Back near: the trimmed tiles grow again by range from where they were cut.
    let logged = s.fetcher.log.len();
    run(&mut s, &mut r, &near, 1e6, t, 0.1, 24);
    assert!(s.is_settled() && s.within_reach == s.wanted.len(), "the near view fits again");
    let mut grown = 0;
    for &i in &trimmed {
        let entry = &s.index.tiles[i];
        let ends = &entry.levels.as_ref().unwrap().bytes;
        let cut = ends[after[&i] as usize - 1];
        let again: Vec<_> = s.fetcher.log[logged..].iter().filter(|(u, _)| u.ends_with(&entry.url)).collect();
        if held_levels(&s).get(&i) > Some(&after[&i]) {
            grown += 1;
            assert!(
                again.iter().all(|(_, r)| r.is_some_and(|(a, _)| a >= cut)) && !again.is_empty(),
                "{} grew from byte {cut}: {again:?}",
                entry.url
            );
        }
    }
    assert!(grown > 0, "some trimmed tile grew again");
}

#[test]
fn whole_tiles_without_prefix_thinning() {
    let mut s = stream(StreamConfig::default());
    let mut r = FakeResidency::new(1 << 20);
    let view = Camera::look_at(DVec3::new(0.0, -8000.0, 4000.0), DVec3::new(0.0, 0.0, 20.0)).view_data(W, H);
    run(&mut s, &mut r, &view, 1e6, 0.0, 0.1, 16);
    assert!(s.is_settled());
    assert_eq!(r.used, 3000, "every tree of the fixture");
    assert!(s.fetcher.log.iter().filter(|(u, _)| u.ends_with(".tile")).all(|(_, range)| range.is_none()));
}

#[test]
fn the_canopy_stands_in_for_trees_under_a_pixel_and_their_tiles_are_not_fetched() {
    let canopy = CanopyView { px_lo: 1.0, px_hi: 2.5, cell_px: 2.0, lod_scale: 1.0 };
    let mut s = stream(StreamConfig::default());
    s.set_prefix_view(Some(PrefixView { thin_px: 8.0, lod_scale: 1.0, canopy: None }));
    s.set_canopy_view(Some(canopy));
    let mut r = FakeResidency::new(1 << 20);
    let mut t = 0.0;
    let mut fetched_before = 0;
    for (k, d) in [40_000.0f64, 5000.0, 400.0].into_iter().enumerate() {
        let view = Camera::look_at(DVec3::new(0.0, -d, d * 0.5), DVec3::new(0.0, 0.0, 20.0)).view_data(W, H);
        t = run(&mut s, &mut r, &view, 1e6, t, 0.1, 24);
        assert!(s.is_settled(), "settles at {d} m");
        assert!(s.canopy_active().is_some(), "the root raster is in");
        let log = &s.fetcher.log[fetched_before..];
        fetched_before = s.fetcher.log.len();
        let px = |h: f32, dist: f32| h * view.px_per_m_at_1m / dist.max(1e-3);
        // Every tile the view wants has a tree of a pixel or more; every known
        // tile in view it does not want has none (the canopy alone draws it).
        for (i, entry) in s.index.tiles.iter().enumerate() {
            let Some(dist) = tile_wanted(&view, &entry.bounds, 1e6) else { continue };
            let h = px(entry.levels.as_ref().unwrap().height_m, dist);
            assert_eq!(s.wanted.contains(&i), h >= 1.0, "{} at {d} m: tallest tree {h:.2} px", entry.url);
        }
        match k {
            0 => {
                // 40 km away: the trees are a fifth of a pixel. The manifest, the root
                // node, canopy rasters and the ground; no tile, no pack, no deeper node.
                let urls: Vec<&str> = log.iter().map(|(u, _)| u.rsplit('/').next().unwrap()).collect();
                let allowed = |u: &&str| {
                    *u == "scene.json" || *u == "r.json" || [".cnpy", ".terr", ".jpg"].iter().any(|e| u.ends_with(e))
                };
                assert!(urls.iter().all(allowed), "{urls:?}");
                assert!(log.iter().any(|(u, _)| u.ends_with("canopy/0/0_0.cnpy")), "{urls:?}");
                assert_eq!(r.used, 0);
                assert_eq!(s.canopy_draws().len(), 1, "the root raster alone");
                assert!(s.stats().canopy_bytes_fetched >= 32_816);
            }
            1 => {
                // 5 km: the nearest trees are about 1.6 px: their tiles come, the far ones do not.
                assert!(r.used > 0 && r.used < 3000, "{} trees resident", r.used);
                assert!(!s.canopy_draws().is_empty());
            }
            _ => {
                // 400 m: every tree is far above the band, so no raster is drawn.
                assert!(s.canopy_draws().is_empty(), "{} rasters drawn close up", s.canopy_draws().len());
            }
        }
    }
    // Without the canopy the far view fetches tiles again.
    let mut s = stream(StreamConfig::default());
    s.set_prefix_view(Some(PrefixView { thin_px: 8.0, lod_scale: 1.0, canopy: None }));
    let mut r = FakeResidency::new(1 << 20);
    let view = Camera::look_at(DVec3::new(0.0, -40_000.0, 20_000.0), DVec3::new(0.0, 0.0, 20.0)).view_data(W, H);
    run(&mut s, &mut r, &view, 1e6, 0.0, 0.1, 24);
    assert!(r.used > 0 && !s.fetcher.log.iter().any(|(u, _)| u.ends_with(".cnpy")));
}

#[test]
fn a_lost_canopy_raster_is_retried_then_its_parent_drawn() {
    let mut s = stream(StreamConfig { retry_base_s: 0.5, ..StreamConfig::default() });
    s.set_canopy_view(Some(CanopyView { px_lo: 1.0, px_hi: 2.5, cell_px: 2.0, lod_scale: 1.0 }));
    s.fetcher.fail.insert("0/0_0.cnpy".into(), VecDeque::from([FetchError::Status { url: "x".into(), status: 503 }]));
    let mut r = FakeResidency::new(1 << 20);
    let view = Camera::look_at(DVec3::new(0.0, -40_000.0, 20_000.0), DVec3::new(0.0, 0.0, 20.0)).view_data(W, H);
    // (The retry is due 0.5 s after the failure: manifest, index root, its children, tiles first.)
    let t = run(&mut s, &mut r, &view, 1e6, 0.0, 0.1, 5);
    assert!(s.canopy_active().is_none(), "not yet: the root raster failed once");
    assert!(!s.is_settled(), "a retry is due");
    // Meanwhile nothing waits for it: the view's trees are fetched.
    assert!(
        s.fetcher.log.iter().any(|(u, _)| u.ends_with(".tile")),
        "tiles wait for a failed root raster: {:?}",
        s.fetcher.log
    );
    assert!(s.fetcher.log.iter().filter(|(u, _)| u.ends_with("/0/0_0.cnpy")).nth(1).is_none(), "retried too early");
    run(&mut s, &mut r, &view, 1e6, t, 0.2, 10);
    assert!(s.canopy_active().is_some() && s.is_settled());
    // A raster that does not decode is given up on: its trees are drawn instead.
    let mut s = stream(StreamConfig::default());
    s.set_canopy_view(Some(CanopyView { px_lo: 1.0, px_hi: 2.5, cell_px: 2.0, lod_scale: 1.0 }));
    s.fetcher.replace.insert("0/0_0.cnpy".into(), b"SYCNgarbage".to_vec());
    run(&mut s, &mut r, &view, 1e6, 0.0, 0.1, 24);
    assert!(s.canopy_active().is_none() && s.is_settled());
    assert!(s.failures().iter().any(|f| f.url.ends_with("canopy/0/0_0.cnpy")), "{:?}", s.failures());
    assert!(s.fetcher.log.iter().any(|(u, _)| u.ends_with(".tile")), "trees instead");
}

#[test]
fn the_canopy_stands_in_where_wanted_trees_cannot_be_drawn_yet() {
    let canopy = CanopyView { px_lo: 1.0, px_hi: 2.5, cell_px: 2.0, lod_scale: 1.0 };
    let far = Camera::look_at(DVec3::new(0.0, -40_000.0, 20_000.0), DVec3::new(0.0, 0.0, 20.0)).view_data(W, H);
    let near = Camera::look_at(DVec3::new(0.0, -400.0, 200.0), DVec3::new(0.0, 0.0, 20.0)).view_data(W, H);
    let mut s = stream(StreamConfig::default());
    s.set_canopy_view(Some(canopy));
    let mut r = FakeResidency::new(1 << 20);
    // From afar the rasters come in, no tile.
    let t = run(&mut s, &mut r, &far, 1e6, 0.0, 0.1, 24);
    assert!(s.is_settled() && r.used == 0);
    // Close up, with nothing answered: every tree would be drawn whole, but
    // none is here, so the rasters over the wanted tiles stand in for them.
    s.fetcher.hold = true;
    let t = run(&mut s, &mut r, &near, 1e6, t, 0.1, 4);
    assert!(!s.canopy_draws().is_empty(), "bare ground while the trees load");
    assert!(s.canopy_draws().iter().all(|d| d.stand_in));
    assert!(!s.canopy_gaps.is_empty(), "the index nodes in view are not read yet");
    // Gaps are squares of the tile grid (the trunks'), not the crowns' bounds,
    // which reach into the neighbouring rasters.
    let m = s.manifest().unwrap();
    let tile_m = m.cell_size_m * m.tile_cells as f32;
    for g in &s.canopy_gaps {
        assert!(g.iter().all(|v| (v / tile_m - (v / tile_m).round()).abs() < 1e-4), "{g:?} off the {tile_m} m grid");
    }
    let covered = |s: &SceneStream<FakeFetcher>, t: usize| {
        let b = &s.index.tiles[t].bounds;
        let c = [f64::from(b.min[0] + b.max[0]) * 0.5, f64::from(b.min[1] + b.max[1]) * 0.5];
        s.canopy_draws().iter().any(|d| {
            let (o, size) = (d.canopy.origin_m, f64::from(d.canopy.size_m));
            let o = [f64::from(o[0]), f64::from(o[1])];
            o[0] <= c[0] && c[0] <= o[0] + size && o[1] <= c[1] && c[1] <= o[1] + size
        })
    };
    // As the nodes and then the tiles come in, every wanted tile not yet
    // resident has its stand-in; once all are in, the canopy gives way to them.
    s.fetcher.hold = false;
    let (mut t, mut checked) = (t, 0);
    for _ in 0..24 {
        t = run(&mut s, &mut r, &near, 1e6, t, 0.1, 1);
        for &w in &s.wanted {
            if !matches!(s.tiles[w], TileState::Resident { .. }) {
                assert!(covered(&s, w), "wanted tile {} has no stand-in", s.index.tiles[w].url);
                checked += 1;
            }
        }
    }
    assert!(checked > 0, "no frame had a wanted tile loading");
    assert!(s.is_settled() && r.used > 0);
    assert!(s.canopy_draws().is_empty(), "{} rasters drawn over resident trees", s.canopy_draws().len());

    // A view that draws meshes only (no far tier, as `--only meshes` and the
    // benchmark's references): once its trees and their meshes are in, the
    // canopy gives way to them too, though no billboards ever come.
    let mut s = stream(StreamConfig::default());
    s.set_canopy_view(Some(canopy));
    let mut r = FakeResidency::new(1 << 20);
    r.parts = PackPart::ALL.map(|p| !p.is_far());
    let t = run(&mut s, &mut r, &far, 1e6, 0.0, 0.1, 24);
    run(&mut s, &mut r, &near, 1e6, t, 0.1, 24);
    assert!(s.is_settled() && r.used > 0, "the trees are resident");
    assert!(s.canopy_draws().is_empty(), "{} rasters over resident trees drawn as meshes", s.canopy_draws().len());

    // A species whose pack cannot be read: its trees are drawn by the canopy.
    let mut s = stream(StreamConfig::default());
    s.set_canopy_view(Some(canopy));
    let mut r = FakeResidency::new(1 << 20);
    run(&mut s, &mut r, &far, 1e6, 0.0, 0.1, 24);
    let species: Vec<String> = s.manifest().unwrap().species.iter().map(|e| e.pack.clone()).collect();
    for pack in &species {
        let key = pack.rsplit('/').next().unwrap().to_string();
        s.fetcher.fail.insert(key, VecDeque::from([FetchError::Status { url: pack.clone(), status: 404 }]));
    }
    run(&mut s, &mut r, &near, 1e6, 2.4, 0.1, 24);
    assert!(r.used > 0, "the trees are resident");
    assert!(!s.canopy_draws().is_empty() && s.canopy_draws().iter().all(|d| d.stand_in), "their canopy stands in");
    let all_lost = s.canopy_draws().len();

    // One species given up on among others drawn: tiles holding a drawn
    // species are not stood in for (their drawn trees would darken twice).
    let mut s = stream(StreamConfig::default());
    s.set_canopy_view(Some(canopy));
    let mut r = FakeResidency::new(1 << 20);
    run(&mut s, &mut r, &far, 1e6, 0.0, 0.1, 24);
    let pack = s.manifest().unwrap().species[0].pack.clone();
    let key = pack.rsplit('/').next().unwrap().to_string();
    s.fetcher.fail.insert(key, VecDeque::from([FetchError::Status { url: pack, status: 404 }]));
    run(&mut s, &mut r, &near, 1e6, 2.4, 0.1, 24);
    assert!(s.is_settled());
    for &t in &s.wanted {
        let TileState::Resident { species, .. } = &s.tiles[t] else { panic!("tile {t} resident") };
        let e = &s.index.tiles[t];
        let square = [e.x as f32, e.y as f32];
        let gap = s.canopy_gaps.iter().any(|g| {
            (g[0] / (g[2] - g[0]) - square[0]).abs() < 1e-3 && (g[1] / (g[3] - g[1]) - square[1]).abs() < 1e-3
        });
        assert_eq!(gap, species.iter().all(|&k| k == 0), "{}: species {species:?}", e.url);
    }
    assert!(s.canopy_draws().len() <= all_lost);
}

/// The fixture's packs stored (each part deflated, `format::stored`): the
/// stream fetches each wanted part's block, counts the bytes sent, inflates
/// them and assembles the same sections a raw pack gives; a corrupt block is
/// retried, then given up on with its URL.
#[test]
fn stored_packs_stream_deflated_parts() {
    let dir = fixture();
    let raw_stream = {
        let (mut s, mut r) = (stream(StreamConfig::default()), FakeResidency::new(1 << 20));
        run(&mut s, &mut r, &south_view(), 6000.0, 0.0, 0.01, 200);
        assert!(s.is_settled());
        (s.stats().bytes_fetched, r.pack_bytes)
    };
    let mut manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(format!("{dir}/scene.json")).unwrap()).unwrap();
    let mut s = stream(StreamConfig::default());
    let mut heads = Vec::new();
    for sp in manifest["species"].as_array_mut().unwrap() {
        let path = sp["pack"].as_str().unwrap().to_string();
        let raw = std::fs::read(format!("{dir}/{path}")).unwrap();
        let stored = crate::format::stored::store_pack(&path, &raw).unwrap();
        let head = PackHead::decode(&path, &stored).unwrap();
        sp["bytes"] = stored.len().into();
        sp["head_bytes"] = head.bytes.len().into();
        s.fetcher.replace.insert(path.clone(), stored);
        heads.push((path, head));
    }
    s.fetcher.replace.insert("scene.json".into(), serde_json::to_vec(&manifest).unwrap());
    let mut r = FakeResidency::new(1 << 20);
    run(&mut s, &mut r, &south_view(), 6000.0, 0.0, 0.01, 200);
    assert!(s.is_settled());
    assert!(s.failures().is_empty(), "{:?}", s.failures());
    assert!((0..3).all(|i| s.species_drawable(i).0));
    // The same sections on the "GPU", for fewer bytes fetched.
    assert_eq!(r.pack_bytes, raw_stream.1);
    let saved = raw_stream.0 - s.stats().bytes_fetched;
    assert!(saved > raw_stream.0 / 4, "{} bytes fetched stored, {} raw", s.stats().bytes_fetched, raw_stream.0);
    // Every pack request after the head is one block, as stored.
    for (u, range) in part_fetches(&s, 0).iter().filter(|(u, _)| u.ends_with(".pack")) {
        let (_, head) = heads.iter().find(|(p, _)| u.ends_with(p.as_str())).unwrap();
        assert!(head.stored.iter().any(|b| b.stored == *range), "{u} {range:?} is no stored block");
    }
    // A corrupt block: retried, then given up on, named; the other species draw.
    let (path, head) = &heads[1];
    let mut bad = s.fetcher.replace[path].clone();
    let far = head.fetch_of(PackPart::Impostors).unwrap().range;
    for x in &mut bad[far.0 as usize..far.0 as usize + 16] {
        *x = 0xff;
    }
    let mut s2 = stream(StreamConfig { retry_base_s: 0.01, ..StreamConfig::default() });
    s2.fetcher.replace = s.fetcher.replace.clone();
    s2.fetcher.replace.insert(path.clone(), bad);
    let mut r = FakeResidency::new(1 << 20);
    run(&mut s2, &mut r, &south_view(), 6000.0, 0.0, 0.05, 400);
    assert!(s2.is_settled());
    let failed = s2.failures();
    assert!(failed.iter().any(|f| f.url.ends_with(path.as_str()) && f.message.contains("inflate")), "{failed:?}");
    assert!(s2.species_drawable(0).0 && s2.species_drawable(2).0);
}
