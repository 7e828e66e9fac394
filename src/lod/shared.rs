//! The layouts that the cull shader (`shaders/cull.wgsl`, `shaders/layout.wgsl`)
//! and its CPU twin ([`super::select`]) both read: the view, the species
//! table, the representations. Each names its WGSL twin.

use bytemuck::{Pod, Zeroable};

/// Per-view constants. Must match `View` in `shaders/layout.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct ViewUniform {
    /// Clip transform of eye-relative positions (rotation + projection only).
    pub clip_from_eye: [[f32; 4]; 4],
    /// Eye position relative to the scene origin, high f32 part (xyz); w the
    /// mesh leaves' alpha test: 1 at the textures' full resolution
    /// (`full_res_alpha`), 2 adaptive (`adaptive_alpha`), 0 plain.
    pub eye_hi: [f32; 4],
    /// Low f32 part: `eye_hi + eye_lo` is the f64 eye to ~1e-7 relative; w the
    /// refinement step shifting the dither and hash patterns (`refine_seed`).
    pub eye_lo: [f32; 4],
    /// Frustum planes in eye-relative space (inside: `n·p + d ≥ 0`); unused planes are zero.
    pub frustum: [[f32; 4]; 6],
    /// Unit vector towards the sun.
    pub sun_dir: [f32; 4],
    /// Sun colour × intensity.
    pub sun_color: [f32; 4],
    /// Ambient colour.
    pub ambient: [f32; 4],
    /// x: pixels per metre at 1 m (× quality), y: draw distance (m), z: transition band,
    /// w: culling mode (0 batches, 1 per tree, 2 none).
    pub lod: [f32; 4],
    /// x: `RenderMode` (`crate::render::gpu_data::RenderMode`), y: batch slots to test, z: debug view, w: species count.
    pub params: [u32; 4],
    /// Inverse of `clip_from_eye` (the cluster pass's per-pixel rays).
    pub eye_from_clip: [[f32; 4]; 4],
    /// x, y: viewport size in pixels; z: prefix-thinning threshold (px, 0 off);
    /// w: 1 for an orthographic view whose projected sizes do not shrink with
    /// distance (a shadow cascade: LoD by texel size), else 0.
    pub viewport: [f32; 4],
    /// Per shadow cascade: the cascade's clip transform of eye-relative
    /// positions (orthographic, reversed Z; texel-snapped).
    pub shadow_from_eye: [[[f32; 4]; 4]; MAX_CASCADES],
    /// Per cascade: metres per shadow texel.
    pub shadow_texel: [f32; 4],
    /// x: cascades in use (0: no shadows), y: shadow map size (texels), z: PCF
    /// kernel radius (texels: 0 one tap), w: distance (m) where shadows have faded out.
    pub shadow: [f32; 4],
    /// The canopy cross-fade (`canopy_weight`): x, y the projected heights of a
    /// batch's tallest tree (px × quality) below which its trees are all / begin to be replaced by the
    /// canopy rasters (x = 0: no canopy); zw unused.
    pub canopy: [f32; 4],
    /// The sky and the air (issue 49; `crate::render::sky_light`).
    pub sky: SkyUniform,
}
const _: () = assert!(std::mem::size_of::<ViewUniform>() == 1104);

/// The sky's light, the air between the eye and what it sees, and which of
/// the light's parts are on. Must match `Sky` in `shaders/sky_model.wgsl`;
/// written by `crate::render::sky_light::SkyLight::uniform`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, Pod, Zeroable)]
pub struct SkyUniform {
    /// The irradiance over π that the sky and the ground below the horizon
    /// give a surface facing n, as 9 spherical-harmonic coefficients (rgb)
    /// pre-multiplied by their basis' constants: `sh[0] + sh[1] y + sh[2] z +
    /// sh[3] x + sh[4] xy + sh[5] yz + sh[6] (3z² − 1) + sh[7] xz + sh[8] (x² − y²)`.
    pub sh: [[f32; 4]; 9],
    /// Preetham et al. 1999's Perez coefficients A–E, each for (Y, x, y).
    pub perez: [[f32; 4]; 5],
    /// The zenith's (Y, x, y) over their distribution at the zenith; w: render
    /// units per kcd/m² (times the dusk's fading).
    pub zenith: [f32; 4],
    /// The sun as the sky's fit saw it (xyz); w: the share of a leaf's albedo
    /// it transmits.
    pub sun: [f32; 4],
    /// Rayleigh scattering at the scene origin's height (rgb, per metre); w:
    /// its scale height (m).
    pub rayleigh: [f32; 4],
    /// x: the haze's (Mie) extinction at the scene origin's height (per
    /// metre), y: its scale height (m); zw unused.
    pub mie: [f32; 4],
    /// The light the air scatters towards the eye over a long path: the
    /// sky's radiance at the horizon as a Fourier series in the azimuth φ
    /// (from +x, east, towards +y, north; rgb each): `air[0] + Σk air[2k−1]
    /// cos kφ + air[2k] sin kφ`, k = 1…4.
    pub air: [[f32; 4]; 9],
    /// x: the light's parts that are on (`LIGHT_*` bits); yzw unused.
    pub parts: [u32; 4],
}
const _: () = assert!(std::mem::size_of::<SkyUniform>() == 448);

/// The light's parts (`SkyUniform::parts`), each switchable. Must match
/// `LIGHT_*` in `shaders/sky_model.wgsl`.
/// The clear sky of Preetham et al. 1999 behind the scene (off: the gradient).
pub const LIGHT_SKY: u32 = 1;
/// Aerial perspective: the air's extinction and in-scattering (off: the grey haze).
pub const LIGHT_AERIAL: u32 = 2;
/// The sky's light as spherical harmonics of the sky (off: the flat hemisphere ambient).
pub const LIGHT_SKY_LIGHT: u32 = 4;
/// Leaves that reflect and transmit as the tracer's do (off: the wrap term).
pub const LIGHT_TRANSMISSION: u32 = 8;
/// Shadows whose penumbra follows the sun's size and the occluder's distance (off: fixed PCF).
pub const LIGHT_SOFT_SHADOWS: u32 = 16;
/// Every part.
pub const LIGHT_ALL: u32 = 31;

/// Most shadow cascades a view carries.
pub const MAX_CASCADES: usize = 4;

/// Per-species selection data. Must match `Species` in `shaders/layout.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, Pod, Zeroable)]
pub struct GpuSpecies {
    /// Bounding sphere of the model at scale 1: centre xyz, radius w.
    pub sphere: [f32; 4],
    /// x: model height (m at scale 1); yzw unused.
    pub select: [f32; 4],
    /// Per representation: the projected tree height (px) from which it is drawn
    /// (the coarsest ready one reaches down to 0).
    pub lower_px: [f32; SLOTS_PER_SPECIES],
    /// First draw item of each representation's segment.
    pub slot_base: [u32; SLOTS_PER_SPECIES],
    /// Capacity of each segment (0: representation not ready, never selected).
    pub slot_cap: [u32; SLOTS_PER_SPECIES],
    /// Indices (meshes) or vertices (billboards, clusters) per instance.
    pub index_count: [u32; SLOTS_PER_SPECIES],
}
const _: () = assert!(std::mem::size_of::<GpuSpecies>() == 160);

/// Per-species array length of the representation fields (REPR_COUNT rounded up to vec4s).
pub const SLOTS_PER_SPECIES: usize = 8;

/// Representations a tree can be drawn with, finest first. A draw slot is
/// `species * REPR_COUNT + repr`. Must match `REPR_*` in `shaders/layout.wgsl`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[repr(u32)]
pub enum Repr {
    /// Mesh level 0 (full detail).
    Mesh0 = 0,
    /// Mesh level 1 (simplified).
    Mesh1 = 1,
    /// The billboard cloud (García et al. 2007): the coarsest level's wood and the
    /// leaves on planes.
    Cloud = 2,
    /// The finest cluster level in use (ellipsoids + lines, Clasen et al. 2010).
    Cluster0 = 3,
    /// The next cluster level.
    Cluster1 = 4,
    /// The next cluster level.
    Cluster2 = 5,
    /// The coarsest cluster level in use.
    Cluster3 = 6,
    /// View-angle billboards or multi-view impostors (the far tier).
    Billboard = 7,
}

/// Number of representations (draw slots per species).
pub const REPR_COUNT: u32 = 8;

/// Cluster levels a species can use at once (the levels whose projected size
/// band meets the cluster range).
pub const CLUSTER_TIERS: usize = 4;

impl Repr {
    /// All, finest first.
    pub const ALL: [Repr; 8] = [
        Repr::Mesh0,
        Repr::Mesh1,
        Repr::Cloud,
        Repr::Cluster0,
        Repr::Cluster1,
        Repr::Cluster2,
        Repr::Cluster3,
        Repr::Billboard,
    ];

    /// The cluster tiers.
    pub const CLUSTERS: [Repr; CLUSTER_TIERS] = [Repr::Cluster0, Repr::Cluster1, Repr::Cluster2, Repr::Cluster3];

    /// Name used in stats (`instances` keys): cluster tiers all count as `ellipsoid`.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Repr::Mesh0 => "mesh0",
            Repr::Mesh1 => "mesh1",
            Repr::Cloud => "cloud",
            Repr::Cluster0 | Repr::Cluster1 | Repr::Cluster2 | Repr::Cluster3 => "ellipsoid",
            Repr::Billboard => "billboard",
        }
    }

    /// The cluster tier (0–3) of a cluster representation.
    #[must_use]
    pub fn cluster_tier(self) -> Option<usize> {
        match self {
            Repr::Cluster0 => Some(0),
            Repr::Cluster1 => Some(1),
            Repr::Cluster2 => Some(2),
            Repr::Cluster3 => Some(3),
            _ => None,
        }
    }
}
