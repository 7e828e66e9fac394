//! `sylva-bake` as a library: every stage of the bake, which the binary's
//! command line (`main.rs`), the tests and the fuzz targets (`fuzz/`) reach.
//!
//! - input readers of untrusted files: `gltf_import`, `placements`, `dem`,
//!   `ortho`, `reproject` (CRS), `attributes` (inventory columns);
//! - the stages of a bake: `bake` (`bake_scene` and its steps), `pack_build`,
//!   `clusters`, `cloud`, `ao`, `allometry`, `batching`, `bucket`, `canopy`,
//!   `scene_write`, `out_dir` (the output folder's safety);
//! - tools and exports: `demo`, `country`, `merge`, `inspect`, `tiles3d`;
//! - shared: `patterns` (name patterns), `rng` (seeded random numbers, noise).

pub mod allometry;
pub mod ao;
pub mod attributes;
pub mod bake;
pub mod batching;
pub mod bucket;
pub mod canopy;
pub mod cloud;
pub mod clusters;
pub mod country;
pub mod dem;
pub mod demo;
pub mod gltf_import;
pub mod inspect;
pub mod merge;
pub mod ortho;
pub mod out_dir;
pub mod pack_build;
pub mod patterns;
pub mod placements;
pub mod reproject;
pub mod rng;
pub mod scene_write;
pub mod tiles3d;
