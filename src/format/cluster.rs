//! Clustered-ellipsoid and line levels of a LoD pack (Clasen et al. 2010): the records of
//! the `ELPS` and `LINE` sections and their metadata.
//!
//! Records are uploaded to the GPU as they are: 24 bytes per ellipsoid (the
//! paper stores 140) and 16 bytes per line (the paper: 48). Positions are 16-bit
//! fixed point over the pack's model bounds (`META.bounds_min..bounds_max`, under
//! 1/65535 of the tree's size), radii half floats, rotations 8-bit quaternions.

use bytemuck::{Pod, Zeroable};
use glam::{Quat, Vec3};
use half::f16;
use serde::{Deserialize, Serialize};

/// One level of ellipsoids or lines.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClusterLevelMeta {
    /// Primitives in the level (records in the section with this level's index).
    pub count: u32,
    /// Projected tree height (px) from which this level is the right one: its
    /// median primitive is then ~5 px wide (ellipsoids) or ~1 px (lines), Clasen et al. 2010, §6.
    pub select_px: f32,
    /// Multi-scale RMSE (0–1) against the full mesh, measured at bake time at `select_px`.
    pub error: f32,
    /// Alpha-noise threshold `t` shared by the level's ellipsoids (0: no holes).
    #[serde(default)]
    pub noise_threshold: f32,
    /// Blend of the surface normal towards the noise normal (0–1).
    #[serde(default)]
    pub normal_blend: f32,
    /// The bake's LoD policy measurement (`crate::lod::policy::policy_keeps`): this level's
    /// multi-scale RMSE and the far tier's against the full mesh, both rendered
    /// by the viewer's pipelines at `select_px` from two views. Absent in older
    /// packs (the level is then drawn).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pareto_error: Option<[f32; 2]>,
    /// The same draws' modelled GPU time per tree (µs), this level's and the far
    /// tier's (`crate::lod::policy`). Absent: the far tier is taken as half
    /// the cost.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pareto_cost: Option<[f32; 2]>,
}

/// The cluster levels of a pack.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClusterMeta {
    /// Ellipsoid levels, finest first (`ELPS` sections, index = level).
    pub ellipsoid_levels: Vec<ClusterLevelMeta>,
    /// Line levels, finest first (`LINE` sections, index = level); level `k` is
    /// drawn together with ellipsoid level `k`.
    pub line_levels: Vec<ClusterLevelMeta>,
    /// Linear RGB of the lines (the bark's mean albedo).
    pub line_color: [f32; 3],
}

/// An ellipsoid as the bake computes it (model space, metres at scale 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ellipsoid {
    /// Centre.
    pub center: Vec3,
    /// Rotation from the ellipsoid's axes to model space.
    pub rotation: Quat,
    /// Semi-axis lengths along the rotated x, y, z axes.
    pub radii: Vec3,
    /// Linear RGB albedo.
    pub color: Vec3,
    /// Noise mip level `l_j = 0.5 (1 + log2 Σ_i w_ij)` (Clasen et al. 2010, §3.1).
    pub noise_level: f32,
}

/// A line (a capsule from `a` to `b`), model space, metres at scale 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Line {
    /// Start (the end nearer the trunk base).
    pub a: Vec3,
    /// End.
    pub b: Vec3,
    /// Radius at `a`.
    pub radius_a: f32,
    /// Radius at `b`.
    pub radius_b: f32,
}

/// Largest noise level a record holds.
pub const MAX_NOISE_LEVEL: f32 = 16.0;

/// Stored ellipsoid (24 bytes). Must match `unpack_ellipsoid` in `shaders/cluster.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable)]
pub struct PackedEllipsoid {
    /// 0: centre x, y (unorm16 over the bounds); 1: centre z, noise level / 16 (unorm16);
    /// 2: radii x, y (f16); 3: radius z, 0 (f16); 4: rotation xyzw (snorm8);
    /// 5: sRGB colour, alpha 255 (unorm8).
    pub words: [u32; 6],
}
const _: () = assert!(std::mem::size_of::<PackedEllipsoid>() == 24);

/// Stored line (16 bytes). Must match `unpack_line` in `shaders/cluster.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable)]
pub struct PackedLine {
    /// 0: a.x, a.y; 1: a.z, b.x; 2: b.y, b.z (unorm16 over the bounds); 3: radii a, b (f16).
    pub words: [u32; 4],
}
const _: () = assert!(std::mem::size_of::<PackedLine>() == 16);

fn unorm16(v: f32, lo: f32, hi: f32) -> u32 {
    let t = if hi > lo { (v - lo) / (hi - lo) } else { 0.0 };
    (t.clamp(0.0, 1.0) * 65535.0).round() as u32
}

fn from_unorm16(q: u32, lo: f32, hi: f32) -> f32 {
    lo + (hi - lo) * (q & 0xffff) as f32 / 65535.0
}

fn pack2(lo: u32, hi: u32) -> u32 {
    (lo & 0xffff) | (hi << 16)
}

fn f16_bits(v: f32) -> u32 {
    u32::from(f16::from_f32(v).to_bits())
}

fn from_f16(bits: u32) -> f32 {
    f16::from_bits((bits & 0xffff) as u16).to_f32()
}

fn snorm8(v: f32) -> u32 {
    ((v.clamp(-1.0, 1.0) * 127.0).round() as i32 as u32) & 0xff
}

fn from_snorm8(b: u32) -> f32 {
    (f32::from((b & 0xff) as u8 as i8) / 127.0).max(-1.0)
}

/// sRGB transfer of a linear value.
#[must_use]
pub fn linear_to_srgb(v: f32) -> f32 {
    let v = v.clamp(0.0, 1.0);
    if v <= 0.003_130_8 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// Linear value of an sRGB one.
#[must_use]
pub fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.040_45 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

impl PackedEllipsoid {
    /// Quantises `e` over the model bounds `lo..hi`.
    #[must_use]
    pub fn encode(e: &Ellipsoid, lo: Vec3, hi: Vec3) -> Self {
        let mut q = e.rotation.normalize();
        if q.w < 0.0 {
            q = -q;
        }
        let c = e.color.to_array().map(|v| (linear_to_srgb(v) * 255.0).round() as u32);
        let level = unorm16(e.noise_level, 0.0, MAX_NOISE_LEVEL);
        Self {
            words: [
                pack2(unorm16(e.center.x, lo.x, hi.x), unorm16(e.center.y, lo.y, hi.y)),
                pack2(unorm16(e.center.z, lo.z, hi.z), level),
                pack2(f16_bits(e.radii.x), f16_bits(e.radii.y)),
                pack2(f16_bits(e.radii.z), 0),
                snorm8(q.x) | (snorm8(q.y) << 8) | (snorm8(q.z) << 16) | (snorm8(q.w) << 24),
                c[0] | (c[1] << 8) | (c[2] << 16) | (255 << 24),
            ],
        }
    }

    /// The ellipsoid as the shader reads it.
    #[must_use]
    pub fn decode(&self, lo: Vec3, hi: Vec3) -> Ellipsoid {
        let w = &self.words;
        let q = Quat::from_xyzw(
            from_snorm8(w[4]),
            from_snorm8(w[4] >> 8),
            from_snorm8(w[4] >> 16),
            from_snorm8(w[4] >> 24),
        );
        Ellipsoid {
            center: Vec3::new(
                from_unorm16(w[0], lo.x, hi.x),
                from_unorm16(w[0] >> 16, lo.y, hi.y),
                from_unorm16(w[1], lo.z, hi.z),
            ),
            rotation: if q.length_squared() > 0.0 { q.normalize() } else { Quat::IDENTITY },
            radii: Vec3::new(from_f16(w[2]), from_f16(w[2] >> 16), from_f16(w[3])),
            color: Vec3::new(
                srgb_to_linear((w[5] & 0xff) as f32 / 255.0),
                srgb_to_linear(((w[5] >> 8) & 0xff) as f32 / 255.0),
                srgb_to_linear(((w[5] >> 16) & 0xff) as f32 / 255.0),
            ),
            noise_level: from_unorm16(w[1] >> 16, 0.0, MAX_NOISE_LEVEL),
        }
    }
}

impl PackedLine {
    /// Quantises `l` over the model bounds `lo..hi`.
    #[must_use]
    pub fn encode(l: &Line, lo: Vec3, hi: Vec3) -> Self {
        Self {
            words: [
                pack2(unorm16(l.a.x, lo.x, hi.x), unorm16(l.a.y, lo.y, hi.y)),
                pack2(unorm16(l.a.z, lo.z, hi.z), unorm16(l.b.x, lo.x, hi.x)),
                pack2(unorm16(l.b.y, lo.y, hi.y), unorm16(l.b.z, lo.z, hi.z)),
                pack2(f16_bits(l.radius_a), f16_bits(l.radius_b)),
            ],
        }
    }

    /// The line as the shader reads it.
    #[must_use]
    pub fn decode(&self, lo: Vec3, hi: Vec3) -> Line {
        let w = &self.words;
        Line {
            a: Vec3::new(
                from_unorm16(w[0], lo.x, hi.x),
                from_unorm16(w[0] >> 16, lo.y, hi.y),
                from_unorm16(w[1], lo.z, hi.z),
            ),
            b: Vec3::new(
                from_unorm16(w[1] >> 16, lo.x, hi.x),
                from_unorm16(w[2], lo.y, hi.y),
                from_unorm16(w[2] >> 16, lo.z, hi.z),
            ),
            radius_a: from_f16(w[3]),
            radius_b: from_f16(w[3] >> 16),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ellipsoid_round_trip_within_quantisation() {
        let lo = Vec3::new(-5.0, -5.0, 0.0);
        let hi = Vec3::new(5.0, 5.0, 20.0);
        let e = Ellipsoid {
            center: Vec3::new(1.234, -2.5, 13.7),
            rotation: Quat::from_euler(glam::EulerRot::ZYX, 0.7, -0.3, 1.1),
            radii: Vec3::new(2.0, 0.75, 0.01),
            color: Vec3::new(0.1, 0.3, 0.05),
            noise_level: 3.4,
        };
        let d = PackedEllipsoid::encode(&e, lo, hi).decode(lo, hi);
        assert!((d.center - e.center).abs().max_element() < 20.0 / 65535.0);
        assert!((d.radii - e.radii).abs().max_element() < 2e-3);
        assert!(d.rotation.dot(e.rotation).abs() > 0.999, "{:?} vs {:?}", d.rotation, e.rotation);
        assert!((d.color - e.color).abs().max_element() < 0.01);
        assert!((d.noise_level - e.noise_level).abs() < 1e-3);
    }

    #[test]
    fn line_round_trip_within_quantisation() {
        let lo = Vec3::new(-5.0, -5.0, 0.0);
        let hi = Vec3::new(5.0, 5.0, 20.0);
        let l = Line { a: Vec3::new(0.0, 0.0, 0.0), b: Vec3::new(3.0, -1.0, 12.0), radius_a: 0.4, radius_b: 0.05 };
        let d = PackedLine::encode(&l, lo, hi).decode(lo, hi);
        assert!((d.a - l.a).abs().max_element() < 1e-3 && (d.b - l.b).abs().max_element() < 1e-3);
        assert!((d.radius_a - 0.4).abs() < 1e-3 && (d.radius_b - 0.05).abs() < 1e-4);
    }
}
