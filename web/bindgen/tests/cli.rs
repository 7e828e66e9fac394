//! `sylva-bindgen` refuses what it cannot use with a message that says what to
//! do. (Its output is checked where it is used: `make web` builds the viewer's
//! glue with it and the browser tests load that viewer.) Being an integration
//! test, this also makes the test build produce target/debug/sylva-bindgen with
//! the workspace's features, which `make web` then runs without a rebuild.

use std::process::Command;

fn bindgen(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_sylva-bindgen")).args(args).output().expect("run sylva-bindgen");
    (out.status.success(), String::from_utf8_lossy(&out.stderr).into_owned())
}

#[test]
fn without_arguments_it_prints_its_usage() {
    let (ok, err) = bindgen(&[]);
    assert!(!ok);
    assert!(err.contains("usage: sylva-bindgen WASM OUT_DIR"), "{err}");
}

#[test]
fn a_missing_wasm_is_named_with_the_command_that_builds_it() {
    let dir = std::env::temp_dir().join(format!("sylva-bindgen-test-{}", std::process::id()));
    let missing = dir.join("nothing.wasm");
    let (ok, err) = bindgen(&[missing.to_str().unwrap(), dir.to_str().unwrap()]);
    assert!(!ok);
    assert!(err.contains("nothing.wasm: no such file"), "{err}");
    assert!(err.contains("--target wasm32-unknown-unknown"), "{err}");
    assert!(!dir.exists(), "nothing is written for a missing input");
}

#[test]
fn a_file_that_is_not_wasm_is_refused() {
    let dir = std::env::temp_dir().join(format!("sylva-bindgen-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("bad.wasm");
    std::fs::write(&bad, b"not a wasm module").unwrap();
    let out = dir.join("pkg");
    let (ok, err) = bindgen(&[bad.to_str().unwrap(), out.to_str().unwrap()]);
    assert!(!ok);
    assert!(err.starts_with("error: "), "{err}");
    assert!(!out.join("sylva.js").exists() && !out.join("bad.js").exists(), "no glue for a bad input");
    std::fs::remove_dir_all(&dir).ok();
}
