//! Rendering with wgpu: one module per pass, the long-lived pipelines apart
//! from per-frame data, CPU twins of GPU structs in [`gpu_data`].

pub mod billboard;
pub mod canopy;
#[cfg(not(target_arch = "wasm32"))]
pub mod capture;
pub mod cluster;
pub mod context;
pub mod counters;
pub mod cull;
pub mod forest;
pub mod gpu_data;
pub mod impostor;
pub mod layouts;
pub mod mesh;
pub mod mips;
pub mod overlay;
pub mod pass;
pub mod path_trace;
pub mod pools;
pub mod reach;
pub mod readback;
pub mod refine;
pub mod settings;
pub mod shaders;
pub mod shadow;
pub mod sky_light;
pub mod species;
pub mod terrain;
pub mod top_level;
/// (Native for now: the probe waits for the GPU; the browser's tracer comes with its pass.)
#[cfg(not(target_arch = "wasm32"))]
pub mod trace;

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
    /// Light of a sun in direction `sun_dir` (unit, towards the sun) standing
    /// `elevation_deg` above the horizon: warmer and weaker towards the
    /// horizon (the longer path through the air), gone below it, with the sky
    /// light fading through dusk.
    #[must_use]
    pub fn for_sun(sun_dir: Vec3, elevation_deg: f32) -> Self {
        let day = Self::default();
        let smooth = |a: f32, b: f32, x: f32| {
            let t = ((x - a) / (b - a)).clamp(0.0, 1.0);
            t * t * (3.0 - 2.0 * t)
        };
        let up = smooth(-1.0, 8.0, elevation_deg);
        let high = smooth(2.0, 30.0, elevation_deg);
        let warm = Vec3::new(1.0, 0.72, 0.45).lerp(Vec3::ONE, high);
        let sky = 0.25 + 0.75 * smooth(-8.0, 15.0, elevation_deg);
        Self {
            sun_dir: sun_dir.normalize_or(Vec3::Z),
            sun_color: day.sun_color * warm * up,
            ambient: day.ambient * sky,
        }
    }

    /// Where a scene's sun is worked out: the middle of where its trees are
    /// (scene-relative, at the lowest tree base).
    #[must_use]
    pub fn sun_point(m: &crate::format::Manifest) -> glam::DVec3 {
        let f = m.focus();
        glam::DVec3::new(
            f64::from(f.min[0] + f.max[0]) * 0.5,
            f64::from(f.min[1] + f.max[1]) * 0.5,
            f64::from(f.min[2]),
        )
    }

    /// The light of the sun at `time` over the scene-relative point `local`
    /// of a scene whose CRS `geo` knows; with the sun's position.
    ///
    /// # Errors
    /// The point cannot be turned into lon/lat (a scene CRS proj4rs cannot invert).
    pub fn at_time(
        geo: &crate::geo::GeoFrame,
        local: glam::DVec3,
        time: &crate::sun::SunTime,
    ) -> Result<(Self, crate::sun::SolarPosition), String> {
        let (lon, lat, _) = geo.to_geo(local).map_err(|e| e.to_string())?;
        let p = crate::sun::solar_position(time, lat, lon);
        Ok((Self::at_angles(geo, local, p.azimuth_deg, p.elevation_deg)?, p))
    }

    /// The light of a sun at `azimuth_deg` (clockwise from true north) and
    /// `elevation_deg` over the scene-relative point `local`.
    ///
    /// # Errors
    /// As [`Self::at_time`].
    pub fn at_angles(
        geo: &crate::geo::GeoFrame,
        local: glam::DVec3,
        azimuth_deg: f64,
        elevation_deg: f64,
    ) -> Result<Self, String> {
        let dir = geo.sun_direction(local, azimuth_deg, elevation_deg).map_err(|e| e.to_string())?;
        Ok(Self::for_sun(dir.as_vec3(), elevation_deg as f32))
    }

    /// The view uniform for a lit render of a single tree (previews and captures:
    /// no culling, so no frustum or LoD data), under this light's default sky.
    #[must_use]
    pub fn view_uniform(&self, clip_from_eye: Mat4, eye_m: Vec3, viewport: [u32; 2]) -> ViewUniform {
        self.view_uniform_with(clip_from_eye, eye_m, viewport, self.default_sky())
    }

    /// This light's sky uniform with the default parts, turbidity and leaves
    /// (an SH projection: worked out once per light by callers that draw often).
    #[must_use]
    pub fn default_sky(&self) -> gpu_data::SkyUniform {
        sky_light::SkyLight::new(self, sky_light::DEFAULT_TURBIDITY)
            .uniform(sky_light::LightParts::default(), sky_light::LEAF_TRANSMIT)
    }

    /// [`Self::view_uniform`] with a sky already worked out.
    #[must_use]
    pub fn view_uniform_with(
        &self,
        clip_from_eye: Mat4,
        eye_m: Vec3,
        viewport: [u32; 2],
        sky: gpu_data::SkyUniform,
    ) -> ViewUniform {
        ViewUniform {
            clip_from_eye: clip_from_eye.to_cols_array_2d(),
            eye_hi: eye_m.extend(0.0).to_array(),
            eye_lo: [0.0; 4],
            frustum: [[0.0, 0.0, 0.0, 1.0]; 6],
            sun_dir: self.sun_dir.extend(0.0).to_array(),
            sun_color: self.sun_color.extend(0.0).to_array(),
            // w: the trees' own baked occlusion on (`own_ao` in light.wgsl).
            ambient: self.ambient.extend(1.0).to_array(),
            lod: [0.0; 4],
            params: [RenderMode::Lit as u32, 0, 0, 0],
            eye_from_clip: clip_from_eye.inverse().to_cols_array_2d(),
            viewport: [viewport[0] as f32, viewport[1] as f32, 0.0, 0.0],
            shadow_from_eye: [[[0.0; 4]; 4]; gpu_data::MAX_CASCADES],
            shadow_texel: [0.0; 4],
            shadow: [0.0; 4],
            canopy: [0.0; 4],
            sky,
        }
    }
}
