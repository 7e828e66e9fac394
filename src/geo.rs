//! Geographic coordinates of a scene: lon/lat/height ↔ metres relative to the
//! scene origin. A scene baked with a geographic fit (`crs.fit`, manifest
//! version 12, [`crate::format::geofit`]) is converted by the fit, in the
//! browser and natively alike; natively, a scene without one falls back to
//! its proj4 definition through proj4rs (the browser's wasm carries no
//! projection library). Used for geographic cameras, shareable links, the sun
//! at a date and XYZ imagery.

use glam::DVec3;
#[cfg(not(target_arch = "wasm32"))]
use proj4rs::transform::{transform, Transform, TransformClosure};
#[cfg(not(target_arch = "wasm32"))]
use proj4rs::Proj;

use crate::format::geofit::GeoFit;
use crate::format::manifest::Crs;

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

#[cfg(not(target_arch = "wasm32"))]
struct P([f64; 3]);

#[cfg(not(target_arch = "wasm32"))]
impl Transform for P {
    fn transform_coordinates<F: TransformClosure>(&mut self, f: &mut F) -> proj4rs::errors::Result<()> {
        let (x, y, z) = f(self.0[0], self.0[1], self.0[2])?;
        self.0 = [x, y, z];
        Ok(())
    }
}

/// Converts between WGS 84 lon/lat (degrees, height in metres) and scene-relative metres.
pub struct GeoFrame {
    how: How,
    origin_m: DVec3,
}

enum How {
    /// The bake's fit.
    Fit(Box<GeoFit>),
    /// The exact projection (native only).
    #[cfg(not(target_arch = "wasm32"))]
    Exact { scene: Box<Proj>, wgs84: Box<Proj> },
}

impl GeoFrame {
    /// For a scene with the CRS `crs` and origin `origin_m`: its fit when it
    /// has one, else (natively) its proj4 definition.
    ///
    /// # Errors
    /// [`GeoError::Crs`] when the scene has no fit and (in the browser) no
    /// way to use its definition, or (natively) proj4rs cannot parse it.
    pub fn for_scene(crs: &Crs, origin_m: [f64; 3]) -> Result<Self, GeoError> {
        if let Some(fit) = &crs.fit {
            return Ok(Self { how: How::Fit(Box::new(fit.clone())), origin_m: DVec3::from(origin_m) });
        }
        #[cfg(not(target_arch = "wasm32"))]
        return Self::new(&crs.proj4, origin_m);
        #[cfg(target_arch = "wasm32")]
        Err(GeoError::Crs(
            crs.proj4.clone(),
            "the scene was baked without a geographic fit (manifest version 12), which the browser needs for \
             lon/lat: re-bake it, or add one with `sylva-bake geo-fit SCENE_DIR`"
                .into(),
        ))
    }

    /// For a scene whose CRS has the proj4 definition `proj4` and origin
    /// `origin_m`, through proj4rs (exact; native only).
    ///
    /// # Errors
    /// [`GeoError::Crs`] when proj4rs cannot parse the definition.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn new(proj4: &str, origin_m: [f64; 3]) -> Result<Self, GeoError> {
        let scene = Proj::from_proj_string(proj4).map_err(|e| GeoError::Crs(proj4.into(), e.to_string()))?;
        let wgs84 = Proj::from_proj_string("+proj=longlat +datum=WGS84 +no_defs")
            .map_err(|e| GeoError::Crs("WGS84".into(), e.to_string()))?;
        Ok(Self { how: How::Exact { scene: Box::new(scene), wgs84: Box::new(wgs84) }, origin_m: DVec3::from(origin_m) })
    }

    /// Whether conversions go through the bake's fit (else the exact projection).
    #[must_use]
    pub fn is_fit(&self) -> bool {
        matches!(self.how, How::Fit(_))
    }

    /// A fit of this frame's conversions over the scene-relative box
    /// `[x0, y0, x1, y1]` (what the bake writes as `crs.fit`).
    ///
    /// # Errors
    /// [`GeoError::Point`] when the projection fails in the box or the box
    /// cannot be fitted (see [`GeoFit::fit`]).
    #[cfg(not(target_arch = "wasm32"))]
    pub fn fit(&self, local: [f64; 4]) -> Result<GeoFit, GeoError> {
        let to_geo = |x: f64, y: f64| self.to_geo(DVec3::new(x, y, 0.0)).ok().map(|(lon, lat, _)| (lon, lat));
        let to_local = |lon: f64, lat: f64| self.to_local(lon, lat, 0.0).ok().map(|v| (v.x, v.y));
        GeoFit::fit(local, &to_geo, &to_local).map_err(GeoError::Point)
    }

    /// Scene-relative metres of `lon`, `lat` (degrees) at `height` metres.
    ///
    /// # Errors
    /// [`GeoError::Point`] for points the projection cannot take.
    pub fn to_local(&self, lon: f64, lat: f64, height: f64) -> Result<DVec3, GeoError> {
        let v = match &self.how {
            How::Fit(fit) => {
                let (x, y) = fit.to_local(lon, lat).unwrap_or((f64::NAN, f64::NAN));
                DVec3::new(x, y, height - self.origin_m.z)
            }
            #[cfg(not(target_arch = "wasm32"))]
            How::Exact { scene, wgs84 } => {
                let mut p = P([lon.to_radians(), lat.to_radians(), 0.0]);
                transform(wgs84, scene, &mut p).map_err(|e| GeoError::Point(e.to_string()))?;
                DVec3::new(p.0[0], p.0[1], height) - self.origin_m
            }
        };
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
        let height = local.z + self.origin_m.z;
        match &self.how {
            How::Fit(fit) => fit
                .to_geo(local.x, local.y)
                .map(|(lon, lat)| (lon, lat, height))
                .ok_or_else(|| GeoError::Point(format!("{local} has no finite lon/lat"))),
            #[cfg(not(target_arch = "wasm32"))]
            How::Exact { scene, wgs84 } => {
                let w = local + self.origin_m;
                let mut p = P([w.x, w.y, 0.0]);
                transform(scene, wgs84, &mut p).map_err(|e| GeoError::Point(e.to_string()))?;
                Ok((p.0[0].to_degrees(), p.0[1].to_degrees(), height))
            }
        }
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

    /// The fit the bake writes against proj4rs at points off its nodes and
    /// check grid, for the projections scenes use, small and large boxes.
    #[test]
    fn the_fit_matches_the_projection_to_a_millimetre() {
        let cases = [
            // UTM 33N, a 12 km and a 300 km box.
            ("+proj=utm +zone=33 +datum=WGS84 +units=m +no_defs", [540_000.0, 5_360_000.0, 0.0], 6_000.0),
            ("+proj=utm +zone=33 +datum=WGS84 +units=m +no_defs", [540_000.0, 5_360_000.0, 0.0], 150_000.0),
            // RD New (Amsterdam's trees), with its datum shift.
            (
                "+proj=sterea +lat_0=52.15616055555555 +lon_0=5.38763888888889 +k=0.9999079 +x_0=155000 \
                 +y_0=463000 +ellps=bessel +towgs84=565.417,50.3319,465.552,-0.398957,0.343988,-1.8774,4.0725 \
                 +units=m +no_defs",
                [121_000.0, 487_000.0, 0.0],
                10_000.0,
            ),
            // Web Mercator over 1,000 km.
            (
                "+proj=merc +a=6378137 +b=6378137 +lat_ts=0 +lon_0=0 +x_0=0 +y_0=0 +k=1 +units=m +no_defs",
                [1_000_000.0, 6_500_000.0, 0.0],
                500_000.0,
            ),
            // NEON's UTM 11N plot.
            ("+proj=utm +zone=11 +datum=WGS84 +units=m +no_defs", [298_000.0, 4_100_000.0, 1_200.0], 2_000.0),
        ];
        for (proj4, origin, half) in cases {
            let exact = GeoFrame::new(proj4, origin).unwrap();
            let fit = exact.fit([-half, -half * 0.7, half, half * 1.3]).unwrap();
            assert!(fit.error_m <= crate::format::geofit::FIT_TOLERANCE_M, "{proj4}: {} m", fit.error_m);
            let crs = Crs { epsg: 0, proj4: proj4.into(), fit: Some(fit.clone()) };
            let fitted = GeoFrame::for_scene(&crs, origin).unwrap();
            assert!(fitted.is_fit() && !exact.is_fit());
            for k in 0..50 {
                let (a, b) = ((k as f64 * 0.618_034).fract(), (k as f64 * 0.414_214).fract());
                let p = DVec3::new(-half + 2.0 * half * a, -half * 0.7 + 2.0 * half * b, 15.0);
                let (lon, lat, h) = exact.to_geo(p).unwrap();
                let (flon, flat, fh) = fitted.to_geo(p).unwrap();
                let d = ((flon - lon) * lat.to_radians().cos()).hypot(flat - lat) * 111_320.0;
                assert!(d < 0.002 && (fh - h).abs() < 1e-9, "{proj4} at {p}: {d} m");
                let back = fitted.to_local(lon, lat, h).unwrap();
                assert!((back - p).length() < 0.002, "{proj4}: {back} vs {p}");
            }
            // North and the sun agree too.
            let at = DVec3::new(half * 0.3, half * 0.2, 0.0);
            let (a, b) = (exact.grid_heading(at, 0.0).unwrap(), fitted.grid_heading(at, 0.0).unwrap());
            assert!((a - b).abs() < 1e-5, "{proj4}: heading {a} vs {b}");
        }
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
