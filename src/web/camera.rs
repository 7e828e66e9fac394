//! The viewer's camera API: orbit, walk, geographic placement and the
//! projections a page's overlays need (one `#[wasm_bindgen] impl` block of
//! [`Viewer`], split from `mod.rs` by topic).

use glam::DVec3;
use wasm_bindgen::prelude::*;

use super::{PendingGeo, Viewer};
use crate::orbit::Orbit;
use crate::scene::StreamEvent;

#[wasm_bindgen]
impl Viewer {
    /// Walking mode on or off. In walking mode `look` turns the head and `walk` moves.
    pub fn set_fly(&mut self, on: bool) {
        if on && !self.fly {
            // Stand where the camera is looking, facing the same way, nearly level.
            self.orbit = self.orbit.standing();
        }
        self.fly = on;
    }

    /// Whether walking mode is on.
    pub fn fly(&self) -> bool {
        self.fly
    }

    /// Turns the view around the eye by `d_heading`, `d_pitch` radians.
    pub fn look(&mut self, d_heading: f64, d_pitch: f64) {
        self.orbit.look(d_heading, d_pitch);
    }

    /// Moves the eye `forward_m` along the heading and `right_m` to the side.
    pub fn walk(&mut self, forward_m: f64, right_m: f64) {
        self.orbit.walk(forward_m, right_m);
    }

    /// Sets a geographic camera: WGS 84 lon/lat (degrees), height (metres, in the
    /// scene's vertical datum), heading and pitch (degrees). Applied once the scene's
    /// CRS is known if the manifest has not arrived yet.
    pub fn set_camera_geo(&mut self, lon: f64, lat: f64, height: f64, heading_deg: f64, pitch_deg: f64) {
        let Some(geo) = &self.geo else {
            self.pending_geo = Some(PendingGeo::Pose([lon, lat, height, heading_deg, pitch_deg]));
            self.placed = true;
            return;
        };
        match geo.to_local(lon, lat, height) {
            Ok(p) => self.set_camera(p.x, p.y, p.z, heading_deg, pitch_deg),
            Err(e) => {
                self.events.push(StreamEvent::Failed { url: String::new(), message: e.to_string(), retrying: false })
            }
        }
    }

    /// Sets the camera as a map or a globe gives it: the eye at WGS 84 `lon`,
    /// `lat`, `height` looking at the point `at_lon`, `at_lat`, `at_height`
    /// (heights in metres, the scene's vertical datum). `bearing_deg`
    /// (clockwise from true north) turns the view when it looks straight
    /// down; otherwise the two points alone set it, so the scene's grid
    /// convergence is taken in. Pitch is not limited: a map looking straight
    /// down is drawn straight down.
    #[allow(clippy::too_many_arguments)]
    pub fn set_camera_look_geo(
        &mut self,
        lon: f64,
        lat: f64,
        height: f64,
        at_lon: f64,
        at_lat: f64,
        at_height: f64,
        bearing_deg: f64,
    ) {
        let Some(geo) = &self.geo else {
            self.pending_geo = Some(PendingGeo::Look([lon, lat, height, at_lon, at_lat, at_height, bearing_deg]));
            self.placed = true;
            return;
        };
        let (eye, at) = match (geo.to_local(lon, lat, height), geo.to_local(at_lon, at_lat, at_height)) {
            (Ok(eye), Ok(at)) => (eye, at),
            (Err(e), _) | (_, Err(e)) => {
                let message = e.to_string();
                self.events.push(StreamEvent::Failed { url: String::new(), message, retrying: false });
                return;
            }
        };
        let straight_down = || geo.grid_heading(eye, bearing_deg).unwrap_or(bearing_deg.to_radians());
        let Some(orbit) = Orbit::looking_at(eye, at, straight_down) else { return };
        self.orbit = orbit;
        self.placed = true;
    }

    /// Where the current camera draws the WGS 84 point `lon`, `lat`,
    /// `height` (the scene's datum): JSON `[x, y]` in drawing-buffer pixels
    /// from the top left, or `null` behind the eye or before the scene's CRS
    /// is known (a map layer's tests compare it with the map's projection).
    pub fn project_geo(&self, lon: f64, lat: f64, height: f64) -> String {
        let Some(Ok(p)) = self.geo.as_ref().map(|g| g.to_local(lon, lat, height)) else { return "null".into() };
        match crate::orbit::project(&self.camera(), self.config.width, self.config.height, p) {
            Some(xy) => serde_json::json!(xy).to_string(),
            None => "null".into(),
        }
    }

    /// The WGS 84 box `[west, south, east, north]` (degrees) around where the
    /// scene's views aim first (its home, else its densest group of trees) as
    /// JSON, or `null` before the manifest and its CRS arrived: a map fits
    /// its view to it.
    pub fn focus_geo_json(&self) -> String {
        let (Some(geo), Some(m)) = (&self.geo, self.frame.stream.manifest()) else { return "null".into() };
        let b = m.focus();
        let corners = [[b.min[0], b.min[1]], [b.max[0], b.min[1]], [b.min[0], b.max[1]], [b.max[0], b.max[1]]];
        let mut bbox = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
        for [x, y] in corners {
            let Ok((lon, lat, _)) = geo.to_geo(DVec3::new(f64::from(x), f64::from(y), 0.0)) else {
                return "null".into();
            };
            bbox = [bbox[0].min(lon), bbox[1].min(lat), bbox[2].max(lon), bbox[3].max(lat)];
        }
        serde_json::json!(bbox).to_string()
    }

    /// Vertical field of view in degrees (default 50; clamped to 1–150).
    pub fn set_fov(&mut self, fov_y_deg: f64) {
        if fov_y_deg.is_finite() {
            self.fov_y_rad = (fov_y_deg.clamp(1.0, 150.0) as f32).to_radians();
        }
    }

    /// A layer over a map (on) or a viewer of its own (off): on, neither
    /// sky nor clear colour is drawn (the canvas is transparent where the
    /// scene draws nothing, composited premultiplied over what lies beneath
    /// it); the terrain stays as `set_terrain` has it.
    pub fn set_overlay(&mut self, on: bool) {
        self.frame.settings.sky = !on;
        self.frame.settings.clear =
            if on { [0.0; 4] } else { crate::render::settings::RenderSettings::default().clear };
        // Every WebGPU canvas takes "premultiplied" (the spec's two modes),
        // though wgpu's capabilities on the web list "opaque" only.
        let alpha = if on { wgpu::CompositeAlphaMode::PreMultiplied } else { wgpu::CompositeAlphaMode::Opaque };
        if alpha != self.config.alpha_mode {
            self.config.alpha_mode = alpha;
            self.surface.configure(&self.frame.device, &self.config);
        }
        self.frame.refine.invalidate();
    }

    /// Scene-relative `[x, y, z]` of a geographic point as JSON, or `null` before the
    /// scene's CRS is known.
    pub fn geo_to_local_json(&self, lon: f64, lat: f64, height: f64) -> String {
        match self.geo.as_ref().map(|g| g.to_local(lon, lat, height)) {
            Some(Ok(p)) => serde_json::json!([p.x, p.y, p.z]).to_string(),
            _ => "null".into(),
        }
    }

    /// Orbits around the target: `dx`, `dy` in radians of heading and pitch.
    pub fn orbit(&mut self, d_heading: f64, d_pitch: f64) {
        self.orbit.orbit(d_heading, d_pitch);
    }

    /// Moves the target in the view's ground plane by screen fractions of the distance.
    pub fn pan(&mut self, right: f64, forward: f64) {
        self.orbit.pan(right, forward);
    }

    /// Multiplies the distance to the target (< 1 zooms in).
    pub fn zoom(&mut self, factor: f64) {
        self.orbit.zoom(factor);
    }

    /// Sets the camera: eye position relative to the scene origin (metres) and
    /// heading/pitch in degrees. The orbit target is placed ahead of the eye.
    pub fn set_camera(&mut self, x: f64, y: f64, z: f64, heading_deg: f64, pitch_deg: f64) {
        self.orbit = Orbit::posed(DVec3::new(x, y, z), heading_deg, pitch_deg, self.orbit.target.z);
        self.placed = true;
    }

    /// Ground height (metres, in the scene's vertical datum) at WGS 84 `lon`,
    /// `lat`: the terrain's where it is loaded, else the trees' bases nearby;
    /// NaN where nothing is known (yet) or before the scene's CRS is.
    pub fn height_at(&self, lon: f64, lat: f64) -> f64 {
        let (Some(geo), Some(m)) = (&self.geo, self.frame.stream.manifest()) else { return f64::NAN };
        let Ok(p) = geo.to_local(lon, lat, 0.0) else { return f64::NAN };
        self.frame.stream.ground_height_at(p.x as f32, p.y as f32).map_or(f64::NAN, |h| f64::from(h) + m.origin_m[2])
    }

    /// Ground height at `(x, y)` metres relative to the scene origin,
    /// relative to the origin like the camera's `z`; NaN where unknown.
    pub fn height_at_local(&self, x: f64, y: f64) -> f64 {
        self.frame.stream.ground_height_at(x as f32, y as f32).map_or(f64::NAN, f64::from)
    }

    /// The camera as JSON: `{x, y, z, heading, pitch}` (metres relative to the
    /// scene origin, degrees) plus `origin` (the scene origin), `epsg` and
    /// `ground` (the ground height under the eye, scene-relative like `z`; null
    /// where unknown).
    pub fn camera_json(&self) -> String {
        let c = self.camera();
        let origin = self.frame.stream.manifest().map_or([0.0; 3], |m| m.origin_m);
        let epsg = self.frame.stream.manifest().map_or(0, |m| m.crs.epsg);
        let ground = self.frame.stream.ground_height_at(c.eye_m.x as f32, c.eye_m.y as f32);
        let mut v = serde_json::json!({
            "x": c.eye_m.x, "y": c.eye_m.y, "z": c.eye_m.z,
            "heading": c.heading_rad.to_degrees(), "pitch": c.pitch_rad.to_degrees(),
            "origin": origin, "epsg": epsg, "fly": self.fly, "ground": ground,
        });
        if let Some((lon, lat, height)) = self.geo.as_ref().and_then(|g| g.to_geo(c.eye_m).ok()) {
            v["lon"] = lon.into();
            v["lat"] = lat.into();
            v["height"] = height.into();
        }
        v.to_string()
    }
}
