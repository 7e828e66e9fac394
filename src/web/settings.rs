//! The viewer's settings API: debug views, level of detail, budgets, canopy,
//! terrain, imagery, the sun, shadows, occlusion, refinement, quality (one
//! `#[wasm_bindgen] impl` block of [`Viewer`], split from `mod.rs` by topic).

use wasm_bindgen::prelude::*;

use super::Viewer;

#[wasm_bindgen]
impl Viewer {
    /// Colours trees by representation and/or draws batch boxes.
    pub fn set_debug(&mut self, lod: bool, bounds: bool) {
        self.frame.settings.debug_lod = lod;
        self.frame.settings.debug_bounds = bounds;
    }

    /// Which texture encodings to fetch: `"auto"` (the best the GPU samples),
    /// `"plain"` (RGBA8 packs even where the GPU samples the scene's
    /// block-compressed variants), `"bc7"` or `"etc2"` (that encoding's
    /// variants where the GPU samples it, else plain): `create(…, {textures})`,
    /// `?textures=`. Applies to packs not yet fetched (call it at once).
    ///
    /// # Errors
    /// Any other name (the message names the four).
    pub fn set_textures(&mut self, textures: &str) -> Result<(), JsValue> {
        self.frame.settings.textures = textures.parse().map_err(|e: String| JsValue::from_str(&e))?;
        Ok(())
    }

    /// Level-of-detail policy: trees at least `ellipsoid_min_px` tall (and below
    /// the simplified mesh) use clustered ellipsoids (infinity: none); `only`
    /// restricts drawing to one family (`"meshes"`, `"ellipsoids"`, `"billboards"`,
    /// `"clouds"`: every baked level of that family; `"all"`: the default mix by
    /// size, the bake's LoD policy); `exact_depth` writes the ellipsoids' exact ray-cast depth;
    /// far batches whose trees are below `thin_px` pixels draw an even, scaled-up
    /// subset of them (0: off).
    ///
    /// # Errors
    /// An `only` that is none of these (nothing is changed).
    pub fn set_lod(
        &mut self,
        ellipsoid_min_px: f32,
        only: &str,
        exact_depth: bool,
        thin_px: f32,
    ) -> Result<(), JsValue> {
        use crate::render::forest::Representations;
        self.frame.settings.representations = match only {
            "all" => Representations::default(),
            "meshes" => Representations::MESHES,
            "ellipsoids" => Representations::CLUSTERS,
            "billboards" => Representations::BILLBOARDS,
            "clouds" => Representations::CLOUDS,
            other => {
                return Err(JsValue::from_str(&format!(
                    "setLod: only '{other}' is not one of all, meshes, ellipsoids, billboards, clouds"
                )))
            }
        };
        // A family asked for by name draws every baked level (no LoD policy).
        self.frame.settings.lod_policy = only == "all";
        self.frame.settings.cluster_min_px =
            if ellipsoid_min_px.is_nan() { f32::INFINITY } else { ellipsoid_min_px.max(0.0) };
        self.frame.settings.cluster_exact_depth = exact_depth;
        self.frame.settings.thin_px = if thin_px.is_finite() { thin_px.clamp(0.0, 64.0) } else { 0.0 };
        Ok(())
    }

    /// Budgets: GPU memory for pools and packs in MB (0: none), download bytes per
    /// second (0: none), requests in flight (at least 1). The viewer degrades within
    /// them (coarser levels, shorter reach for new tiles) and says so in `stats()`.
    pub fn set_budget(&mut self, gpu_mb: f64, bytes_per_s: f64, in_flight: u32) {
        let mut c = self.frame.stream.config();
        c.gpu_budget_bytes = if gpu_mb.is_finite() && gpu_mb > 0.0 { (gpu_mb * 1e6) as u64 } else { 0 };
        c.max_bytes_per_s = if bytes_per_s.is_finite() && bytes_per_s > 0.0 { bytes_per_s } else { 0.0 };
        c.max_in_flight = in_flight.clamp(1, 64) as usize;
        self.frame.stream.set_config(c);
        self.frame.refine.invalidate();
    }

    /// The canopy rasters on (the default: where trees are a pixel or two they
    /// give way to the scene's canopy rasters, and trees under a pixel are
    /// neither fetched nor drawn) or off (every tree, however small).
    pub fn set_canopy(&mut self, on: bool) {
        self.frame.settings.canopy = on;
        self.frame.refine.invalidate();
    }

    /// Terrain on or off (off: neither fetched nor drawn), and the projected
    /// geometric error (pixels) up to which a coarser terrain level is kept.
    pub fn set_terrain(&mut self, on: bool, error_px: f32) {
        self.frame.settings.terrain = on;
        let mut c = self.frame.stream.config();
        c.terrain_error_px = if error_px.is_finite() { error_px.clamp(0.25, 64.0) } else { 2.0 };
        self.frame.stream.set_config(c);
        self.frame.refine.invalidate();
    }

    /// Where ground imagery comes from: `"scene"` (the scene's baked imagery,
    /// the default), `"off"`, or an XYZ/WMTS URL template in Web Mercator
    /// (`{z}/{x}/{y}`, `{-y}`, or `{TileMatrix}/{TileCol}/{TileRow}`) whose
    /// finest zoom is `max_zoom`.
    ///
    /// # Errors
    /// A template without the placeholders (the message says which are needed).
    pub fn set_imagery(&mut self, source: &str, max_zoom: u8) -> Result<(), JsValue> {
        use crate::scene::imagery::{ImageryChoice, XyzSource};
        let choice = match source {
            "" | "scene" => ImageryChoice::Scene,
            "off" => ImageryChoice::Off,
            t => ImageryChoice::Xyz(XyzSource::new(t, max_zoom).map_err(|e| JsValue::from_str(&e))?),
        };
        self.frame.stream.set_imagery(choice);
        self.frame.refine.invalidate();
        Ok(())
    }

    /// The sun at a local date and time of the scene's place (ISO 8601, e.g.
    /// `2026-06-21T15:00`, `Z` or `±HH:MM` for the offset from UTC; without
    /// one the whole hour of the place's longitude); `""` restores the
    /// default light. Returns `{azimuth, elevation}` (degrees) as JSON.
    ///
    /// # Errors
    /// A time that does not parse (the message shows the form), or a scene
    /// not loaded yet.
    pub fn set_sun_time(&mut self, time: &str) -> Result<String, JsValue> {
        if time.trim().is_empty() {
            self.frame.settings.lighting = crate::render::Lighting::default();
            return Ok("null".into());
        }
        let t = crate::sun::SunTime::parse(time).map_err(|e| JsValue::from_str(&e))?;
        let (Some(geo), Some(m)) = (&self.geo, self.frame.stream.manifest()) else {
            return Err(JsValue::from_str("the scene is not loaded yet"));
        };
        let (l, p) = crate::render::Lighting::at_time(geo, crate::render::Lighting::sun_point(m), &t)
            .map_err(|e| JsValue::from_str(&e))?;
        self.frame.settings.lighting = l;
        Ok(serde_json::json!({ "azimuth": p.azimuth_deg, "elevation": p.elevation_deg }).to_string())
    }

    /// The sun at `azimuth` (degrees clockwise from north) and `elevation`.
    ///
    /// # Errors
    /// A scene not loaded yet, or angles out of range.
    pub fn set_sun_angles(&mut self, azimuth: f64, elevation: f64) -> Result<(), JsValue> {
        if !(azimuth.is_finite() && (-90.0..=90.0).contains(&elevation)) {
            return Err(JsValue::from_str("setSun: azimuth in degrees, elevation −90–90"));
        }
        let (Some(geo), Some(m)) = (&self.geo, self.frame.stream.manifest()) else {
            return Err(JsValue::from_str("the scene is not loaded yet"));
        };
        self.frame.settings.lighting =
            crate::render::Lighting::at_angles(geo, crate::render::Lighting::sun_point(m), azimuth, elevation)
                .map_err(|e| JsValue::from_str(&e))?;
        Ok(())
    }

    /// The sun's shadows: `"off"`, `"low"` or `"high"`.
    ///
    /// # Errors
    /// Any other quality (the message names the three).
    pub fn set_shadows(&mut self, quality: &str) -> Result<(), JsValue> {
        self.frame.settings.shadows =
            quality.parse().map_err(|e: String| JsValue::from_str(&format!("setLighting: {e}")))?;
        Ok(())
    }

    /// The season deciduous species are drawn in: `"leaf-on"`, `"autumn"` or
    /// `"leaf-off"` (a leaf-off view fetches their bare far tiers).
    ///
    /// # Errors
    /// Any other season (the message names the three).
    pub fn set_season(&mut self, season: &str) -> Result<(), JsValue> {
        self.frame.settings.season =
            season.parse().map_err(|e: String| JsValue::from_str(&format!("setSeason: {e}")))?;
        Ok(())
    }

    /// The date the seasons follow (`"2026-10-20"`): each deciduous species in
    /// the state its genus's leaf calendar gives at the scene's latitude and
    /// elevation then (over `set_season`); `""`: no date (`set_season` again).
    /// Returns the date's state of the default deciduous calendar
    /// (`"leaf-on"`, `"autumn"`, `"leaf-off"`).
    ///
    /// # Errors
    /// Not a date, or the scene not loaded yet.
    pub fn set_date(&mut self, date: &str) -> Result<String, JsValue> {
        if date.trim().is_empty() {
            self.frame.settings.date = None;
            self.frame.set_day(None);
            return Ok(String::new());
        }
        let Some(m) = self.frame.stream.manifest() else {
            return Err(JsValue::from_str("setDate: the scene is not loaded yet"));
        };
        let (d, _) = crate::render::settings::SeasonDate::at_scene(m, date)
            .map_err(|e| JsValue::from_str(&format!("setDate: {e}")))?;
        self.frame.settings.date = Some(d);
        // A scene with a timeline: the trees standing then, at their size then.
        self.frame.set_day(crate::format::attributes::parse_date(date));
        Ok(self.frame.settings.canopy_season().name().to_string())
    }

    /// Each tree's own baked ambient occlusion on or off.
    pub fn set_ao(&mut self, on: bool) {
        self.frame.settings.ao = on;
    }

    /// The parts of the light (`LIGHT_*` bits; `web/sylva.js` reads their
    /// names) and the air's turbidity (clamped to the clear sky's fit, 1.7–10;
    /// the page checks it).
    pub fn set_light(&mut self, parts: u32, turbidity: f32) {
        self.frame.settings.light_parts = crate::render::sky_light::LightParts(parts & crate::lod::shared::LIGHT_ALL);
        self.frame.settings.turbidity = turbidity.clamp(1.7, 10.0);
    }

    /// Progressive refinement while the camera rests: on or off, jittered
    /// frames per quality level (1–256) and quality levels above the plain
    /// frame (0–4, the last one full meshes).
    pub fn set_refine(&mut self, on: bool, frames: u32, levels: u32) {
        self.frame.refine.config = crate::render::refine::RefineConfig {
            enabled: on,
            jitter_frames: frames.clamp(1, 256),
            levels: levels.min(crate::render::refine::MAX_REFINE_LEVELS),
        };
    }

    /// Whether a refinement is under way: more frames would improve the image
    /// (the raster's refinement, or the path-traced view's samples).
    /// False when it has converged (the viewer idles) or is off.
    pub fn refining(&self) -> bool {
        if let Some(p) = &self.photo {
            return p.wants_frames();
        }
        self.frame.refine.config.enabled && !self.frame.refine.converged() && self.frame.stream.manifest().is_some()
    }

    /// The renderer: `"raster"` (the streamed levels of detail, the default)
    /// or `"path-trace"`: the view traced at full detail (issue 48) — every
    /// tree within `reach_m` of the eye (0: twice the distance the camera
    /// looks at + 200 m, within 300–4000 m) at its full mesh and the terrain
    /// under them, the sun's disk, the clear sky of `turbidity` (the raster's
    /// simple light with `simple`), `bounces` bounces — a sample a pixel each
    /// frame while the camera rests, up to `spp`, then the viewer idles.
    ///
    /// # Errors
    /// An unknown renderer, or settings out of range (named).
    pub fn set_renderer(
        &mut self,
        renderer: &str,
        spp: u32,
        reach_m: f64,
        bounces: u32,
        simple: bool,
        turbidity: f32,
    ) -> Result<(), JsValue> {
        match renderer {
            "raster" => {
                self.photo = None;
                self.drawn_camera = None;
                Ok(())
            }
            "path-trace" => {
                if !(1..=65_536).contains(&spp) {
                    return Err(JsValue::from_str("path-trace: spp is 1–65536 samples a pixel"));
                }
                if !(reach_m.is_finite() && (reach_m == 0.0 || (1.0..=20_000.0).contains(&reach_m))) {
                    return Err(JsValue::from_str("path-trace: reach is 1–20000 m (0: as far as the view looks)"));
                }
                // 0: twice the distance the orbit looks at, and 200 m more (the
                // whole first view of a district), within 300–4000 m.
                let reach_m = if reach_m == 0.0 {
                    (self.orbit.distance * 2.0 + 200.0).clamp(300.0, 4000.0).round()
                } else {
                    reach_m
                };
                if bounces > 16 {
                    return Err(JsValue::from_str("path-trace: bounces is 0–16"));
                }
                if !(1.7..=10.0).contains(&turbidity) {
                    return Err(JsValue::from_str("path-trace: the clear sky is fitted for turbidity 1.7–10"));
                }
                let settings = super::photo::PhotoSettings { spp, reach_m, bounces, simple, turbidity };
                let eye = self.camera().eye_m;
                match &mut self.photo {
                    // The same view's scene: only the image's settings change.
                    Some(p) if p.settings.reach_m == reach_m && !p.stale(eye) && !p.failed() => p.set(settings),
                    _ => {
                        self.photo_loads += 1;
                        self.photo = Some(super::photo::Photo::start(&self.scene_url, eye, settings, self.photo_loads));
                    }
                }
                Ok(())
            }
            other => Err(JsValue::from_str(&format!("{other}: the renderer is raster or path-trace"))),
        }
    }

    /// The path-traced view's state as JSON (`null` with the raster renderer):
    /// `{state: loading|ready|failed, samples, spp, reach_m, trees,
    /// trees_in_scene, instanced_triangles, terrain_triangles, gpu_bytes,
    /// fetch_rounds, bytes_fetched, error}`.
    pub fn photo_json(&self) -> String {
        self.photo.as_ref().map_or_else(|| "null".into(), super::photo::Photo::json)
    }

    /// Frames submitted to the GPU so far.
    pub fn frames_drawn(&self) -> f64 {
        self.frame.frames() as f64
    }

    /// Impostors as a moving frame draws them (the frame-time governor): the
    /// nearest view alone at the depth of each tree's quad, or (false) three
    /// views blended with each pixel's own depth.
    pub fn set_moving_impostors(&mut self, on: bool) {
        self.frame.settings.moving_impostors = on;
    }

    /// LoD quality factor (1, 0.5, 0.25).
    pub fn set_quality(&mut self, quality: f32) {
        self.frame.settings.quality = quality.clamp(0.05, 4.0);
    }
}
