//! The sky as the raster lights with it (issue 49): the clear sky of Preetham,
//! Shirley & Smits 1999 — the path tracer's ([`crate::trace::sky`]) — behind
//! the scene, in the air between the eye and what it sees (aerial
//! perspective), and as the light it gives a surface of any facing:
//! the sky's radiance, with the level ground below the horizon the tracer
//! puts there, projected onto spherical harmonics to order 2 and convolved
//! with the cosine lobe (Ramamoorthi & Hanrahan 2001, "An Efficient
//! Representation for Irradiance Environment Maps", §3, eq. 7–8) once per
//! sun change. The shaders' side is `shaders/light.wgsl`; the uniform
//! [`SkyUniform`] travels in the view.

use std::fmt;
use std::str::FromStr;

use bytemuck::Zeroable;
use glam::Vec3;

use crate::lod::shared::{
    SkyUniform, LIGHT_AERIAL, LIGHT_ALL, LIGHT_SKY, LIGHT_SKY_LIGHT, LIGHT_SOFT_SHADOWS, LIGHT_TRANSMISSION,
};
use crate::trace::sky::{PreethamSky, UNITS_PER_KCD};

/// The air's turbidity by default (Preetham et al. 1999: 2 very clear, 3 clear, 6 hazy).
pub const DEFAULT_TURBIDITY: f32 = 3.0;
/// The share of a leaf's albedo it transmits (the rest it reflects): the
/// tracer's leaf model (`PathOptions::leaf_transmit`) and the raster's.
pub const LEAF_TRANSMIT: f32 = 0.3;
/// The albedo of the level ground the sky's light sees below the horizon
/// (the tracer's beyond what it traces, the raster's background).
pub const GROUND_ALBEDO: Vec3 = Vec3::new(0.16, 0.15, 0.08);

/// Rayleigh scattering of air at sea level (1/m, at 680, 550 and 440 nm for
/// red, green and blue; Hillaire 2020, "A Scalable and Production Ready Sky
/// and Atmosphere Rendering Technique", §3 — Bruneton & Neyret 2008's
/// values) and its scale height.
pub const RAYLEIGH: Vec3 = Vec3::new(5.802e-6, 13.558e-6, 33.1e-6);
/// See [`RAYLEIGH`] (m).
pub const RAYLEIGH_HEIGHT_M: f32 = 8000.0;
/// The haze's (Mie) scale height (m; Hillaire 2020, §3).
pub const MIE_HEIGHT_M: f32 = 1200.0;

/// Which parts of the light are on: a set of `LIGHT_*` bits, written `all`,
/// `none` or a comma-separated list of `sky`, `aerial`, `sky-light`,
/// `transmission`, `soft-shadows` (`setLighting({parts})`, `--light-parts`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LightParts(pub u32);

/// The parts' names, in their bits' order.
pub const LIGHT_PART_NAMES: [(&str, u32); 5] = [
    ("sky", LIGHT_SKY),
    ("aerial", LIGHT_AERIAL),
    ("sky-light", LIGHT_SKY_LIGHT),
    ("transmission", LIGHT_TRANSMISSION),
    ("soft-shadows", LIGHT_SOFT_SHADOWS),
];

impl LightParts {
    /// Every part.
    pub const ALL: Self = Self(LIGHT_ALL);
    /// None: the light before issue 49 (the sky a gradient, a grey haze, a flat
    /// hemisphere ambient, the leaves' wrap term, fixed-width PCF).
    pub const NONE: Self = Self(0);

    /// Whether `bit` is on.
    #[must_use]
    pub fn has(self, bit: u32) -> bool {
        self.0 & bit != 0
    }
}

impl Default for LightParts {
    fn default() -> Self {
        Self::ALL
    }
}

impl FromStr for LightParts {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim() {
            "all" => return Ok(Self::ALL),
            "none" => return Ok(Self::NONE),
            _ => {}
        }
        let mut bits = 0;
        for word in s.split(',').map(str::trim) {
            let Some((_, bit)) = LIGHT_PART_NAMES.iter().find(|(name, _)| *name == word) else {
                let known: Vec<&str> = LIGHT_PART_NAMES.iter().map(|(n, _)| *n).collect();
                return Err(format!("unknown light part {word:?} (known: all, none, {})", known.join(", ")));
            };
            bits |= bit;
        }
        Ok(Self(bits))
    }
}

impl fmt::Display for LightParts {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::ALL => return f.write_str("all"),
            Self::NONE => return f.write_str("none"),
            _ => {}
        }
        let names: Vec<&str> = LIGHT_PART_NAMES.iter().filter(|(_, b)| self.has(*b)).map(|(n, _)| *n).collect();
        f.write_str(&names.join(","))
    }
}

/// The real spherical harmonics to order 2 at the unit direction `d`
/// (Ramamoorthi & Hanrahan 2001, eq. 3): Y00, Y1-1 (y), Y10 (z), Y11 (x),
/// Y2-2 (xy), Y2-1 (yz), Y20 (3z² − 1), Y21 (xz), Y22 (x² − y²).
#[must_use]
pub fn sh_basis(d: Vec3) -> [f32; 9] {
    let k = SH_CONSTANTS;
    [
        k[0],
        k[1] * d.y,
        k[2] * d.z,
        k[3] * d.x,
        k[4] * d.x * d.y,
        k[5] * d.y * d.z,
        k[6] * (3.0 * d.z * d.z - 1.0),
        k[7] * d.x * d.z,
        k[8] * (d.x * d.x - d.y * d.y),
    ]
}

/// The basis' constants (eq. 3).
const SH_CONSTANTS: [f32; 9] =
    [0.282_095, 0.488_603, 0.488_603, 0.488_603, 1.092_548, 1.092_548, 0.315_392, 1.092_548, 0.546_274];

/// The band (l) of each coefficient.
const SH_BAND: [usize; 9] = [0, 1, 1, 1, 2, 2, 2, 2, 2];

/// `radiance` over the sphere projected onto [`sh_basis`] (midpoint rule on
/// `rows` rings of zenith angle × 2 `rows` azimuths, weighted by solid angle).
#[must_use]
pub fn project_sh(radiance: impl Fn(Vec3) -> Vec3, rows: usize) -> [Vec3; 9] {
    let rows = rows.max(2);
    let cols = 2 * rows;
    let mut out = [Vec3::ZERO; 9];
    let d_theta = std::f32::consts::PI / rows as f32;
    let d_phi = 2.0 * std::f32::consts::PI / cols as f32;
    for i in 0..rows {
        let theta = (i as f32 + 0.5) * d_theta;
        let (st, ct) = theta.sin_cos();
        let weight = st * d_theta * d_phi;
        for j in 0..cols {
            let (sp, cp) = ((j as f32 + 0.5) * d_phi).sin_cos();
            let d = Vec3::new(st * cp, st * sp, ct);
            let l = radiance(d) * weight;
            for (o, y) in out.iter_mut().zip(sh_basis(d)) {
                *o += l * y;
            }
        }
    }
    out
}

/// The irradiance over π (what a white Lambertian surface facing n
/// reflects) of radiance with SH coefficients `radiance`: each band times
/// Â_l / π (Â0 = π, Â1 = 2π/3, Â2 = π/4; eq. 8).
#[must_use]
pub fn irradiance_sh(radiance: &[Vec3; 9]) -> [Vec3; 9] {
    const A_OVER_PI: [f32; 3] = [1.0, 2.0 / 3.0, 0.25];
    let mut out = *radiance;
    for (o, band) in out.iter_mut().zip(SH_BAND) {
        *o *= A_OVER_PI[band];
    }
    out
}

/// `sh` at the direction `n` (CPU twin of `sky_sh` in `shaders/light.wgsl`).
#[must_use]
pub fn eval_sh(sh: &[Vec3; 9], n: Vec3) -> Vec3 {
    sh.iter().zip(sh_basis(n)).map(|(c, y)| *c * y).sum()
}

/// The sky of one light: Preetham's clear sky for the sun, faded with the
/// dusk as the raster's ambient fades, over level ground of
/// [`GROUND_ALBEDO`] lit by the sun and the sky — the environment the path
/// tracer's physical light sees (`sky` in `shaders/path_trace.wgsl`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SkyLight {
    /// The clear sky.
    pub sky: PreethamSky,
    /// Render units per kcd/m² times the dusk's fading.
    pub units: f32,
    /// Towards the sun (unit).
    pub sun_dir: Vec3,
    /// The sun's irradiance at normal incidence over π.
    pub sun_color: Vec3,
    /// The ground's albedo below the horizon.
    pub ground_albedo: Vec3,
    /// The air's turbidity (the sky's and the haze's).
    pub turbidity: f32,
}

/// How bright the raster's gradient sky is relative to day: the ambient
/// light's luminance against 0.4573 (`sky_scale` in `shaders/light.wgsl`).
#[must_use]
pub fn sky_scale(lighting: &super::Lighting) -> f32 {
    (lighting.ambient.dot(LUMINANCE) / 0.4573).clamp(0.15, 1.5)
}

/// Rec. 709 luminance weights.
const LUMINANCE: Vec3 = Vec3::new(0.2126, 0.7152, 0.0722);

/// How the clear sky fades through dusk: as [`super::Lighting::for_sun`]
/// fades the ambient light (its luminance against the default's), at most 1.
#[must_use]
pub fn dusk_fade(lighting: &super::Lighting) -> f32 {
    let day = super::Lighting::default().ambient.dot(LUMINANCE);
    (lighting.ambient.dot(LUMINANCE) / day).clamp(0.0, 1.0)
}

impl SkyLight {
    /// The sky of `lighting` (its sun) through air of `turbidity`.
    #[must_use]
    pub fn new(lighting: &super::Lighting, turbidity: f32) -> Self {
        Self {
            sky: PreethamSky::new(lighting.sun_dir, turbidity),
            units: UNITS_PER_KCD * dusk_fade(lighting),
            sun_dir: lighting.sun_dir.normalize_or(Vec3::Z),
            sun_color: lighting.sun_color,
            ground_albedo: GROUND_ALBEDO,
            turbidity,
        }
    }

    /// The sky's radiance towards `d` (unit; render units, linear sRGB), the
    /// sun's disk not included.
    #[must_use]
    pub fn sky(&self, d: Vec3) -> Vec3 {
        crate::trace::sky::xyy_to_linear_srgb(self.sky.yxy(d)) * self.units
    }

    /// What is seen towards `d`: the sky above the horizon, below it the
    /// level ground lit by the sun and by the sky (taken 45° up in the same
    /// azimuth), unshadowed. Twin: `sky` in `shaders/path_trace.wgsl`.
    #[must_use]
    pub fn radiance(&self, d: Vec3) -> Vec3 {
        if d.z >= 0.0 {
            return self.sky(d);
        }
        let horizontal = Vec3::new(d.x, d.y, 0.0);
        let up45 = (horizontal + Vec3::Z * (horizontal.length() + 1e-3)).normalize();
        self.ground_albedo * (self.sun_color * self.sun_dir.z.max(0.0) + self.sky(up45))
    }

    /// The air's light ([`SkyUniform::air`]): the sky's radiance at the
    /// horizon fitted by a Fourier series of the azimuth to the
    /// [`AIR_HARMONICS`]th harmonic (128 azimuths), rgb each: the mean, then
    /// per harmonic k its cos kφ and sin kφ terms.
    #[must_use]
    pub fn air_ring(&self) -> [Vec3; AIR_TERMS] {
        const N: usize = 128;
        let mut out = [Vec3::ZERO; AIR_TERMS];
        for i in 0..N {
            let phi = std::f32::consts::TAU * (i as f32 + 0.5) / N as f32;
            let l = self.sky(Vec3::new(phi.cos(), phi.sin(), 0.0));
            out[0] += l / N as f32;
            for k in 1..=AIR_HARMONICS {
                let (s, c) = (k as f32 * phi).sin_cos();
                out[2 * k - 1] += l * (2.0 * c / N as f32);
                out[2 * k] += l * (2.0 * s / N as f32);
            }
        }
        out
    }

    /// The irradiance over π this sky gives a surface facing n, as SH
    /// coefficients ([`eval_sh`]).
    #[must_use]
    pub fn irradiance(&self) -> [Vec3; 9] {
        irradiance_sh(&project_sh(|d| self.radiance(d), 48))
    }

    /// The view's sky uniform with `parts` on, leaves transmitting
    /// `leaf_transmit` of their albedo.
    #[must_use]
    pub fn uniform(&self, parts: LightParts, leaf_transmit: f32) -> SkyUniform {
        let sh = self.irradiance();
        let mut u = SkyUniform::zeroed();
        for (o, (c, k)) in u.sh.iter_mut().zip(sh.iter().zip(SH_CONSTANTS)) {
            *o = (*c * k).extend(0.0).to_array();
        }
        for (k, row) in u.perez.iter_mut().enumerate() {
            *row = [self.sky.perez[0][k], self.sky.perez[1][k], self.sky.perez[2][k], 0.0];
        }
        u.zenith = [self.sky.zenith[0], self.sky.zenith[1], self.sky.zenith[2], self.units];
        u.sun = self.sky.fitted_sun().extend(leaf_transmit.clamp(0.0, 1.0)).to_array();
        u.rayleigh = RAYLEIGH.extend(RAYLEIGH_HEIGHT_M).to_array();
        u.mie = [mie_extinction(self.turbidity), MIE_HEIGHT_M, 0.0, 0.0];
        u.air = self.air_ring().map(|c| c.extend(0.0).to_array());
        u.parts = [parts.0, 0, 0, 0];
        u
    }
}

/// Harmonics of the air's light's fit ([`SkyLight::air_ring`]).
pub const AIR_HARMONICS: usize = 4;
/// Its terms: the mean, then a cosine and a sine per harmonic.
pub const AIR_TERMS: usize = 2 * AIR_HARMONICS + 1;

/// The air's light towards `rel` from the fitted ring ([`SkyLight::air_ring`]).
/// Twin: `air_light` in `shaders/sky_model.wgsl`.
#[must_use]
pub fn air_light(ring: &[Vec3; AIR_TERMS], rel: Vec3) -> Vec3 {
    let h = rel.truncate() / rel.truncate().length().max(1e-6);
    let mut l = ring[0];
    // cos kφ + i sin kφ as powers of cos φ + i sin φ.
    let (mut c, mut s) = (1.0f32, 0.0f32);
    for k in 1..=AIR_HARMONICS {
        (c, s) = (c * h.x - s * h.y, s * h.x + c * h.y);
        l += ring[2 * k - 1] * c + ring[2 * k] * s;
    }
    l.max(Vec3::ZERO)
}

/// The haze's extinction at sea level (1/m) for `turbidity`: Preetham et
/// al.'s turbidity is the optical thickness of the air with its haze over
/// that of the clear air alone (§3.1), so the haze's own vertical thickness
/// is (T − 1) times the Rayleigh thickness at 550 nm, spread over
/// [`MIE_HEIGHT_M`] (T = 3: 1.8e-4/m at the ground, a visual range near 20 km).
#[must_use]
pub fn mie_extinction(turbidity: f32) -> f32 {
    let rayleigh_thickness = RAYLEIGH.y * RAYLEIGH_HEIGHT_M;
    (turbidity.clamp(1.7, 10.0) - 1.0) * rayleigh_thickness / MIE_HEIGHT_M
}

/// The air's transmittance over the segment from an eye `eye_z` metres above
/// the scene's origin along `rel` (metres, +Z up): the optical depth of each
/// exponential layer integrated in closed form. Twin: `air_transmittance` in
/// `shaders/light.wgsl`.
#[must_use]
pub fn air_transmittance(eye_z: f32, rel: Vec3, turbidity: f32) -> Vec3 {
    let s = rel.length();
    let z = eye_z.max(0.0);
    let depth = |h: f32| {
        let x = rel.z / h;
        let a = (-z / h).exp();
        if x.abs() < 1e-4 {
            s * a * (1.0 - 0.5 * x)
        } else {
            s / x * (a - (-z / h - x).exp())
        }
    };
    let tau = RAYLEIGH * depth(RAYLEIGH_HEIGHT_M) + Vec3::splat(mie_extinction(turbidity) * depth(MIE_HEIGHT_M));
    (-tau).exp()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn random_dirs(n: usize) -> Vec<Vec3> {
        // A golden-angle spiral: evenly spread unit vectors.
        (0..n)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
                let r = (1.0 - z * z).sqrt();
                let phi = i as f32 * 2.399_963;
                Vec3::new(r * phi.cos(), r * phi.sin(), z)
            })
            .collect()
    }

    #[test]
    fn the_projection_of_known_environments_gives_their_irradiance() {
        // A constant environment L: irradiance π L everywhere (over π: L).
        let c = Vec3::new(0.3, 0.5, 0.7);
        let sh = irradiance_sh(&project_sh(|_| c, 32));
        for n in random_dirs(50) {
            assert!((eval_sh(&sh, n) - c).abs().max_element() < 2e-3, "{n}: {}", eval_sh(&sh, n));
        }
        // A linear field L(d) = 1 + d·a: E(n)/π = 1 + (2/3) n·a (the cosine
        // lobe's band-1 factor), exactly in SH.
        let a = Vec3::new(0.2, -0.3, 0.5);
        let sh = irradiance_sh(&project_sh(|d| Vec3::splat(1.0 + d.dot(a)), 32));
        for n in random_dirs(50) {
            let want = 1.0 + 2.0 / 3.0 * n.dot(a);
            assert!((eval_sh(&sh, n).x - want).abs() < 2e-3, "{n}: {} vs {want}", eval_sh(&sh, n).x);
        }
        // The upper hemisphere at radiance 1 and nothing below: irradiance over
        // π for a surface facing up is 1, facing down 0, sideways ½; order 2
        // holds these within Ramamoorthi & Hanrahan's 9 % bound.
        let sh = irradiance_sh(&project_sh(|d| Vec3::splat(if d.z > 0.0 { 1.0 } else { 0.0 }), 64));
        let up = eval_sh(&sh, Vec3::Z).x;
        let side = eval_sh(&sh, Vec3::X).x;
        let down = eval_sh(&sh, -Vec3::Z).x;
        assert!((up - 1.0).abs() < 0.09 && (side - 0.5).abs() < 0.02 && down.abs() < 0.09, "{up} {side} {down}");
    }

    #[test]
    fn the_sky_lights_a_surface_facing_it_as_its_integral_does() {
        // The SH irradiance against a brute-force cosine-weighted integral of
        // the same sky, for a high and a low sun: within 10 % where it is bright.
        for (elevation, azimuth) in [(55.0f32, 140.0f32), (8.0, 250.0)] {
            let (e, az) = (elevation.to_radians(), azimuth.to_radians());
            let sun = Vec3::new(az.sin() * e.cos(), az.cos() * e.cos(), e.sin());
            let lighting = crate::render::Lighting::for_sun(sun, elevation);
            let sky = SkyLight::new(&lighting, DEFAULT_TURBIDITY);
            let sh = sky.irradiance();
            for n in [Vec3::Z, sun, Vec3::new(-sun.x, -sun.y, 0.3).normalize(), Vec3::X] {
                let brute: Vec3 =
                    random_dirs(40_000).into_iter().map(|d| sky.radiance(d) * d.dot(n).max(0.0)).sum::<Vec3>()
                        * (4.0 / 40_000.0);
                let got = eval_sh(&sh, n);
                let rel = (got - brute).abs().max_element() / brute.max_element();
                assert!(rel < 0.1, "sun {elevation}°, n {n}: SH {got} vs integral {brute}");
            }
            // The sky lights a surface facing up less than the sun does by
            // day (a clear sky gives 10–40 % of the light on level ground;
            // Preetham's sky at T = 3 with the sun 55° up, about 31 %).
            if elevation > 30.0 {
                let up = eval_sh(&sh, Vec3::Z).dot(Vec3::splat(1.0 / 3.0));
                let sun_up = lighting.sun_color.dot(Vec3::splat(1.0 / 3.0)) * sun.z;
                let share = up / (up + sun_up);
                assert!((0.1..0.4).contains(&share), "the sky's share of the light on level ground: {share}");
            }
        }
    }

    #[test]
    fn the_air_thins_with_height_and_reddens_what_it_veils() {
        let t = air_transmittance(0.0, Vec3::new(5000.0, 0.0, 0.0), 3.0);
        // Blue scattered most, every channel between 0 and 1.
        assert!(t.z < t.y && t.y < t.x && t.x < 1.0 && t.z > 0.0, "{t}");
        // Visual range near 20 km at T = 3 (contrast 2 % at 3.9 / β).
        let v = 3.912 / (mie_extinction(3.0) + RAYLEIGH.y);
        assert!((15_000.0..30_000.0).contains(&v), "visual range {v} m");
        // Looking down from 2 km sees less air than along the ground; a level
        // segment up there less than the same one below.
        let down = air_transmittance(2000.0, Vec3::new(3000.0, 0.0, -2000.0), 3.0);
        let level_low = air_transmittance(0.0, Vec3::new(3605.0, 0.0, 0.0), 3.0);
        assert!(down.y > level_low.y, "{down} vs {level_low}");
        assert!(air_transmittance(2000.0, Vec3::X * 3000.0, 3.0).y > air_transmittance(0.0, Vec3::X * 3000.0, 3.0).y);
        // The closed form against a sum of small steps along a slanted segment.
        let rel = Vec3::new(4000.0, 1000.0, 900.0);
        let steps = 10_000;
        let mut tau = Vec3::ZERO;
        for k in 0..steps {
            let z = 100.0 + rel.z * (k as f32 + 0.5) / steps as f32;
            let beta = RAYLEIGH * (-z / RAYLEIGH_HEIGHT_M).exp()
                + Vec3::splat(mie_extinction(3.0) * (-z / MIE_HEIGHT_M).exp());
            tau += beta * rel.length() / steps as f32;
        }
        let closed = air_transmittance(100.0, rel, 3.0);
        assert!((closed - (-tau).exp()).abs().max_element() < 1e-4, "{closed} vs {}", (-tau).exp());
    }

    #[test]
    fn the_airs_light_follows_the_horizon_all_round() {
        // The four-harmonic ring against the horizon's radiance itself, with
        // the sun high and low (its glow then narrower): every azimuth's
        // luminance within the bound (measured 0.001 and 0.126), the mean
        // over the ring kept.
        for (elevation, bound) in [(55.0f32, 0.01f32), (8.0, 0.15)] {
            let e = elevation.to_radians();
            let sun = Vec3::new(0.6 * e.cos(), -0.8 * e.cos(), e.sin());
            let sky = SkyLight::new(&crate::render::Lighting::for_sun(sun, elevation), DEFAULT_TURBIDITY);
            let ring = sky.air_ring();
            let (mut worst, mut sum_fit, mut sum_sky) = (0f32, 0f32, 0f32);
            for k in 0..90 {
                let a = k as f32 * 4f32.to_radians();
                let d = Vec3::new(a.cos(), a.sin(), 0.0);
                let fit = air_light(&ring, d * 1000.0 - Vec3::Z * 30.0).dot(LUMINANCE);
                let exact = sky.sky(d).dot(LUMINANCE);
                worst = worst.max((fit - exact).abs() / exact);
                sum_fit += fit;
                sum_sky += exact;
            }
            assert!(worst < bound, "sun {elevation}°: the ring is off the horizon by {worst:.3}");
            assert!((sum_fit / sum_sky - 1.0).abs() < 0.01);
        }
    }

    #[test]
    fn light_parts_read_and_write_their_names() {
        assert_eq!("all".parse::<LightParts>(), Ok(LightParts::ALL));
        assert_eq!("none".parse::<LightParts>(), Ok(LightParts::NONE));
        let p: LightParts = "sky, sky-light".parse().unwrap_or(LightParts::NONE);
        assert_eq!(p, LightParts(LIGHT_SKY | LIGHT_SKY_LIGHT));
        assert_eq!(p.to_string(), "sky,sky-light");
        assert_eq!(p.to_string().parse::<LightParts>(), Ok(p));
        let err = "sky,fog".parse::<LightParts>().unwrap_err();
        assert!(err.contains("fog") && err.contains("transmission"), "{err}");
    }
}
