//! Sylva: a GPU-driven forest renderer for whole forests in the browser and headless.
//! The modules by layer, top first (`docs/ARCHITECTURE.md`, checked by `tests/it/layers.rs`):
//!
//! * hosts: `cli/` (the binary), [`offscreen`] (native), `web` (wasm), [`bench`], [`serve`].
//! * [`frame`] — one frame of renderer + stream + settings for both hosts, and its stats.
//! * [`render`] — wgpu context and passes (and the billboard capture the bake uses).
//! * [`scene`] — fetching, streaming and residency of scenes; styles and search.
//! * [`lod`] — the level-of-detail rules on the CPU, each the twin of its WGSL.
//! * [`trace`] — the path tracer's geometry on the CPU (rays, BVH), the twin of its WGSL.
//! * [`camera`], [`orbit`], [`geo`], [`sun`], [`metrics`] — view maths, the viewer's camera
//!   controls, lon/lat ↔ scene metres, the sun, image error (Clasen et al. 2010, §4).
//! * [`format`] — the scene manifest, LoD packs, tiles and sidecars (on disk and over the wire).
//! * [`paths`], [`calendar`] — reading untrusted paths and files; calendar days.
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
pub mod phenology;
pub mod render;
pub mod scene;
#[cfg(not(target_arch = "wasm32"))]
pub mod serve;
pub mod sun;
pub mod trace;
#[cfg(target_arch = "wasm32")]
pub mod web;
