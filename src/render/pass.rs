//! What a draw pass is to the renderer: the frame's main render pass and its
//! id pass (picking) run a list of [`DrawPass`]es in order, each recording its
//! own draws, and the renderer's GPU memory is the sum of what each holds (in
//! the spirit of re_renderer's `Renderer` + `DrawData`: the pass owns its
//! pipelines and per-frame data; the frame only orders them). A new pass is
//! one type implementing this trait and one entry in
//! [`super::forest::ForestRenderer`]'s list; its per-frame data is prepared
//! by its own method before the frame is recorded.

use super::gpu_data::ViewUniform;
use super::pools::Pools;
use super::reach::Reach;

/// What every pass may read while it records.
pub struct PassContext<'a> {
    /// The resident trees (batches, instances, draw items).
    pub pools: &'a Pools,
    /// How far each species' trees reach on screen (skips needless draws).
    pub reach: &'a Reach,
    /// The frame being recorded.
    pub frame: &'a FrameData,
}

/// One pass of the frame's main render pass (and of its id pass).
pub trait DrawPass {
    /// Whether it draws in this frame (the sky only when asked for, the
    /// bounds overlay only when debugging).
    fn enabled(&self, _frame: &FrameData) -> bool {
        true
    }

    /// Records its draws (view bound at group 0); returns the draw calls recorded.
    fn draw<'p>(&'p self, pass: &mut wgpu::RenderPass<'p>, cx: &PassContext<'p>) -> u32;

    /// Records its draws into the id pass (each tree writing its pool
    /// instance + 1, the ground 0): nothing by default (the sky, overlays).
    fn draw_ids<'p>(&'p self, _pass: &mut wgpu::RenderPass<'p>, _cx: &PassContext<'p>) -> u32 {
        0
    }

    /// Builds the pipelines of its id pass (the first pick).
    fn build_ids(&self, _device: &wgpu::Device) {}

    /// GPU bytes it holds beyond the shared pools.
    fn gpu_bytes(&self) -> u64 {
        0
    }
}

/// One frame's data, prepared on the CPU and consumed by the passes.
#[derive(Debug, Clone, Copy)]
pub struct FrameData {
    /// The view uniform as written.
    pub view: ViewUniform,
    /// What the species draws need.
    pub species: SpeciesFrame,
    /// Draw the batch-bounds overlay.
    pub debug_bounds: bool,
    /// Clear colour (linear RGBA).
    pub clear: [f64; 4],
    /// Draw the sky first.
    pub sky: bool,
    /// Shadow cascades drawn this frame (0: no shadows).
    pub cascades: u32,
}

/// What the species draws need of a frame.
#[derive(Debug, Clone, Copy)]
pub struct SpeciesFrame {
    /// Half width of the transition bands.
    pub fade_band: f32,
    /// Ellipsoids write their exact depth.
    pub cluster_exact_depth: bool,
    /// Impostors drawn as a moving frame's (`RenderSettings::moving_impostors`).
    pub moving_impostors: bool,
}
