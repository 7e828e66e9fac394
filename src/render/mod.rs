//! Rendering with wgpu: one module per pass, the long-lived pipelines apart
//! from per-frame data, CPU twins of GPU structs in [`gpu_data`].

pub mod billboard;
#[cfg(not(target_arch = "wasm32"))]
pub mod capture;
pub mod cluster;
pub mod context;
pub mod cull;
pub mod forest;
pub mod frame;
pub mod gpu_data;
pub mod layouts;
pub mod mesh;
pub mod mips;
#[cfg(not(target_arch = "wasm32"))]
pub mod offscreen;
pub mod overlay;
pub mod pools;
pub mod reach;
pub mod readback;
pub mod settings;
pub mod shaders;
pub mod species;
pub mod stats;
pub mod terrain;

use glam::{Mat4, Vec3};

pub use context::{ContextError, GpuContext};
use gpu_data::{RenderMode, ViewUniform};

/// The sun and ambient light shared by every representation, so a tree keeps
/// its colour when its level of detail changes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lighting {
    /// Unit vector towards the sun.
    pub sun_dir: Vec3,
    /// Sun colour × intensity (linear).
    pub sun_color: Vec3,
    /// Ambient colour (linear).
    pub ambient: Vec3,
}

impl Default for Lighting {
    fn default() -> Self {
        Self {
            sun_dir: Vec3::new(0.35, -0.45, 0.82).normalize(),
            sun_color: Vec3::new(1.0, 0.96, 0.88) * 0.85,
            ambient: Vec3::new(0.42, 0.46, 0.52),
        }
    }
}

impl Lighting {
    /// The view uniform for a lit render of a single tree (previews and captures:
    /// no culling, so no frustum or LoD data).
    #[must_use]
    pub fn view_uniform(&self, clip_from_eye: Mat4, eye_m: Vec3, viewport: [u32; 2]) -> ViewUniform {
        ViewUniform {
            clip_from_eye: clip_from_eye.to_cols_array_2d(),
            eye_hi: eye_m.extend(0.0).to_array(),
            eye_lo: [0.0; 4],
            frustum: [[0.0, 0.0, 0.0, 1.0]; 6],
            sun_dir: self.sun_dir.extend(0.0).to_array(),
            sun_color: self.sun_color.extend(0.0).to_array(),
            ambient: self.ambient.extend(0.0).to_array(),
            lod: [0.0; 4],
            params: [RenderMode::Lit as u32, 0, 0, 0],
            eye_from_clip: clip_from_eye.inverse().to_cols_array_2d(),
            viewport: [viewport[0] as f32, viewport[1] as f32, 0.0, 0.0],
        }
    }
}
