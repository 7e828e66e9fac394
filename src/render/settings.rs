//! How a frame is drawn: quality, draw distance, transitions, representations,
//! culling baselines and debug views. Plain data, set by the hosts and the
//! benchmarks, read by the passes.

pub use super::shadow::ShadowQuality;
use super::Lighting;

/// Which culling the cull pass does: Sylva's, or a baseline to compare with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CullingMode {
    /// Batches first (sphere, box, distance), then trees (Eichner 2024).
    #[default]
    Batches,
    /// Every resident tree tested on its own (the batch step skipped).
    PerTree,
    /// No culling: every resident tree is drawn (LoD still chosen).
    None,
}

/// Which of a pack's texture encodings a viewer fetches ([`RenderSettings::textures`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TextureChoice {
    /// The first block-compressed variant the GPU samples (BC7, then ETC2),
    /// else the plain pack — natively on a CPU rasteriser the plain pack.
    #[default]
    Auto,
    /// The plain (RGBA8) packs.
    Plain,
    /// This encoding's variants where the GPU samples it (a CPU rasteriser
    /// too), else the plain packs.
    Only(crate::format::pack::TexelEncoding),
}

impl std::str::FromStr for TextureChoice {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        use crate::format::pack::TexelEncoding;
        match s.trim() {
            "auto" => Ok(Self::Auto),
            "plain" => Ok(Self::Plain),
            "bc7" => Ok(Self::Only(TexelEncoding::Bc7)),
            "etc2" => Ok(Self::Only(TexelEncoding::Etc2)),
            other => Err(format!("textures {other:?}: auto, plain, bc7 or etc2")),
        }
    }
}

/// How to draw: quality, draw distance, transitions, debug colouring.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderSettings {
    /// Scales projected sizes before LoD selection (1, ½, ¼ like Clasen et al. 2010, Fig. 12).
    pub quality: f32,
    /// Fetch every tile whole, not the prefix levels prefix thinning draws (for
    /// comparisons; the image is the same).
    pub whole_tiles: bool,
    /// Which of a pack's texture encodings to fetch: the best the GPU samples
    /// (`Auto`), the plain RGBA8 packs, or one block encoding's variants where
    /// the GPU samples it (for comparisons; applies to packs not yet fetched).
    pub textures: TextureChoice,
    /// Where trees are a pixel or two, draw the scene's canopy rasters instead,
    /// cross-faded with them (scenes of version 8; [`CANOPY_PX`]): trees under
    /// a pixel are then neither fetched nor drawn.
    pub canopy: bool,
    /// Trees farther than this are not drawn (metres; infinite by default: far
    /// tiles are fetched and drawn as thin prefixes, so a view of any height
    /// shows its forest, and pools that fill shorten the reach themselves).
    pub draw_distance_m: f32,
    /// Half width of a transition band, as a fraction of its threshold.
    pub fade_band: f32,
    /// Colour trees by representation.
    pub debug_lod: bool,
    /// Colour the ground by the shadow cascade that holds it (its colour's
    /// brightness: 0.5 + 0.5 × the sun's visibility there).
    pub debug_cascades: bool,
    /// With `debug_cascades`: the ground the first cascade holds shaded by
    /// the second (the test that both give the ground the same light).
    pub debug_next_cascade: bool,
    /// Draw the boxes of the batches that pass the batch test.
    pub debug_bounds: bool,
    /// Sun and ambient.
    pub lighting: Lighting,
    /// Which parts of the light are on ([`super::sky_light::LightParts`]):
    /// all by default (the light judged against the path-traced reference);
    /// none is the light before issue 49.
    pub light_parts: super::sky_light::LightParts,
    /// The air's turbidity (the clear sky, its light and the aerial
    /// perspective; Preetham et al. 1999: 2 very clear, 3 clear, 6 hazy).
    pub turbidity: f32,
    /// Clear colour (linear RGBA).
    pub clear: [f64; 4],
    /// Draw the sky (and the ground beyond the terrain) behind the scene. Off
    /// for a layer over a map (with a transparent `clear`): only what the
    /// scene draws covers the map. Far trees keep their haze either way.
    pub sky: bool,
    /// Culling (benchmark baselines).
    pub culling: CullingMode,
    /// Trees drawn at least this tall (px) but below the simplified mesh's
    /// threshold use the clustered ellipsoids and lines of their pack (Clasen et al. 2010);
    /// smaller ones billboards. Infinity: no ellipsoids; 0: no billboards.
    pub cluster_min_px: f32,
    /// Which representation families may be drawn (benchmark baselines); the
    /// coarsest allowed one reaches down to 0 px, the finest up to infinity.
    pub representations: Representations,
    /// Ellipsoids write their exact ray-cast depth per pixel. Off by default: the
    /// proxy then sits at the ellipsoid's front-most depth and early depth tests
    /// stay on — 2.2–2.5× cheaper cluster draws for +0.001 multi-scale RMSE
    /// (docs/BENCHMARKS.md); only interpenetrating primitives can sort wrongly.
    pub cluster_exact_depth: bool,
    /// Prefix thinning (Eichner 2024, ch. 7): a density-ordered batch whose trees are
    /// below this many pixels tall draws a prefix of them, scaled up to keep the
    /// canopy's coverage. 0: off.
    pub thin_px: f32,
    /// Fetch and draw the terrain (when the scene has one).
    pub terrain: bool,
    /// Morph terrain vertices towards the coarser level as it nears (no
    /// popping at level changes); off only for comparisons.
    pub terrain_morph: bool,
    /// The sun's shadows ([`super::shadow`]).
    pub shadows: ShadowQuality,
    /// Each tree's own ambient occlusion, baked into its pack (`sylva-bake`'s
    /// AO field): darker inside crowns at every level of detail. Packs baked
    /// before it draw unoccluded either way.
    pub ao: bool,
    /// Impostors as a moving frame draws them (the browser's frame-time
    /// governor, every level but its first): the nearest baked view alone, sampled
    /// once, at the depth of the tree's quad rather than each pixel's own —
    /// the depth test then runs before the shading and hidden crowns cost
    /// nothing (6–9× cheaper on lavapipe); crowns that interpenetrate sort by
    /// their quads. Off: three views blended with parallax, per-pixel depth.
    pub moving_impostors: bool,
    /// The far tier where a pack has both: multi-view impostors (default) or
    /// the single-view billboards. A pack with one of them draws that one.
    pub far_tier: FarTier,
    /// Mesh leaves are alpha-tested at their texture's full resolution rather
    /// than its mip (the accuracy reference): a far leaf card, smaller than a
    /// pixel, is then kept where it covers the pixel's centre, so a far crown
    /// keeps its true coverage instead of vanishing with its textures' coarse
    /// mips. Off for drawing (it aliases).
    pub full_res_alpha: bool,
    /// Adaptive transparency (`mesh.wgsl`): a mesh leaf seen at its
    /// texture's coarsest mips keeps each pixel with the leaf's true coverage
    /// (a hashed test) instead of the mip's all-or-nothing alpha. Off: the
    /// plain alpha test (comparisons).
    pub adaptive_alpha: bool,
    /// The bake's LoD policy (`crate::lod::policy::policy_keeps`): a cluster
    /// level, the simplified mesh or the billboard cloud is drawn only where the
    /// bake measured it worth its time against the far tier
    /// ([`crate::lod::policy`]).
    /// Off: every baked level within `representations` (benchmark baselines).
    pub lod_policy: bool,
    /// Shifts the cross-fade dither pattern (the progressive-refinement step,
    /// [`super::refine`]): accumulated steps then blend both sides of a
    /// transition. 0: the fixed pattern.
    pub refine_seed: u32,
    /// The season deciduous species are drawn in (their packs' `season`;
    /// evergreens look the same all year), unless `date` is given.
    pub season: Season,
    /// A date and place for the seasons (`--date`, `setDate`): each deciduous
    /// species in the state its genus's leaf calendar gives there
    /// ([`crate::phenology`]); `None`: `season` for every one.
    pub date: Option<SeasonDate>,
}

/// A day of the year at a place, for the species' leaf calendars.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SeasonDate {
    /// Day of the year (1 = 1 January).
    pub day: f32,
    /// Latitude, degrees (south negative).
    pub latitude: f64,
    /// Elevation, metres.
    pub elevation_m: f64,
}

impl RenderSettings {
    /// The season a deciduous species with `meta`'s seasons is drawn in: at
    /// the date where one is set (its genus's calendar, the default one for
    /// a pack that names none), else `season`. Evergreens (no `meta`): leaf-on.
    #[must_use]
    pub fn season_of(&self, meta: Option<&crate::format::pack::SeasonMeta>) -> Season {
        season_at(meta, self.season, self.date)
    }

    /// The season a stand of mixed deciduous species is drawn in where one
    /// state stands for all (the canopy rasters): the default calendar's at the date.
    #[must_use]
    pub fn canopy_season(&self) -> Season {
        match self.date {
            Some(d) => crate::phenology::DEFAULT.at(d.latitude, d.elevation_m).phase(d.day).season(),
            None => self.season,
        }
    }
}

impl SeasonDate {
    /// The date `text` (`YYYY-MM-DD`, as `--date` and `setDate` take it) at the
    /// middle of `m`'s trees (its latitude and ground's elevation); with the
    /// date's year, month and day.
    ///
    /// # Errors
    /// Not a date, or a scene whose CRS cannot place it.
    pub fn at_scene(m: &crate::format::Manifest, text: &str) -> Result<(Self, (i32, u32, u32)), String> {
        let t = crate::sun::SunTime::parse(&format!("{}T12:00", text.trim())).map_err(|e| {
            format!(
                "date {text:?}: expected YYYY-MM-DD, e.g. 2026-10-20 ({})",
                e.split_once(": ").map_or(e.as_str(), |(_, why)| why.split(" (expected").next().unwrap_or(why))
            )
        })?;
        let geo = crate::geo::GeoFrame::for_scene(&m.crs, m.origin_m).map_err(|e| format!("date {text:?}: {e}"))?;
        let (_, latitude, elevation_m) =
            geo.to_geo(super::Lighting::sun_point(m)).map_err(|e| format!("date {text:?}: {e}"))?;
        if !(latitude.is_finite() && elevation_m.is_finite()) {
            return Err(format!("date {text:?}: the scene's middle has no latitude or elevation"));
        }
        // (Midday of the day: a day's state.)
        let day = crate::phenology::day_of_year(t.year, t.month, t.day) as f32 + 0.5;
        Ok((Self { day, latitude, elevation_m }, (t.year, t.month, t.day)))
    }
}

/// [`RenderSettings::season_of`] from its parts: `meta`'s species drawn with
/// `season`, or at `date` where one is set.
#[must_use]
pub fn season_at(meta: Option<&crate::format::pack::SeasonMeta>, season: Season, date: Option<SeasonDate>) -> Season {
    match (meta, date) {
        (None, _) => Season::LeafOn,
        (Some(m), Some(d)) => phenology_of(m).at(d.latitude, d.elevation_m).phase(d.day).season(),
        (Some(_), None) => season,
    }
}

pub use crate::format::pack::Season;

/// A typical leaf's luminance (linear): an autumn leaf keeps its light and
/// dark against it. Twin of the constant in `seasonal_leaf` (`shaders/trees.wgsl`).
pub const AUTUMN_LEAF_LUMINANCE: f32 = 0.08;

/// How far a tree of `variation` (0–31) has turned in autumn (0.4–1): the
/// trees of a stand turn at their own pace. Twin of `autumn_progress` in `shaders/trees.wgsl`.
#[must_use]
pub fn autumn_progress(variation: u32) -> f32 {
    let x = variation as f32 * 0.618_034 + 0.3;
    0.4 + 0.6 * (x - x.floor())
}

/// The mean of [`autumn_progress`] over the 32 variations (a stand's; tested).
pub const AUTUMN_MEAN_PROGRESS: f32 = 0.7;

/// A leaf texel's albedo (linear) in autumn, for a species whose autumn colour
/// is `autumn` (linear), on a tree `progress` (0–1) turned: towards the colour,
/// scaled by the texel's luminance against a typical leaf's. Twin of
/// `seasonal_leaf` in `shaders/trees.wgsl`.
#[must_use]
pub fn autumn_albedo(albedo: [f32; 3], autumn: [f32; 3], progress: f32) -> [f32; 3] {
    let l = 0.2126 * albedo[0] + 0.7152 * albedo[1] + 0.0722 * albedo[2];
    let shade = (l / AUTUMN_LEAF_LUMINANCE).clamp(0.3, 2.0);
    [0, 1, 2].map(|k| albedo[k] + (autumn[k] * shade - albedo[k]) * progress)
}

/// The tree passes' `DrawParams.season` for a species with `meta`'s seasons
/// (none: an evergreen, drawn leaf-on) drawn in `season`: its autumn colour
/// (linear RGB) and the state code.
#[must_use]
pub fn season_params(meta: Option<&crate::format::pack::SeasonMeta>, season: Season) -> [f32; 4] {
    let Some(m) = meta else { return [0.0; 4] };
    let [r, g, b] = autumn_linear(m);
    [r, g, b, season.code()]
}

/// [`season_params`] at `date` where one is set: the state code is then 3 +
/// the species' phase in its leaf calendar (0–3), which the passes move per
/// tree by [`PHASE_SPREAD`] (`tree_phase` in `shaders/trees.wgsl`); else
/// `season`'s code.
#[must_use]
pub fn season_params_at(
    meta: Option<&crate::format::pack::SeasonMeta>,
    season: Season,
    date: Option<SeasonDate>,
) -> [f32; 4] {
    let Some(m) = meta else { return [0.0; 4] };
    let [r, g, b] = autumn_linear(m);
    match date {
        Some(d) => [r, g, b, 3.0 + phenology_of(m).at(d.latitude, d.elevation_m).phase(d.day).0],
        None => [r, g, b, season.code()],
    }
}

/// How far apart a stand's trees start a change of its leaf calendar
/// (unfolding, colouring, fall), as a share of the stand's change: a tree
/// starts after a delay of up to this by its variation and goes through the
/// change in the rest (a 21-day leaf-out: trees start over 13 days, each
/// takes 8). Twin of `PHASE_SPREAD` in `shaders/trees.wgsl`.
pub const PHASE_SPREAD: f32 = 0.6;

/// A tree's own phase at a date where the stand's is `stand` (0–3), by its
/// `variation` (0–31): between changes the stand's, within one delayed and
/// quicker, done when the stand is. Twin of `tree_phase` in `shaders/trees.wgsl`.
#[must_use]
pub fn tree_phase(stand: f32, variation: u32) -> f32 {
    let p = stand.clamp(0.0, 3.0);
    let k = p.floor().min(2.0);
    let x = variation as f32 * 0.618_034 + 0.3;
    let delay = PHASE_SPREAD * (x - x.floor());
    k + ((p - k - delay) / (1.0 - PHASE_SPREAD)).clamp(0.0, 1.0)
}

fn phenology_of(m: &crate::format::pack::SeasonMeta) -> crate::phenology::Phenology {
    m.genus.as_deref().map_or(crate::phenology::DEFAULT, crate::phenology::of_genus)
}

/// A deciduous species' autumn colour (its pack's `season.autumn`), linear RGB.
#[must_use]
pub fn autumn_linear(meta: &crate::format::pack::SeasonMeta) -> [f32; 3] {
    meta.autumn.map(super::mips::srgb_to_linear)
}

/// Which far-field representation a species draws where its pack has both.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FarTier {
    /// Multi-view impostors ([`super::impostor`]).
    #[default]
    Impostors,
    /// View-angle billboards ([`super::billboard`]).
    Billboards,
}

/// Default of [`RenderSettings::thin_px`].
pub const DEFAULT_THIN_PX: f32 = 8.0;

/// The canopy cross-fade ([`RenderSettings::canopy`]): where a batch's
/// tallest tree projects (px, × quality) below the first height the canopy
/// rasters stand in for all of the batch's trees, from the second up they are
/// drawn whole, between a share of them (`canopy_weight` and `canopy_drops`
/// in `shaders/select.wgsl`).
pub const CANOPY_PX: [f32; 2] = [1.0, 2.5];

/// Canopy rasters are refined (children replace their parent) while their
/// cells project above this many pixels.
pub const CANOPY_CELL_PX: f32 = 2.0;

pub use crate::lod::bands::Representations;

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            quality: 1.0,
            textures: TextureChoice::Auto,
            draw_distance_m: f32::INFINITY,
            fade_band: 0.12,
            debug_lod: false,
            debug_cascades: false,
            debug_next_cascade: false,
            debug_bounds: false,
            lighting: Lighting::default(),
            light_parts: super::sky_light::LightParts::ALL,
            turbidity: super::sky_light::DEFAULT_TURBIDITY,
            clear: [0.55, 0.68, 0.82, 1.0],
            sky: true,
            culling: CullingMode::Batches,
            cluster_min_px: DEFAULT_CLUSTER_MIN_PX,
            representations: Representations::ALL,
            cluster_exact_depth: false,
            thin_px: DEFAULT_THIN_PX,
            terrain: true,
            terrain_morph: true,
            shadows: ShadowQuality::Off,
            ao: true,
            far_tier: FarTier::Impostors,
            moving_impostors: false,
            full_res_alpha: false,
            adaptive_alpha: true,
            lod_policy: true,
            refine_seed: 0,
            season: Season::LeafOn,
            date: None,
            whole_tiles: false,
            canopy: true,
        }
    }
}

/// Default of [`RenderSettings::cluster_min_px`].
pub const DEFAULT_CLUSTER_MIN_PX: f32 = 40.0;

#[cfg(test)]
mod tests {
    use super::*;

    /// At a date each tree goes through a change at its own time: half the
    /// stand bare half through its fall, the mean near the stand's; between
    /// changes (in leaf, in full colour, bare) every tree as the stand.
    #[test]
    fn a_stand_goes_through_a_change_at_its_trees_own_pace() {
        let phases: Vec<f32> = (0..32).map(|v| tree_phase(2.5, v)).collect();
        let mean = phases.iter().sum::<f32>() / 32.0;
        assert!((mean - 2.5).abs() < 0.05, "{mean}");
        assert!(phases.iter().all(|p| (2.0..=3.0).contains(p)));
        let bare = phases.iter().filter(|&&p| p >= 2.5).count();
        assert!((12..=20).contains(&bare), "half the stand bare half through its fall: {bare}");
        for stand in [0.0, 1.0, 2.0, 3.0] {
            assert!((0..32).all(|v| tree_phase(stand, v) == stand), "every tree at {stand}");
        }
        // Each tree moves forward with the stand.
        for v in 0..32 {
            let steps: Vec<f32> = (0..=300).map(|i| tree_phase(i as f32 * 0.01, v)).collect();
            assert!(steps.windows(2).all(|w| w[1] >= w[0]), "variation {v}");
        }
        // The code the passes read: 3 + the species' phase at a date, the season's code without.
        let meta = crate::format::pack::SeasonMeta {
            autumn: [200, 90, 30],
            bare_far: true,
            bare_cover: 0.2,
            genus: Some("Fagus".into()),
        };
        let july = SeasonDate { day: 196.5, latitude: 50.0, elevation_m: 0.0 };
        assert_eq!(season_params_at(Some(&meta), Season::LeafOff, Some(july))[3], 4.0);
        assert_eq!(season_params_at(Some(&meta), Season::Autumn, None)[3], Season::Autumn.code());
        assert_eq!(season_params_at(None, Season::Autumn, Some(july)), [0.0; 4]);
    }

    #[test]
    fn a_stand_turns_at_its_trees_own_pace() {
        let p: Vec<f32> = (0..32).map(autumn_progress).collect();
        assert!(p.iter().all(|v| (0.4..=1.0).contains(v)), "{p:?}");
        let mean = p.iter().sum::<f32>() / 32.0;
        assert!((mean - AUTUMN_MEAN_PROGRESS).abs() < 0.02, "mean {mean}");
        assert!(p.iter().any(|v| *v < 0.5) && p.iter().any(|v| *v > 0.9), "a spread: {p:?}");
        // Fully turned, a leaf takes the autumn colour at its own luminance; not at all, its own.
        let green = [0.05, 0.12, 0.03];
        assert_eq!(autumn_albedo(green, [0.5, 0.1, 0.02], 0.0), green);
        let red = autumn_albedo(green, [0.5, 0.1, 0.02], 1.0);
        assert!(red[0] > red[1] && red[0] > green[0] * 3.0, "{red:?}");
    }
}
