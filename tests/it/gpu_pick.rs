//! GPU tests of picking on `tests/fixtures/forest-small`: the id
//! pass answers with the tree drawn at a pixel, through every representation,
//! against a CPU oracle that projects each resident tree's bounds.
//!
//! - A tree is picked only where its projected bounds cover the pixel.
//! - A pixel no tree's bounds cover picks nothing.
//! - Picking passes through leaf gaps: some pixels inside a nearer tree's
//!   bounds pick a tree behind it (the id pass is alpha-tested like the colour).
//! - The picked pool instance maps back to its tile, its index and its id
//!   (`SceneStream::locate_instance`, `describe_tree`), at the same position.
//!
//! And styles (the same issue), on a copy of the fixture given attributes:
//! a filter's drawn trees are the CPU oracle's with the filtered ones left
//! out; a colouring colours exactly the trees it should (each pixel's colour
//! against the category of the tree the id pass finds there); a selected tree
//! is highlighted.

use std::path::{Path, PathBuf};

use glam::{DVec3, Vec3, Vec4Swizzles};
use sylva::camera::Camera;
use sylva::format::Manifest;
use sylva::offscreen::OffscreenScene;
use sylva::render::forest::{PoolConfig, RenderSettings, Representations};
use sylva::render::gpu_data::{Repr, REPR_COUNT};
use sylva::render::settings::FarTier;

const W: u32 = 320;
const H: u32 = 180;
const POOLS: PoolConfig = PoolConfig { instances: 1 << 16, batches: 1 << 12, items: 1 << 17, species: 8 };

fn fixture() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/forest-small")
}

fn open() -> OffscreenScene {
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        std::env::set_var("XDG_RUNTIME_DIR", "/tmp");
    }
    OffscreenScene::open(fixture().to_str().unwrap(), W, H, POOLS)
        .expect("a GPU adapter (install mesa-vulkan-drivers for lavapipe)")
}

/// A resident tree as the oracle sees it: where it stands and its projected bounds.
struct Projected {
    instance: u32,
    position: Vec3,
    /// Bounding circle on screen (px) and the distance of its centre.
    centre_px: [f32; 2],
    radius_px: f32,
    /// A tight core: half the crown's horizontal half-width about the crown's
    /// centre (px), where a nearer tree's leaves mostly hide what is behind.
    core_px: f32,
    depth: f32,
}

/// Every resident tree in front of the camera, its bounding sphere projected
/// (conservatively: the sphere's radius at its centre's depth, plus 25 % and 2 px).
fn project_all(off: &OffscreenScene, m: &Manifest, cam: &Camera) -> Vec<Projected> {
    let (_, batches, instances, _) = off.read_selection();
    let view = cam.view_data(W, H);
    let eye = (view.eye_hi.as_dvec3() + view.eye_lo.as_dvec3()).as_vec3();
    let mut out = Vec::new();
    for b in batches.iter().filter(|b| b.instance_count > 0) {
        let s = &m.species[b.species as usize];
        let lo = Vec3::from(s.bounds.min);
        let hi = Vec3::from(s.bounds.max);
        for i in b.instance_offset..b.instance_offset + b.instance_count {
            let t = instances[i as usize].decode(b);
            let half = (hi - lo) * 0.5 * t.scale * Vec3::new(t.aspect.max(1.0), t.aspect.max(1.0), 1.0);
            let pos = Vec3::from(t.position_m);
            let centre = pos + Vec3::new(0.0, 0.0, (lo.z + hi.z) * 0.5 * t.scale);
            let clip = view.clip_from_eye * (centre - eye).extend(1.0);
            if clip.w <= 0.5 {
                continue;
            }
            let ndc = clip.xy() / clip.w;
            let px = [(ndc.x * 0.5 + 0.5) * W as f32, (0.5 - ndc.y * 0.5) * H as f32];
            let r = half.length() * view.px_per_m_at_1m / clip.w;
            out.push(Projected {
                instance: i,
                position: pos,
                centre_px: px,
                radius_px: r * 1.25 + 2.0,
                core_px: 0.5 * half.x.min(half.y) * view.px_per_m_at_1m / clip.w,
                depth: clip.w,
            });
        }
    }
    out
}

fn covers(p: &Projected, x: f32, y: f32) -> bool {
    let (dx, dy) = (x - p.centre_px[0], y - p.centre_px[1]);
    dx * dx + dy * dy <= p.radius_px * p.radius_px
}

/// The representation families each draw slot of `instance` is in, from the
/// last cull pass's draw items.
fn families_of(off: &OffscreenScene, instance: u32) -> Vec<&'static str> {
    let (slots, _, _, _) = off.read_selection();
    let mut out = Vec::new();
    for (slot, items) in slots.iter().enumerate() {
        if items.iter().any(|&(x, _)| x == instance) {
            let r = slot as u32 % REPR_COUNT;
            out.push(match r {
                r if r == Repr::Mesh0 as u32 || r == Repr::Mesh1 as u32 => "mesh",
                r if r == Repr::Cloud as u32 => "cloud",
                r if r == Repr::Billboard as u32 => "far",
                _ => "ellipsoid",
            });
        }
    }
    out
}

/// The camera: from the south-west edge of the forest, a little above the
/// canopy, looking across it to the sky.
fn camera(m: &Manifest) -> Camera {
    let lo = DVec3::from(m.bounds.min.map(f64::from));
    let hi = DVec3::from(m.bounds.max.map(f64::from));
    let c = (lo + hi) * 0.5;
    Camera::look_at(DVec3::new(lo.x + 20.0, lo.y + 20.0, hi.z), DVec3::new(c.x, c.y, hi.z - 40.0))
}

#[test]
fn picks_hit_the_tree_drawn_at_each_representation() {
    let mut off = open();
    off.load_view(&Camera::default(), 30.0);
    let m = off.stream.manifest().expect("manifest").clone();
    let cam = camera(&m);
    let cases: [(&str, Representations, FarTier, &str); 4] = [
        ("meshes", Representations::MESHES, FarTier::Impostors, "mesh"),
        ("ellipsoids", Representations::CLUSTERS, FarTier::Impostors, "ellipsoid"),
        ("impostors", Representations::BILLBOARDS, FarTier::Impostors, "far"),
        ("billboards", Representations::BILLBOARDS, FarTier::Billboards, "far"),
    ];
    let mut checked_describe = false;
    for (name, representations, far_tier, family) in cases {
        off.settings = RenderSettings {
            representations,
            far_tier,
            lod_policy: false,
            // No thinning: a thinned billboard is scaled past its tree's bounds.
            thin_px: 0.0,
            ..RenderSettings::default()
        };
        off.load_view(&cam, 30.0);
        off.render(&cam, false);
        if let Some(dir) = std::env::var_os("SYLVA_PICK_PNG") {
            let path = PathBuf::from(dir).join(format!("pick-{name}.png"));
            image::save_buffer(path, &off.read_image(), W, H, image::ColorType::Rgba8).unwrap();
        }
        let view = cam.view_data(W, H);
        let (mut hits, mut empty, mut through_gaps, mut in_family) = (0, 0, 0, 0);
        for gy in 0..9 {
            for gx in 0..16 {
                let (x, y) = (gx * W / 16 + W / 32, gy * H / 9 + H / 18);
                let picked = off.pick_blocking(&view, [x, y]);
                // The oracle from the pools the pick's cull pass read.
                let trees = project_all(&off, &m, &cam);
                let (fx, fy) = (x as f32 + 0.5, y as f32 + 0.5);
                let under: Vec<&Projected> = trees.iter().filter(|p| covers(p, fx, fy)).collect();
                match picked {
                    None => {
                        if under.is_empty() {
                            empty += 1;
                        }
                    }
                    Some(i) => {
                        let p = trees
                            .iter()
                            .find(|p| p.instance == i)
                            .unwrap_or_else(|| panic!("{name}: picked instance {i} at {x},{y} is not a resident tree"));
                        assert!(covers(p, fx, fy), "{name}: picked tree {i} at {x},{y} lies outside its bounds");
                        hits += 1;
                        let in_core = |q: &&&Projected| {
                            let (dx, dy) = (fx - q.centre_px[0], fy - q.centre_px[1]);
                            (dx * dx + dy * dy).sqrt() <= q.core_px
                        };
                        if under.iter().filter(in_core).any(|q| q.depth + 1.0 < p.depth && q.instance != i) {
                            through_gaps += 1;
                        }
                        if families_of(&off, i).contains(&family) {
                            in_family += 1;
                        }
                        if !checked_describe {
                            checked_describe = true;
                            describe_matches(&off, &m, i, p.position);
                        }
                    }
                }
                // Where no tree's bounds reach, nothing is picked.
                if under.is_empty() {
                    assert_eq!(picked, None, "{name}: {x},{y} picked a tree where no tree stands");
                }
            }
        }
        eprintln!("{name}: {hits} hits ({in_family} as {family}), {through_gaps} through a nearer tree, {empty} empty");
        assert!(hits >= 20, "{name}: only {hits} of 144 pixels hit a tree");
        assert_eq!(in_family, hits, "{name}: some picked trees were not drawn as {family}");
        assert!(empty >= 5, "{name}: the view has no open ground to miss on ({empty})");
        if name != "billboards" {
            // Crowns are not solid: some pixels show a farther tree through a nearer one's gaps.
            assert!(through_gaps >= 1, "{name}: no pick passed through a nearer tree's gaps");
        }
    }
}

/// The located tile, index and id of a picked instance name the same tree.
fn describe_matches(off: &OffscreenScene, m: &Manifest, instance: u32, position: Vec3) {
    let t = off.stream.locate_instance(instance).expect("a picked instance is in a resident tile");
    let tile = std::fs::read(&t.tile_url).unwrap();
    let ids = std::fs::read(&t.ids_url).unwrap();
    let files = [t.tile_url.as_str(), t.ids_url.as_str(), t.attributes_url.as_str()];
    let geo = sylva::geo::GeoFrame::new(&m.crs.proj4, m.origin_m).ok();
    let d = sylva::scene::query::describe_tree(m, geo.as_ref(), [&tile, &ids], None, files, t.index).unwrap();
    let all = sylva::format::decode_ids("ids", &ids).unwrap();
    assert_eq!(d["id"].as_u64(), Some(all[t.index as usize]));
    let at: Vec<f64> = d["position"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    for k in 0..3 {
        let want = m.origin_m[k] + f64::from(position[k]);
        assert!((at[k] - want).abs() < 0.02, "position {k}: {} against {want}", at[k]);
    }
    assert!(d["lon"].as_f64().is_some_and(|l| (14.0..16.0).contains(&l)), "{d}");
}

/// A copy of the fixture with two attributes per tree: `kind` (a category,
/// "a", "b" or "c" by id % 3) and `girth` (an integer, id % 101).
fn attributed_fixture(name: &str) -> PathBuf {
    use sylva::format::attributes::{
        encode_attributes, AttributeCodes, AttributeColumn, AttributeSchema, AttributeType,
    };
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("pick-attributes-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let schema = AttributeSchema {
        columns: vec![
            AttributeColumn {
                name: "kind".into(),
                kind: AttributeType::Category,
                width: 1,
                min: 0.0,
                max: 0.0,
                categories: vec!["a".into(), "b".into(), "c".into()],
                count: 3000,
            },
            AttributeColumn {
                name: "girth".into(),
                kind: AttributeType::Integer,
                width: 1,
                min: 0.0,
                max: 100.0,
                categories: Vec::new(),
                count: 3000,
            },
        ],
    };
    let s = schema.clone();
    crate::common::rewritten_copy(
        &fixture(),
        &dir,
        |m| {
            m.version = m.version.max(6);
            m.attributes = Some(s);
        },
        |_, _| {},
    );
    let m = Manifest::decode("scene.json", &std::fs::read(dir.join("scene.json")).unwrap()).unwrap();
    for t in &m.tiles {
        let ids = sylva::format::decode_ids("ids", &std::fs::read(dir.join(&t.ids_url)).unwrap()).unwrap();
        let codes = AttributeCodes {
            count: ids.len(),
            columns: vec![ids.iter().map(|i| (i % 3) as u32).collect(), ids.iter().map(|i| (i % 101) as u32).collect()],
        };
        let url = sylva::format::attributes::attributes_url(&t.url);
        std::fs::write(dir.join(url), encode_attributes(&schema, &codes)).unwrap();
    }
    dir
}

fn open_at(scene: &Path) -> OffscreenScene {
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        std::env::set_var("XDG_RUNTIME_DIR", "/tmp");
    }
    OffscreenScene::open(scene.to_str().unwrap(), W, H, POOLS).expect("a GPU adapter")
}

fn style(off: &OffscreenScene, json: serde_json::Value) -> sylva::scene::style::TreeStyle {
    let m = off.stream.manifest().unwrap();
    let species: Vec<String> = m.species.iter().map(|s| s.name.clone()).collect();
    sylva::scene::style::TreeStyle::parse(m.attributes.as_ref(), &species, &json).unwrap()
}

/// Per pool instance: its tree id (from the resident tiles' sidecars, read from disk).
fn pool_ids(off: &OffscreenScene, scene: &Path) -> Vec<Option<u64>> {
    let mut out = vec![None; POOLS.instances as usize];
    for (range, t) in off.stream.tile_locations() {
        let name = Path::new(&t.ids_url).strip_prefix(scene).map_or(PathBuf::from(&t.ids_url), Path::to_path_buf);
        let ids = sylva::format::decode_ids("ids", &std::fs::read(scene.join(name)).unwrap()).unwrap();
        // (t.index: the range's first tree in the tile; a tile held in part has a range per batch.)
        for (k, i) in range.enumerate() {
            out[i as usize] = Some(ids[t.index as usize + k]);
        }
    }
    out
}

/// With the filter `{"kind": "a", "girth": [20, null]}` on the attributed fixture
/// (ids ≡ 0 mod 3 with id mod 101 ≥ 20 pass): the GPU's draw items equal the
/// CPU oracle's given each pool instance's style. Returns the pool's ids, those
/// styles, and the oracle's items drawn whole (side 0) and in all.
fn filtered_draws_match_the_oracle(off: &OffscreenScene, scene: &Path) -> (Vec<Option<u64>>, Vec<u8>, usize, usize) {
    use sylva::lod::select::{cpu_select_styled, unpack_item_y};
    let ids = pool_ids(off, scene);
    let styles: Vec<u8> = ids
        .iter()
        .map(|id| match id {
            Some(i) if i % 3 == 0 && i % 101 >= 20 => 0,
            _ => sylva::scene::style::STYLE_HIDDEN,
        })
        .collect();
    let (gpu, batches, instances, _) = off.read_selection();
    let oracle = cpu_select_styled(off.renderer.last_view(), &batches, &instances, off.renderer.species_table(), |i| {
        styles.get(i as usize).is_some_and(|s| s & sylva::scene::style::STYLE_HIDDEN != 0)
    });
    let (mut whole, mut all) = (0, 0);
    for (slot, (g, c)) in gpu.iter().zip(&oracle.slots).enumerate() {
        let mut g: Vec<(u32, u32)> = g.iter().map(|&(i, y)| (i, unpack_item_y(y).1)).collect();
        let mut c: Vec<(u32, u32)> = c.iter().map(|&(i, y)| (i, unpack_item_y(y).1)).collect();
        g.sort_unstable();
        c.sort_unstable();
        assert_eq!(g, c, "slot {slot}: the filtered draw items differ from the oracle's");
        whole += c.iter().filter(|(_, side)| *side == 0).count();
        all += c.len();
    }
    (ids, styles, whole, all)
}

#[test]
fn a_filter_culls_exactly_the_trees_it_leaves_out() {
    use sylva::lod::select::unpack_item_y;
    let scene = attributed_fixture("filter");
    let mut off = open_at(&scene);
    off.load_view(&Camera::default(), 30.0);
    let m = off.stream.manifest().unwrap().clone();
    let cam = camera(&m);
    off.settings.thin_px = 0.0;
    let drawn = |off: &OffscreenScene| {
        let (slots, _, _, _) = off.read_selection();
        slots.iter().map(|s| s.iter().filter(|(_, y)| unpack_item_y(*y).1 == 0).count()).sum::<usize>()
    };
    off.load_view(&cam, 30.0);
    off.render(&cam, false);
    let all = drawn(&off);
    // Kind "a" with a girth of 20 or more: about a quarter of the trees.
    let filter = style(&off, serde_json::json!({"filter": {"kind": "a", "girth": [20, null]}}));
    off.set_style(Some(filter));
    off.load_view(&cam, 30.0);
    off.render(&cam, false);
    let (_, _, total, _) = filtered_draws_match_the_oracle(&off, &scene);
    let shown = drawn(&off);
    assert_eq!(shown, total);
    eprintln!("filter: {shown} of {all} trees drawn");
    assert!(all > 200 && shown > 20, "too few trees in view ({shown} of {all})");
    assert!((shown as f64) < all as f64 * 0.4, "the filter hid too few trees ({shown} of {all})");
    // No style again: every tree is back.
    off.set_style(None);
    off.render(&cam, false);
    assert_eq!(drawn(&off), all);
}

#[test]
fn a_filter_on_tiles_held_in_part_hides_exactly_its_trees() {
    let scene = attributed_fixture("filter-prefix");
    let mut off = open_at(&scene);
    off.load_manifest(30.0);
    let m = off.stream.manifest().unwrap().clone();
    let c = (DVec3::from(m.bounds.min.map(f64::from)) + DVec3::from(m.bounds.max.map(f64::from))) * 0.5;
    // From 2.5 km above: prefix thinning draws a part of each batch, and only
    // that part is fetched; the style's sidecars hold every tree of the tile.
    let cam = Camera { eye_m: c + DVec3::Z * 2500.0, pitch_rad: -std::f64::consts::FRAC_PI_2, ..Camera::default() };
    let filter = style(&off, serde_json::json!({"filter": {"kind": "a", "girth": [20, null]}}));
    off.set_style(Some(filter));
    off.load_view(&cam, 30.0);
    off.render(&cam, false);
    off.render(&cam, false);
    let (ids, styles, _, shown) = filtered_draws_match_the_oracle(&off, &scene);
    let (_, batches, _, _) = off.read_selection();
    assert!(batches.iter().any(|b| b.flags & sylva::format::tile::BATCH_PARTIAL != 0), "tiles held in part");
    let held = ids.iter().filter(|i| i.is_some()).count();
    let kept = styles.iter().zip(&ids).filter(|(s, i)| i.is_some() && **s == 0).count();
    eprintln!("filter on prefixes: {shown} drawn, {kept} of {held} held trees pass");
    assert!(held < 3000 && shown > 5 && kept < held / 2, "{shown} drawn, {kept} of {held} pass");
}

#[test]
fn a_style_colours_the_trees_it_names_and_a_selection_is_highlighted() {
    let scene = attributed_fixture("colour");
    let mut off = open_at(&scene);
    off.load_view(&Camera::default(), 30.0);
    let m = off.stream.manifest().unwrap().clone();
    let cam = camera(&m);
    let colour =
        style(&off, serde_json::json!({"color": {"by": "kind", "categories": {"a": "#ff0000", "b": "#0000ff"}}}));
    for (name, representations) in [
        ("meshes", Representations::MESHES),
        ("ellipsoids", Representations::CLUSTERS),
        ("far", Representations::BILLBOARDS),
    ] {
        off.settings = RenderSettings { representations, lod_policy: false, thin_px: 0.0, ..RenderSettings::default() };
        off.set_style(Some(colour.clone()));
        off.load_view(&cam, 30.0);
        off.render(&cam, false);
        let img = off.read_image();
        if let Some(dir) = std::env::var_os("SYLVA_PICK_PNG") {
            image::save_buffer(
                PathBuf::from(dir).join(format!("style-{name}.png")),
                &img,
                W,
                H,
                image::ColorType::Rgba8,
            )
            .unwrap();
        }
        let ids = pool_ids(&off, &scene);
        let view = cam.view_data(W, H);
        let (mut right, mut wrong, mut seen) = (0, 0, [0; 3]);
        for gy in 0..9 {
            for gx in 0..16 {
                let (x, y) = (gx * W / 16 + W / 32, gy * H / 9 + H / 18);
                let Some(i) = off.pick_blocking(&view, [x, y]) else { continue };
                let kind = (ids[i as usize].expect("a picked tree has an id") % 3) as usize;
                let k = ((y * W + x) * 4) as usize;
                let [r, g, b] = [img[k], img[k + 1], img[k + 2]].map(i32::from);
                let ok = match kind {
                    0 => r > g && r > b,
                    1 => b > r && b > g,
                    _ => g > r && g > b,
                };
                seen[kind] += 1;
                if ok {
                    right += 1;
                } else {
                    wrong += 1;
                }
            }
        }
        eprintln!("{name}: {right} pixels right, {wrong} wrong, kinds seen {seen:?}");
        assert!(seen.iter().all(|&n| n >= 5), "{name}: too few trees of each kind under the grid: {seen:?}");
        assert!(wrong * 10 <= right, "{name}: {wrong} pixels in the wrong colour against {right}");
    }
    // Select the tree under the middle pixel: it turns yellow there.
    off.settings = RenderSettings { thin_px: 0.0, ..RenderSettings::default() };
    off.set_style(None);
    off.render(&cam, false);
    let view = cam.view_data(W, H);
    let ids = pool_ids(&off, &scene);
    let (x, y) = (W / 2, H * 2 / 3);
    let i = off.pick_blocking(&view, [x, y]).expect("a tree under the lower middle");
    let before = off.read_image();
    off.select([ids[i as usize].unwrap()]);
    // The selection needs the resident tiles' ids: they stream in first.
    off.load_view(&cam, 30.0);
    off.render(&cam, false);
    let after = off.read_image();
    let k = ((y * W + x) * 4) as usize;
    let yellow = |p: &[u8]| i32::from(p[0]) + i32::from(p[1]) - 2 * i32::from(p[2]);
    assert!(
        yellow(&after[k..k + 3]) > yellow(&before[k..k + 3]) + 60,
        "the selected tree is not highlighted: {:?} → {:?}",
        &before[k..k + 3],
        &after[k..k + 3]
    );
    // Pixels of other trees keep their colour.
    let changed = (0..(W * H) as usize).filter(|p| before[p * 4..p * 4 + 3] != after[p * 4..p * 4 + 3]).count();
    assert!(changed < (W * H) as usize / 10, "{changed} pixels changed for one selected tree");
}

/// Far away, thinned batches draw their kept trees bigger (prefix thinning):
/// a click on any foliage pixel still picks a tree (the pick's cull grows the
/// bounds of thinned trees as they are drawn).
#[test]
fn far_thinned_trees_are_picked_where_they_are_drawn() {
    use sylva::offscreen::NamedView;
    let mut off = open();
    off.load_view(&Camera::default(), 30.0);
    let cam = off.named_camera(NamedView::Far, 30.0).unwrap();
    // Thinning from 200 px: the far view's trees (tens of pixels) are thinned hard.
    off.settings = RenderSettings { thin_px: 200.0, ..RenderSettings::default() };
    off.load_view(&cam, 30.0);
    off.render(&cam, true);
    let stats = off.stats_of_last_frame();
    let drawn: u64 = stats.instances.values().sum();
    assert!(drawn < 2000, "the far view is not thinned ({drawn} of 3,000 trees drawn)");
    let img = off.read_image();
    if let Some(dir) = std::env::var_os("SYLVA_PICK_PNG") {
        image::save_buffer(PathBuf::from(dir).join("pick-far.png"), &img, W, H, image::ColorType::Rgba8).unwrap();
    }
    let view = cam.view_data(W, H);
    // Every fifth pixel each way: each kept tree (tens of pixels across) is
    // sampled many times.
    let mut pixels = Vec::new();
    for y in (0..H).step_by(5) {
        for x in (0..W).step_by(5) {
            let k = ((y * W + x) * 4) as usize;
            let [r, g, b] = [img[k], img[k + 1], img[k + 2]].map(i32::from);
            if g > r + 8 && g > b + 8 {
                pixels.push([x, y]);
            }
        }
    }
    // (Thousands of picks: submitted one after another, waited for once.)
    let foliage = pixels.len();
    let picked = off.pick_many_blocking(&view, &pixels).iter().filter(|id| id.is_some()).count();
    eprintln!("far: {picked} of {foliage} foliage pixels picked a tree; instances {:?}", stats.instances);
    assert!(foliage >= 30, "the far view shows too little foliage ({foliage} pixels)");
    assert!(picked * 100 >= foliage * 99, "{picked} of {foliage} foliage pixels picked a tree");
}

/// A copy of the fixture with a timeline (censuses 2008-11-07, 2013-07-01,
/// 2018-07-25): every other batch of each tile is flagged `BATCH_DATED` and its
/// trees died before 2013-07-01 (10 m in 2008); of the other batches' trees,
/// even ids stand throughout (8, 10, 12 m), odd ids grow in from 2013-07-01
/// (6 m in 2018). Returns the scene and the day of each census.
fn timeline_fixture(name: &str) -> (PathBuf, [i64; 3]) {
    use sylva::format::attributes::{
        encode_attributes, null_code, parse_date, AttributeCodes, AttributeColumn, AttributeSchema, AttributeType,
    };
    use sylva::format::tile::BATCH_DATED;
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("timeline-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let days = ["2008-11-07", "2013-07-01", "2018-07-25"].map(|d| parse_date(d).unwrap());
    let column = |name: &str, kind, min: f64, max: f64| AttributeColumn {
        name: name.into(),
        kind,
        width: 2,
        min,
        max,
        categories: Vec::new(),
        count: 1000,
    };
    let heights: Vec<String> =
        ["2008-11-07", "2013-07-01", "2018-07-25"].iter().map(|d| format!("height_{d}")).collect();
    let mut columns = vec![
        column("standing_from", AttributeType::Date, days[1] as f64, days[1] as f64),
        column("standing_until", AttributeType::Date, days[1] as f64, days[1] as f64),
    ];
    columns.extend(heights.iter().map(|h| column(h, AttributeType::Number, 0.0, 20.0)));
    let schema = AttributeSchema { columns };
    let s = schema.clone();
    let mut dated: std::collections::HashMap<String, Vec<bool>> = std::collections::HashMap::new();
    crate::common::rewritten_copy(
        &fixture(),
        &dir,
        |m| {
            m.version = m.version.max(6);
            m.attributes = Some(s);
            m.timeline = Some(sylva::format::timeline::Timeline {
                censuses: vec!["2008-11-07".into(), "2013-07-01".into(), "2018-07-25".into()],
                latest: "2018-07-25".into(),
                from: "standing_from".into(),
                until: "standing_until".into(),
                heights: heights.clone(),
            });
        },
        |tile, entry| {
            let mut flags = vec![false; tile.instances.len()];
            for (k, b) in tile.batches.iter_mut().enumerate() {
                if k % 2 == 0 {
                    b.flags |= BATCH_DATED;
                    let at = b.instance_offset as usize;
                    flags[at..at + b.instance_count as usize].fill(true);
                }
            }
            dated.insert(entry.url.clone(), flags);
        },
    );
    let m = Manifest::decode("scene.json", &std::fs::read(dir.join("scene.json")).unwrap()).unwrap();
    let c = &schema.columns;
    let null = null_code(2);
    for t in &m.tiles {
        let ids = sylva::format::decode_ids("ids", &std::fs::read(dir.join(&t.ids_url)).unwrap()).unwrap();
        let flags = &dated[&t.url];
        let mut cols: Vec<Vec<u32>> = (0..5).map(|_| Vec::with_capacity(ids.len())).collect();
        for (id, &d) in ids.iter().zip(flags) {
            let h = |v: f64| c[2].code_of_number(v);
            let row = if d {
                [null, c[1].code_of_number(days[1] as f64), h(10.0), null, null]
            } else if id % 2 == 0 {
                [null, null, h(8.0), h(10.0), h(12.0)]
            } else {
                [c[0].code_of_number(days[1] as f64), null, null, null, h(6.0)]
            };
            for (col, v) in cols.iter_mut().zip(row) {
                col.push(v);
            }
        }
        let codes = AttributeCodes { count: ids.len(), columns: cols };
        let url = sylva::format::attributes::attributes_url(&t.url);
        std::fs::write(dir.join(url), encode_attributes(&schema, &codes)).unwrap();
    }
    (dir, days)
}

/// The forest at a date (issue 46): a view without one draws no tree of a
/// `BATCH_DATED` batch; at 2010-01-01 the GPU draws exactly the trees standing
/// then (the dated batches' and the even ids'), at 2016-01-01 the others'
/// (the odd ids grown in), each at its size then: its draw items equal the
/// CPU oracle's (`cpu_select_at`) given each tree's standing and growth byte.
#[test]
fn a_date_draws_the_trees_standing_then_at_their_size_then() {
    use sylva::format::timeline::{growth_byte, growth_of_byte};
    use sylva::lod::select::{cpu_select_at, unpack_item_y};
    let (scene, days) = timeline_fixture("dates");
    let mut off = open_at(&scene);
    off.load_view(&Camera::default(), 30.0);
    let m = off.stream.manifest().unwrap().clone();
    let columns = m.timeline.as_ref().unwrap().resolve(m.attributes.as_ref()).unwrap();
    // Every tree's timeline, by id, from the sidecars.
    let mut timelines = std::collections::HashMap::new();
    let schema = m.attributes.as_ref().unwrap();
    for t in &m.tiles {
        let ids = sylva::format::decode_ids("ids", &std::fs::read(scene.join(&t.ids_url)).unwrap()).unwrap();
        let url = sylva::format::attributes::attributes_url(&t.url);
        let bytes = std::fs::read(scene.join(url)).unwrap();
        let codes = sylva::format::attributes::decode_attributes("attr", &bytes, schema, ids.len()).unwrap();
        for (i, id) in ids.iter().enumerate() {
            timelines.insert(*id, columns.tree(schema, &codes, i));
        }
    }
    let cam = camera(&m);
    off.settings.thin_px = 0.0;
    // Per pool instance: (id, in a dated batch).
    let pool = |off: &OffscreenScene| -> Vec<Option<(u64, bool)>> {
        let ids = pool_ids(off, &scene);
        let (_, batches, _, _) = off.read_selection();
        let mut dated = vec![false; ids.len()];
        for b in &batches {
            if b.flags & sylva::format::tile::BATCH_DATED != 0 {
                let at = b.instance_offset as usize;
                dated[at..at + b.instance_count as usize].fill(true);
            }
        }
        ids.iter().zip(dated).map(|(id, d)| id.map(|id| (id, d))).collect()
    };
    // The trees of the whole-drawn items, checked against the oracle given `look`.
    let drawn = |off: &OffscreenScene, dated: bool, look: &dyn Fn(u32) -> Option<f32>| -> Vec<u32> {
        let (gpu, batches, instances, _) = off.read_selection();
        let oracle =
            cpu_select_at(off.renderer.last_view(), &batches, &instances, off.renderer.species_table(), dated, look);
        let mut trees = Vec::new();
        for (slot, (g, c)) in gpu.iter().zip(&oracle.slots).enumerate() {
            let mut g: Vec<(u32, u32)> = g.iter().map(|&(i, y)| (i, unpack_item_y(y).1)).collect();
            let mut c: Vec<(u32, u32)> = c.iter().map(|&(i, y)| (i, unpack_item_y(y).1)).collect();
            g.sort_unstable();
            c.sort_unstable();
            assert_eq!(g, c, "slot {slot}: the draw items at a date differ from the oracle's");
            trees.extend(g.iter().map(|&(i, _)| i));
        }
        trees.sort_unstable();
        trees.dedup();
        trees
    };
    off.load_view(&cam, 30.0);
    off.render(&cam, false);
    let now = drawn(&off, false, &|_| Some(1.0));
    let p = pool(&off);
    assert!(now.len() > 100, "{} trees drawn", now.len());
    assert!(
        now.iter().all(|&i| p[i as usize].is_some_and(|(_, d)| !d)),
        "a view without a date drew a dated batch's tree"
    );
    // The rule, from the fixture's own numbers (not the timeline's code).
    let rule = |id: u64, dated: bool, day: i64| -> Option<f64> {
        let lerp = |d0: i64, h0: f64, d1: i64, h1: f64| h0 + (h1 - h0) * (day - d0) as f64 / (d1 - d0) as f64;
        match (dated, id.is_multiple_of(2)) {
            (true, _) => (day < days[1]).then_some(1.0),
            (false, true) if day < days[1] => Some(lerp(days[0], 8.0, days[1], 10.0).clamp(8.0, 10.0) / 12.0),
            (false, true) => Some(lerp(days[1], 10.0, days[2], 12.0).min(12.0) / 12.0),
            (false, false) => (day >= days[1]).then(|| lerp(days[1], 1.3, days[2], 6.0).min(6.0) / 6.0),
        }
    };
    for date in ["2010-01-01", "2016-01-01"] {
        let day = sylva::format::attributes::parse_date(date).unwrap();
        off.set_day(Some(day));
        off.load_view(&cam, 30.0);
        off.render(&cam, false);
        off.render(&cam, false);
        let p = pool(&off);
        // Each tree as the timeline has it (what the style gave the GPU), and as the rule has it.
        for (id, d) in p.iter().flatten() {
            let t = &timelines[id];
            match (rule(*id, *d, day), t.stands(day)) {
                (Some(g), true) => {
                    assert!((g - t.growth(day)).abs() < 0.002, "tree {id}: {g} against {}", t.growth(day))
                }
                (None, false) => {}
                (g, s) => panic!("tree {id} on {date}: the rule says {g:?}, the timeline standing {s}"),
            }
        }
        let look = |i: u32| -> Option<f32> {
            let (id, _) = p.get(i as usize).copied().flatten()?;
            let t = &timelines[&id];
            t.stands(day).then(|| growth_of_byte(growth_byte(t.growth(day))))
        };
        let trees = drawn(&off, true, &look);
        let standing: Vec<(u64, bool)> = trees.iter().filter_map(|&i| p[i as usize]).collect();
        let (dated, even, odd) = (
            standing.iter().filter(|(_, d)| *d).count(),
            standing.iter().filter(|(id, d)| !d && id % 2 == 0).count(),
            standing.iter().filter(|(id, d)| !d && id % 2 == 1).count(),
        );
        eprintln!("{date}: {} trees drawn: {dated} of dated batches, {even} even, {odd} odd", trees.len());
        assert!(trees.iter().all(|&i| look(i).is_some()), "{date}: a tree not standing then was drawn");
        if day < days[1] {
            assert!(dated > 20 && even > 20 && odd == 0, "{date}: {dated} dated, {even} even, {odd} odd");
        } else {
            assert!(dated == 0 && even > 20 && odd > 20, "{date}: {dated} dated, {even} even, {odd} odd");
        }
        // Picks at the date name trees standing then (in 2010 some of the dated batches').
        let picked = picks(&mut off, &cam);
        assert!(picked.len() >= 20, "{date}: {} picks hit a tree", picked.len());
        assert!(picked.iter().all(|&i| look(i).is_some()), "{date}: a pick named a tree not standing then");
        let of_dated = picked.iter().filter(|&&i| p[i as usize].is_some_and(|(_, d)| d)).count();
        assert_eq!(of_dated > 0, day < days[1], "{date}: {of_dated} picks of the dated batches' trees");
    }
    // No date again: the latest trees, as before.
    off.set_day(None);
    off.render(&cam, false);
    assert_eq!(drawn(&off, false, &|_| Some(1.0)), now);
    let p = pool(&off);
    assert!(picks(&mut off, &cam).iter().all(|&i| p[i as usize].is_some_and(|(_, d)| !d)));
}

/// The pool instances picked on a 16 × 9 grid of pixels of `cam`'s view.
fn picks(off: &mut OffscreenScene, cam: &Camera) -> Vec<u32> {
    let view = cam.view_data(W, H);
    let pixels: Vec<[u32; 2]> =
        (0..9).flat_map(|gy| (0..16).map(move |gx| [gx * W / 16 + W / 32, gy * H / 9 + H / 18])).collect();
    off.pick_many_blocking(&view, &pixels).into_iter().flatten().collect()
}

/// Issue 46, phenology: on 15 January and 15 July the fixture's beech stand
/// (deciduous) covers very different shares of the view, its spruce stand
/// (a conifer) exactly the same. Each stand is drawn alone (a style keeping its
/// trees' ids); its cover is the pixels that differ from the view without trees.
#[test]
fn january_and_july_differ_for_a_deciduous_stand_and_not_for_a_conifer() {
    use sylva::render::settings::SeasonDate;
    let mut off = open_at(&fixture());
    off.load_view(&Camera::default(), 30.0);
    let m = off.stream.manifest().unwrap().clone();
    let cam = camera(&m);
    off.settings.thin_px = 0.0;
    // Each species' tree ids.
    let mut ids_of = vec![Vec::new(); m.species.len()];
    for t in sylva::format::index::read_all_tiles(&fixture(), &m).unwrap() {
        let tile = std::fs::read(fixture().join(&t.url)).unwrap();
        let tile = sylva::format::Tile::decode("t", &tile, m.species.len() as u32).unwrap();
        let ids = sylva::format::decode_ids("ids", &std::fs::read(fixture().join(&t.ids_url)).unwrap()).unwrap();
        for b in &tile.batches {
            let run = b.instance_offset as usize..(b.instance_offset + b.instance_count) as usize;
            ids_of[b.species as usize].extend_from_slice(&ids[run]);
        }
    }
    let mut image = |ids: &[u64], date: &str| {
        off.settings.date = Some(SeasonDate::at_scene(&m, date).unwrap().0);
        let keep = style(&off, serde_json::json!({"filter": {"id": ids}}));
        off.set_style(Some(keep));
        off.load_view(&cam, 30.0);
        off.render(&cam, false);
        off.render(&cam, false);
        off.read_image()
    };
    let bare = image(&[u64::MAX - 1], "2026-07-15");
    let cover = |img: &[u8]| {
        img.chunks(4).zip(bare.chunks(4)).filter(|(a, b)| (0..3).any(|c| a[c].abs_diff(b[c]) > 12)).count()
    };
    let species = |name: &str| m.species.iter().position(|s| s.name == name).unwrap();
    let (beech, spruce) = (&ids_of[species("beech")], &ids_of[species("spruce")]);
    assert!(beech.len() > 100 && spruce.len() > 100);
    let (beech_jan, beech_jul) = (image(beech, "2026-01-15"), image(beech, "2026-07-15"));
    let (spruce_jan, spruce_jul) = (image(spruce, "2026-01-15"), image(spruce, "2026-07-15"));
    let (bj, bl, sj, sl) = (cover(&beech_jan), cover(&beech_jul), cover(&spruce_jan), cover(&spruce_jul));
    eprintln!("cover in pixels: beech January {bj}, July {bl}; spruce January {sj}, July {sl}");
    assert!(bl > 500 && sl > 500, "too little of either stand in view ({bl}, {sl})");
    assert!((bj as f64) < 0.7 * bl as f64, "the beech stand covers {bj} pixels in January, {bl} in July");
    assert_eq!(spruce_jan, spruce_jul, "the spruce stand looks the same in January and July");
}
