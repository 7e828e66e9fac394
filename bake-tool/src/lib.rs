//! The parts of `sylva-bake` that other crates reach: the glTF importer (for
//! its fuzz target, `fuzz/fuzz_targets/import_gltf.rs`). The rest of the bake
//! lives in the binary.

pub mod gltf_import;
