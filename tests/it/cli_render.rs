//! `sylva render` on broken scenes: what can be drawn is drawn, the
//! stats list what failed, and the exit status says the render is incomplete
//! unless `--allow-partial` accepts it. No false "error:" lines from the
//! Vulkan loader on a headless machine.

use std::path::{Path, PathBuf};
use std::process::Command;

fn tmp(name: &str) -> PathBuf {
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("render-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A copy of the test scene.
fn scene_copy(dir: &Path) -> PathBuf {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/forest-small");
    let dst = dir.join("scene");
    let mut stack = vec![PathBuf::new()];
    while let Some(rel) = stack.pop() {
        std::fs::create_dir_all(dst.join(&rel)).unwrap();
        for e in std::fs::read_dir(src.join(&rel)).unwrap() {
            let e = e.unwrap();
            let child = rel.join(e.file_name());
            if e.file_type().unwrap().is_dir() {
                stack.push(child);
            } else {
                std::fs::copy(e.path(), dst.join(&child)).unwrap();
            }
        }
    }
    dst
}

/// Exit success, stats and stderr of a small render of `scene`.
fn render(scene: &Path, view: &str, extra: &[&str]) -> (bool, serde_json::Value, String) {
    let dir = scene.parent().unwrap();
    let (png, stats) = (dir.join(format!("{view}.png")), dir.join(format!("{view}.json")));
    let _ = std::fs::remove_file(&png);
    // No runtime folder, as on a headless machine: the binary makes its own.
    let out = Command::new(env!("CARGO_BIN_EXE_sylva"))
        .env_remove("XDG_RUNTIME_DIR")
        .args(["render", "--scene"])
        .arg(scene)
        .args(["--view", view, "--size", "160x90", "--timeout", "60", "--out"])
        .arg(&png)
        .arg("--stats")
        .arg(&stats)
        .args(extra)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(!stderr.contains("XDG_RUNTIME_DIR"), "the Vulkan loader's false alarm: {stderr}");
    assert!(png.exists(), "the PNG is written in every case: {stderr}");
    let stats = serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
    (out.status.success(), stats, stderr)
}

fn drawn(stats: &serde_json::Value) -> u64 {
    stats["instances"].as_object().unwrap().values().map(|v| v.as_u64().unwrap()).sum()
}

#[test]
fn broken_packs_and_tiles_make_render_fail_unless_partial_is_allowed() {
    let dir = tmp("broken");
    let scene = scene_copy(&dir);
    let (ok, stats, stderr) = render(&scene, "far", &[]);
    assert!(ok, "{stderr}");
    assert_eq!(stats["failed"], serde_json::json!([]), "a whole scene fails nothing");
    let whole = drawn(&stats);
    assert!(whole > 1000, "{whole} trees drawn");
    // The stats say the camera rendered, as --camera takes it: the same view again.
    let camera = stats["camera"].as_str().unwrap().to_string();
    // (Shadows off where they are not what is tested: they are most of a render's
    // time on lavapipe, 6 of 7.8 s; the view's trees are the same without them.)
    let (ok, again, stderr) = render(&scene, "far", &["--camera", &camera, "--shadows", "off"]);
    assert!(ok, "{stderr}");
    let numbers = |s: &serde_json::Value| -> Vec<f64> {
        s["camera"].as_str().unwrap().split(',').map(|v| v.parse().unwrap()).collect()
    };
    let (a, b) = (numbers(&stats), numbers(&again));
    assert!(a.len() == 5 && a.iter().zip(&b).all(|(a, b)| (a - b).abs() < 1e-6), "{a:?} then {b:?}");
    assert_eq!(drawn(&again), whole);
    // A pack of random bytes: the other species are drawn, the render fails.
    let mut noise = 0x1234_5678_9abc_def0u64;
    let random: Vec<u8> = (0..20_000)
        .map(|_| {
            noise ^= noise << 13;
            noise ^= noise >> 7;
            noise ^= noise << 17;
            noise as u8
        })
        .collect();
    std::fs::write(scene.join("species/beech.pack"), &random).unwrap();
    let (ok, stats, stderr) = render(&scene, "far", &[]);
    assert!(!ok, "a render without a species' pack must fail: {stderr}");
    assert!(
        stderr.contains("incomplete") && stderr.contains("beech.pack") && stderr.contains("--allow-partial"),
        "{stderr}"
    );
    let failed = stats["failed"].as_array().unwrap();
    assert!(failed.iter().any(|f| f["url"].as_str().unwrap().ends_with("beech.pack")), "{failed:?}");
    let partial = drawn(&stats);
    assert!(partial > 0 && partial < whole, "the rest is drawn: {partial} of {whole}");
    let (ok, stats, stderr) = render(&scene, "far", &["--allow-partial", "--shadows", "off"]);
    assert!(ok && stderr.contains("warning: the render is incomplete"), "{stderr}");
    assert_eq!(stats["failed"].as_array().unwrap().len(), failed.len());
    // A corrupt tile: dropped, listed, and the render fails.
    std::fs::copy(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/forest-small/species/beech.pack"),
        scene.join("species/beech.pack"),
    )
    .unwrap();
    std::fs::write(scene.join("tiles/0_0.tile"), &random[..4096]).unwrap();
    let (ok, stats, stderr) = render(&scene, "top", &["--shadows", "off"]);
    assert!(!ok, "{stderr}");
    let failed = stats["failed"].as_array().unwrap();
    assert!(failed.iter().any(|f| f["url"].as_str().unwrap().ends_with("tiles/0_0.tile")), "{failed:?}");
    assert!(drawn(&stats) > 0);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Mean of the RGB values of a PNG.
fn brightness(path: &Path) -> f64 {
    let img = image::open(path).unwrap().to_rgb8();
    img.as_raw().iter().map(|&v| f64::from(v)).sum::<f64>() / img.as_raw().len() as f64
}

#[test]
fn a_shadow_study_renders_one_image_per_time_as_the_sun_moves() {
    let dir = tmp("sun");
    let scene = scene_copy(&dir);
    let out = dir.join("study.png");
    let run = |extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_sylva"))
            .env_remove("XDG_RUNTIME_DIR")
            .args(["render", "--scene"])
            .arg(&scene)
            .args(["--view", "top", "--size", "160x90", "--timeout", "60", "--out"])
            .arg(&out)
            .args(extra)
            .output()
            .unwrap()
    };
    // The fixture stands in the Wachau (48.4° N, 15.5° E): on the June solstice
    // the sun rises in the north-east before 05:00 summer time, is due south near
    // 13:15 and has set by 21:15.
    let o = run(&["--sun-time", "2026-06-21T07:00+02:00,2026-06-21T13:15+02:00,2026-06-21T21:30+02:00"]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    let names = ["study-2026-06-21T0700.png", "study-2026-06-21T1315.png", "study-2026-06-21T2130.png"];
    for n in names {
        assert!(dir.join(n).exists(), "{n}: {stderr}");
    }
    let az = |t: &str| -> f64 {
        let line = stderr.lines().find(|l| l.contains(t)).unwrap_or_else(|| panic!("{t}: {stderr}"));
        line.split("azimuth ").nth(1).unwrap().split('°').next().unwrap().parse().unwrap()
    };
    assert!((70.0..110.0).contains(&az("T0700")), "morning sun in the east: {stderr}");
    assert!((170.0..190.0).contains(&az("T1315")), "noon sun in the south: {stderr}");
    assert!(stderr.contains("3 images beside"), "{stderr}");
    // Noon is brightest; after sunset the ground and canopy lose the sun.
    let [morning, noon, night] = names.map(|n| brightness(&dir.join(n)));
    assert!(noon > morning && morning > night + 5.0, "brightness {morning:.1} / {noon:.1} / {night:.1}");
    // Angles instead of a time; bad values are named.
    let o = run(&["--sun", "225,35"]);
    assert!(o.status.success() && out.exists(), "{}", String::from_utf8_lossy(&o.stderr));
    for bad in [["--sun-time", "21.06.2026 15:00"], ["--sun", "225"], ["--sun", "10,120"]] {
        let o = run(&bad);
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && e.contains(bad[0]) && !e.contains("panicked"), "{bad:?}: {e}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// `--date` (issue 46): each deciduous species in its calendar's state at the
/// scene's place then, and the sun at that date: a January view of the
/// fixture (48.4° N) is the leaf-off view under the January noon sun, a July
/// view the leaf-on one under July's; the two differ; a bad date is named.
#[test]
fn a_date_sets_the_seasons_and_the_sun() {
    let dir = tmp("date");
    let scene = scene_copy(&dir);
    let run = |name: &str, extra: &[&str]| -> Vec<u8> {
        let out = dir.join(format!("{name}.png"));
        let o = Command::new(env!("CARGO_BIN_EXE_sylva"))
            .env_remove("XDG_RUNTIME_DIR")
            .args(["render", "--scene"])
            .arg(&scene)
            .args(["--view", "medium", "--size", "160x90", "--timeout", "60", "--out"])
            .arg(&out)
            .args(extra)
            .output()
            .unwrap();
        assert!(o.status.success(), "{name}: {}", String::from_utf8_lossy(&o.stderr));
        image::open(&out).unwrap().to_rgb8().into_raw()
    };
    let january = run("january", &["--date", "2026-01-15"]);
    assert!(january == run("leaf-off", &["--season", "leaf-off", "--sun-time", "2026-01-15T12:00"]));
    let july = run("july", &["--date", "2026-07-15"]);
    assert!(july == run("leaf-on", &["--sun-time", "2026-07-15T12:00"]));
    let differ = january.chunks(3).zip(july.chunks(3)).filter(|(a, b)| a != b).count();
    assert!(differ > 100, "January and July differ in {differ} pixels");
    // The trees go through a change at their own pace: on 2 November (the
    // default calendar half through its leaf fall here) about half the crowns
    // are bare, between 29 October (all in colour) and 15 November (all bare);
    // the same sun for the three.
    let sun = ["--sun", "180,25"];
    let on = |d: &str| run(&format!("fall-{d}"), &["--date", d, sun[0], sun[1]]);
    let (coloured, half, bare) = (on("2026-10-29"), on("2026-11-02"), on("2026-11-15"));
    let differ = |a: &[u8], b: &[u8]| a.chunks(3).zip(b.chunks(3)).filter(|(x, y)| x != y).count() as f64;
    // (Against 29 October: 15 November also changes the far tiers and the
    // canopy to their bare state; 2 November only drops some crowns' leaves.)
    let (all, some) = (differ(&bare, &coloured), differ(&half, &coloured));
    eprintln!("changed since 29 October: by 2 November {some} pixels, by 15 November {all}");
    assert!(all > 100.0 && some > 0.15 * all && some < 0.85 * all, "by 2 November {some}, by 15 November {all} pixels");
    // The date's season wins over --season; a date is checked.
    assert!(july == run("july-over-season", &["--date", "2026-07-15", "--season", "leaf-off"]));
    let o = Command::new(env!("CARGO_BIN_EXE_sylva"))
        .env_remove("XDG_RUNTIME_DIR")
        .args(["render", "--scene"])
        .arg(&scene)
        .args(["--size", "16x16", "--date", "2026-13-01", "--out"])
        .arg(dir.join("bad.png"))
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && e.contains("2026-13-01") && !e.contains("panicked"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

/// `sylva pick` prints the tree at a pixel (its id from the tile's sidecar,
/// species, height, place) or null where none is drawn; bad pixels are refused.
#[test]
fn pick_prints_the_tree_at_a_pixel_or_null() {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/forest-small");
    let pick = |at: &str, view: &str| {
        let out = Command::new(env!("CARGO_BIN_EXE_sylva"))
            .env_remove("XDG_RUNTIME_DIR")
            .args(["pick", "--scene"])
            .arg(&scene)
            .args(["--view", view, "--size", "160x90", "--timeout", "60", "--at", at])
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(!stderr.contains("panicked"), "{stderr}");
        (out.status.success(), String::from_utf8_lossy(&out.stdout).into_owned(), stderr)
    };
    // The medium view's centre is in the forest.
    let (ok, stdout, stderr) = pick("80,45", "medium");
    assert!(ok, "{stderr}");
    let tree: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert!(tree["id"].as_u64().is_some(), "{stdout}");
    assert!(["spruce", "beech", "birch"].contains(&tree["species"].as_str().unwrap()), "{stdout}");
    let height = tree["height"].as_f64().unwrap();
    assert!((5.0..60.0).contains(&height), "{stdout}");
    assert!(tree["lon"].as_f64().is_some_and(|l| (14.0..16.0).contains(&l)), "{stdout}");
    assert!(stderr.contains("picked 80,45 of 160x90: tree "), "{stderr}");
    // The medium view's top row is sky.
    let (ok, stdout, stderr) = pick("80,0", "medium");
    assert!(ok, "{stderr}");
    assert_eq!(stdout.trim(), "null");
    // Outside the image, or not a pixel.
    let (ok, _, stderr) = pick("160,10", "top");
    assert!(!ok && stderr.contains("outside the 160x90 image"), "{stderr}");
    let (ok, _, stderr) = pick("a,b", "top");
    assert!(!ok && stderr.contains("expected X,Y"), "{stderr}");
}

#[test]
fn scene_files_that_are_no_regular_files_fail_at_once_and_are_listed() {
    // A FIFO waited for a writer (render never exited), a link to
    // /dev/zero read gigabytes, a folder or a link loop as a ground image
    // rendered grey with nothing listed. Every local scene file is read as a
    // regular file only: the rest draws, the render lists them and fails.
    // (Link loops: scene::fetch's unit test.)
    let dir = tmp("irregular");
    let scene = scene_copy(&dir);
    let files = |sub: &str, ext: &str| -> Vec<PathBuf> {
        let mut out = Vec::new();
        let mut stack = vec![scene.join(sub)];
        while let Some(d) = stack.pop() {
            for e in std::fs::read_dir(&d).unwrap() {
                let p = e.unwrap().path();
                if p.is_dir() {
                    stack.push(p);
                } else if p.extension().is_some_and(|x| x == ext) {
                    out.push(p);
                }
            }
        }
        assert!(!out.is_empty(), "the fixture has {sub}/**/*.{ext}");
        out
    };
    for p in files("canopy", "cnpy") {
        std::fs::remove_file(&p).unwrap();
        assert!(Command::new("mkfifo").arg(&p).status().unwrap().success());
    }
    for p in files("terrain/img", "jpg") {
        std::fs::remove_file(&p).unwrap();
        std::fs::create_dir(&p).unwrap();
    }
    let (ok, stats, stderr) = render(&scene, "top", &["--shadows", "off"]);
    assert!(!ok && stderr.contains("incomplete"), "{stderr}");
    let failed: Vec<(String, String)> = stats["failed"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| (f["url"].as_str().unwrap().to_string(), f["message"].as_str().unwrap().to_string()))
        .collect();
    for (ext, says) in [(".cnpy", "is a FIFO"), (".jpg", "is a folder")] {
        assert!(
            failed.iter().any(|(u, m)| u.ends_with(ext) && m.contains(says)),
            "no {ext} failure ({says}) among {failed:?}"
        );
    }
    assert!(drawn(&stats) > 1000, "the trees are drawn");
    // query: a tile's ids linked to /dev/zero are refused, not read (2 GB before).
    let ids = std::fs::read_dir(scene.join("tiles"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|x| x == "ids"))
        .unwrap();
    std::fs::remove_file(&ids).unwrap();
    std::os::unix::fs::symlink("/dev/zero", &ids).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_sylva")).args(["query", "--scene"]).arg(&scene).output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && stderr.contains("is a device, not a regular file"), "{stderr}");
    assert!(stderr.contains(ids.file_name().unwrap().to_str().unwrap()), "names the file: {stderr}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `sylva compare` refuses images of different sizes unless told to stretch the
/// second (a frame the governor drew at a lower scale): a stretched copy of an
/// image is close to it, a different image is not.
#[test]
fn compare_stretches_a_smaller_frame_only_when_asked() {
    let dir = tmp("compare-stretch");
    // A smooth gradient at 64×36 and the same at 32×18; a checker at 32×18.
    let grad = |w: u32, h: u32| {
        image::RgbaImage::from_fn(w, h, |x, y| image::Rgba([(x * 255 / w) as u8, (y * 255 / h) as u8, 90, 255]))
    };
    let (a, b, c) = (dir.join("a.png"), dir.join("b.png"), dir.join("c.png"));
    grad(64, 36).save(&a).unwrap();
    grad(32, 18).save(&b).unwrap();
    image::RgbaImage::from_fn(32, 18, |x, y| image::Rgba(if (x + y) % 2 == 0 { [255; 4] } else { [0, 0, 0, 255] }))
        .save(&c)
        .unwrap();
    let compare = |extra: &[&str], other: &Path| {
        Command::new(env!("CARGO_BIN_EXE_sylva")).arg("compare").args(extra).arg(&a).arg(other).output().unwrap()
    };
    let o = compare(&[], &b);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("sizes must match"), "{o:?}");
    let near: f64 = String::from_utf8_lossy(&compare(&["--stretch"], &b).stdout).trim().parse().unwrap();
    let far: f64 = String::from_utf8_lossy(&compare(&["--stretch"], &c).stdout).trim().parse().unwrap();
    assert!(near < 0.02 && far > 0.2, "stretched gradient {near}, checker {far}");
}

#[test]
fn path_trace_writes_the_traced_view_and_refuses_what_it_cannot_trace() {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/forest-small");
    let dir = tmp("path-trace");
    let (png, stats) = (dir.join("traced.png"), dir.join("traced.json"));
    let out = Command::new(env!("CARGO_BIN_EXE_sylva"))
        .args(["render", "--scene"])
        .arg(&scene)
        .args(["--view", "medium", "--size", "48x27", "--path-trace", "--spp", "1", "--out"])
        .arg(&png)
        .arg("--stats")
        .arg(&stats)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{stderr}");
    let s: serde_json::Value = serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
    assert_eq!(s["renderer"], "path-trace");
    assert!(s["trees"].as_u64().unwrap() > 1000 && s["instanced_triangles"].as_u64().unwrap() > 1_000_000, "{s}");
    // The fixture's terrain is traced (its tiles within reach as triangles).
    assert!(s["terrain_triangles"].as_u64().unwrap() > 1000, "{s}");
    let img = image::open(&png).unwrap().to_rgba8();
    let green = img.as_raw().chunks_exact(4).filter(|p| sylva::metrics::is_foliage(p)).count();
    assert!(green > 48 * 27 / 5, "{green} foliage pixels of {}", 48 * 27);
    // What it cannot trace is refused with a reason.
    let refuse = |args: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_sylva")).args(args).output().unwrap();
        assert!(!out.status.success());
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let url = refuse(&[
        "render",
        "--scene",
        "http://127.0.0.1:9/scene.json",
        "--path-trace",
        "--out",
        "/dev/null",
        "--timeout",
        "1",
    ]);
    assert!(url.contains("cannot load the scene") || url.contains("scene directory"), "{url}");
    let spp = refuse(&["render", "--scene", "x", "--spp", "4", "--out", "/dev/null"]);
    assert!(spp.contains("--path-trace"), "{spp}");
}
