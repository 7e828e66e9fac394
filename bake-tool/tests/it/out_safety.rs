//! The output folder promise (docs/SECURITY.md): a bake, demo or merge removes
//! only files that a bake wrote; a folder holding anything else is refused
//! unless `--force`, which keeps those files; a link is followed; leftovers of
//! an interrupted bake are removed by the next one.

use std::collections::BTreeSet;
use std::path::Path;
use std::process::Command;

use crate::common::{bin, fails, run, snapshot, tmp};

/// A quick demo bake (few trees, small textures, no cluster levels).
fn demo(out: &Path, trees: u32, seed: u32) -> Command {
    let mut c = bin();
    c.args(["demo", "--trees", &trees.to_string(), "--seed", &seed.to_string()])
        .args(["--billboard-size", "16", "--texture-size", "16", "--no-clusters", "--cell-size", "16"])
        .args(["--tile-cells", "1"])
        .arg("--out")
        .arg(out);
    c
}

/// The files under `dir` (relative paths).
fn files(dir: &Path) -> BTreeSet<String> {
    snapshot(dir).into_iter().map(|(p, _)| p).collect()
}

/// The files the bake in `dir` says it wrote.
fn owned(dir: &Path) -> BTreeSet<String> {
    let list: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join(".sylva-bake-files.json")).unwrap()).unwrap();
    list["files"].as_array().unwrap().iter().map(|f| f.as_str().unwrap().to_string()).collect()
}

/// Runs `cmd` on `dir` and checks that every file that went away is one that
/// a bake of this test wrote (`written`: the lists of the bakes so far, kept
/// by the test, not by the code under test). Returns the command's stderr.
fn only_own_files_removed(
    dir: &Path,
    cmd: &mut Command,
    should_succeed: bool,
    written: &mut BTreeSet<String>,
) -> String {
    let before = files(dir);
    let out = cmd.output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.success(), should_succeed, "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    let after = files(dir);
    for gone in before.difference(&after) {
        assert!(written.contains(gone), "{gone} was removed but no bake of this test wrote it\n{stderr}");
    }
    if should_succeed {
        written.extend(owned(dir));
    }
    stderr
}

#[test]
fn a_bake_removes_only_files_a_bake_wrote() {
    let dir = tmp("own-files");
    let scene = dir.join("scene");
    run(&mut demo(&scene, 300, 1));
    let first = owned(&scene);
    let mut written = first.clone();
    assert!(first.contains("scene.json") && first.iter().any(|f| f.starts_with("tiles/")), "{first:?}");
    assert_eq!(files(&scene), first.iter().cloned().chain([".sylva-bake-files.json".to_string()]).collect());
    // A re-bake with fewer trees replaces the scene: old tiles it does not
    // write again are removed, and only those.
    only_own_files_removed(&scene, &mut demo(&scene, 40, 2), true, &mut written);
    let second = owned(&scene);
    assert!(second.len() < first.len(), "{} → {} files", first.len(), second.len());
    assert_eq!(files(&scene), second.iter().cloned().chain([".sylva-bake-files.json".to_string()]).collect());
    // Inputs kept in the scene folder: refused, nothing touched.
    std::fs::write(scene.join("trees.csv"), "lon,lat\n15.4,48.4\n").unwrap();
    std::fs::write(scene.join("tiles/notes.txt"), "mine").unwrap();
    let e = only_own_files_removed(&scene, &mut demo(&scene, 40, 3), false, &mut written);
    assert!(e.contains("2 files that no bake wrote") && e.contains("trees.csv") && e.contains("--force"), "{e}");
    // With --force the scene is replaced beside them, and they are kept.
    only_own_files_removed(&scene, demo(&scene, 40, 3).arg("--force"), true, &mut written);
    assert_eq!(std::fs::read_to_string(scene.join("tiles/notes.txt")).unwrap(), "mine");
    assert!(scene.join("trees.csv").exists() && scene.join("scene.json").exists());
    // A bake whose input lies in --out is refused, naming it.
    let glb = scene.join("oak.glb");
    std::fs::write(&glb, b"glTF").unwrap();
    let e = fails(
        bin()
            .args(["bake", "--model"])
            .arg(format!("oak={}", glb.display()))
            .arg("--placements")
            .arg(scene.join("trees.csv"))
            .arg("--out")
            .arg(&scene),
    );
    assert!(e.contains("holds the input") && e.contains("trees.csv"), "{e}");
    // Any folder with a scene.json is no scene: `{}` and a thesis stay.
    let other = dir.join("thesis");
    std::fs::create_dir_all(&other).unwrap();
    std::fs::write(other.join("scene.json"), "{}").unwrap();
    std::fs::write(other.join("thesis.txt"), "four years").unwrap();
    let e = only_own_files_removed(&other, &mut demo(&other, 40, 1), false, &mut written);
    assert!(e.contains("thesis.txt") && e.contains("scene.json"), "{e}");
    // --force keeps them, and does not write over a scene.json it did not write.
    let e = only_own_files_removed(&other, demo(&other, 40, 1).arg("--force"), false, &mut written);
    assert!(e.contains("scene.json") && e.contains("no bake wrote"), "{e}");
    assert_eq!(std::fs::read_to_string(other.join("scene.json")).unwrap(), "{}");
    assert_eq!(files(&other).len(), 2, "no working folder left behind");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_scene_baked_before_file_lists_is_replaced_but_nothing_else() {
    // Scenes from earlier versions have no list: a valid scene.json and the
    // files of the scene layout count as the bake's, nothing else.
    let dir = tmp("legacy");
    let scene = dir.join("scene");
    run(&mut demo(&scene, 100, 1));
    let mut written = owned(&scene);
    std::fs::remove_file(scene.join(".sylva-bake-files.json")).unwrap();
    std::fs::write(scene.join("README.txt"), "about this scene").unwrap();
    std::fs::write(scene.join("tiles/notes.txt"), "mine").unwrap();
    let e = only_own_files_removed(&scene, &mut demo(&scene, 50, 2), false, &mut written);
    assert!(e.contains("README.txt") && e.contains("tiles/notes.txt"), "{e}");
    std::fs::remove_file(scene.join("README.txt")).unwrap();
    std::fs::remove_file(scene.join("tiles/notes.txt")).unwrap();
    only_own_files_removed(&scene, &mut demo(&scene, 50, 2), true, &mut written);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_doctored_list_or_a_planted_link_removes_nothing_of_the_users() {
    let dir = tmp("doctored");
    let scene = dir.join("scene");
    run(&mut demo(&scene, 300, 1));
    let mut written = owned(&scene);
    // The user's files: one beside the scene, one outside reached by a link.
    std::fs::create_dir_all(dir.join("documents")).unwrap();
    std::fs::write(dir.join("documents/important.doc"), "keep").unwrap();
    std::fs::write(dir.join("outside.txt"), "keep").unwrap();
    std::fs::write(scene.join("thesis.txt"), "keep").unwrap();
    #[cfg(unix)]
    std::os::unix::fs::symlink(dir.join("documents"), scene.join("lnk")).unwrap();
    // A list that claims them (and tries to climb out).
    let mut list: serde_json::Value =
        serde_json::from_slice(&std::fs::read(scene.join(".sylva-bake-files.json")).unwrap()).unwrap();
    for f in ["thesis.txt", "lnk", "lnk/important.doc", "../outside.txt", "tiles/../thesis.txt"] {
        list["files"].as_array_mut().unwrap().push(f.into());
    }
    std::fs::write(scene.join(".sylva-bake-files.json"), serde_json::to_vec(&list).unwrap()).unwrap();
    let e = only_own_files_removed(&scene, &mut demo(&scene, 40, 2), false, &mut written);
    assert!(e.contains("thesis.txt"), "the list does not make them the bake's: {e}");
    only_own_files_removed(&scene, demo(&scene, 40, 2).arg("--force"), true, &mut written);
    for kept in [dir.join("documents/important.doc"), dir.join("outside.txt"), scene.join("thesis.txt")] {
        assert_eq!(std::fs::read_to_string(&kept).unwrap(), "keep", "{}", kept.display());
    }
    // A folder of the scene replaced by a link to the user's documents: nothing
    // is written or removed through it.
    #[cfg(unix)]
    {
        std::fs::remove_dir_all(scene.join("species")).unwrap();
        std::os::unix::fs::symlink(dir.join("documents"), scene.join("species")).unwrap();
        let e = only_own_files_removed(&scene, demo(&scene, 40, 3).arg("--force"), false, &mut written);
        assert!(e.contains("species"), "{e}");
        assert_eq!(std::fs::read_dir(dir.join("documents")).unwrap().count(), 1, "nothing written through the link");
        assert!(scene.join("scene.json").exists(), "the old scene is left as it was");
    }
    // A folder beside --out whose name only starts like an old working folder.
    std::fs::create_dir_all(dir.join(".scene.tmp-2023-backup")).unwrap();
    std::fs::remove_file(scene.join("thesis.txt")).unwrap();
    #[cfg(unix)]
    {
        std::fs::remove_file(scene.join("species")).unwrap();
        std::fs::remove_file(scene.join("lnk")).unwrap();
    }
    run(&mut demo(&scene, 40, 4));
    assert!(dir.join(".scene.tmp-2023-backup").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_linked_out_is_followed_and_bad_outs_are_named() {
    let dir = tmp("links");
    let real = dir.join("scenes/v1");
    run(&mut demo(&real, 60, 1));
    #[cfg(unix)]
    {
        let link = dir.join("current");
        std::os::unix::fs::symlink(&real, &link).unwrap();
        let before = std::fs::read(real.join("scene.json")).unwrap();
        run(&mut demo(&link, 30, 2));
        assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink(), "the link is kept");
        assert_ne!(std::fs::read(real.join("scene.json")).unwrap(), before, "the linked scene was rebaked");
        assert_eq!(std::fs::read(link.join("scene.json")).unwrap(), std::fs::read(real.join("scene.json")).unwrap());
        let dangling = dir.join("dangling");
        std::os::unix::fs::symlink(dir.join("nowhere"), &dangling).unwrap();
        let e = fails(&mut demo(&dangling, 30, 2));
        assert!(e.contains("dangling") && e.contains("does not exist"), "{e}");
    }
    // An --out that is a file, or below a file: the message names the path.
    let file = dir.join("a-file");
    std::fs::write(&file, "x").unwrap();
    let e = fails(&mut demo(&file, 30, 1));
    assert!(e.contains("a-file") && e.contains("not a folder"), "{e}");
    let e = fails(&mut demo(&file.join("sub"), 30, 1));
    assert!(e.contains("a-file/sub"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn an_interrupted_bake_leaves_nothing_that_the_next_bake_keeps() {
    let dir = tmp("killed");
    let scene = dir.join("scene");
    run(&mut demo(&scene, 60, 1));
    let before = snapshot(&scene);
    // kill -9 in the middle of a bake: its working folder stays behind...
    // (Its packs built, not taken from the cache: the bake must still be running.)
    let mut child =
        demo(&scene, 3000, 2).env_remove("SYLVA_BAKE_PACK_CACHE").stderr(std::process::Stdio::null()).spawn().unwrap();
    let working = scene.join(format!(".sylva-tmp-{}", child.id()));
    let started = std::time::Instant::now();
    while !working.exists() && started.elapsed().as_secs() < 120 {
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(working.exists(), "the bake was killed while writing");
    // ... the old scene is whole ...
    let old: Vec<_> = snapshot(&scene).into_iter().filter(|(p, _)| !p.starts_with(".sylva-tmp-")).collect();
    assert_eq!(old, before, "the old scene is untouched by the killed bake");
    // ... and the next bake removes it (and the sibling layout of earlier versions).
    let sibling = dir.join(".scene.tmp-999999999");
    std::fs::create_dir_all(sibling.join("tiles")).unwrap();
    let log = String::from_utf8_lossy(&run(&mut demo(&scene, 60, 3)).stderr).into_owned();
    assert!(log.contains("interrupted bake"), "{log}");
    assert!(!working.exists() && !sibling.exists());
    assert!(files(&scene).iter().all(|f| !f.starts_with(".sylva-tmp")));
    std::fs::remove_dir_all(&dir).unwrap();
}
