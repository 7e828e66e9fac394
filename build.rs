//! Minifies the WGSL modules of `shaders/` into `OUT_DIR` for
//! `src/render/shaders.rs`: line comments, indentation and blank lines out
//! (WGSL has no string literals, so `//` always starts a comment). The wasm
//! carries about 73 KB of shader text instead of 128 (issue 47); the sources
//! in `shaders/` stay as written.

use std::path::Path;

fn main() {
    println!("cargo:rerun-if-changed=shaders");
    let out = std::env::var("OUT_DIR").expect("OUT_DIR");
    let mut names: Vec<_> = std::fs::read_dir("shaders")
        .expect("shaders/")
        .map(|e| e.expect("an entry of shaders/").path())
        .filter(|p| p.extension().is_some_and(|e| e == "wgsl"))
        .collect();
    names.sort();
    for path in names {
        println!("cargo:rerun-if-changed={}", path.display());
        let source = std::fs::read_to_string(&path).expect("a WGSL module");
        let mut min = String::with_capacity(source.len());
        for line in source.lines() {
            let code = line.split("//").next().unwrap_or("").trim();
            if !code.is_empty() {
                min.push_str(code);
                min.push('\n');
            }
        }
        let file = path.file_name().expect("a file name");
        std::fs::write(Path::new(&out).join(file), min).expect("write a minified module");
    }
}
