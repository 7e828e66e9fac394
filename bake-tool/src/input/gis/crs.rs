//! The CRS a GIS file declares: an EPSG code (a GeoPackage's
//! `gpkg_spatial_ref_sys`, a FlatGeobuf header, a WKT's outer `AUTHORITY`),
//! or a WKT (`.prj`) without one. ESRI's `.prj` carries no code: its name is
//! matched against the EPSG names of crs-definitions (`ETRS_1989_UTM_Zone_32N`
//! is `ETRS89 / UTM zone 32N`), else the WKT is turned into a proj string by
//! proj4wkt and used as it is.

use std::collections::HashMap;
use std::sync::OnceLock;

use anyhow::{anyhow, Result};

/// A file's CRS.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DeclaredCrs {
    /// An EPSG code.
    Epsg(u32),
    /// A CRS the file names that cannot be used (no EPSG code, no EPSG name,
    /// no projection proj4rs knows): why, for the error a bake without
    /// `--input-crs` gives.
    Unusable(String),
    /// A CRS with no EPSG code: its WKT name and proj string.
    Proj4 {
        /// The WKT's name (`PROJCS["…"`).
        name: String,
        /// The proj string proj4wkt made of it.
        proj4: String,
    },
}

impl DeclaredCrs {
    /// For the log: `EPSG:28992` or the WKT's name.
    #[must_use]
    pub fn describe(&self) -> String {
        match self {
            DeclaredCrs::Epsg(c) => format!("EPSG:{c}"),
            DeclaredCrs::Proj4 { name, proj4 } => format!("{name:?} ({proj4})"),
            DeclaredCrs::Unusable(why) => format!("an unusable one ({why})"),
        }
    }

    /// Whether its coordinates are degrees (`None`: unknown to proj4rs).
    #[must_use]
    pub fn is_geographic(&self) -> Option<bool> {
        match self {
            DeclaredCrs::Epsg(c) => crate::input::reproject::Crs::from_epsg(*c).ok().map(|c| c.is_geographic()),
            DeclaredCrs::Proj4 { proj4, .. } => proj4rs::Proj::from_proj_string(proj4).ok().map(|p| p.is_latlong()),
            DeclaredCrs::Unusable(_) => None,
        }
    }

    /// Reads a WKT (WKT1 as `.prj` files hold it, or WKT2); one that cannot
    /// be used is [`DeclaredCrs::Unusable`] (`--input-crs` may stand in).
    #[must_use]
    pub fn read_wkt(wkt: &str) -> Self {
        Self::from_wkt(wkt).unwrap_or_else(|e| DeclaredCrs::Unusable(e.to_string()))
    }

    /// Reads a WKT (WKT1 as `.prj` files hold it, or WKT2). A compound CRS
    /// (`COMPD_CS`, `COMPOUNDCRS`) is read as its horizontal part.
    ///
    /// # Errors
    /// A WKT with no EPSG code, no EPSG name and no projection proj4wkt knows.
    pub fn from_wkt(wkt: &str) -> Result<Self> {
        let trimmed = wkt.trim_start();
        let upper = trimmed.get(..12).unwrap_or(trimmed).to_ascii_uppercase();
        if upper.starts_with("COMPD_CS[") || upper.starts_with("COMPOUNDCRS[") {
            // The first member after the name: the horizontal CRS.
            let inner = trimmed.find('[').map_or("", |i| &trimmed[i + 1..]);
            let after_name = inner.find(',').map_or("", |i| &inner[i + 1..]);
            let mut depth = 0i32;
            let end = after_name
                .char_indices()
                .find(|&(_, c)| {
                    match c {
                        '[' | '(' => depth += 1,
                        ']' | ')' => depth -= 1,
                        _ => {}
                    }
                    depth == 0 && (c == ']' || c == ')')
                })
                .map_or(after_name.len(), |(i, _)| i + 1);
            return Self::from_wkt(after_name[..end].trim());
        }
        if let Some(code) =
            epsg_of_wkt(wkt).filter(|&c| u16::try_from(c).ok().and_then(crs_definitions::from_code).is_some())
        {
            return Ok(DeclaredCrs::Epsg(code));
        }
        let name = wkt_name(wkt).unwrap_or_default();
        let (whole, projection) = epsg_names();
        let key = normalise(&name);
        if let Some(&code) = whole.get(&key).or_else(|| projection.get(&key).and_then(Option::as_ref)) {
            return Ok(DeclaredCrs::Epsg(code));
        }
        let proj4 = proj4wkt::wkt_to_projstring(wkt).map_err(|e| {
            anyhow!("its CRS {name:?} has no EPSG code, is no EPSG name and cannot be read as a projection ({e})")
        })?;
        proj4rs::Proj::from_proj_string(&proj4)
            .map_err(|e| anyhow!("its CRS {name:?} ({proj4}) cannot be used by proj4rs: {e}"))?;
        Ok(DeclaredCrs::Proj4 { name, proj4 })
    }
}

/// The EPSG code of a WKT's outermost `AUTHORITY["EPSG","…"]` (WKT1) or
/// `ID["EPSG",…]` (WKT2): the CRS's own, not its datum's or unit's.
#[must_use]
pub fn epsg_of_wkt(wkt: &str) -> Option<u32> {
    let bytes = wkt.as_bytes();
    let mut depth = 0i32;
    let mut in_string = false;
    let mut found = None;
    let mut i = 0;
    while i < bytes.len() {
        let c = bytes[i];
        if in_string {
            in_string = c != b'"';
        } else {
            match c {
                b'"' => in_string = true,
                b'[' | b'(' => depth += 1,
                b']' | b')' => depth -= 1,
                _ if depth == 1 => {
                    let rest = &wkt[i..];
                    let upper = rest.get(..10).unwrap_or(rest).to_ascii_uppercase();
                    let skip = if upper.starts_with("AUTHORITY[") {
                        10
                    } else if upper.starts_with("ID[") {
                        3
                    } else {
                        0
                    };
                    if skip > 0 && (i == 0 || matches!(bytes[i - 1], b',' | b' ' | b'\n' | b'\t')) {
                        let args: String = rest[skip..].chars().take_while(|&c| c != ']').collect();
                        let mut parts = args.split(',').map(|s| s.trim().trim_matches('"'));
                        if parts.next().is_some_and(|a| a.eq_ignore_ascii_case("EPSG")) {
                            found = parts.next().and_then(|c| c.parse().ok()).or(found);
                        }
                    }
                }
                _ => {}
            }
        }
        i += 1;
    }
    found
}

/// The name of a WKT's CRS: `PROJCS["name",…` → `name`.
fn wkt_name(wkt: &str) -> Option<String> {
    let start = wkt.find('"')? + 1;
    let len = wkt[start..].find('"')?;
    Some(wkt[start..start + len].to_string())
}

/// A CRS name compared without case, punctuation, ESRI's `GCS_` and its
/// four-digit datum years: `GCS_WGS_1984` and `WGS 84` are one name.
fn normalise(name: &str) -> String {
    let lower = name.to_lowercase();
    let lower = lower.strip_prefix("gcs_").unwrap_or(&lower);
    let mut s: String = lower.chars().filter(char::is_ascii_alphanumeric).collect();
    for (long, short) in [("wgs1984", "wgs84"), ("etrs1989", "etrs89"), ("nad1983", "nad83"), ("nad1927", "nad27")] {
        s = s.replace(long, short);
    }
    s
}

/// Every crs-definitions CRS by its normalised name (the lowest code where
/// names repeat), and by the part of its name after the datum (`RD New` of
/// `Amersfoort / RD New`, as ESRI names it) where that part is one CRS's.
#[allow(clippy::type_complexity)]
fn epsg_names() -> &'static (HashMap<String, u32>, HashMap<String, Option<u32>>) {
    static NAMES: OnceLock<(HashMap<String, u32>, HashMap<String, Option<u32>>)> = OnceLock::new();
    NAMES.get_or_init(|| {
        let (mut whole, mut projection) = (HashMap::new(), HashMap::new());
        for code in 1..=u16::MAX {
            if let Some(def) = crs_definitions::from_code(code) {
                if let Some(name) = wkt_name(def.wkt) {
                    whole.entry(normalise(&name)).or_insert(u32::from(code));
                    if let Some((_, after)) = name.split_once(" / ") {
                        projection
                            .entry(normalise(after))
                            .and_modify(|c: &mut Option<u32>| *c = None)
                            .or_insert(Some(u32::from(code)));
                    }
                }
            }
        }
        (whole, projection)
    })
}

/// The EPSG code of a GeoJSON `crs` member (GeoJSON 2008, still written by
/// GIS exports): `"EPSG:28992"`, `"urn:ogc:def:crs:EPSG::28992"`; CRS84 and
/// EPSG:4326 are none (the GeoJSON default).
pub fn geojson_crs(v: &serde_json::Value) -> Option<u32> {
    let name = v.get("crs")?.get("properties")?.get("name")?.as_str()?;
    let code = name.rsplit(':').next()?;
    code.parse().ok().filter(|&c| c != 4326)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn esri_and_ogc_wkts_name_their_epsg_code() {
        // OGC WKT1 (GDAL's .prj): the outer AUTHORITY, not the datum's.
        let ogc = crs_definitions::from_code(32633).unwrap().wkt;
        assert_eq!(DeclaredCrs::from_wkt(ogc).unwrap(), DeclaredCrs::Epsg(32633));
        // ESRI .prj files: no AUTHORITY; names matched.
        let esri_utm = r#"PROJCS["ETRS_1989_UTM_Zone_32N",GEOGCS["GCS_ETRS_1989",DATUM["D_ETRS_1989",SPHEROID["GRS_1980",6378137.0,298.257222101]],PRIMEM["Greenwich",0.0],UNIT["Degree",0.0174532925199433]],PROJECTION["Transverse_Mercator"],PARAMETER["False_Easting",500000.0],PARAMETER["False_Northing",0.0],PARAMETER["Central_Meridian",9.0],PARAMETER["Scale_Factor",0.9996],PARAMETER["Latitude_Of_Origin",0.0],UNIT["Meter",1.0]]"#;
        assert_eq!(DeclaredCrs::from_wkt(esri_utm).unwrap(), DeclaredCrs::Epsg(25832));
        let esri_wgs = r#"GEOGCS["GCS_WGS_1984",DATUM["D_WGS_1984",SPHEROID["WGS_1984",6378137.0,298.257223563]],PRIMEM["Greenwich",0.0],UNIT["Degree",0.0174532925199433]]"#;
        assert_eq!(DeclaredCrs::from_wkt(esri_wgs).unwrap(), DeclaredCrs::Epsg(4326));
        assert_eq!(DeclaredCrs::Epsg(4326).is_geographic(), Some(true));
        let rd = r#"PROJCS["Amersfoort_RD_New",GEOGCS["GCS_Amersfoort",DATUM["D_Amersfoort",SPHEROID["Bessel_1841",6377397.155,299.1528128]],PRIMEM["Greenwich",0.0],UNIT["Degree",0.0174532925199433]],PROJECTION["Double_Stereographic"],PARAMETER["False_Easting",155000.0],PARAMETER["False_Northing",463000.0],PARAMETER["Central_Meridian",5.38763888888889],PARAMETER["Scale_Factor",0.9999079],PARAMETER["Latitude_Of_Origin",52.15616055555555],UNIT["Meter",1.0]]"#;
        assert_eq!(DeclaredCrs::from_wkt(rd).unwrap(), DeclaredCrs::Epsg(28992));
        // WKT2: the outer ID.
        let wkt2 = r#"PROJCRS["WGS 84 / UTM zone 10N",BASEGEOGCRS["WGS 84",DATUM["World Geodetic System 1984",ELLIPSOID["WGS 84",6378137,298.257223563]],ID["EPSG",4326]],CONVERSION["UTM zone 10N",METHOD["Transverse Mercator",ID["EPSG",9807]]],ID["EPSG",32610]]"#;
        assert_eq!(epsg_of_wkt(wkt2), Some(32610));
    }

    #[test]
    fn a_wkt_without_a_code_or_known_name_is_used_as_a_projection() {
        let custom = r#"PROJCS["Forest_District_Grid",GEOGCS["GCS_WGS_1984",DATUM["D_WGS_1984",SPHEROID["WGS_1984",6378137.0,298.257223563]],PRIMEM["Greenwich",0.0],UNIT["Degree",0.0174532925199433]],PROJECTION["Transverse_Mercator"],PARAMETER["False_Easting",100000.0],PARAMETER["False_Northing",0.0],PARAMETER["Central_Meridian",11.0],PARAMETER["Scale_Factor",1.0],PARAMETER["Latitude_Of_Origin",0.0],UNIT["Meter",1.0]]"#;
        match DeclaredCrs::from_wkt(custom).unwrap() {
            DeclaredCrs::Proj4 { name, proj4 } => {
                assert_eq!(name, "Forest_District_Grid");
                assert!(proj4.contains("+proj=tmerc") && proj4.contains("+lon_0=11"), "{proj4}");
            }
            other => panic!("{other:?}"),
        }
        let e = DeclaredCrs::from_wkt("PROJCS[\"nonsense\",FOO[1]]").unwrap_err().to_string();
        assert!(e.contains("nonsense"), "{e}");
        assert!(DeclaredCrs::from_wkt("").is_err());
    }
}
