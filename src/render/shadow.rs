//! Sun shadows: cascaded shadow maps whose casters are chosen on the GPU.
//!
//! Each frame the camera's view is cut into up to [`MAX_CASCADES`] slices by
//! distance; each slice gets an orthographic view from the sun that bounds the
//! slice's sphere (so its size does not change as the camera turns), snapped to
//! whole shadow texels in scene coordinates (so the map does not shimmer as
//! the camera moves), and reaching back towards the sun far enough for every
//! tree that can shade the slice. For each cascade the *same* cull pass as the
//! camera's ([`super::cull`]) runs with the cascade's view: batches and trees
//! against the cascade's box, the representation picked by the tree's size in
//! shadow texels (alpha-tested meshes near, ellipsoids or billboards turned to
//! the sun far). Then the species draws run depth-only into the cascade's layer
//! of a depth array. The CPU work per frame is O(cascades × species).
//!
//! The lit passes look the fragment up in the first cascade that holds it
//! (`shaders/shadow.wgsl`: normal-offset and sun-offset receivers against
//! acne, PCF over bilinear comparisons), fading shadows out towards the
//! shadow distance.

use glam::{DVec3, Mat4, Vec3, Vec4};

use super::gpu_data::ViewUniform;
pub use super::gpu_data::MAX_CASCADES;
use super::layouts::shadow_map;

/// How the sun's shadows are drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ShadowQuality {
    /// No shadows.
    #[default]
    Off,
    /// Two cascades over 300 m (maps of 0.8 texels per screen pixel, 512²–1024²),
    /// one bilinear tap.
    Low,
    /// Three cascades over 600 m (1.6 texels per screen pixel, 512²–2048²),
    /// 3×3 bilinear taps.
    High,
    /// The benchmarks' reference (not offered to users): four 3072² cascades
    /// over the same 600 m, casters at the camera's level of detail.
    Reference,
}

impl ShadowQuality {
    /// Every quality, cheapest first.
    pub const ALL: [ShadowQuality; 3] = [ShadowQuality::Off, ShadowQuality::Low, ShadowQuality::High];

    /// The name used on the command line, in JS and in stats.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            ShadowQuality::Off => "off",
            ShadowQuality::Low => "low",
            ShadowQuality::High => "high",
            ShadowQuality::Reference => "reference",
        }
    }

    /// The cascades of this quality (`None` when off), their maps at their
    /// largest: [`ShadowConfig::fitted`] sizes them to a viewport.
    #[must_use]
    pub fn config(self) -> Option<ShadowConfig> {
        let c = ShadowConfig {
            cascades: 3,
            size: 2048,
            min_size: 512,
            texels_per_px: 1.6,
            distance_m: 600.0,
            pcf_radius: 1,
            lod_scale: 0.5,
            lod_decay: 0.5,
        };
        match self {
            ShadowQuality::Off => None,
            ShadowQuality::Low => Some(ShadowConfig {
                cascades: 2,
                size: 1024,
                min_size: 512,
                texels_per_px: 0.8,
                distance_m: 300.0,
                pcf_radius: 0,
                ..c
            }),
            ShadowQuality::High => Some(c),
            ShadowQuality::Reference => Some(ShadowConfig {
                cascades: 4,
                size: 3072,
                min_size: 3072,
                texels_per_px: 0.0,
                lod_scale: 1.0,
                lod_decay: 1.0,
                ..c
            }),
        }
    }
}

impl std::str::FromStr for ShadowQuality {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        Self::ALL
            .into_iter()
            .find(|q| q.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| format!("unknown shadow quality {s:?}: use off, low or high"))
    }
}

impl std::fmt::Display for ShadowQuality {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The cascades of a [`ShadowQuality`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShadowConfig {
    /// Cascades (1–[`MAX_CASCADES`]).
    pub cascades: u32,
    /// Texels a side of each cascade's map (the largest, before [`Self::fitted`]).
    pub size: u32,
    /// The smallest map [`Self::fitted`] makes.
    pub min_size: u32,
    /// Map texels per screen pixel of the viewport's longer side (0: always `size`):
    /// shadows as sharp on a phone as on a wall screen, at a cost that follows
    /// the screen's.
    pub texels_per_px: f32,
    /// Shadows fade out by this distance from the eye (m; at most the draw distance).
    pub distance_m: f32,
    /// PCF kernel radius in texels (0: one bilinear tap, 1: 3×3 taps).
    pub pcf_radius: u32,
    /// Casters' size in texels is scaled by this before their representation
    /// is picked: a shadow shows a silhouette, softened by the filter, and
    /// needs less detail than the tree seen directly.
    pub lod_scale: f32,
    /// And by this again for each farther cascade: ray-cast ellipsoids cast in
    /// the near cascades, billboards beyond (the far casters are many and small).
    pub lod_decay: f32,
}

impl ShadowConfig {
    /// This configuration with its maps sized for a `viewport` (px): `size`
    /// at most, `min_size` at least, in steps of 256 texels.
    #[must_use]
    pub fn fitted(self, viewport: [u32; 2]) -> Self {
        if self.texels_per_px <= 0.0 {
            return self;
        }
        let want = (viewport[0].max(viewport[1]) as f32 * self.texels_per_px / 256.0).ceil() as u32 * 256;
        Self { size: want.clamp(self.min_size, self.size.max(self.min_size)), ..self }
    }

    /// The LoD scale of cascade `i`'s casters.
    #[must_use]
    pub fn cascade_lod_scale(&self, i: usize) -> f32 {
        self.lod_scale * self.lod_decay.powi(i as i32)
    }

    /// GPU bytes of the shadow map (32-bit depth).
    #[must_use]
    pub fn bytes(&self) -> u64 {
        u64::from(self.size) * u64::from(self.size) * 4 * u64::from(self.cascades)
    }
}

/// One cascade of a frame: the sun's view of a slice of the camera's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cascade {
    /// Clip transform of eye-relative positions (orthographic, reversed Z).
    pub clip_from_eye: Mat4,
    /// Eye-relative planes of the cascade's box (inside: `n·p + d ≥ 0`).
    pub frustum: [Vec4; 6],
    /// Metres per shadow texel.
    pub texel_m: f32,
    /// Distance (m, along the view) where the camera's slice ends.
    pub far_m: f32,
}

/// Fraction of logarithmic (against uniform) spacing of the cascade splits.
const SPLIT_LAMBDA: f32 = 0.85;
/// The first split's nearest distance (m): nothing nearer needs its own texels.
const SPLIT_NEAR_M: f32 = 2.0;

/// The far end of each of `n` cascades out to `distance_m` ("practical" splits:
/// mostly logarithmic, so texels on the ground keep about the same size on screen).
#[must_use]
pub fn split_distances(n: u32, distance_m: f32) -> Vec<f32> {
    let near = SPLIT_NEAR_M.min(distance_m * 0.5);
    (1..=n)
        .map(|i| {
            let t = i as f32 / n as f32;
            let log = near * (distance_m / near).powf(t);
            let lin = near + (distance_m - near) * t;
            SPLIT_LAMBDA * log + (1.0 - SPLIT_LAMBDA) * lin
        })
        .collect()
}

/// The sun's light basis: (right, up, forward), forward pointing away from the sun.
fn light_basis(sun_dir: Vec3) -> (DVec3, DVec3, DVec3) {
    let f = (-sun_dir.as_dvec3()).normalize_or(DVec3::NEG_Z);
    let hint = if f.z.abs() > 0.99 { DVec3::Y } else { DVec3::Z };
    let right = f.cross(hint).normalize();
    let up = right.cross(f);
    (right, up, f)
}

/// The cascades of a frame: `clip_from_eye` the camera's (rotation and infinite
/// reversed-Z projection of eye-relative positions), `eye` its position
/// (scene-relative, f64), `sun_dir` towards the sun, `caster_reach_m` how far
/// towards the sun trees can stand and still shade a slice. Deterministic in
/// its inputs: the same view gives the same cascades, and moving the eye moves
/// each cascade by whole texels.
#[must_use]
pub fn cascades(
    clip_from_eye: Mat4,
    eye: DVec3,
    sun_dir: Vec3,
    config: &ShadowConfig,
    distance_m: f32,
    caster_reach_m: f32,
) -> Vec<Cascade> {
    // The camera's axes and half-angles from its rotation + projection: row 3
    // is the view direction (w = depth), rows 0 and 1 its right and up scaled
    // by 1/tan of the half-angles. Rounded so rotation noise never changes a
    // slice's sphere (its radius must not flicker between texel sizes).
    let row = |i: usize| clip_from_eye.row(i).truncate();
    let round = |v: f32| (v * 1e5).round() / 1e5;
    let forward = row(3).normalize_or(Vec3::Y);
    let tan_x = round(1.0 / row(0).length().max(1e-6));
    let tan_y = round(1.0 / row(1).length().max(1e-6));
    let (right, up, f) = light_basis(sun_dir);
    let size = config.size as f64;
    let splits = split_distances(config.cascades.clamp(1, MAX_CASCADES as u32), distance_m);
    let mut near = 0.0f32;
    let mut out = Vec::with_capacity(splits.len());
    for far in splits {
        // The slice's bounding sphere in camera space: centred on the axis
        // where the near and far corners are equally far (or at the far
        // plane's centre when that is nearer), rounded up to 1/16 m.
        let (n, f_) = (f64::from(near), f64::from(far));
        let k2 = f64::from(tan_x).powi(2) + f64::from(tan_y).powi(2);
        let z = ((n + f_) * 0.5 * (1.0 + k2)).min(f_);
        let radius = ((f_ - z).powi(2) + f_ * f_ * k2).max((z - n).powi(2) + n * n * k2).sqrt();
        let radius = ((radius * 16.0).ceil() / 16.0).max(1.0);
        let centre = forward * z as f32;
        let texel = 2.0 * radius / size;
        // Snap the centre to whole texels of the light's plane, in scene coordinates.
        let c_abs = eye + centre.as_dvec3();
        let (u, v) = (c_abs.dot(right), c_abs.dot(up));
        let (su, sv) = ((u / texel).round() * texel, (v / texel).round() * texel);
        let c_rel = centre.as_dvec3() + right * (su - u) + up * (sv - v);
        let d_near = -(radius + f64::from(caster_reach_m));
        let d_far = radius;
        // Rows: x = right·(p − c)/r, y = up·(p − c)/r, z = (d_far − f·(p − c))/(d_far − d_near), w = 1.
        let depth = d_far - d_near;
        let row = |axis: DVec3, scale: f64, offset: f64| {
            let a = axis * scale;
            [a.x, a.y, a.z, offset - a.dot(c_rel)]
        };
        let rx = row(right, 1.0 / radius, 0.0);
        let ry = row(up, 1.0 / radius, 0.0);
        let rz = row(f, -1.0 / depth, d_far / depth);
        let m = Mat4::from_cols_array_2d(&[
            [rx[0] as f32, ry[0] as f32, rz[0] as f32, 0.0],
            [rx[1] as f32, ry[1] as f32, rz[1] as f32, 0.0],
            [rx[2] as f32, ry[2] as f32, rz[2] as f32, 0.0],
            [rx[3] as f32, ry[3] as f32, rz[3] as f32, 1.0],
        ]);
        out.push(Cascade {
            clip_from_eye: m,
            frustum: crate::camera::frustum_planes(&m),
            texel_m: texel as f32,
            far_m: far,
        });
        near = far;
    }
    out
}

/// The view uniform of `cascade` derived from the camera's `main`: the
/// cascade's projection and box, sizes in texels (`viewport.w` = 1), no draw
/// distance, no prefix thinning, no shadows of its own.
#[must_use]
pub fn cascade_view(main: &ViewUniform, cascade: &Cascade, size: u32) -> ViewUniform {
    ViewUniform {
        clip_from_eye: cascade.clip_from_eye.to_cols_array_2d(),
        frustum: cascade.frustum.map(|p| p.to_array()),
        lod: [1.0 / cascade.texel_m, 1e30, main.lod[2], main.lod[3]],
        eye_from_clip: cascade.clip_from_eye.inverse().to_cols_array_2d(),
        viewport: [size as f32, size as f32, 0.0, 1.0],
        shadow_from_eye: [[[0.0; 4]; 4]; MAX_CASCADES],
        shadow_texel: [0.0; 4],
        shadow: [0.0; 4],
        canopy: [0.0; 4],
        ..*main
    }
}

/// Writes the cascades into the camera's view uniform, for the lit passes.
pub fn apply_to_view(view: &mut ViewUniform, cascades: &[Cascade], config: &ShadowConfig) {
    for (i, c) in cascades.iter().enumerate().take(MAX_CASCADES) {
        view.shadow_from_eye[i] = c.clip_from_eye.to_cols_array_2d();
        view.shadow_texel[i] = c.texel_m;
    }
    let fade_m = cascades.last().map_or(0.0, |c| c.far_m);
    view.shadow = [cascades.len() as f32, config.size as f32, config.pcf_radius as f32, fade_m];
}

/// The shadow map of the current quality and its views.
pub struct ShadowMaps {
    /// The configuration asked for.
    pub requested: ShadowConfig,
    /// That configuration cut to the device's limits: what the map is.
    pub config: ShadowConfig,
    /// All layers, for sampling.
    pub array: wgpu::TextureView,
    /// One view per layer, for drawing.
    pub layers: Vec<wgpu::TextureView>,
}

impl ShadowMaps {
    /// Makes the map for `config`, cut to the device's texture size limit.
    #[must_use]
    pub fn new(device: &wgpu::Device, requested: ShadowConfig) -> Self {
        let config = requested;
        let limits = device.limits();
        let config = ShadowConfig {
            size: config.size.min(limits.max_texture_dimension_2d),
            cascades: config.cascades.clamp(1, (MAX_CASCADES as u32).min(limits.max_texture_array_layers)),
            ..config
        };
        let texture = shadow_map(device, config.size, config.cascades);
        let array = texture.create_view(&wgpu::TextureViewDescriptor {
            label: Some("shadow map array"),
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
        let layers = (0..config.cascades)
            .map(|l| {
                texture.create_view(&wgpu::TextureViewDescriptor {
                    label: Some("shadow cascade"),
                    dimension: Some(wgpu::TextureViewDimension::D2),
                    base_array_layer: l,
                    array_layer_count: Some(1),
                    ..Default::default()
                })
            })
            .collect();
        Self { requested, config, array, layers }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;

    fn setup() -> (Camera, Vec3, ShadowConfig) {
        let cam = Camera::look_at(DVec3::new(100.0, -50.0, 30.0), DVec3::new(150.0, 100.0, 0.0));
        let sun = Vec3::new(0.3, -0.4, 0.8).normalize();
        (cam, sun, ShadowQuality::High.config().unwrap())
    }

    #[test]
    fn splits_grow_to_the_shadow_distance() {
        let s = split_distances(4, 800.0);
        assert_eq!(s.len(), 4);
        assert!(s.windows(2).all(|w| w[1] > w[0]), "{s:?}");
        assert!((s[3] - 800.0).abs() < 1e-2);
        assert!(s[0] < 40.0, "the first cascade stays near: {s:?}");
    }

    #[test]
    fn every_point_of_a_slice_lands_inside_its_cascade() {
        let (cam, sun, config) = setup();
        let v = cam.view_data(1280, 720);
        let cs = cascades(v.clip_from_eye, cam.eye_m, sun, &config, config.distance_m, 200.0);
        let inv = v.clip_from_eye.inverse();
        let mut near = 0.0;
        for c in &cs {
            for (x, y) in [(-1.0, -1.0), (1.0, 1.0), (0.3, -0.7), (0.0, 0.0)] {
                let p = inv * Vec4::new(x, y, 1.0, 1.0);
                let dir = (p.truncate() / p.w).normalize();
                let fwd = cam.forward().as_vec3();
                for depth in [near + 0.01, c.far_m - 0.01] {
                    let q = dir * (depth / dir.dot(fwd));
                    let s = c.clip_from_eye * q.extend(1.0);
                    // (Snapping moves the centre by up to half a texel.)
                    let edge = 1.0 + 1.0 / config.size as f32;
                    assert!(s.x.abs() <= edge && s.y.abs() <= edge, "{s} of {q}");
                    assert!((0.0..=1.0).contains(&s.z), "depth {s}");
                    assert!(c.frustum.iter().all(|pl| pl.truncate().dot(q) + pl.w >= -1e-3));
                    // A caster 150 m towards the sun from it is in the box too.
                    let caster = q + sun * 150.0;
                    let s = c.clip_from_eye * caster.extend(1.0);
                    assert!((0.0..=1.0).contains(&s.z) && s.x.abs() <= edge, "caster {s}");
                }
            }
            near = c.far_m;
        }
    }

    #[test]
    fn cascades_move_by_whole_texels_and_keep_their_size_as_the_camera_turns() {
        let (mut cam, sun, config) = setup();
        let a = cascades(cam.view_data(800, 600).clip_from_eye, cam.eye_m, sun, &config, 800.0, 100.0);
        cam.heading_rad += 0.7;
        cam.eye_m += DVec3::new(3.3, -1.7, 0.0);
        let b = cascades(cam.view_data(800, 600).clip_from_eye, cam.eye_m, sun, &config, 800.0, 100.0);
        for (ca, cb) in a.iter().zip(&b) {
            assert_eq!(ca.texel_m, cb.texel_m, "turning keeps the texel size");
            // A fixed scene point maps to texel grids offset by whole texels.
            let p_scene = DVec3::new(140.0, 60.0, 2.0);
            let texel_of = |c: &Cascade, eye: DVec3| {
                let s = c.clip_from_eye * (p_scene - eye).as_vec3().extend(1.0);
                (s.truncate().truncate() * 0.5 * config.size as f32).to_array()
            };
            let ta = texel_of(ca, DVec3::new(100.0, -50.0, 30.0));
            let tb = texel_of(cb, cam.eye_m);
            for k in 0..2 {
                let d = tb[k] - ta[k];
                assert!((d - d.round()).abs() < 0.02, "offset {d} texels is not whole");
            }
        }
    }

    #[test]
    fn qualities_parse_and_size_their_maps() {
        assert_eq!("HIGH".parse::<ShadowQuality>(), Ok(ShadowQuality::High));
        assert!("medium".parse::<ShadowQuality>().unwrap_err().contains("off, low or high"));
        assert_eq!(ShadowQuality::Off.config(), None);
        let high = ShadowQuality::High.config().unwrap();
        assert_eq!(high.bytes(), 3 * 2048 * 2048 * 4);
        // Maps follow the screen: 1.6 texels per pixel, 1024–2048.
        assert_eq!(high.fitted([640, 360]).size, 1024);
        assert_eq!(high.fitted([1000, 700]).size, 1792);
        assert_eq!(high.fitted([3840, 2160]).size, 2048);
        assert_eq!(ShadowQuality::Low.config().unwrap().fitted([1280, 720]).size, 1024);
        assert_eq!(ShadowQuality::Low.config().unwrap().fitted([320, 240]).size, 512);
        assert_eq!(ShadowQuality::Reference.config().unwrap().fitted([320, 240]).size, 3072);
        assert!(high.cascade_lod_scale(2) < high.cascade_lod_scale(0));
    }
}
