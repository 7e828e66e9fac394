//! The readers of untrusted input: every byte is bounded and checked before
//! it is used, and an error names the file (and row, or node) it is about.

pub mod allometry;
pub mod attributes;
pub mod chm;
pub mod dem;
pub mod gis;
pub mod gltf_import;
pub mod names;
pub mod ortho;
pub mod placements;
pub mod reproject;
pub mod stands;
pub mod text;
