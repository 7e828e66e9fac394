//! `sylva-bake` as a library: every part of the bake, which the binary's
//! command line (`main.rs`, `cli/`), the tests and the fuzz targets (`fuzz/`)
//! reach.
//!
//! - `input/`: the readers of untrusted input (glTF trees, inventories as CSV or
//!   GeoJSON, DEM and orthophoto GeoTIFFs, CRS reprojection, attribute columns,
//!   allometry tables);
//! - `bake/`: the bake as one pipeline of stages (`bake_scene`: trees, ground,
//!   packs, tiles, terrain, imagery, write) and what they build with (batching,
//!   buckets, the canopy quadtree, the scene writer);
//! - `pack/`: the LoD pack builder (mesh levels, billboards, impostors, cluster
//!   levels, billboard clouds, the trees' own occlusion);
//! - `export/`: other formats (3D Tiles);
//! - `demo/`: the procedural demo scenes (a valley, a country);
//! - `merge`, `inspect`: the tools on baked scenes; `out_dir`: the output
//!   folder's safety; `patterns`, `rng`: shared helpers.

pub mod bake;
pub mod demo;
pub mod export;
pub mod input;
pub mod inspect;
pub mod library;
pub mod merge;
pub mod out_dir;
pub mod pack;
pub mod patterns;
pub mod rng;
