//! The camera: f64 position relative to the scene origin on the CPU; the GPU gets a
//! rotation-only, eye-relative clip transform, the eye split into two f32s and
//! frustum planes in the same eye-relative space. Reversed-Z, infinite far plane.

use glam::{DVec3, Mat4, Vec3, Vec4};

/// A perspective camera. Headings follow maps: 0 = north (+y), 90° = east (+x).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Eye position, metres relative to the scene origin.
    pub eye_m: DVec3,
    /// Heading in radians, clockwise from north.
    pub heading_rad: f64,
    /// Pitch in radians: 0 horizontal, negative looking down, −π/2 straight down.
    pub pitch_rad: f64,
    /// Vertical field of view in radians.
    pub fov_y_rad: f32,
    /// Near plane distance in metres.
    pub near_m: f32,
}

impl Default for Camera {
    fn default() -> Self {
        Self { eye_m: DVec3::ZERO, heading_rad: 0.0, pitch_rad: 0.0, fov_y_rad: 50f32.to_radians(), near_m: 0.1 }
    }
}

/// What a frame needs from the camera, in GPU-ready form.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewData {
    /// Clip from eye-relative coordinates.
    pub clip_from_eye: Mat4,
    /// High f32 part of the eye.
    pub eye_hi: Vec3,
    /// Low f32 part of the eye.
    pub eye_lo: Vec3,
    /// Eye-relative frustum planes (inside: `n·p + d ≥ 0`), normalised; a
    /// degenerate plane (the infinite far plane) is `(0, 0, 0, 1)`.
    pub frustum: [Vec4; 6],
    /// Pixels per metre at 1 m distance: `height / (2 tan(fov/2))`.
    pub px_per_m_at_1m: f32,
    /// Viewport size in pixels.
    pub viewport: [u32; 2],
}

impl Camera {
    /// A camera at `eye` looking at `target` (both relative to the scene origin).
    #[must_use]
    pub fn look_at(eye: DVec3, target: DVec3) -> Self {
        let d = target - eye;
        let heading = d.x.atan2(d.y);
        let pitch = d.z.atan2(d.truncate().length());
        Self { eye_m: eye, heading_rad: heading, pitch_rad: pitch, ..Self::default() }
    }

    /// A camera that sees no scene: far below everything, looking down. Streams
    /// the manifest without fetching what a view would (before the first view
    /// is placed).
    #[must_use]
    pub fn nowhere() -> Self {
        Self { eye_m: DVec3::new(0.0, 0.0, -1e7), pitch_rad: -std::f64::consts::FRAC_PI_2, ..Self::default() }
    }

    /// Unit view direction.
    #[must_use]
    pub fn forward(&self) -> DVec3 {
        let (sh, ch) = self.heading_rad.sin_cos();
        let (sp, cp) = self.pitch_rad.sin_cos();
        DVec3::new(sh * cp, ch * cp, sp)
    }

    /// The per-frame view data for a `width`×`height` target.
    #[must_use]
    pub fn view_data(&self, width: u32, height: u32) -> ViewData {
        let f = self.forward().as_vec3();
        // Straight up or down, world up is parallel to the view: use the heading instead.
        let up = if f.cross(Vec3::Z).length_squared() < 1e-8 {
            let (sh, ch) = self.heading_rad.sin_cos();
            Vec3::new(sh as f32, ch as f32, 0.0) * -f.z.signum()
        } else {
            Vec3::Z
        };
        let eye_from_world = glam::camera::rh::view::look_to_mat4(Vec3::ZERO, f, up);
        let aspect = width.max(1) as f32 / height.max(1) as f32;
        let proj = glam::camera::rh::proj::directx::perspective_infinite_reverse(
            self.fov_y_rad,
            aspect,
            self.near_m.max(1e-4),
        );
        let clip_from_eye = proj * eye_from_world;
        let eye_hi = self.eye_m.as_vec3();
        let eye_lo = (self.eye_m - eye_hi.as_dvec3()).as_vec3();
        ViewData {
            clip_from_eye,
            eye_hi,
            eye_lo,
            frustum: frustum_planes(&clip_from_eye),
            px_per_m_at_1m: height as f32 / (2.0 * (self.fov_y_rad * 0.5).tan()),
            viewport: [width, height],
        }
    }
}

/// Gribb–Hartmann planes for WebGPU clip space (0 ≤ z ≤ w): left, right, bottom,
/// top, near (z ≤ w under reversed Z) and far (z ≥ 0; degenerate for an infinite
/// projection, so it is replaced by an always-inside plane).
#[must_use]
pub fn frustum_planes(m: &Mat4) -> [Vec4; 6] {
    let r = [m.row(0), m.row(1), m.row(2), m.row(3)];
    let raw = [r[3] + r[0], r[3] - r[0], r[3] + r[1], r[3] - r[1], r[3] - r[2], r[2]];
    raw.map(|p| {
        let n = p.truncate().length();
        // Guard the normalisation: the infinite far plane has no normal.
        if n > 1e-6 {
            p / n
        } else {
            Vec4::new(0.0, 0.0, 0.0, 1.0)
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frustum_contains_what_is_ahead_and_not_behind() {
        let cam = Camera { eye_m: DVec3::new(1e6, 5e6, 10.0), heading_rad: 0.0, ..Camera::default() };
        let v = cam.view_data(800, 600);
        let inside = |p: Vec3| v.frustum.iter().all(|pl| pl.truncate().dot(p) + pl.w >= 0.0);
        assert!(inside(Vec3::new(0.0, 100.0, 0.0)), "straight ahead (north)");
        assert!(inside(Vec3::new(0.0, 1e7, 0.0)), "far ahead: no far plane");
        assert!(!inside(Vec3::new(0.0, -100.0, 0.0)), "behind");
        assert!(!inside(Vec3::new(500.0, 100.0, 0.0)), "far to the right");
        assert!(!inside(Vec3::new(0.0, 0.05, 0.0)), "closer than the near plane");
        // The eye split reconstructs the f64 position to well under a millimetre.
        let back = v.eye_hi.as_dvec3() + v.eye_lo.as_dvec3();
        assert!((back - cam.eye_m).length() < 1e-6);
    }

    #[test]
    fn straight_down_and_horizon_views_are_finite() {
        for pitch in [-std::f64::consts::FRAC_PI_2, 0.0, std::f64::consts::FRAC_PI_2] {
            let cam = Camera { pitch_rad: pitch, heading_rad: 1.0, ..Camera::default() };
            let v = cam.view_data(100, 100);
            assert!(v.clip_from_eye.is_finite(), "pitch {pitch}");
            assert!(v.frustum.iter().all(|p| p.is_finite()));
        }
    }
}
