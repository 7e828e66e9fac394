//! Sylva: a GPU-driven forest renderer for whole forests in the browser and headless.
//!
//! * [`camera`] — the camera and the view maths every layer shares (ground floor).
//! * [`geo`] — lon/lat ↔ scene-relative metres through the scene CRS.
//! * [`format`] — the scene manifest, LoD packs and tiles (on disk and over the wire).
//! * [`render`] — wgpu context and passes (mesh; the billboard capture used by the bake).
//! * [`metrics`] — image error (multi-scale RMSE, Clasen et al. 2010, §4).
//! * [`bench`] — `sylva bench`: run time against image error on camera paths (native).
//! * [`scene`] — fetching, streaming and residency of scenes.
//! * [`paths`] — relative paths from untrusted text (URIs, request paths).
//!
//! The bake tool (`bake-tool/`, crate `sylva-bake`) writes what this crate reads.

#[cfg(not(target_arch = "wasm32"))]
pub mod bench;
pub mod calendar;
pub mod camera;
pub mod format;
pub mod frame;
pub mod geo;
pub mod lod;
pub mod metrics;
#[cfg(not(target_arch = "wasm32"))]
pub mod offscreen;
pub mod orbit;
pub mod paths;
pub mod render;
pub mod scene;
#[cfg(not(target_arch = "wasm32"))]
pub mod serve;
pub mod sun;
#[cfg(target_arch = "wasm32")]
pub mod web;
