//! The parts of `sylva-bake` that other crates reach: the glTF importer and
//! the DEM reader (for their fuzz targets, `fuzz/fuzz_targets/import_gltf.rs`
//! and `read_dem.rs`) and the name patterns the importer shares with the binary. The rest of the bake lives in the binary.

pub mod dem;
pub mod gltf_import;
pub mod ortho;
pub mod patterns;
