//! Geographic coordinates of a scene: lon/lat/height ↔ metres relative to the
//! scene origin, through the scene's projected CRS (its proj4 definition from
//! the manifest) with proj4rs. Used for geographic cameras and shareable links.

use glam::DVec3;
use proj4rs::transform::{transform, Transform, TransformClosure};
use proj4rs::Proj;

/// Why a conversion failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GeoError {
    /// The manifest's proj4 definition is not usable.
    #[error("the scene CRS {0:?} cannot be used for geographic coordinates: {1}")]
    Crs(String, String),
    /// A point could not be transformed.
    #[error("cannot convert the point: {0}")]
    Point(String),
}

struct P([f64; 3]);

impl Transform for P {
    fn transform_coordinates<F: TransformClosure>(&mut self, f: &mut F) -> proj4rs::errors::Result<()> {
        let (x, y, z) = f(self.0[0], self.0[1], self.0[2])?;
        self.0 = [x, y, z];
        Ok(())
    }
}

/// Converts between WGS 84 lon/lat (degrees, height in metres) and scene-relative metres.
pub struct GeoFrame {
    scene: Proj,
    wgs84: Proj,
    origin_m: DVec3,
}

impl GeoFrame {
    /// For a scene whose CRS has the proj4 definition `proj4` and origin `origin_m`.
    ///
    /// # Errors
    /// [`GeoError::Crs`] when proj4rs cannot parse the definition.
    pub fn new(proj4: &str, origin_m: [f64; 3]) -> Result<Self, GeoError> {
        let scene = Proj::from_proj_string(proj4).map_err(|e| GeoError::Crs(proj4.into(), e.to_string()))?;
        let wgs84 = Proj::from_proj_string("+proj=longlat +datum=WGS84 +no_defs")
            .map_err(|e| GeoError::Crs("WGS84".into(), e.to_string()))?;
        Ok(Self { scene, wgs84, origin_m: DVec3::from(origin_m) })
    }

    /// Scene-relative metres of `lon`, `lat` (degrees) at `height` metres.
    ///
    /// # Errors
    /// [`GeoError::Point`] for points the projection cannot take.
    pub fn to_local(&self, lon: f64, lat: f64, height: f64) -> Result<DVec3, GeoError> {
        let mut p = P([lon.to_radians(), lat.to_radians(), 0.0]);
        transform(&self.wgs84, &self.scene, &mut p).map_err(|e| GeoError::Point(e.to_string()))?;
        let v = DVec3::new(p.0[0], p.0[1], height) - self.origin_m;
        if v.is_finite() {
            Ok(v)
        } else {
            Err(GeoError::Point(format!("{lon}, {lat} has no finite projection")))
        }
    }

    /// (lon, lat, height) of a scene-relative point.
    ///
    /// # Errors
    /// [`GeoError::Point`] for points the projection cannot take.
    pub fn to_geo(&self, local: DVec3) -> Result<(f64, f64, f64), GeoError> {
        let w = local + self.origin_m;
        let mut p = P([w.x, w.y, 0.0]);
        transform(&self.scene, &self.wgs84, &mut p).map_err(|e| GeoError::Point(e.to_string()))?;
        Ok((p.0[0].to_degrees(), p.0[1].to_degrees(), w.z))
    }
}

impl GeoFrame {
    /// Unit vector towards a sun at `azimuth_deg` (clockwise from true north)
    /// and `elevation_deg`, in scene coordinates at the scene-relative point
    /// `local`: the scene's grid north is turned from true north by the
    /// projection's convergence there (up to a few degrees in UTM).
    ///
    /// # Errors
    /// [`GeoError::Point`] for points the projection cannot take.
    pub fn sun_direction(&self, local: DVec3, azimuth_deg: f64, elevation_deg: f64) -> Result<DVec3, GeoError> {
        let north = self.true_north(local)?;
        let east = glam::DVec2::new(north.y, -north.x);
        let (az, el) = (azimuth_deg.to_radians(), elevation_deg.to_radians());
        let flat = east * az.sin() * el.cos() + north * az.cos() * el.cos();
        Ok(DVec3::new(flat.x, flat.y, el.sin()).normalize())
    }
}

impl GeoFrame {
    /// Unit vector (scene x, y) towards true north at the scene-relative
    /// point `local`: grid north turned by the projection's convergence.
    ///
    /// # Errors
    /// [`GeoError::Point`] for points the projection cannot take or where
    /// north has no direction (a pole).
    pub fn true_north(&self, local: DVec3) -> Result<glam::DVec2, GeoError> {
        let (lon, lat, _) = self.to_geo(local)?;
        let ahead = self.to_local(lon, (lat + 1e-3).min(90.0), local.z)?;
        let north = (ahead - local).truncate().normalize_or_zero();
        if north == glam::DVec2::ZERO {
            return Err(GeoError::Point(format!("no north at {lon}, {lat}")));
        }
        Ok(north)
    }

    /// The scene's heading (radians clockwise from grid north, as
    /// [`crate::camera::Camera`] takes it) of a bearing `true_deg` degrees
    /// clockwise from true north at `local`, as maps and globes give it.
    ///
    /// # Errors
    /// As [`Self::true_north`].
    pub fn grid_heading(&self, local: DVec3, true_deg: f64) -> Result<f64, GeoError> {
        let north = self.true_north(local)?;
        Ok(north.x.atan2(north.y) + true_deg.to_radians())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_through_utm33() {
        let f =
            GeoFrame::new("+proj=utm +zone=33 +datum=WGS84 +units=m +no_defs", [540_000.0, 5_360_000.0, 0.0]).unwrap();
        // Reference: PROJ (pyproj) puts 15.4° E 48.4° N at E 529 606.786, N 5 360 837.401 in UTM 33N.
        let local = f.to_local(15.4, 48.4, 300.0).unwrap();
        assert!((local.x - (529_606.786 - 540_000.0)).abs() < 0.01 && (local.y - 837.401).abs() < 0.01, "{local}");
        let (lon, lat, h) = f.to_geo(local).unwrap();
        assert!((lon - 15.4).abs() < 1e-9 && (lat - 48.4).abs() < 1e-9 && (h - 300.0).abs() < 1e-9);
        assert!(GeoFrame::new("+proj=nonsense", [0.0; 3]).is_err());
    }

    #[test]
    fn grid_heading_turns_true_bearings_by_the_convergence() {
        let f =
            GeoFrame::new("+proj=utm +zone=33 +datum=WGS84 +units=m +no_defs", [540_000.0, 5_360_000.0, 0.0]).unwrap();
        // West of the central meridian (15° E) the meridian runs towards it
        // going north, so true north lies clockwise of grid north by
        // atan(tan Δλ · sin φ) = 2.243° (PROJ's meridian convergence there is
        // −2.243°: grid north seen from true north), and a true bearing of 0°
        // is a grid heading of +2.243°.
        let local = f.to_local(12.0, 48.4, 0.0).unwrap();
        let h = f.grid_heading(local, 0.0).unwrap().to_degrees();
        assert!((h - 2.243).abs() < 0.01, "{h}");
        let h90 = f.grid_heading(local, 90.0).unwrap().to_degrees();
        assert!((h90 - h - 90.0).abs() < 1e-9, "{h90}");
        // On the central meridian grid and true north agree.
        let on = f.to_local(15.0, 48.4, 0.0).unwrap();
        assert!((f.grid_heading(on, 30.0).unwrap().to_degrees() - 30.0).abs() < 1e-6);
    }
}
