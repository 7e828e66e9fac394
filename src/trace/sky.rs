//! The clear sky of Preetham, Shirley & Smits 1999 ("A Practical Analytic
//! Model for Daylight"): the sky's luminance and chromaticity in any direction
//! from the sun's position and the air's turbidity — Perez et al.'s
//! distribution (§3.2, eq. 3) with the fitted coefficients and zenith values of
//! appendix A.2. The path tracer's sky and the raster's (`preetham_radiance`
//! in `shaders/sky_model.wgsl` is the twin of [`PreethamSky::radiance`]; the
//! raster's in render units faded through dusk, `render::sky_light`).
//!
//! Directions are unit vectors with +Z up. The model is fitted for the sun
//! above the horizon and turbidity 2–10 (the paper's range; below about 1.7
//! its luminance coefficient B turns positive): the sun's zenith angle is
//! taken at most 87°, the turbidity clamped to 1.7–10.

use glam::Vec3;

/// Render units (the raster's light: a white surface facing the sun reflects
/// `sun_color`, about 0.85) per kcd/m² of sky luminance: the sun's normal
/// illuminance taken as 100 klx on a clear day, so 1 kcd/m² is 0.85 π / 100.
pub const UNITS_PER_KCD: f32 = 0.85 * std::f32::consts::PI / 100.0;

/// A clear sky for one sun position and turbidity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PreethamSky {
    /// Towards the sun (unit, +Z up).
    pub sun_dir: Vec3,
    /// The sun's zenith angle used by the fit (radians, at most 87°).
    pub theta_s: f32,
    /// Perez coefficients A–E for Y, x and y (appendix A.2).
    pub perez: [[f32; 5]; 3],
    /// The zenith's Y (kcd/m²), x and y, each divided by its distribution at
    /// the zenith (so a direction's value is this × F(θ, γ)).
    pub zenith: [f32; 3],
}

/// Perez et al.'s distribution: F(θ, γ) = (1 + A e^(B / cos θ)) (1 + C e^(D γ) + E cos² γ),
/// with cos θ at least 0.01 (at and below the horizon). Twin: `perez_yxy` in
/// `shaders/sky_model.wgsl`.
#[must_use]
pub fn perez(cos_theta: f32, gamma: f32, c: [f32; 5]) -> f32 {
    let cos_gamma = gamma.cos();
    (1.0 + c[0] * (c[1] / cos_theta.max(0.01)).exp())
        * (1.0 + c[2] * (c[3] * gamma).exp() + c[4] * cos_gamma * cos_gamma)
}

impl PreethamSky {
    /// The sky for a sun towards `sun_dir` (unit, +Z up) and `turbidity`
    /// (2 very clear, 3 clear, 6 hazy).
    #[must_use]
    pub fn new(sun_dir: Vec3, turbidity: f32) -> Self {
        let t = turbidity.clamp(1.7, 10.0);
        let sun_dir = sun_dir.normalize_or(Vec3::Z);
        let theta_s = sun_dir.z.clamp(-1.0, 1.0).acos().min(87f32.to_radians());
        // Appendix A.2: the distribution coefficients, linear in T (Y, x, y).
        let coefficients = [
            [
                0.1787 * t - 1.4630,
                -0.3554 * t + 0.4275,
                -0.0227 * t + 5.3251,
                0.1206 * t - 2.5771,
                -0.0670 * t + 0.3703,
            ],
            [
                -0.0193 * t - 0.2592,
                -0.0665 * t + 0.0008,
                -0.0004 * t + 0.2125,
                -0.0641 * t - 0.8989,
                -0.0033 * t + 0.0452,
            ],
            [
                -0.0167 * t - 0.2608,
                -0.0950 * t + 0.0092,
                -0.0079 * t + 0.2102,
                -0.0441 * t - 1.6537,
                -0.0109 * t + 0.0529,
            ],
        ];
        // The zenith's luminance (kcd/m²) and chromaticity.
        let chi = (4.0 / 9.0 - t / 120.0) * (std::f32::consts::PI - 2.0 * theta_s);
        let y_lum = ((4.0453 * t - 4.9710) * chi.tan() - 0.2155 * t + 2.4192).max(0.0);
        let th = [theta_s.powi(3), theta_s.powi(2), theta_s, 1.0];
        let row = |r: [f32; 4]| r[0] * th[0] + r[1] * th[1] + r[2] * th[2] + r[3] * th[3];
        let x = t * t * row([0.00166, -0.00375, 0.00209, 0.0])
            + t * row([-0.02903, 0.06377, -0.03202, 0.00394])
            + row([0.11693, -0.21196, 0.06052, 0.25886]);
        let y = t * t * row([0.00275, -0.00610, 0.00317, 0.0])
            + t * row([-0.04214, 0.08970, -0.04153, 0.00516])
            + row([0.15346, -0.26756, 0.06670, 0.26688]);
        let at_zenith = |c| perez(1.0, theta_s, c);
        let zenith =
            [y_lum / at_zenith(coefficients[0]), x / at_zenith(coefficients[1]), y / at_zenith(coefficients[2])];
        Self { sun_dir, theta_s, perez: coefficients, zenith }
    }

    /// The sun's direction as the fit saw it (its zenith angle capped at 87°).
    #[must_use]
    pub fn fitted_sun(&self) -> Vec3 {
        let (s, c) = self.theta_s.sin_cos();
        let horizontal = Vec3::new(self.sun_dir.x, self.sun_dir.y, 0.0).normalize_or(Vec3::X);
        horizontal * s + Vec3::Z * c
    }

    /// The sky's luminance (kcd/m²) and chromaticity (x, y) towards `dir`
    /// (unit; at and below the horizon, the horizon's).
    #[must_use]
    pub fn yxy(&self, dir: Vec3) -> [f32; 3] {
        let gamma = dir.dot(self.fitted_sun()).clamp(-1.0, 1.0).acos();
        let cos_theta = dir.z;
        [
            self.zenith[0] * perez(cos_theta, gamma, self.perez[0]),
            self.zenith[1] * perez(cos_theta, gamma, self.perez[1]),
            self.zenith[2] * perez(cos_theta, gamma, self.perez[2]),
        ]
    }

    /// The sky's radiance towards `dir` in render units, linear sRGB.
    /// Twin: `preetham_radiance` in `shaders/sky_model.wgsl` (the raster's
    /// and the tracer's).
    #[must_use]
    pub fn radiance(&self, dir: Vec3) -> Vec3 {
        xyy_to_linear_srgb(self.yxy(dir)) * UNITS_PER_KCD
    }
}

/// CIE xyY (Y first) to linear sRGB (D65 primaries).
#[must_use]
pub fn xyy_to_linear_srgb([lum, x, y]: [f32; 3]) -> Vec3 {
    let y = y.max(1e-4);
    let big_x = x * lum / y;
    let big_z = (1.0 - x - y) * lum / y;
    Vec3::new(
        3.2406 * big_x - 1.5372 * lum - 0.4986 * big_z,
        -0.9689 * big_x + 1.8758 * lum + 0.0415 * big_z,
        0.0557 * big_x - 0.2040 * lum + 1.0570 * big_z,
    )
    .max(Vec3::ZERO)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sun_at(elevation_deg: f32, azimuth_deg: f32) -> Vec3 {
        let (e, a) = (elevation_deg.to_radians(), azimuth_deg.to_radians());
        Vec3::new(a.sin() * e.cos(), a.cos() * e.cos(), e.sin())
    }

    #[test]
    fn the_zenith_has_the_papers_values() {
        // Appendix A.2 at T = 3 with the sun 30° from the zenith: χ = (4/9 −
        // 3/120)(π − π/3) = 0.8785, Yz = (4.0453·3 − 4.9710) tan χ − 0.2155·3
        // + 2.4192 = 10.42 kcd/m².
        let sky = PreethamSky::new(sun_at(60.0, 180.0), 3.0);
        let [lum, x, y] = sky.yxy(Vec3::Z);
        assert!((lum - 10.42).abs() < 0.02, "zenith luminance {lum}");
        // A clear zenith is blue: chromaticity well below white's (1/3, 1/3).
        assert!((0.22..0.3).contains(&x) && (0.22..0.32).contains(&y), "zenith chromaticity ({x}, {y})");
        let rgb = sky.radiance(Vec3::Z);
        assert!(rgb.z > rgb.y && rgb.y > rgb.x, "the zenith is blue: {rgb}");
    }

    #[test]
    fn the_sky_brightens_towards_the_sun_and_the_horizon() {
        let sky = PreethamSky::new(sun_at(30.0, 90.0), 3.0);
        let lum = |d: Vec3| sky.yxy(d.normalize())[0];
        let near_sun = lum(sun_at(35.0, 90.0));
        let opposite = lum(sun_at(35.0, 270.0));
        assert!(near_sun > 3.0 * opposite, "circumsolar {near_sun} vs opposite {opposite}");
        // Horizon brightening away from the sun (clear sky): low sky brighter than
        // the sky 60° up on the same side.
        assert!(lum(sun_at(5.0, 0.0)) > lum(sun_at(60.0, 0.0)));
        // Haze brightens and whitens the sky away from the sun.
        let hazy = PreethamSky::new(sun_at(30.0, 90.0), 6.0);
        assert!(hazy.yxy(sun_at(35.0, 270.0))[0] > opposite);
        // Every direction finite and non-negative, the sun low or high, down included.
        for s in [sun_at(2.0, 10.0), sun_at(89.0, 200.0), sun_at(-5.0, 0.0)] {
            let sky = PreethamSky::new(s, 2.5);
            for d in [Vec3::Z, Vec3::X, -Vec3::Z, sun_at(10.0, 45.0)] {
                let r = sky.radiance(d);
                assert!(r.is_finite() && r.min_element() >= 0.0, "{s} {d}: {r}");
            }
        }
    }
}
