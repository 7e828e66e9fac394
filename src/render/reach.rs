//! The reach of a view: per species, an upper bound of the projected height (px)
//! of its resident trees within the draw distance, from the resident tiles'
//! boxes and tallest trees. The frame skips draws no tree can need by it; the
//! streamer fetches only the pack parts it allows ([`Reach::parts_needed`]).

use glam::Vec3;

use super::pools::TileBounds;
use super::settings::{CullingMode, RenderSettings, Representations};
use crate::camera::ViewData;
use crate::format::pack::PACK_PARTS;
use crate::format::PackMeta;
use crate::lod::bands::{bands, MeshOffer, Offer};
use crate::lod::policy::policy_keeps;

/// Projected tree height from which a tile's batches are bounded one by one.
const REFINE_PX: f32 = 40.0;

/// What a measurement depends on: the same view, settings and residency give
/// the same bounds (streaming and the frame both ask within one frame).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Measured {
    eye: Vec3,
    px_per_m: f32,
    reach_m: f32,
    cluster_min_px: f32,
    fade_band: f32,
    representations: Representations,
    lod_policy: bool,
    /// Which far tier a species with both draws (and so fetches).
    far_tier: super::settings::FarTier,
    /// The season drawn, and the date the species' own seasons follow (which
    /// deciduous species want their bare far tiers).
    season: super::settings::Season,
    date: Option<super::settings::SeasonDate>,
    residency: u64,
}

/// Per-species projected-height bounds of the last measured view.
#[derive(Debug, Clone, Default)]
pub struct Reach {
    species_max_px: Vec<f32>,
    /// Each species' tallest resident tree (m), within reach or not.
    species_tallest_m: Vec<f32>,
    measured: Option<Measured>,
}

impl Reach {
    /// Bounds each species' projected tree height for `view` from `tiles`
    /// (residency `generation`), unless the same was measured already.
    pub fn measure(
        &mut self,
        tiles: &[TileBounds],
        generation: u64,
        species: usize,
        view: &ViewData,
        settings: &RenderSettings,
    ) {
        let eye = view.eye_hi + view.eye_lo;
        let px = view.px_per_m_at_1m * settings.quality;
        let reach = if settings.culling == CullingMode::None { f32::INFINITY } else { settings.draw_distance_m };
        let key = Measured {
            eye,
            px_per_m: px,
            reach_m: reach,
            cluster_min_px: settings.cluster_min_px,
            fade_band: settings.fade_band,
            representations: settings.representations,
            lod_policy: settings.lod_policy,
            far_tier: settings.far_tier,
            season: settings.season,
            date: settings.date,
            residency: generation,
        };
        if self.measured == Some(key) && self.species_max_px.len() == species {
            return;
        }
        self.measured = Some(key);
        self.species_max_px.clear();
        self.species_max_px.resize(species, 0.0);
        self.species_tallest_m.clear();
        self.species_tallest_m.resize(species, 0.0);
        for t in tiles {
            for &(s, h) in &t.heights {
                if let Some(m) = self.species_tallest_m.get_mut(s as usize) {
                    *m = m.max(h);
                }
            }
        }
        // Tiles whose trees may reach this size on screen are bounded batch by batch
        // (tighter: which mesh levels and clusters a view needs); the others whole.
        let refine_px = settings.cluster_min_px.min(REFINE_PX) * (1.0 - settings.fade_band);
        let max_px = &mut self.species_max_px;
        let mut raise = |s: u32, h: f32, d: f32| {
            if let Some(m) = max_px.get_mut(s as usize) {
                *m = m.max(h * px / d.max(1e-3));
            }
        };
        for t in tiles {
            let d = (t.lo - eye).max(eye - t.hi).max(Vec3::ZERO).length();
            if d > reach {
                continue;
            }
            let tallest = t.heights.iter().map(|(_, h)| *h).fold(0.0, f32::max);
            if tallest * px / d.max(1e-3) >= refine_px {
                for &(lo, hi, s, h) in &t.batches {
                    let d = (lo - eye).max(eye - hi).max(Vec3::ZERO).length();
                    if d <= reach {
                        raise(s, h, d);
                    }
                }
                continue;
            }
            for &(s, h) in &t.heights {
                raise(s, h, d);
            }
        }
    }

    /// Each species' bound on the projected height (px) of its resident trees
    /// within reach (0: none).
    #[must_use]
    pub fn species_max_px(&self) -> &[f32] {
        &self.species_max_px
    }

    /// Species `s`'s tallest resident tree (m; infinite before the first measure).
    #[must_use]
    pub fn tallest_m(&self, s: usize) -> f32 {
        if self.measured.is_none() {
            return f32::INFINITY;
        }
        self.species_tallest_m.get(s).copied().unwrap_or(0.0)
    }

    /// The bound of species `s` (infinity before any measurement: draw everything).
    #[must_use]
    pub fn max_px(&self, s: usize) -> f32 {
        if self.measured.is_none() {
            return f32::INFINITY;
        }
        self.species_max_px.get(s).copied().unwrap_or(0.0)
    }

    /// Which parts of species `s`'s pack ([`crate::format::pack::PackPart::ALL`]
    /// order: billboards, impostors, clusters, coarse mesh levels, full mesh,
    /// bare billboards, bare impostors; one far tier, the one drawn) the
    /// resident trees within reach can need, from the measured
    /// heights and the representations allowed: a far view needs neither
    /// meshes nor clusters, a medium one not the full mesh; a leaf-off view the
    /// bare far tiers of a deciduous species that has them, not its leafy ones.
    #[must_use]
    pub fn parts_needed(&self, s: usize, meta: &PackMeta) -> [bool; PACK_PARTS] {
        let max_px = self.species_max_px.get(s).copied().unwrap_or(0.0);
        let Some(m) = self.measured else { return [false; PACK_PARTS] };
        // The bands the species table will draw, from what the pack holds.
        let mesh =
            |l: usize| meta.mesh_levels.get(l).map(|m| MeshOffer { select_px: m.select_px, policy_px: m.policy_px });
        // (The species table draws levels 0 and 1; a pack may hold more.)
        let offer = Offer {
            meshes: [mesh(0), mesh(1)],
            cloud: meta.cloud.as_ref().map(|c| (c.select_px, policy_keeps(c.pareto_error, c.pareto_cost, false))),
            clusters: meta.clusters.as_ref().is_some_and(|c| !c.ellipsoid_levels.is_empty()),
            far: meta.billboards.is_some() || meta.impostors.is_some(),
        };
        let levels = meta.clusters.iter().flat_map(|c| c.ellipsoid_levels.iter());
        let b = bands(&offer, m.representations, m.lod_policy, m.cluster_min_px, levels);
        let has_mesh = b.mesh_floor.is_finite();
        // Cross-fades start below a threshold: fetch a little early.
        let slack = 1.0 - m.fade_band;
        let has_cl = b.clusters.is_some();
        let coarsest_is_mesh = !b.far && !has_cl && b.cloud.is_none();
        let meshes = has_mesh && (max_px >= b.mesh_floor * slack || coarsest_is_mesh);
        let cloud = b.cloud.is_some_and(|f| max_px >= f * slack || (!b.far && !has_cl));
        // The full mesh only where a tree can reach its threshold (one level: always).
        let full = meshes && (meta.mesh_levels.len() == 1 || b.mesh[0].is_some_and(|px| max_px >= px * slack));
        let clusters = b.has_clusters() && b.clusters.is_some_and(|min| max_px >= min * slack);
        let bare = meta.season.as_ref().is_some_and(|s| {
            s.bare_far && super::settings::season_at(Some(s), m.season, m.date) == super::settings::Season::LeafOff
        });
        // One far tier fetched: the one `Species` draws (impostors where set and
        // held, else billboards).
        let impostors = meta.impostors.is_some()
            && (m.far_tier == super::settings::FarTier::Impostors || meta.billboards.is_none());
        let billboards = !impostors && meta.billboards.is_some();
        let (leafy, bare) = (b.far && !bare, b.far && bare);
        [
            leafy && billboards,
            leafy && impostors,
            clusters,
            meshes || cloud,
            full,
            bare && billboards,
            bare && impostors,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::format::pack::{ImpostorMeta, MeshLevelMeta, TextureArrayMeta};

    /// A far view (trees 5 px tall) of a pack whose far tier is impostors only:
    /// the far part is fetched, no mesh.
    #[test]
    fn a_far_view_fetches_impostors_only_packs_far_part() {
        let reach = Reach {
            species_max_px: vec![5.0],
            species_tallest_m: vec![20.0],
            measured: Some(Measured {
                eye: Vec3::ZERO,
                px_per_m: 500.0,
                reach_m: 6000.0,
                cluster_min_px: 40.0,
                fade_band: 0.12,
                representations: Representations::ALL,
                lod_policy: false,
                far_tier: super::super::settings::FarTier::Impostors,
                season: crate::format::pack::Season::LeafOn,
                date: None,
                residency: 0,
            }),
        };
        let mut meta = PackMeta {
            name: "oak".into(),
            height_m: 20.0,
            bounds_min: [-5.0, -5.0, 0.0],
            bounds_max: [5.0, 5.0, 20.0],
            materials: Vec::new(),
            material_texture: None,
            mesh_levels: vec![MeshLevelMeta {
                vertex_count: 3,
                index_count: 3,
                pos_min: [0.0; 3],
                pos_max: [1.0; 3],
                uv_min: [0.0; 2],
                uv_max: [1.0; 2],
                draws: Vec::new(),
                select_px: 120.0,
                policy_px: None,
                variants: 0,
            }],
            billboards: None,
            clusters: None,
            impostors: Some(ImpostorMeta {
                grid: 2,
                texture: TextureArrayMeta::plain(4, 4, 3),
                center: [0.0, 0.0, 10.0],
                radius: 12.0,
                normal_length: Vec::new(),
                half_extent: None,
                variants: None,
            }),
            cloud: None,
            season: None,
        };
        assert_eq!(reach.parts_needed(0, &meta), [false, true, false, false, false, false, false]);
        // Leaf-off: a deciduous species with bare far tiers wants them instead;
        // an evergreen (no season) or one without them its leafy ones.
        let mut bare = reach.clone();
        if let Some(m) = bare.measured.as_mut() {
            m.season = crate::format::pack::Season::LeafOff;
        }
        assert_eq!(bare.parts_needed(0, &meta), [false, true, false, false, false, false, false]);
        meta.season = Some(crate::format::pack::SeasonMeta {
            autumn: [200, 90, 30],
            bare_far: true,
            bare_cover: 0.2,
            genus: None,
        });
        assert_eq!(bare.parts_needed(0, &meta), [false, false, false, false, false, false, true]);
        assert_eq!(reach.parts_needed(0, &meta), [false, true, false, false, false, false, false]);
        // At a date: a January view at 50° N wants the bare far tiers of a
        // deciduous species, a July view the leafy ones, whatever the season set.
        for (day, bare_wanted) in [(15.0, true), (196.0, false)] {
            let mut dated = reach.clone();
            if let Some(m) = dated.measured.as_mut() {
                m.date = Some(super::super::settings::SeasonDate { day, latitude: 50.0, elevation_m: 0.0 });
            }
            assert_eq!(
                dated.parts_needed(0, &meta),
                [false, !bare_wanted, false, false, false, false, bare_wanted],
                "day {day}"
            );
        }
        meta.season = None;
        // A billboard cloud from 40 px: not for 5 px trees; for 45 px ones the
        // coarse part (which holds it), not the full mesh.
        meta.cloud = Some(crate::format::cloud::CloudMeta {
            planes: 1,
            cells: 1,
            fragments: 0,
            material: 0,
            select_px: 40.0,
            mesh: meta.mesh_levels[0].clone(),
            pareto_error: None,
            pareto_cost: None,
        });
        assert_eq!(reach.parts_needed(0, &meta), [false, true, false, false, false, false, false]);
        let mut closer = reach.clone();
        closer.species_max_px = vec![45.0];
        assert_eq!(closer.parts_needed(0, &meta), [false, true, false, true, false, false, false]);
        // The LoD policy: a cloud the bake found no better than the far tier is
        // not fetched; one it kept is.
        let mut policy = closer.clone();
        if let Some(m) = policy.measured.as_mut() {
            m.lod_policy = true;
        }
        meta.cloud.as_mut().unwrap().pareto_error = Some([0.03, 0.031]);
        assert_eq!(policy.parts_needed(0, &meta), [false, true, false, false, false, false, false]);
        meta.cloud.as_mut().unwrap().pareto_error = Some([0.02, 0.031]);
        assert_eq!(policy.parts_needed(0, &meta), [false, true, false, true, false, false, false]);
        meta.cloud = None;
        // Without any far tier the mesh is the coarsest and is fetched.
        meta.impostors = None;
        assert_eq!(reach.parts_needed(0, &meta), [false, false, false, true, true, false, false]);
    }

    /// A pack with both far tiers: the one the settings draw is fetched, the
    /// other not; a pack with one tier: that one, whatever the setting.
    #[test]
    fn one_far_tier_is_fetched() {
        use super::super::settings::FarTier;
        let mut reach = Reach { species_max_px: vec![5.0], species_tallest_m: vec![20.0], measured: None };
        let base = RenderSettings::default();
        let view =
            crate::camera::Camera::look_at(glam::DVec3::new(0.0, -100.0, 20.0), glam::DVec3::ZERO).view_data(64, 64);
        let meta = |billboards: bool, impostors: bool| {
            let mut m: PackMeta = serde_json::from_str(FAR_META).unwrap();
            if !billboards {
                m.billboards = None;
            }
            if !impostors {
                m.impostors = None;
            }
            m
        };
        for (tier, both) in [(FarTier::Impostors, [false, true]), (FarTier::Billboards, [true, false])] {
            let settings = RenderSettings { far_tier: tier, ..base };
            reach.measure(&[], 0, 1, &view, &settings);
            reach.species_max_px = vec![5.0];
            assert_eq!(reach.parts_needed(0, &meta(true, true))[..2], both, "{tier:?}");
            assert_eq!(reach.parts_needed(0, &meta(true, false))[..2], [true, false], "{tier:?}");
            assert_eq!(reach.parts_needed(0, &meta(false, true))[..2], [false, true], "{tier:?}");
        }
    }

    const FAR_META: &str = r#"{"name":"t","height_m":10,"bounds_min":[-1,-1,0],"bounds_max":[1,1,10],
        "materials":[],"material_texture":null,"mesh_levels":[],"clusters":null,"cloud":null,
        "billboards":{"angles":8,"azimuths":1,"texture":{"size":4,"layers":8,"mips":1},"center":[0,0,5],
            "half_width":1,"half_height":5,"select_px":0},
        "impostors":{"grid":2,"texture":{"size":4,"layers":4,"mips":1},"center":[0,0,5],"radius":6,
            "normal_length":[]}}"#;
}
