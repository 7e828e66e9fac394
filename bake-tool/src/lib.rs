//! The parts of `sylva-bake` that other crates reach: the glTF importer, the
//! DEM reader and the inventory readers (for their fuzz targets in `fuzz/`),
//! the name patterns the importer shares with the binary, and the CRS
//! reprojection the readers use. The rest of the bake lives in the binary.

pub mod dem;
pub mod gltf_import;
pub mod ortho;
pub mod patterns;
pub mod placements;
pub mod reproject;
