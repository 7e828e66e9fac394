//! `sylva-bindgen WASM OUT_DIR`: the JS glue of the browser viewer, as
//! `wasm-bindgen --target web --no-typescript --out-dir OUT_DIR WASM` writes it
//! (the same library, `wasm-bindgen-cli-support`, with the CLI's defaults).
//!
//! Why not the CLI: `cargo install wasm-bindgen-cli` also builds its test
//! runner's web server, TLS and compression stacks in release — 6 minutes of a
//! fresh 2-core CI machine for a tool that runs for seconds (docs/BENCHMARKS.md,
//! "The test suite's time"). This crate builds with the workspace, in the
//! workspace's lockfile, at the version the `sylva` crate pins.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{bail, Context, Result};

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [wasm, out] = &args[..] else {
        bail!("usage: sylva-bindgen WASM OUT_DIR (the viewer's wasm32 build, e.g. target/wasm32-unknown-unknown/release/sylva.wasm, and the folder for its glue, e.g. web/pkg)");
    };
    let (wasm, out) = (PathBuf::from(wasm), PathBuf::from(out));
    if !wasm.is_file() {
        bail!(
            "{}: no such file (build it first: make web, or cargo rustc --release -p sylva --lib --crate-type cdylib --target wasm32-unknown-unknown)",
            wasm.display()
        );
    }
    wasm_bindgen_cli_support::Bindgen::new()
        .input_path(&wasm)
        .web(true)?
        .typescript(false)
        // The CLI's default (the library's is to omit it): `init()` without
        // arguments fetches the wasm beside the glue.
        .omit_default_module_path(false)
        .generate(&out)
        .with_context(|| format!("generating the JS glue of {} into {}", wasm.display(), out.display()))
}
