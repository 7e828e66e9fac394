//! Multi-view impostors: each tree's far field as views from a hemi-octahedral
//! grid of directions (colour, coverage, normal, depth, occlusion per view),
//! blended three at a time per pixel with parallax from depth, so a tree does
//! not turn with the camera. Shader: `shaders/impostor.wgsl` (grid math in
//! `shaders/impostor_views.wgsl`, mirrored here as the CPU oracle and for the
//! bake's capture).

use glam::{Mat4, Vec2, Vec3};

use super::billboard::{FarTierPipeline, BILLBOARD_VERTICES};
use super::layouts::SharedLayouts;
use super::mesh::upload_texture_array;
use super::shaders;
use crate::format::pack::{kind, ImpostorMeta};
use crate::format::Pack;

/// Vertices per impostor (one quad, two triangles).
pub const IMPOSTOR_VERTICES: u32 = BILLBOARD_VERTICES;

/// A direction of the upper hemisphere (z below 0 is clamped to the horizon)
/// → grid coordinates in [0, 1]²: the octahedral projection turned 45°, the
/// horizon on the square's border and straight up at its centre.
#[must_use]
pub fn hemi_oct_encode(d: Vec3) -> Vec2 {
    let v = Vec3::new(d.x, d.y, d.z.max(0.0));
    let p = Vec2::new(v.x, v.y) / (v.x.abs() + v.y.abs() + v.z).max(1e-8);
    Vec2::new(p.x + p.y, p.x - p.y) * 0.5 + 0.5
}

/// Grid coordinates → unit direction.
#[must_use]
pub fn hemi_oct_decode(g: Vec2) -> Vec3 {
    let e = g * 2.0 - 1.0;
    let x = (e.x + e.y) * 0.5;
    let y = (e.x - e.y) * 0.5;
    Vec3::new(x, y, (1.0 - x.abs() - y.abs()).max(0.0)).normalize()
}

/// Direction (from the tree towards the camera) of view `layer` (row · grid + column).
#[must_use]
pub fn view_dir(layer: u32, grid: u32) -> Vec3 {
    let n = (grid - 1) as f32;
    hemi_oct_decode(Vec2::new((layer % grid) as f32, (layer / grid) as f32) / n)
}

/// Image axes (right, up) of the view looking back along `d`.
#[must_use]
pub fn view_axes(d: Vec3) -> (Vec3, Vec3) {
    let r = Vec3::Z.cross(d);
    let right = if r.length_squared() < 1e-8 { Vec3::Y } else { r.normalize() };
    (right, d.cross(right))
}

/// The three views around unit direction `d` and their blend weights
/// (barycentric in the grid triangle that holds `d`; they sum to 1).
#[must_use]
pub fn blend_views(d: Vec3, grid: u32) -> [(u32, f32); 3] {
    let n = (grid - 1) as f32;
    let f = hemi_oct_encode(d) * n;
    let cell = f.floor().clamp(Vec2::ZERO, Vec2::splat(n - 1.0));
    let t = (f - cell).clamp(Vec2::ZERO, Vec2::ONE);
    let (cx, cy) = (cell.x as u32, cell.y as u32);
    let at = |x: u32, y: u32| y * grid + x;
    if t.x + t.y <= 1.0 {
        [(at(cx, cy), 1.0 - t.x - t.y), (at(cx + 1, cy), t.x), (at(cx, cy + 1), t.y)]
    } else {
        [(at(cx + 1, cy + 1), t.x + t.y - 1.0), (at(cx, cy + 1), 1.0 - t.x), (at(cx + 1, cy), 1.0 - t.y)]
    }
}

/// Clip-from-model transform of view `layer`'s orthographic capture (reversed
/// Z): the sphere (`center`, `radius`) fills the image, and depth 1 … 0 maps to
/// +radius … −radius along the view direction ([`depth_to_offset`]).
#[must_use]
pub fn capture_clip_from_model(center: Vec3, radius: f32, layer: u32, grid: u32) -> Mat4 {
    let d = view_dir(layer, grid);
    let (_, up) = view_axes(d);
    let eye = center + d * (radius * 2.0);
    let view = glam::camera::rh::view::look_at_mat4(eye, center, up);
    // near and far swapped: reversed Z, like every other pass.
    let proj = glam::camera::rh::proj::directx::orthographic(-radius, radius, -radius, radius, radius * 3.0, radius);
    proj * view
}

/// A captured reversed-Z depth → offset from the sphere's centre along the
/// view direction, as a fraction of the radius (−1 … 1).
#[must_use]
pub fn depth_to_offset(depth: f32) -> f32 {
    depth * 2.0 - 1.0
}

/// The byte of a surface texel's alpha: occlusion with the leaf flag.
#[must_use]
pub fn pack_ao_leaf(ao: f32, leaf: bool) -> u8 {
    u8::from(leaf) * 128 + (ao.clamp(0.0, 1.0) * 127.0).round() as u8
}

/// The impostor pipeline (`shaders/impostor.wgsl`): colour, surface, sampler.
pub type ImpostorPipeline = FarTierPipeline;

/// The impostors' pipelines for `color_format` targets.
#[must_use]
pub fn impostor_pipeline(
    device: &wgpu::Device,
    shared: &SharedLayouts,
    color_format: wgpu::TextureFormat,
) -> ImpostorPipeline {
    FarTierPipeline::new(device, shared, color_format, "impostor", &shaders::IMPOSTOR.source(), 2, true)
}

/// One species' impostor arrays on the GPU.
pub struct ImpostorGpu {
    /// Group 1 of the impostor pipeline.
    pub bind_group: wgpu::BindGroup,
    /// The metadata (grid, sphere).
    pub meta: ImpostorMeta,
    /// Bytes uploaded.
    pub bytes: u64,
    /// Half extents of the model's box about the sphere's centre.
    pub half_extent: [f32; 3],
}

impl ImpostorGpu {
    /// Uploads the impostor arrays of `pack` of far-tier state `state` (0
    /// leaf-on, 1 a deciduous species' bare wood), if it has them.
    #[must_use]
    pub fn upload(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        state: u32,
        pipeline: &ImpostorPipeline,
        pack: &Pack<'_>,
    ) -> Option<Self> {
        let meta = pack.meta.impostors.clone()?;
        let color = pack.section(kind::IMPOSTOR_COLOR, state)?;
        let surface = pack.section(kind::IMPOSTOR_SURFACE, state)?;
        let color_tex = upload_texture_array(
            device,
            queue,
            "impostor colour",
            &meta.texture,
            color,
            wgpu::TextureFormat::Rgba8UnormSrgb,
        );
        let surface_tex = upload_texture_array(
            device,
            queue,
            "impostor surface",
            &meta.texture,
            surface,
            wgpu::TextureFormat::Rgba8Unorm,
        );
        let bind_group = pipeline.bind_group(device, "impostor textures", &[&color_tex, &surface_tex]);
        // The box about the sphere's centre (the centre is the box's own).
        let c = glam::Vec3::from(meta.center);
        let half = meta.half_extent.map_or_else(
            || (glam::Vec3::from(pack.meta.bounds_max) - c).max(c - glam::Vec3::from(pack.meta.bounds_min)),
            glam::Vec3::from,
        );
        Some(Self { bind_group, bytes: (color.len() + surface.len()) as u64, meta, half_extent: half.to_array() })
    }

    /// Fills the draw params of the far-tier slot: ids.w the grid, bb_center
    /// the sphere (centre, radius), bb_size the box's half extents (xyz) and
    /// the variants captured (w).
    pub fn draw_params(&self, params: &mut super::gpu_data::DrawParams) {
        params.ids[3] = self.meta.grid;
        params.bb_center = [self.meta.center[0], self.meta.center[1], self.meta.center[2], self.meta.radius];
        let variants = self.meta.variants.unwrap_or(1) as f32;
        params.bb_size = [self.half_extent[0], self.half_extent[1], self.half_extent[2], variants];
        // The normals' agreement per mip (1 where the pack has none).
        let r = |m: usize| self.meta.normal_length.get(m).copied().unwrap_or(1.0);
        params.bounds_min = [r(0), r(1), r(2), r(3)];
        params.bounds_extent = [r(4), r(5), r(6), r(7)];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_round_trips_and_covers_the_hemisphere() {
        for grid in [2, 5, 8, 12] {
            for layer in 0..grid * grid {
                let d = view_dir(layer, grid);
                assert!((d.length() - 1.0).abs() < 1e-5 && d.z >= 0.0);
                let w = blend_views(d, grid);
                // A view's own direction selects it alone.
                let own: f32 = w.iter().filter(|(l, _)| *l == layer).map(|(_, w)| w).sum();
                assert!((own - 1.0).abs() < 1e-4, "grid {grid} layer {layer}: {w:?}");
            }
        }
        // The horizon is the border, straight up the centre.
        assert!((hemi_oct_encode(Vec3::Z) - Vec2::splat(0.5)).length() < 1e-6);
        let g = hemi_oct_encode(Vec3::X);
        assert!(g.x == 1.0 || g.y == 1.0 || g.x == 0.0 || g.y == 0.0, "{g}");
    }

    #[test]
    fn weights_are_barycentric_and_reproduce_the_direction() {
        let grid = 8;
        for i in 0..500 {
            let a = i as f32 * 2.399;
            let e = (i as f32 * 0.37).sin().abs() * 1.5;
            let d = Vec3::new(a.cos() * e.cos(), a.sin() * e.cos(), e.sin()).normalize();
            let w = blend_views(d, grid);
            let sum: f32 = w.iter().map(|(_, w)| w).sum();
            assert!((sum - 1.0).abs() < 1e-5 && w.iter().all(|(l, w)| *w >= -1e-6 && *l < grid * grid), "{w:?}");
            // The weights interpolate the grid coordinates back to the direction's.
            let g: Vec2 =
                w.iter().map(|(l, w)| Vec2::new((l % grid) as f32, (l / grid) as f32) / (grid - 1) as f32 * *w).sum();
            assert!((g - hemi_oct_encode(d)).length() < 1e-4, "{d}: {g} vs {}", hemi_oct_encode(d));
        }
    }

    #[test]
    fn capture_depth_maps_the_sphere() {
        let (c, r) = (Vec3::new(0.5, -0.2, 6.0), 5.0);
        for layer in [0, 7, 27, 63] {
            let d = view_dir(layer, 8);
            let m = capture_clip_from_model(c, r, layer, 8);
            for (off, want) in [(r, 1.0), (0.0, 0.0), (-r, -1.0)] {
                let p = m.project_point3(c + d * off);
                assert!((depth_to_offset(p.z) - want).abs() < 1e-4, "layer {layer} offset {off}: depth {}", p.z);
                assert!(p.x.abs() < 1e-4 && p.y.abs() < 1e-4);
            }
            // Image right and up are the view's axes.
            let (right, up) = view_axes(d);
            let p = m.project_point3(c + right * r * 0.5 + up * r * 0.25);
            assert!((p.x - 0.5).abs() < 1e-4 && (p.y - 0.25).abs() < 1e-4, "{p}");
        }
    }
}
