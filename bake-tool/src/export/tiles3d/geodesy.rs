//! Where the export's trees stand on the globe: WGS84 geodetic ↔ ECEF, a
//! tile's east-north-up frame, and a tree's placement in it.

use anyhow::Result;
use glam::DVec3;
use serde_json::{json, Value};
use sylva::geo::GeoFrame;

/// WGS84 semi-major axis, metres.
pub(super) const WGS84_A: f64 = 6_378_137.0;
/// WGS84 flattening.
pub(super) const WGS84_F: f64 = 1.0 / 298.257_223_563;

/// Earth-centred, Earth-fixed metres of a WGS84 point (degrees, metres).
#[must_use]
pub fn geodetic_to_ecef(lon_deg: f64, lat_deg: f64, h: f64) -> DVec3 {
    let e2 = WGS84_F * (2.0 - WGS84_F);
    let (sl, cl) = lat_deg.to_radians().sin_cos();
    let (so, co) = lon_deg.to_radians().sin_cos();
    let n = WGS84_A / (1.0 - e2 * sl * sl).sqrt();
    DVec3::new((n + h) * cl * co, (n + h) * cl * so, (n * (1.0 - e2) + h) * sl)
}

/// (lon, lat in degrees, height in metres) of an Earth-centred, Earth-fixed point.
#[cfg(test)]
pub(super) fn ecef_to_geodetic(p: DVec3) -> (f64, f64, f64) {
    let e2 = WGS84_F * (2.0 - WGS84_F);
    let lon = p.y.atan2(p.x);
    let r = p.x.hypot(p.y);
    let mut lat = p.z.atan2(r * (1.0 - e2));
    let mut h = 0.0;
    for _ in 0..8 {
        let s = lat.sin();
        let n = WGS84_A / (1.0 - e2 * s * s).sqrt();
        h = r / lat.cos() - n;
        lat = p.z.atan2(r * (1.0 - e2 * n / (n + h)));
    }
    (lon.to_degrees(), lat.to_degrees(), h)
}

/// The east-north-up frame at a WGS84 point: (origin, east, north, up) in ECEF.
#[must_use]
pub fn enu_frame(lon_deg: f64, lat_deg: f64, h: f64) -> [DVec3; 4] {
    let (sl, cl) = lat_deg.to_radians().sin_cos();
    let (so, co) = lon_deg.to_radians().sin_cos();
    [
        geodetic_to_ecef(lon_deg, lat_deg, h),
        DVec3::new(-so, co, 0.0),
        DVec3::new(-sl * co, -sl * so, cl),
        DVec3::new(cl * co, cl * so, sl),
    ]
}

/// The frame as a 3D Tiles `transform` (column-major 4×4, ENU → ECEF).
pub(super) fn transform_json(f: &[DVec3; 4]) -> Value {
    let [o, e, n, u] = f;
    json!([e.x, e.y, e.z, 0.0, n.x, n.y, n.z, 0.0, u.x, u.y, u.z, 0.0, o.x, o.y, o.z, 1.0])
}

/// A tree in its tile's frame, as glTF (y up): translation, rotation about +y, scale.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExportedTree {
    /// glTF translation (x east, y up, z south), metres.
    pub translation: [f32; 3],
    /// Quaternion `[x, y, z, w]` about +y.
    pub rotation: [f32; 4],
    /// Scale `[horizontal, vertical, horizontal]`.
    pub scale: [f32; 3],
    /// The tree's index in its tile (the order of `.ids` and `.attr`).
    pub index: u32,
}

/// Places a tree (`local`: trunk base relative to the scene origin; yaw in the
/// scene's grid) in the frame `f` through WGS84.
pub(super) fn place(
    geo: &GeoFrame,
    f: &[DVec3; 4],
    local: DVec3,
    yaw: f64,
    scale: f32,
    aspect: f32,
) -> Result<ExportedTree> {
    let enu = |p: DVec3| -> Result<DVec3> {
        let (lon, lat, h) = geo.to_geo(p).map_err(|e| anyhow::anyhow!("{e}"))?;
        let d = geodetic_to_ecef(lon, lat, h) - f[0];
        Ok(DVec3::new(d.dot(f[1]), d.dot(f[2]), d.dot(f[3])))
    };
    let t = enu(local)?;
    // The model's x axis, one metre along the grid's yaw, as the frame sees it (grid convergence).
    let ahead = enu(local + DVec3::new(yaw.cos(), yaw.sin(), 0.0))? - t;
    let theta = ahead.y.atan2(ahead.x);
    let (s, c) = (theta * 0.5).sin_cos();
    Ok(ExportedTree {
        translation: [t.x as f32, t.z as f32, -t.y as f32],
        rotation: [0.0, s as f32, 0.0, c as f32],
        scale: [scale * aspect, scale, scale * aspect],
        index: 0,
    })
}

/// The scene-relative trunk position a glTF translation in frame `f` maps back to.
///
/// # Errors
/// Points the scene's projection cannot take.
#[cfg(test)]
pub(super) fn unplace(geo: &GeoFrame, f: &[DVec3; 4], translation: [f32; 3]) -> Result<DVec3> {
    let t = DVec3::new(f64::from(translation[0]), -f64::from(translation[2]), f64::from(translation[1]));
    let p = f[0] + f[1] * t.x + f[2] * t.y + f[3] * t.z;
    let (lon, lat, h) = ecef_to_geodetic(p);
    geo.to_local(lon, lat, h).map_err(|e| anyhow::anyhow!("{e}"))
}
