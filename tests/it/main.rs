//! The integration tests of the `sylva` crate, one module a subject, in one
//! test binary: each binary links wgpu and the whole crate, so one binary
//! instead of fifteen saves their links (docs/BENCHMARKS.md, "The test suite's
//! time"). `tests/alloc.rs` and `tests/stress.rs` stay binaries of their own:
//! they measure their process (a counting global allocator, the resident set).
//!
//! Run one module with `cargo test --test it gpu_scene::` or
//! `cargo nextest run --test it gpu_scene::`.

mod common;

mod bench;
mod cli_render;
mod formats;
mod gpu_ao;
mod gpu_clusters;
mod gpu_impostor;
mod gpu_layout;
mod gpu_light;
mod gpu_mesh;
mod gpu_pick;
mod gpu_refine;
mod gpu_scene;
mod gpu_seams;
mod gpu_shadows;
mod gpu_trace;
mod layers;
mod mips;
mod serve;
mod shader_validation;
