//! The viewer's camera controls, free of the browser so that they are tested
//! natively: an orbit around a target on the ground (drag to orbit, pan,
//! zoom), walking at eye height (look, walk), a pose given as an eye and
//! angles, a camera set as a map or a globe gives it (an eye looking at a
//! point), and where a point lands on the screen. `web/` drives it.

use glam::DVec3;

use crate::camera::Camera;

/// An orbit camera: a target on the ground, a distance, a heading and a pitch
/// (radians; heading clockwise from grid north, pitch negative looking down).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Orbit {
    /// The point the camera looks at and orbits around (scene metres).
    pub target: DVec3,
    /// Eye to target (metres).
    pub distance: f64,
    /// Heading of the view (radians, clockwise from grid north).
    pub heading: f64,
    /// Pitch of the view (radians, 0 level, negative down).
    pub pitch: f64,
}

/// The eye's least height over the ground while orbiting (metres).
pub const MIN_EYE_OVER_GROUND_M: f64 = 1.5;
/// The eye's height over the ground while walking (metres).
pub const WALKING_EYE_M: f64 = 1.7;

impl Orbit {
    /// The camera of this orbit (near plane scaled with the distance).
    #[must_use]
    pub fn camera(&self) -> Camera {
        let c = Camera { heading_rad: self.heading, pitch_rad: self.pitch, ..Camera::default() };
        Camera {
            eye_m: self.target - c.forward() * self.distance,
            near_m: (self.distance * 0.002).clamp(0.05, 5.0) as f32,
            ..c
        }
    }

    /// The orbit's camera kept out of the ground: with `ground` (the height
    /// under the eye) the eye stays at least 1.5 m above it, or at eye height
    /// (1.7 m) when `walking`.
    #[must_use]
    pub fn camera_over(&self, ground: Option<f64>, walking: bool) -> Camera {
        let mut cam = self.camera();
        if let Some(ground) = ground {
            cam.eye_m.z =
                if walking { ground + WALKING_EYE_M } else { cam.eye_m.z.max(ground + MIN_EYE_OVER_GROUND_M) };
        }
        cam
    }

    /// Orbits around the target by `d_heading`, `d_pitch` radians (pitch
    /// kept between almost straight down and a little above level).
    pub fn orbit(&mut self, d_heading: f64, d_pitch: f64) {
        self.heading += d_heading;
        self.pitch = (self.pitch + d_pitch).clamp(-1.55, 0.6);
    }

    /// Moves the target in the view's ground plane by `right`, `forward`
    /// fractions of the distance.
    pub fn pan(&mut self, right: f64, forward: f64) {
        let (s, c) = self.heading.sin_cos();
        let d = self.distance;
        self.target += DVec3::new(c * right * d + s * forward * d, -s * right * d + c * forward * d, 0.0);
    }

    /// Multiplies the distance to the target (< 1 zooms in; a step at most
    /// 5× either way, the distance within 2 m–200 km).
    pub fn zoom(&mut self, factor: f64) {
        self.distance = (self.distance * factor.clamp(0.2, 5.0)).clamp(2.0, 200_000.0);
    }

    /// Walking starts: stand where the camera looks, facing the same way,
    /// nearly level.
    #[must_use]
    pub fn standing(&self) -> Self {
        Self { target: self.target, distance: 3.0, heading: self.heading, pitch: 0.05 }
    }

    /// Turns the view around the eye by `d_heading`, `d_pitch` radians.
    pub fn look(&mut self, d_heading: f64, d_pitch: f64) {
        let eye = self.camera().eye_m;
        self.heading += d_heading;
        self.pitch = (self.pitch + d_pitch).clamp(-1.5, 1.2);
        let forward = Camera { heading_rad: self.heading, pitch_rad: self.pitch, ..Camera::default() }.forward();
        self.target = eye + forward * self.distance;
    }

    /// Moves the eye `forward_m` along the heading and `right_m` to the side.
    pub fn walk(&mut self, forward_m: f64, right_m: f64) {
        let (s, c) = self.heading.sin_cos();
        self.target += DVec3::new(s * forward_m + c * right_m, c * forward_m - s * right_m, 0.0);
    }

    /// The orbit of an eye at `eye` looking by `heading_deg`, `pitch_deg`
    /// (pitch kept within −89°…34°): the target ahead on the ground plane of
    /// the current target's height (`ground_z`) when looking down by more
    /// than 5°, else 100 m ahead.
    #[must_use]
    pub fn posed(eye: DVec3, heading_deg: f64, pitch_deg: f64, ground_z: f64) -> Self {
        let cam = Camera {
            heading_rad: heading_deg.to_radians(),
            pitch_rad: pitch_deg.clamp(-89.0, 34.0).to_radians(),
            ..Camera::default()
        };
        let distance =
            if pitch_deg < -5.0 { (eye.z - ground_z).abs().max(10.0) / (-cam.pitch_rad).sin() } else { 100.0 };
        Self { target: eye + cam.forward() * distance, distance, heading: cam.heading_rad, pitch: cam.pitch_rad }
    }

    /// The orbit of an eye at `eye` looking at `at` (a map's or a globe's
    /// camera); straight down, `heading` (radians) turns the view. `None`
    /// when the two points coincide or are not finite.
    #[must_use]
    pub fn looking_at(eye: DVec3, at: DVec3, heading: impl FnOnce() -> f64) -> Option<Self> {
        let d = at - eye;
        let distance = d.length();
        if !(distance.is_finite() && distance > 1e-6) {
            return None;
        }
        let horizontal = d.truncate().length();
        let heading = if horizontal > 1e-7 * distance { d.x.atan2(d.y) } else { heading() };
        Some(Self { target: at, distance, heading, pitch: d.z.atan2(horizontal) })
    }
}

/// Where `camera` draws the scene point `p` on a `width`×`height` target:
/// pixels from the top left, `None` behind the eye.
#[must_use]
pub fn project(camera: &Camera, width: u32, height: u32, p: DVec3) -> Option<[f64; 2]> {
    let view = camera.view_data(width, height);
    let clip = view.clip_from_eye * (p - camera.eye_m).as_vec3().extend(1.0);
    if clip.w <= 1e-6 {
        return None;
    }
    let (w, h) = (f64::from(width), f64::from(height));
    Some([(f64::from(clip.x / clip.w) * 0.5 + 0.5) * w, (0.5 - f64::from(clip.y / clip.w) * 0.5) * h])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn near(a: DVec3, b: DVec3, tol: f64) -> bool {
        (a - b).length() < tol
    }

    #[test]
    fn a_pose_puts_the_eye_where_it_was_given() {
        let eye = DVec3::new(120.0, -340.0, 95.0);
        for (heading, pitch) in [(0.0, -30.0), (137.0, -60.0), (-20.0, 0.0), (90.0, 20.0)] {
            let o = Orbit::posed(eye, heading, pitch, 20.0);
            let cam = o.camera();
            assert!(near(cam.eye_m, eye, 1e-6), "{heading} {pitch}: {:?}", cam.eye_m);
            assert!((cam.heading_rad - f64::to_radians(heading)).abs() < 1e-12);
            assert!((cam.pitch_rad - f64::to_radians(pitch)).abs() < 1e-12);
        }
        // Looking down, the target lies on the ground plane given.
        let o = Orbit::posed(eye, 30.0, -45.0, 20.0);
        assert!((o.target.z - 20.0).abs() < 1e-9, "{:?}", o.target);
        // Pitch beyond the limits is clamped.
        assert!((Orbit::posed(eye, 0.0, -120.0, 0.0).pitch - f64::to_radians(-89.0)).abs() < 1e-12);
    }

    #[test]
    fn orbiting_keeps_the_target_and_looking_keeps_the_eye() {
        let mut o = Orbit { target: DVec3::new(10.0, 20.0, 5.0), distance: 300.0, heading: 0.3, pitch: -0.5 };
        let target = o.target;
        o.orbit(1.0, -2.0);
        assert_eq!(o.target, target);
        assert_eq!(o.pitch, -1.55, "pitch clamped");
        let eye = o.camera().eye_m;
        o.look(0.4, 0.2);
        assert!(near(o.camera().eye_m, eye, 1e-9));
        assert!(near(o.target - eye, o.camera().forward() * o.distance, 1e-9));
    }

    #[test]
    fn walking_and_panning_move_along_the_heading() {
        // Heading 90°: east. Walking forward moves east, to the right south.
        let mut o = Orbit { target: DVec3::ZERO, distance: 3.0, heading: std::f64::consts::FRAC_PI_2, pitch: 0.05 };
        o.walk(10.0, 0.0);
        assert!(near(o.target, DVec3::new(10.0, 0.0, 0.0), 1e-9), "{:?}", o.target);
        o.walk(0.0, 5.0);
        assert!(near(o.target, DVec3::new(10.0, -5.0, 0.0), 1e-9), "{:?}", o.target);
        // Heading 0: north. A pan by a tenth of the distance forward moves north.
        let mut p = Orbit { target: DVec3::ZERO, distance: 200.0, heading: 0.0, pitch: -0.5 };
        p.pan(0.0, 0.1);
        assert!(near(p.target, DVec3::new(0.0, 20.0, 0.0), 1e-9));
        p.pan(0.1, 0.0);
        assert!(near(p.target, DVec3::new(20.0, 20.0, 0.0), 1e-9));
        p.zoom(1e-9);
        assert_eq!(p.distance, 40.0, "a step is at most 5×");
        for _ in 0..10 {
            p.zoom(0.2);
        }
        assert_eq!(p.distance, 2.0);
    }

    #[test]
    fn the_eye_stays_above_the_ground() {
        let o = Orbit { target: DVec3::new(0.0, 0.0, 10.0), distance: 100.0, heading: 0.0, pitch: 0.3 };
        let below = o.camera().eye_m.z;
        let cam = o.camera_over(Some(below + 40.0), false);
        assert_eq!(cam.eye_m.z, below + 40.0 + MIN_EYE_OVER_GROUND_M);
        let walking = o.camera_over(Some(3.0), true);
        assert_eq!(walking.eye_m.z, 3.0 + WALKING_EYE_M);
        assert_eq!(o.camera_over(None, true).eye_m, o.camera().eye_m);
    }

    #[test]
    fn looking_at_a_point_draws_it_in_the_middle() {
        let eye = DVec3::new(-200.0, -150.0, 300.0);
        let at = DVec3::new(40.0, 90.0, 12.0);
        let o = Orbit::looking_at(eye, at, || 0.0).unwrap();
        let cam = o.camera();
        assert!(near(cam.eye_m, eye, 1e-6), "{:?}", cam.eye_m);
        let [x, y] = project(&cam, 640, 360, at).unwrap();
        assert!((x - 320.0).abs() < 1e-3 && (y - 180.0).abs() < 1e-3, "{x} {y}");
        // A point to the right of the view lands right of the middle; behind the eye, nowhere.
        let right = at + DVec3::new(cam.forward().y, -cam.forward().x, 0.0) * 50.0;
        assert!(project(&cam, 640, 360, right).unwrap()[0] > 320.0);
        assert!(project(&cam, 640, 360, eye - cam.forward() * 10.0).is_none());
        // Straight down: the heading given turns the view; coincident points: no camera.
        let down = Orbit::looking_at(DVec3::new(0.0, 0.0, 500.0), DVec3::ZERO, || 1.25).unwrap();
        assert_eq!(down.heading, 1.25);
        assert!((down.pitch + std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!(Orbit::looking_at(eye, eye, || 0.0).is_none());
        assert!(Orbit::looking_at(eye, DVec3::splat(f64::NAN), || 0.0).is_none());
    }
}
