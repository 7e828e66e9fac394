//! The sun at a date, time and place: NOAA's solar position algorithm (the
//! "General Solar Position Calculations" of the NOAA Global Monitoring
//! Division, after Meeus, *Astronomical Algorithms*), accurate to about 0.01°
//! between 1800 and 2100, with NOAA's atmospheric refraction correction.
//!
//! Times are parsed from ISO 8601 (`2026-06-21T15:00`, seconds optional, `Z`
//! or `±HH:MM` for the offset from UTC). A time without an offset is the local
//! *mean* time of the place's time zone derived from its longitude (the
//! nearest whole hour: `round(lon / 15)`), which is what a planner means by
//! "15:00 there" within an hour of daylight saving; give the offset to be exact.

use std::f64::consts::PI;

/// A moment: a civil date and time and its offset from UTC.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SunTime {
    /// Year (e.g. 2026).
    pub year: i32,
    /// Month, 1–12.
    pub month: u32,
    /// Day of the month, 1–31.
    pub day: u32,
    /// Hour, 0–23 (24:00 is accepted as the end of the day).
    pub hour: u32,
    /// Minute, 0–59.
    pub minute: u32,
    /// Seconds, 0–60.
    pub second: f64,
    /// Offset of the civil time from UTC, minutes (east positive), if given.
    pub utc_offset_min: Option<i32>,
}

/// Where the sun stands, seen from a place.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolarPosition {
    /// Azimuth, degrees clockwise from true north.
    pub azimuth_deg: f64,
    /// Elevation above the horizon, degrees, with refraction (negative below it).
    pub elevation_deg: f64,
    /// Declination, degrees.
    pub declination_deg: f64,
    /// Equation of time, minutes.
    pub equation_of_time_min: f64,
}

impl SunTime {
    /// Parses `YYYY-MM-DDTHH:MM[:SS[.s]][Z|±HH:MM]` (a space may replace the `T`).
    ///
    /// # Errors
    /// A message naming what is wrong, with an example of the form.
    pub fn parse(text: &str) -> Result<Self, String> {
        let bad =
            |why: &str| format!("sun time {text:?}: {why} (expected e.g. 2026-06-21T15:00 or 2026-06-21T15:00+02:00)");
        let t = text.trim();
        let (date, rest) = t.split_once(['T', ' ']).ok_or_else(|| bad("no time after the date"))?;
        let d: Vec<&str> = date.split('-').collect();
        let [y, mo, da] = d[..] else { return Err(bad("the date is not YYYY-MM-DD")) };
        let year: i32 = y.parse().map_err(|_| bad("the year is not a number"))?;
        let month: u32 = mo.parse().map_err(|_| bad("the month is not a number"))?;
        let day: u32 = da.parse().map_err(|_| bad("the day is not a number"))?;
        let (clock, offset) = if let Some(c) = rest.strip_suffix('Z') {
            (c, Some(0))
        } else if let Some(i) = rest.rfind(['+', '-']) {
            let (c, o) = rest.split_at(i);
            let sign = if o.starts_with('-') { -1 } else { 1 };
            let (oh, om) = o[1..].split_once(':').unwrap_or((&o[1..], "0"));
            let oh: i32 = oh.parse().map_err(|_| bad("the UTC offset is not ±HH:MM"))?;
            let om: i32 = om.parse().map_err(|_| bad("the UTC offset is not ±HH:MM"))?;
            if oh > 14 || om > 59 {
                return Err(bad("the UTC offset is beyond ±14:00"));
            }
            (c, Some(sign * (oh * 60 + om)))
        } else {
            (rest, None)
        };
        let c: Vec<&str> = clock.split(':').collect();
        let (hour, minute, second) = match c[..] {
            [h, m] => (h, m, "0"),
            [h, m, s] => (h, m, s),
            _ => return Err(bad("the time is not HH:MM or HH:MM:SS")),
        };
        let hour: u32 = hour.parse().map_err(|_| bad("the hour is not a number"))?;
        let minute: u32 = minute.parse().map_err(|_| bad("the minute is not a number"))?;
        let second: f64 = second.parse().map_err(|_| bad("the seconds are not a number"))?;
        if !(1..=12).contains(&month) || day == 0 || day > crate::calendar::days_in_month(year, month) {
            return Err(bad("no such date"));
        }
        if hour > 24 || minute > 59 || !(0.0..61.0).contains(&second) || (hour == 24 && (minute > 0 || second > 0.0)) {
            return Err(bad("no such time of day"));
        }
        if !(1800..=2200).contains(&year) {
            return Err(bad("the year is outside 1800–2200, where the algorithm holds"));
        }
        Ok(Self { year, month, day, hour, minute, second, utc_offset_min: offset })
    }

    /// The offset from UTC used at longitude `lon_deg`: the given one, else
    /// the nearest whole hour of the longitude.
    #[must_use]
    pub fn offset_min(&self, lon_deg: f64) -> i32 {
        self.utc_offset_min.unwrap_or_else(|| ((lon_deg / 15.0).round() * 60.0) as i32)
    }

    /// Julian day (UT) of this moment at longitude `lon_deg`.
    #[must_use]
    pub fn julian_day(&self, lon_deg: f64) -> f64 {
        let (mut y, mut m) = (f64::from(self.year), f64::from(self.month));
        if m <= 2.0 {
            y -= 1.0;
            m += 12.0;
        }
        let a = (y / 100.0).floor();
        let b = 2.0 - a + (a / 4.0).floor();
        let jd0 = (365.25 * (y + 4716.0)).floor() + (30.6001 * (m + 1.0)).floor() + f64::from(self.day) + b - 1524.5;
        let local_min = f64::from(self.hour) * 60.0 + f64::from(self.minute) + self.second / 60.0;
        jd0 + (local_min - f64::from(self.offset_min(lon_deg))) / 1440.0
    }
}

/// The sun's position at `time` seen from `lat_deg`, `lon_deg` (WGS 84
/// degrees, east positive).
#[must_use]
pub fn solar_position(time: &SunTime, lat_deg: f64, lon_deg: f64) -> SolarPosition {
    let r = |d: f64| d.to_radians();
    let jd = time.julian_day(lon_deg);
    let t = (jd - 2_451_545.0) / 36_525.0;
    let l0 = (280.466_46 + t * (36_000.769_83 + t * 0.000_303_2)).rem_euclid(360.0);
    let m = 357.529_11 + t * (35_999.050_29 - 0.000_153_7 * t);
    let e = 0.016_708_634 - t * (0.000_042_037 + 0.000_000_126_7 * t);
    let c = r(m).sin() * (1.914_602 - t * (0.004_817 + 0.000_014 * t))
        + r(2.0 * m).sin() * (0.019_993 - 0.000_101 * t)
        + r(3.0 * m).sin() * 0.000_289;
    let true_long = l0 + c;
    let omega = 125.04 - 1_934.136 * t;
    let app_long = true_long - 0.005_69 - 0.004_78 * r(omega).sin();
    let mean_obliq = 23.0 + (26.0 + (21.448 - t * (46.815 + t * (0.000_59 - t * 0.001_813))) / 60.0) / 60.0;
    let obliq = mean_obliq + 0.002_56 * r(omega).cos();
    let decl = (r(obliq).sin() * r(app_long).sin()).asin();
    let y = (r(obliq) / 2.0).tan().powi(2);
    let eot = 4.0
        * (y * (2.0 * r(l0)).sin() - 2.0 * e * r(m).sin() + 4.0 * e * y * r(m).sin() * (2.0 * r(l0)).cos()
            - 0.5 * y * y * (4.0 * r(l0)).sin()
            - 1.25 * e * e * (2.0 * r(m)).sin())
        .to_degrees();
    // True solar time at the place, minutes.
    let utc_min = (jd + 0.5).fract() * 1440.0;
    let tst = (utc_min + eot + 4.0 * lon_deg).rem_euclid(1440.0);
    let hour_angle = tst / 4.0 - 180.0;
    let lat = r(lat_deg);
    let cos_zenith = (lat.sin() * decl.sin() + lat.cos() * decl.cos() * r(hour_angle).cos()).clamp(-1.0, 1.0);
    let zenith = cos_zenith.acos();
    let elevation = 90.0 - zenith.to_degrees();
    // Azimuth clockwise from north.
    let denom = lat.cos() * zenith.sin();
    let azimuth = if denom.abs() < 1e-12 {
        if lat_deg > 0.0 {
            180.0
        } else {
            0.0
        }
    } else {
        let a = ((lat.sin() * zenith.cos() - decl.sin()) / denom).clamp(-1.0, 1.0).acos().to_degrees();
        if hour_angle > 0.0 {
            (a + 180.0).rem_euclid(360.0)
        } else {
            (540.0 - a).rem_euclid(360.0)
        }
    };
    SolarPosition {
        azimuth_deg: azimuth,
        elevation_deg: elevation + refraction_deg(elevation),
        declination_deg: decl.to_degrees(),
        equation_of_time_min: eot,
    }
}

/// NOAA's approximate atmospheric refraction (degrees) at a true elevation.
fn refraction_deg(e: f64) -> f64 {
    if e > 85.0 {
        return 0.0;
    }
    let te = (e * PI / 180.0).tan();
    let arcsec = if e > 5.0 {
        58.1 / te - 0.07 / te.powi(3) + 0.000_086 / te.powi(5)
    } else if e > -0.575 {
        1735.0 + e * (-518.2 + e * (103.4 + e * (-12.79 + e * 0.711)))
    } else {
        -20.772 / te
    };
    arcsec / 3600.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_the_nrel_spa_reference_and_the_seasons() {
        // NREL's SPA report (Reda & Andreas 2008, table A4.1): Golden, Colorado,
        // 2003-10-17 12:30:30 −07:00: zenith 50.11162°, azimuth 194.34024°
        // (their refraction for 820 mbar and 11 °C; NOAA's is for the standard
        // atmosphere, a few hundredths of a degree apart here).
        let t = SunTime::parse("2003-10-17T12:30:30-07:00").unwrap();
        let p = solar_position(&t, 39.742_476, -105.1786);
        assert!((90.0 - p.elevation_deg - 50.111_62).abs() < 0.05, "{p:?}");
        assert!((p.azimuth_deg - 194.340_24).abs() < 0.05, "{p:?}");
        // June solstice: the declination is the obliquity (23.44°); at solar noon
        // on the equator the sun stands 23.44° north of the zenith.
        let noon = SunTime::parse("2026-06-21T12:00Z").unwrap();
        let p = solar_position(&noon, 0.0, 0.0);
        assert!((p.declination_deg - 23.44).abs() < 0.02, "{p:?}");
        assert!((p.elevation_deg - (90.0 - 23.44)).abs() < 0.5 && p.azimuth_deg.abs() < 5.0, "{p:?}");
        // Berlin at 15:00 summer time (13:00 UTC) on the solstice: solar noon is
        // at 11:08 UTC (13.4° east, equation of time −1.8 min), so the hour
        // angle is 28°: sin(el) = sin 52.52° sin 23.44° + cos 52.52° cos 23.44°
        // cos 28° → 54.0° up, south-west (227°).
        let berlin = solar_position(&SunTime::parse("2026-06-21T15:00+02:00").unwrap(), 52.52, 13.405);
        assert!((berlin.azimuth_deg - 227.0).abs() < 1.0 && (berlin.elevation_deg - 54.0).abs() < 0.5, "{berlin:?}");
        // Midnight there: below the horizon, to the north.
        let night = solar_position(&SunTime::parse("2026-06-21T01:00+02:00").unwrap(), 52.52, 13.405);
        assert!(night.elevation_deg < -10.0 && !(90.0..270.0).contains(&night.azimuth_deg), "{night:?}");
        // The southern hemisphere at noon in June: low, to the north.
        let hobart = solar_position(&SunTime::parse("2026-06-21T12:00+10:00").unwrap(), -42.88, 147.33);
        assert!(hobart.elevation_deg < 25.0 && hobart.elevation_deg > 20.0, "{hobart:?}");
        assert!(!(90.0..270.0).contains(&hobart.azimuth_deg), "{hobart:?}");
    }

    #[test]
    fn times_parse_with_or_without_an_offset_and_bad_ones_say_why() {
        let t = SunTime::parse("2026-06-21T15:00").unwrap();
        assert_eq!(
            (t.year, t.month, t.day, t.hour, t.minute, t.second, t.utc_offset_min),
            (2026, 6, 21, 15, 0, 0.0, None)
        );
        // Without an offset: the longitude's whole hour (Berlin: +1 h).
        assert_eq!(t.offset_min(13.4), 60);
        assert_eq!(t.offset_min(-119.27), -480);
        assert_eq!(SunTime::parse("2026-06-21 15:00:30Z").unwrap().utc_offset_min, Some(0));
        assert_eq!(SunTime::parse("2026-06-21T15:00-03:30").unwrap().utc_offset_min, Some(-210));
        // The same moment in two zones is the same Julian day.
        let a = SunTime::parse("2026-06-21T15:00+02:00").unwrap().julian_day(0.0);
        let b = SunTime::parse("2026-06-21T13:00Z").unwrap().julian_day(0.0);
        assert!((a - b).abs() < 1e-9);
        // J2000.0 is JD 2451545.0.
        assert_eq!(SunTime::parse("2000-01-01T12:00Z").unwrap().julian_day(0.0), 2_451_545.0);
        for (bad, why) in [
            ("2026-06-21", "no time"),
            ("2026-02-30T10:00", "no such date"),
            ("2026-06-21T25:00", "no such time"),
            ("2026-06-21T10:00+15:00", "beyond"),
            ("21.06.2026T10:00", "YYYY-MM-DD"),
            ("1700-06-21T10:00", "1800–2200"),
        ] {
            let e = SunTime::parse(bad).unwrap_err();
            assert!(e.contains(why) && e.contains("expected e.g."), "{bad}: {e}");
        }
    }
}
