//! The parts of `sylva-bake` that other crates reach: the glTF importer (for
//! its fuzz target, `fuzz/fuzz_targets/import_gltf.rs`) and the name patterns
//! it shares with the binary. The rest of the bake lives in the binary.

pub mod gltf_import;
pub mod patterns;
