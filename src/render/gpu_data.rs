//! CPU twins of the structs the shaders read. Each names its WGSL twin.

use bytemuck::{Pod, Zeroable};

/// Per-view constants. Must match `View` in `shaders/common.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct ViewUniform {
    /// Clip transform of eye-relative positions (rotation + projection only).
    pub clip_from_eye: [[f32; 4]; 4],
    /// Eye position relative to the scene origin (xyz), w unused.
    pub eye_m: [f32; 4],
    /// Unit vector towards the sun.
    pub sun_dir: [f32; 4],
    /// Sun colour × intensity.
    pub sun_color: [f32; 4],
    /// Ambient colour.
    pub ambient: [f32; 4],
    /// x: [`RenderMode`] as u32.
    pub params: [u32; 4],
}
const _: () = assert!(std::mem::size_of::<ViewUniform>() == 144);

/// Dequantisation of one mesh level. Must match `MeshParams` in `shaders/mesh.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct MeshUniform {
    /// Position of quantised 0 (xyz).
    pub pos_min: [f32; 4],
    /// Position span of quantised 0..65535 (xyz).
    pub pos_extent: [f32; 4],
    /// Texture coordinate of quantised 0.
    pub uv_min: [f32; 2],
    /// Texture coordinate span.
    pub uv_extent: [f32; 2],
}
const _: () = assert!(std::mem::size_of::<MeshUniform>() == 48);

/// A material. Must match `Material` in `shaders/mesh.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GpuMaterial {
    /// Linear RGBA factor.
    pub base_color: [f32; 4],
    /// Discard below this alpha.
    pub alpha_cutoff: f32,
    /// Texture layer or -1.
    pub layer: i32,
    /// 0 leaf, 1 branch.
    pub kind: u32,
    /// Padding.
    pub pad: u32,
}
const _: () = assert!(std::mem::size_of::<GpuMaterial>() == 32);

/// One instance of the simple (non-GPU-driven) mesh draw. Vertex attributes 4 and 5
/// of `shaders/mesh.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct MeshInstance {
    /// Trunk base relative to the eye (xyz) and yaw in radians (w).
    pub eye_pos_yaw: [f32; 4],
    /// Scale, variation (0–31), unused, unused.
    pub scale_variation: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<MeshInstance>() == 32);

/// What the fragment stage writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum RenderMode {
    /// Shaded colour.
    Lit = 0,
    /// Albedo + normal (billboard capture).
    Capture = 1,
}
