//! Phenology: when a deciduous genus is in leaf, colouring and bare at a date
//! and place (issue 46, first slice: the rule; the viewer's date control
//! follows).
//!
//! Each genus has five days of the year for a lowland site at 50° N (Central
//! Europe): leaf unfolding begins, full leaf, colouring begins, full colour,
//! leaf fall complete. The days are moved by place:
//! - **Latitude**: Hopkins' bioclimatic law (Hopkins 1918, *Periodical events
//!   and natural law as guides to agricultural research and practice*, Monthly
//!   Weather Review Supplement 9): spring events come about 4 days later per
//!   degree poleward, autumn ones correspondingly earlier, between 35° and 70°
//!   (nearer the equator the 35° calendar: carried further the rate would
//!   leave no winter). South of the equator the year is turned by half (the
//!   same latitude's season six months apart).
//! - **Elevation**: Čufar et al. 2012 (*Temporal shifts in leaf phenology of
//!   beech (Fagus sylvatica) depend on elevation*, Trees 26: 1091–1100, over 47
//!   Slovenian sites 1955–2007): leaf unfolding 2.6 days later and leaf
//!   colouring 1.9 days earlier per 100 m.
//!
//! The beech row follows Čufar et al.'s network means (leaf unfolding mid-April
//! to mid-May, colouring 3–29 October across elevations 55–1,050 m), taken to
//! 50° N lowland; the other genera are placed against it by their known order
//! (birch, horse chestnut, willow and larch early in spring; oak and ash late;
//! birch and horse chestnut colouring first, oak, alder and plane last). They are
//! estimates of long-term means, not a forecast: a year's weather moves each
//! event by a week or two (Estrella & Menzel 2006, *Responses of leaf colouring
//! in four deciduous tree species to climate and weather in Germany*, Climate
//! Research 32: 253–267, found colouring barely predictable from weather).

/// The days of the year of a genus's leaf events at 50° N, sea level.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Phenology {
    /// Leaf unfolding begins.
    pub leaf_out: f32,
    /// In full leaf.
    pub full_leaf: f32,
    /// Leaf colouring begins.
    pub colour: f32,
    /// Full autumn colour.
    pub full_colour: f32,
    /// Leaf fall complete: bare.
    pub bare: f32,
}

/// Latitude the table is for, degrees north.
pub const REFERENCE_LATITUDE: f64 = 50.0;
/// Hopkins' law: days per degree of latitude poleward (spring later, autumn earlier).
pub const DAYS_PER_DEGREE: f64 = 4.0;
/// Čufar et al. 2012: leaf unfolding later per 100 m of elevation, days.
pub const SPRING_DAYS_PER_100_M: f64 = 2.6;
/// Čufar et al. 2012: leaf colouring earlier per 100 m of elevation, days.
pub const AUTUMN_DAYS_PER_100_M: f64 = 1.9;

const fn row(leaf_out: f32, colour: f32, bare: f32) -> Phenology {
    // Full leaf three weeks after unfolding begins; full colour two weeks after
    // colouring begins (never past the leaves' fall).
    let full_colour = if colour + 14.0 < bare { colour + 14.0 } else { bare - 1.0 };
    Phenology { leaf_out, full_leaf: leaf_out + 21.0, colour, full_colour, bare }
}

/// The rule of a deciduous genus (Latin name, any case), or the default
/// broadleaf's (the beech's days) for a genus not in the table.
#[must_use]
pub fn of_genus(genus: &str) -> Phenology {
    GENERA.iter().find(|(g, _)| g.eq_ignore_ascii_case(genus.trim())).map_or(DEFAULT, |(_, p)| *p)
}

/// The default deciduous rule (a genus the table lacks): the beech's.
pub const DEFAULT: Phenology = row(113.0, 282.0, 305.0);

/// The table: genus → leaf unfolding, colouring and bare days at 50° N, sea level.
pub const GENERA: [(&str, Phenology); 35] = [
    ("Fagus", row(113.0, 282.0, 305.0)),
    ("Quercus", row(120.0, 288.0, 315.0)),
    ("Betula", row(105.0, 272.0, 298.0)),
    ("Aesculus", row(102.0, 268.0, 295.0)),
    ("Acer", row(110.0, 280.0, 303.0)),
    ("Tilia", row(114.0, 276.0, 300.0)),
    ("Fraxinus", row(124.0, 284.0, 300.0)),
    ("Carpinus", row(111.0, 285.0, 310.0)),
    ("Ulmus", row(110.0, 285.0, 305.0)),
    ("Alnus", row(108.0, 295.0, 312.0)),
    ("Corylus", row(105.0, 285.0, 305.0)),
    ("Populus", row(104.0, 283.0, 305.0)),
    ("Salix", row(100.0, 285.0, 308.0)),
    ("Larix", row(98.0, 290.0, 310.0)),
    ("Prunus", row(104.0, 278.0, 300.0)),
    ("Malus", row(106.0, 282.0, 305.0)),
    ("Pyrus", row(106.0, 285.0, 308.0)),
    ("Sorbus", row(104.0, 270.0, 295.0)),
    ("Crataegus", row(102.0, 280.0, 302.0)),
    ("Robinia", row(127.0, 285.0, 300.0)),
    ("Gleditsia", row(128.0, 282.0, 300.0)),
    ("Juglans", row(125.0, 278.0, 295.0)),
    ("Castanea", row(118.0, 290.0, 312.0)),
    ("Platanus", row(118.0, 292.0, 325.0)),
    ("Liquidambar", row(115.0, 295.0, 325.0)),
    ("Liriodendron", row(112.0, 285.0, 310.0)),
    ("Magnolia", row(110.0, 285.0, 310.0)),
    ("Catalpa", row(132.0, 285.0, 300.0)),
    ("Ginkgo", row(110.0, 295.0, 318.0)),
    ("Ailanthus", row(125.0, 282.0, 300.0)),
    ("Morus", row(122.0, 285.0, 305.0)),
    ("Celtis", row(118.0, 288.0, 310.0)),
    ("Zelkova", row(115.0, 290.0, 312.0)),
    ("Taxodium", row(118.0, 295.0, 320.0)),
    ("Metasequoia", row(112.0, 292.0, 318.0)),
];

/// Where a genus is in its year: 0 bare (winter), 0–1 leaves unfolding, 1 in
/// full leaf, 1–2 colouring, 2 in full colour, 2–3 leaves falling, 3 bare
/// again. The integer parts name the state, the fractions how far a stand is
/// through a change (for the trees' own pace about it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Phase(pub f32);

impl Phase {
    /// The state a whole stand is drawn in when one state must stand for it
    /// (the far tiers, the canopy rasters): bare before half its leaves are
    /// out and after half have fallen, colouring from the middle of the
    /// colouring on, else in leaf.
    #[must_use]
    pub fn season(self) -> crate::format::pack::Season {
        use crate::format::pack::Season;
        match self.0 {
            p if !(0.5..2.5).contains(&p) => Season::LeafOff,
            p if p >= 1.5 => Season::Autumn,
            _ => Season::LeafOn,
        }
    }
}

impl Phenology {
    /// The rule's days moved to `latitude` (degrees, south negative) and
    /// `elevation_m` (Hopkins 1918; Čufar et al. 2012). South of the equator the
    /// days are those of the same northern latitude half a year on.
    #[must_use]
    pub fn at(self, latitude: f64, elevation_m: f64) -> Self {
        // (Below 35° the 35° calendar: Hopkins' rate carried further would
        // leave no winter at all; above 70° the 70° one. NaN: the reference.)
        let lat = if latitude.is_nan() { REFERENCE_LATITUDE } else { latitude.abs().clamp(35.0, 70.0) };
        let elevation_m = if elevation_m.is_nan() { 0.0 } else { elevation_m };
        let elevation = elevation_m.clamp(-500.0, 4_000.0);
        let spring = ((lat - REFERENCE_LATITUDE) * DAYS_PER_DEGREE + elevation / 100.0 * SPRING_DAYS_PER_100_M) as f32;
        let autumn = ((lat - REFERENCE_LATITUDE) * DAYS_PER_DEGREE + elevation / 100.0 * AUTUMN_DAYS_PER_100_M) as f32;
        let turn = if latitude < 0.0 { 182.5 } else { 0.0 };
        // Spring never meets autumn: at least 60 days in leaf.
        let leaf_out = self.leaf_out + spring + turn;
        let full_leaf = self.full_leaf + spring + turn;
        let colour = (self.colour - autumn + turn).max(full_leaf + 60.0);
        let shift = colour - (self.colour + turn);
        Self {
            leaf_out,
            full_leaf,
            colour,
            full_colour: self.full_colour + turn + shift,
            bare: self.bare + turn + shift,
        }
    }

    /// Where the genus is on day `day` of the year (1 = 1 January; fractions
    /// allowed) with these days (already moved to the place).
    #[must_use]
    pub fn phase(self, day: f32) -> Phase {
        // Days may run past 365 (a southern year, a late place): take the day
        // in the rule's own year, the one that starts at its leaf-out less half
        // the winter.
        let winter = 365.0 - (self.bare - self.leaf_out);
        let start = self.leaf_out - winter * 0.5;
        let d = start + (day - start).rem_euclid(365.0);
        let ramp = |a: f32, b: f32| ((d - a) / (b - a).max(1.0)).clamp(0.0, 1.0);
        if d < self.full_leaf {
            Phase(ramp(self.leaf_out, self.full_leaf))
        } else if d < self.full_colour {
            Phase(1.0 + ramp(self.colour, self.full_colour))
        } else {
            Phase(2.0 + ramp(self.full_colour, self.bare))
        }
    }
}

/// Day of the year (1–366) of a proleptic Gregorian date.
#[must_use]
pub fn day_of_year(year: i32, month: u32, day: u32) -> u32 {
    (1..month).map(|m| crate::calendar::days_in_month(year, m)).sum::<u32>() + day
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::format::pack::Season;

    /// The rule's table: the state of a beech, an oak and a birch at fixed
    /// dates in the lowlands at 50° N, and where the place moves them.
    #[test]
    fn the_state_at_fixed_dates_and_places_is_the_rules() {
        let doy = |m, d| day_of_year(2026, m, d) as f32;
        let at = |g: &str, lat: f64, elev: f64, m, d| of_genus(g).at(lat, elev).phase(doy(m, d)).season();
        // 50° N, sea level.
        for g in ["Fagus", "Quercus", "Betula"] {
            assert_eq!(at(g, 50.0, 0.0, 1, 15), Season::LeafOff, "{g} in January");
            assert_eq!(at(g, 50.0, 0.0, 7, 15), Season::LeafOn, "{g} in July");
            assert_eq!(at(g, 50.0, 0.0, 12, 1), Season::LeafOff, "{g} in December");
        }
        assert_eq!(at("Fagus", 50.0, 0.0, 10, 25), Season::Autumn);
        // Birch is out before oak: on 1 May (day 121) birch in leaf, oak still bare.
        assert_eq!(at("Betula", 50.0, 0.0, 5, 1), Season::LeafOn);
        assert_eq!(at("Quercus", 50.0, 0.0, 5, 1), Season::LeafOff);
        // Phases: beech unfolding from day 113, full leaf at 134.
        let beech = of_genus("fagus").at(50.0, 0.0);
        assert_eq!(beech.phase(113.0), Phase(0.0));
        assert!((beech.phase(123.5).0 - 0.5).abs() < 1e-4);
        assert_eq!(beech.phase(200.0), Phase(1.0));
        assert_eq!(beech.phase(296.0), Phase(2.0));
        assert_eq!(beech.phase(305.0), Phase(3.0));
        // Hopkins: 10° farther north, spring 40 days later, autumn 40 days earlier.
        let north = of_genus("Fagus").at(60.0, 0.0);
        assert_eq!((north.leaf_out, north.colour), (153.0, 242.0));
        // Čufar et al.: 1,000 m up, unfolding 26 days later, colouring 19 earlier.
        let up = of_genus("Fagus").at(50.0, 1000.0);
        assert_eq!((up.leaf_out, up.colour), (139.0, 263.0));
        // South of the equator the year is turned: a beech at 50° S is bare in July, in leaf in January.
        assert_eq!(at("Fagus", -50.0, 0.0, 7, 15), Season::LeafOff);
        assert_eq!(at("Fagus", -50.0, 0.0, 1, 15), Season::LeafOn);
        // Far north and high up the summer still lasts 60 days.
        let arctic = of_genus("Quercus").at(70.0, 2000.0);
        assert!(arctic.colour >= arctic.full_leaf + 60.0);
        assert_eq!(arctic.phase(arctic.full_leaf + 30.0).season(), Season::LeafOn);
        // Near the equator the 35° calendar (a winter still); NaN places the reference.
        let south = of_genus("Platanus").at(20.0, 0.0);
        assert_eq!(south, of_genus("Platanus").at(35.0, 0.0));
        assert_eq!(south.phase(day_of_year(2026, 1, 15) as f32).season(), Season::LeafOff);
        assert_eq!(of_genus("Fagus").at(f64::NAN, f64::NAN), of_genus("Fagus").at(50.0, 0.0));
        // A genus the table lacks takes the default; the table has no repeats.
        assert_eq!(of_genus("Nothofagus"), DEFAULT);
        for (i, (g, p)) in GENERA.iter().enumerate() {
            assert!(!GENERA[..i].iter().any(|(h, _)| h == g), "{g} twice");
            assert!(
                p.leaf_out < p.full_leaf
                    && p.full_leaf < p.colour
                    && p.colour < p.full_colour
                    && p.full_colour < p.bare
            );
        }
    }

    #[test]
    fn days_of_the_year() {
        assert_eq!(day_of_year(2026, 1, 1), 1);
        assert_eq!(day_of_year(2026, 12, 31), 365);
        assert_eq!(day_of_year(2024, 12, 31), 366);
        assert_eq!(day_of_year(2024, 3, 1), 61);
    }
}
