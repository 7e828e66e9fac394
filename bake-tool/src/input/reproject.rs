//! Coordinate reference systems: lon/lat → a projected CRS with proj4rs and the
//! EPSG definitions of crs-definitions. No hand-rolled projection formulas.

use anyhow::{anyhow, bail, Result};
use proj4rs::transform::{transform, Transform, TransformClosure};
use proj4rs::Proj;

/// A projected CRS the scene is baked in.
pub struct Crs {
    /// EPSG code.
    pub epsg: u32,
    /// proj4 definition.
    pub proj4: String,
    proj: Proj,
}

impl std::fmt::Debug for Crs {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "EPSG:{} ({})", self.epsg, self.proj4)
    }
}

impl Crs {
    /// Looks up an EPSG code. Geographic CRSs are refused for scenes (they are not in metres).
    pub fn from_epsg(epsg: u32) -> Result<Self> {
        let code = u16::try_from(epsg).map_err(|_| anyhow!("EPSG:{epsg} is not a known EPSG code"))?;
        let def = crs_definitions::from_code(code)
            .ok_or_else(|| anyhow!("EPSG:{epsg} is not in the CRS database (crs-definitions); pick a projected CRS such as a UTM zone (EPSG:326xx/327xx)"))?;
        let proj = Proj::from_proj_string(def.proj4)
            .map_err(|e| anyhow!("EPSG:{epsg} ({}) cannot be used by proj4rs: {e}", def.proj4))?;
        Ok(Self { epsg, proj4: def.proj4.to_string(), proj })
    }

    /// A CRS a file declares without an EPSG code (a `.prj` WKT turned into a
    /// proj string): `epsg` is 0; for reading placements, not for scenes.
    pub fn from_proj4(name: &str, proj4: &str) -> Result<Self> {
        let proj = Proj::from_proj_string(proj4)
            .map_err(|e| anyhow!("CRS {name:?} ({proj4}) cannot be used by proj4rs: {e}"))?;
        Ok(Self { epsg: 0, proj4: proj4.to_string(), proj })
    }

    /// Parses `EPSG:32633` or `32633`.
    pub fn parse(text: &str) -> Result<Self> {
        let code = text.trim().trim_start_matches("EPSG:").trim_start_matches("epsg:");
        let epsg: u32 = code.parse().map_err(|_| anyhow!("--crs {text:?}: expected an EPSG code like EPSG:32633"))?;
        Self::from_epsg(epsg)
    }

    /// Whether coordinates are lon/lat degrees.
    pub fn is_geographic(&self) -> bool {
        self.proj.is_latlong()
    }

    /// A projected CRS for scenes; refuses geographic ones.
    pub fn projected(epsg: u32) -> Result<Self> {
        let crs = Self::from_epsg(epsg)?;
        if crs.is_geographic() {
            bail!("EPSG:{epsg} is geographic (degrees); a scene needs a projected CRS in metres such as UTM");
        }
        Ok(crs)
    }

    /// The WGS 84 / UTM zone CRS covering `lon`, `lat` (degrees).
    pub fn utm_for(lon: f64, lat: f64) -> Result<Self> {
        let zone = (((lon + 180.0) / 6.0).floor() as i64).clamp(0, 59) + 1;
        let epsg = if lat >= 0.0 { 32600 } else { 32700 } + zone as u32;
        Self::projected(epsg)
    }
}

struct Point3([f64; 3]);

impl Transform for Point3 {
    fn transform_coordinates<F: TransformClosure>(&mut self, f: &mut F) -> proj4rs::errors::Result<()> {
        let [x, y, z] = self.0;
        let (x, y, z) = f(x, y, z)?;
        self.0 = [x, y, z];
        Ok(())
    }
}

/// Transforms points between CRSs, one at a time so one bad point does not stop the rest.
pub struct Reprojector {
    src: Crs,
    dst: Proj,
}

impl Reprojector {
    /// From `src` to `dst`.
    pub fn new(src: Crs, dst: &Crs) -> Result<Self> {
        let dst_proj = Proj::from_proj_string(&dst.proj4).map_err(|e| anyhow!("{dst:?}: {e}"))?;
        Ok(Self { src, dst: dst_proj })
    }

    /// Transforms one point; geographic inputs are (lon, lat) in degrees.
    pub fn apply(&self, x: f64, y: f64) -> Result<(f64, f64)> {
        let mut p =
            if self.src.is_geographic() { Point3([x.to_radians(), y.to_radians(), 0.0]) } else { Point3([x, y, 0.0]) };
        transform(&self.src.proj, &self.dst, &mut p).map_err(|e| anyhow!("{e}"))?;
        let [ox, oy, _] = p.0;
        let (ox, oy) = if self.dst.is_latlong() { (ox.to_degrees(), oy.to_degrees()) } else { (ox, oy) };
        if !ox.is_finite() || !oy.is_finite() {
            bail!("the projection gave a non-finite result");
        }
        Ok((ox, oy))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utm_zone_selection() {
        assert_eq!(Crs::utm_for(4.9, 52.37).unwrap().epsg, 32631);
        assert_eq!(Crs::utm_for(15.4, 48.4).unwrap().epsg, 32633);
        assert_eq!(Crs::utm_for(-70.0, -33.0).unwrap().epsg, 32719);
    }

    #[test]
    fn reprojection_matches_proj_reference_values() {
        // Reference values from PROJ 9 through pyproj (`Transformer.from_crs("EPSG:4326",
        // "EPSG:326zz", always_xy=True)`), computed once and pasted here.
        let cases = [
            (32631, 4.9003, 52.3789, 629_346.321_275, 5_804_881.148_641), // Amsterdam Centraal
            (32633, 15.4, 48.4, 529_606.786_407, 5_360_837.401_285),      // Wachau
            (32633, 9.5, 48.0, 89_790.666_696, 5_330_953.163_952),        // 5.5° west of the zone centre
        ];
        for (epsg, lon, lat, e_ref, n_ref) in cases {
            let r = Reprojector::new(Crs::from_epsg(4326).unwrap(), &Crs::projected(epsg).unwrap()).unwrap();
            let (e, n) = r.apply(lon, lat).unwrap();
            assert!((e - e_ref).abs() < 0.01 && (n - n_ref).abs() < 0.01, "EPSG:{epsg} {lon},{lat}: {e},{n}");
        }
    }

    #[test]
    fn zone_centre_meridian_has_false_easting() {
        // On the central meridian (15° E for zone 33) the easting is exactly 500 000 m,
        // and the equator has northing 0.
        let r = Reprojector::new(Crs::from_epsg(4326).unwrap(), &Crs::projected(32633).unwrap()).unwrap();
        let (e, n) = r.apply(15.0, 0.0).unwrap();
        assert!((e - 500_000.0).abs() < 1e-6 && n.abs() < 1e-6, "{e} {n}");
        // 1° north along the central meridian: k0 · meridian arc = 0.9996 · 110 574.4 m.
        let (_, n1) = r.apply(15.0, 1.0).unwrap();
        assert!((n1 - 110_530.2).abs() < 1.0, "{n1}");
    }

    #[test]
    fn round_trip_far_from_zone_centre() {
        let utm = Crs::projected(32633).unwrap();
        let fwd = Reprojector::new(Crs::from_epsg(4326).unwrap(), &utm).unwrap();
        let inv = Reprojector::new(Crs::projected(32633).unwrap(), &Crs::from_epsg(4326).unwrap()).unwrap();
        for (lon, lat) in [(9.5, 48.0), (20.9, 60.0), (15.0, 0.5)] {
            let (e, n) = fwd.apply(lon, lat).unwrap();
            let (lon2, lat2) = inv.apply(e, n).unwrap();
            assert!((lon - lon2).abs() < 1e-7 && (lat - lat2).abs() < 1e-7, "{lon},{lat} -> {lon2},{lat2}");
        }
    }

    #[test]
    fn far_from_the_zone_centre_matches_reference_values() {
        // EPSG:4326 → EPSG:32633 by PROJ 9 (pyproj 3.7), up to 6° from the central
        // meridian (zone 33 spans 12°–18°; these lie in neighbouring zones).
        let fwd = Reprojector::new(Crs::from_epsg(4326).unwrap(), &Crs::projected(32633).unwrap()).unwrap();
        for (lon, lat, e, n) in [
            (9.5, 48.0, 89_790.666_696, 5_330_953.163_952),
            (20.9, 60.0, 828_796.993_392, 6_666_091.488_869),
            (12.0, 47.5, 274_068.607_960, 5_265_092.549_077),
            (15.0, 0.5, 500_000.0, 55_265.037_143),
        ] {
            let (x, y) = fwd.apply(lon, lat).unwrap();
            assert!((x - e).abs() < 0.01 && (y - n).abs() < 0.01, "{lon},{lat}: {x:.3},{y:.3} vs {e},{n}");
        }
    }

    #[test]
    fn geographic_scene_crs_is_refused() {
        let err = Crs::projected(4326).unwrap_err().to_string();
        assert!(err.contains("geographic"), "{err}");
        assert!(Crs::parse("EPSG:99999999").is_err());
    }
}
