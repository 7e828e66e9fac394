//! Level of detail on the CPU: every rule that decides what a tree is drawn
//! with, free of the GPU, each beside (and naming) its WGSL twin in
//! `shaders/cull.wgsl` and `shaders/select.wgsl`. `scene/` reads them to
//! stream what a view will draw, `render/` to lay out the species table the
//! cull shader reads, tests to check the GPU's selection.
//!
//! - [`shared`]: the layouts the cull shader and these rules both read (the
//!   view, the species table, the representations);
//! - [`select`]: the cull's selection (batches, trees, representation bands,
//!   prefix thinning, the canopy cross-fade);
//! - [`bands`]: the representation choice (from what projected height each
//!   representation takes over), for the species table and for streaming;
//! - [`policy`]: the bake's LoD policy (which representation is the default at
//!   a size, from the measured error and time).

pub mod bands;
pub mod policy;
pub mod select;
pub mod shared;
