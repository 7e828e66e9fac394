//! The path tracer's geometry, GPU-free (issue 48): rays, the ray–box and
//! ray–triangle tests, and the bounding volume hierarchy over a species' full
//! mesh that the tracer traverses — the bottom level of the two-level
//! structure of Dietrich et al. 2005 (§4.1: one acceleration structure per
//! plant model, a top level over the instances, rays transformed into the
//! model's space where they enter an instance).
//!
//! Each function here is the twin of its WGSL in `shaders/trace.wgsl`, written
//! with the same operations in the same order; `tests/it/gpu_trace.rs` traces
//! the same random rays with both and compares the hits.

pub mod bvh;
pub mod environment;
pub mod load;
pub mod scene;
pub mod sky;

use glam::Vec3;

/// A ray: `origin + t · dir` for `t` in `(0, t_max)`. `dir` need not be unit
/// length (`t` is then in units of its length).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    /// Where it starts.
    pub origin: Vec3,
    /// Its direction.
    pub dir: Vec3,
    /// Hits at or beyond this distance do not count.
    pub t_max: f32,
}

/// A ray's nearest hit on a triangle mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Distance along the ray (in units of `dir`'s length).
    pub t: f32,
    /// The triangle: its index in the mesh's index list / 3.
    pub triangle: u32,
    /// Barycentric coordinates of the hit: weight of the triangle's second
    /// and third corner (the first's is `1 − u − v`).
    pub u: f32,
    /// See `u`.
    pub v: f32,
    /// Where the triangle is in its hierarchy's leaf order (brute force: its
    /// index); on the GPU, in the concatenated triangles of every species.
    pub index: u32,
}

/// `1 / dir` per axis for the slab test, with components nearer zero than
/// 1e-20 replaced by ±1e-20 first (negative ones by −1e-20, the rest, −0
/// included, by +1e-20, as WGSL's comparison sees them): the slab
/// distances stay finite, so neither side meets `0 · ∞` (NaN, on which Rust's
/// and WGSL's `min`/`max` differ). Twin: `ray_inv_dir` in `shaders/trace.wgsl`.
#[must_use]
pub fn inv_dir(dir: Vec3) -> Vec3 {
    let tiny = |c: f32| {
        if c.abs() < 1e-20 {
            if c < 0.0 {
                -1e-20
            } else {
                1e-20
            }
        } else {
            c
        }
    };
    Vec3::new(1.0 / tiny(dir.x), 1.0 / tiny(dir.y), 1.0 / tiny(dir.z))
}

/// The slab test (Kay & Kajiya 1986; in the form of Williams et al. 2005, §3):
/// the distance at which the ray enters the box `min..max` (0 if it starts
/// inside), or `None` if it misses it or enters at or beyond `t_max`.
/// `inv_dir` is [`inv_dir`] of the ray's direction.
/// Twin: `ray_box` in `shaders/trace.wgsl`.
#[must_use]
pub fn ray_box(origin: Vec3, inv_dir: Vec3, min: Vec3, max: Vec3, t_max: f32) -> Option<f32> {
    let t0 = (min - origin) * inv_dir;
    let t1 = (max - origin) * inv_dir;
    let near = t0.min(t1);
    let far = t0.max(t1);
    let enter = near.x.max(near.y).max(near.z).max(0.0);
    let exit = far.x.min(far.y).min(far.z);
    (enter <= exit && enter < t_max).then_some(enter)
}

/// A triangle as the tracer stores it: its first corner and the two edges
/// from it (Möller & Trumbore 1997, §2), two-sided.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Triangle {
    /// First corner.
    pub v0: Vec3,
    /// Second corner − first.
    pub e1: Vec3,
    /// Third corner − first.
    pub e2: Vec3,
}

impl Triangle {
    /// The triangle of three corners.
    #[must_use]
    pub fn new(a: Vec3, b: Vec3, c: Vec3) -> Self {
        Self { v0: a, e1: b - a, e2: c - a }
    }
}

/// Möller & Trumbore 1997 ("Fast, minimum storage ray/triangle intersection",
/// §2–3), both sides: `(t, u, v)` where the ray meets `tri` at `t` in
/// `(0, t_max)`, else `None`. A ray in the triangle's plane misses it.
/// Twin: `ray_triangle` in `shaders/trace.wgsl`.
#[must_use]
pub fn ray_triangle(origin: Vec3, dir: Vec3, tri: &Triangle, t_max: f32) -> Option<(f32, f32, f32)> {
    let p = dir.cross(tri.e2);
    let det = tri.e1.dot(p);
    if det.abs() < 1e-12 {
        return None;
    }
    let inv = 1.0 / det;
    let s = origin - tri.v0;
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(tri.e1);
    let v = dir.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = tri.e2.dot(q) * inv;
    (t > 0.0 && t < t_max).then_some((t, u, v))
}

/// The nearest hit of `ray` among every triangle of `triangles`, tested one by
/// one: the brute-force answer a [`bvh::Bvh`] must give.
#[must_use]
pub fn brute_force(triangles: &[Triangle], ray: &Ray) -> Option<Hit> {
    let mut best: Option<Hit> = None;
    for (i, tri) in triangles.iter().enumerate() {
        let limit = best.map_or(ray.t_max, |h| h.t);
        if let Some((t, u, v)) = ray_triangle(ray.origin, ray.dir, tri, limit) {
            best = Some(Hit { t, triangle: i as u32, u, v, index: i as u32 });
        }
    }
    best
}

/// A small deterministic generator (xorshift32, Marsaglia 2003) for test
/// scenes and benchmark rays: the same sequence on every machine.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Xorshift32(pub u32);

impl Xorshift32 {
    /// The next number in [0, 1).
    pub fn unit(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 17;
        self.0 ^= self.0 << 5;
        (self.0 >> 8) as f32 / (1u32 << 24) as f32
    }

    /// A point in the box `min..max`.
    pub fn inside(&mut self, min: Vec3, max: Vec3) -> Vec3 {
        min + Vec3::new(self.unit(), self.unit(), self.unit()) * (max - min)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ray_meets_a_triangle_from_either_side_inside_its_edges() {
        let tri = Triangle::new(Vec3::ZERO, Vec3::X, Vec3::Y);
        let (t, u, v) = ray_triangle(Vec3::new(0.25, 0.25, 2.0), -Vec3::Z, &tri, f32::MAX).expect("hit from above");
        assert!((t - 2.0).abs() < 1e-6 && (u - 0.25).abs() < 1e-6 && (v - 0.25).abs() < 1e-6);
        assert!(ray_triangle(Vec3::new(0.25, 0.25, -1.0), Vec3::Z, &tri, f32::MAX).is_some(), "from below");
        assert!(ray_triangle(Vec3::new(0.75, 0.75, 2.0), -Vec3::Z, &tri, f32::MAX).is_none(), "beyond the hypotenuse");
        assert!(ray_triangle(Vec3::new(0.25, 0.25, 2.0), Vec3::Z, &tri, f32::MAX).is_none(), "behind the origin");
        assert!(ray_triangle(Vec3::new(0.25, 0.25, 2.0), -Vec3::Z, &tri, 1.5).is_none(), "beyond t_max");
        assert!(ray_triangle(Vec3::new(-1.0, 0.25, 0.0), Vec3::X, &tri, f32::MAX).is_none(), "in its plane");
    }

    #[test]
    fn the_slab_test_enters_misses_and_starts_inside() {
        let (min, max) = (Vec3::splat(-1.0), Vec3::splat(1.0));
        let o = Vec3::new(-3.0, 0.0, 0.0);
        assert_eq!(ray_box(o, inv_dir(Vec3::X), min, max, f32::MAX), Some(2.0));
        assert_eq!(ray_box(o, inv_dir(-Vec3::X), min, max, f32::MAX), None, "pointing away");
        assert_eq!(ray_box(o, inv_dir(Vec3::X), min, max, 2.0), None, "enters at t_max");
        assert_eq!(ray_box(Vec3::ZERO, inv_dir(Vec3::Y), min, max, f32::MAX), Some(0.0), "inside");
        // Axis-parallel inside a slab: finite distances (no 0 · ∞), a hit;
        // along a face's plane: a graze, which misses (the same on the GPU).
        assert_eq!(ray_box(Vec3::new(-3.0, 0.5, 0.0), inv_dir(Vec3::X), min, max, f32::MAX), Some(2.0));
        assert_eq!(ray_box(Vec3::new(-3.0, 1.0, 0.0), inv_dir(Vec3::X), min, max, f32::MAX), None);
        assert_eq!(ray_box(Vec3::new(-3.0, 1.5, 0.0), inv_dir(Vec3::X), min, max, f32::MAX), None);
    }
}
