// Sylva's JS API: `const v = await Sylva.create(canvasOrElement, {scene})`
// (also {camera, lighting, season, date, refine}: as the setters below take them;
// {textures: 'plain' | 'bc7' | 'etc2'}: RGBA8 packs where the GPU would take the
// BC7 or ETC2 variants, or one of those alone).
// Wraps the wasm Viewer (src/web/) with a render loop, camera controls
// (mouse, touch, keyboard), events and the camera in the URL hash.
//
//   v.setCamera({lon, lat, height, heading, pitch})   WGS 84 degrees, metres, degrees
//   v.setCamera({x, y, z, heading, pitch})   or metres relative to the scene origin
//   v.setFly(true)                          walking mode (eye height above the ground)
//   v.flyTo({...}, seconds)                 smooth move; {lon, lat, aboveGround} flies to a height above the ground
//   v.heightAt(lon, lat)                    ground height there (metres, the scene's datum), null if unknown
//   v.heightAtLocal(x, y)                   the same at scene metres (relative to the origin, like camera().z)
//   v.setTerrain(on, errorPx = 2)           terrain on/off; coarser terrain with a larger errorPx
//   v.setCanopy(on)                         the canopy rasters where trees are a pixel or two (default on;
//                                           off: every tree drawn, and fetched, however small)
//   v.setImagery(source, {maxZoom = 19})     ground imagery: 'scene' (baked, the default), null (none), or an
//                                           XYZ/WMTS URL template ({z}/{x}/{y}, {-y}, {TileMatrix}/{TileCol}/{TileRow})
//   v.setSun({date, time, utcOffset})      the sun at a local date and time there (NOAA); or {azimuth, elevation}; null: default
//   v.setLighting({shadows, ao, parts, turbidity}) the sun's shadows: 'off' | 'low' | 'high' (the default);
//                                           ao: each tree's own baked ambient occlusion, true (the default) | false;
//                                           parts: 'all' (the default) | 'none' | 'sky,aerial,sky-light,transmission,soft-shadows';
//                                           turbidity: the air, 1.7–10 (3, clear)
//   v.setSeason(season)                     deciduous species in 'leaf-on' (the default) | 'autumn' | 'leaf-off'
//                                           (bare wood; their bare far tiers are fetched then); evergreens alike in all
//   v.setDate('2026-10-20')                 each deciduous species as its genus's leaf calendar has it there then,
//                                           the sun at that date, and in a scene with censuses the trees
//                                           standing then at their size then (null: no date)
//   v.on('progress' | 'stats' | 'error' | 'warning' | 'camerachange' | 'ready', fn)
//   v.on('click' | 'hover', fn)             fn({x, y, tree}): the tree under the pointer (as pick) or null
//   await v.pick(x, y)                      the tree drawn at canvas CSS pixel (x, y), or null:
//                                           {id, row, species, attributes, lon, lat, height, position}
//                                           (id: a number, or the inventory's text id such as 'EY17080' with row
//                                           its input row; null with row for a tree without an id)
//   v.stats()                               same keys as `sylva render --stats` (`governor`: the governor's level and why)
//   v.setQuality({target_ms = 33, min_scale = 0.35, enabled})  the frame-time governor: while the camera moves,
//                                           impostors, shadows (soft ones with them), render scale, then LoD step down to hold target_ms, and back
//                                           up; at rest full quality ('off': none; a number: the LoD factor)
//   await v.query(filter, {limit = 10000})  trees by attribute and id, as `sylva query`: {count, ids, bounds, tiles, skipped};
//                                           filter {species: 'quercus*', dbh: [30, null], planted: ['1990-01-01', null], id: [..]}
//   v.setStyle({color: {by, categories | ramp, domain}, filter})  colour trees by an attribute or 'species' and hide
//                                           what the filter leaves out (culled on the GPU); null: none. Returns the legend
//                                           {title, entries: [{label, color}]}; v.legend keeps it; 'style' event
//   v.select(ids)                           highlight these trees at every level of detail ([]: none); ids are
//                                           numbers or an inventory's text ids
//   await v.flyToTree(id, {seconds, distance})  select a tree and fly to look at it; resolves to its query result
//   v.attributes()                          the scene's attribute columns [{name, type, min, max, categories}] or null
//   v.timeline()                            a scene's censuses: {censuses, latest, first, last} (setDate across them) or null
//   v.setRenderer('path-trace', {spp = 256, reach = 0, bounces = 2, light = 'physical', turbidity = 3})
//                                           the view traced at full detail (every tree within reach at its full
//                                           mesh, the sun's disk, a clear sky, bounces), a sample a pixel each
//                                           frame while the camera rests, up to spp; 'raster' (the default) back.
//                                           v.photo(): {state: 'loading' | 'ready' | 'failed', samples, spp, reach_m,
//                                           load, restarts, fetch_rounds, bytes_loaded, load_ms, build_ms, trees,
//                                           trees_in_scene, instanced_triangles, terrain_triangles, gpu_bytes,
//                                           error} or null
//   v.ready                                 resolves after the first frame with everything the view needs
//   v.destroy()
//
// As a layer over a map (web/sylva-maplibre.js): create(canvas, {overlay: true, controls: false})
// draws no sky (the canvas is transparent where no tree is) and leaves pointer events to the page;
//   v.lookAt(eye, target, bearing)          eye and target {lon, lat, height}; bearing (degrees from true
//                                           north) turns a view straight down
//   v.setFov(degrees)                       vertical field of view (50 by default)
//   v.project(lon, lat, height)             where the current camera draws that point: {x, y} canvas CSS px, or null
//   await v.focusBounds()                   [west, south, east, north] around where the scene's views aim first
//   v.tick(now)                             draw now if anything changed (a map's render callback calls it)

import init, { Viewer, TileWalk, queryMayMatch, queryTile } from './pkg/sylva.js';
import { Governor } from './governor.js';

let wasmReady = null;

// Frames drawn after a change before the viewer idles. The stream is driven by
// the CPU from the camera, so the first frame asks for what the view needs and
// `progress.settled` keeps the viewer drawing while it loads; the rest are
// margin for frames the GPU was still busy with (a CPU GPU takes seconds each).
const SETTLE_FRAMES = 3;

/** Loads the wasm module once per page. */
function loadWasm() {
  if (!wasmReady) {
    wasmReady = init({ module_or_path: new URL('./pkg/sylva_bg.wasm', import.meta.url) });
  }
  return wasmReady;
}

/** Why WebGPU is missing, in words a user can act on. */
export function webgpuHelp() {
  return 'This browser has no WebGPU. Use a current Chrome or Edge (113+), Safari 18+ or Firefox 141+; ' +
    'on Linux, Chromium needs --enable-unsafe-webgpu --enable-features=Vulkan.';
}

// The light's parts by name (`LIGHT_*` in src/lod/shared.rs): 'all', 'none'
// or a comma-separated list; throws for an unknown name.
const LIGHT_PARTS = ['sky', 'aerial', 'sky-light', 'transmission', 'soft-shadows'];
function lightParts(spec) {
  const s = String(spec).trim();
  if (s === 'all') return (1 << LIGHT_PARTS.length) - 1;
  if (s === 'none') return 0;
  let bits = 0;
  for (const word of s.split(',').map((w) => w.trim())) {
    const k = LIGHT_PARTS.indexOf(word);
    if (k < 0) throw new Error(`setLighting: unknown light part ${JSON.stringify(word)} (known: all, none, ${LIGHT_PARTS.join(', ')})`);
    bits |= 1 << k;
  }
  return bits;
}

class SylvaViewer {
  constructor(canvas, viewer, options) {
    this.canvas = canvas;
    this.viewer = viewer;
    this.options = options;
    this.handlers = {};
    this.destroyed = false;
    this.dirty = SETTLE_FRAMES; // frames to draw before idling (render on demand)
    this.lastCamera = '';
    this.lastStatsMs = 0;
    this.frameTimes = [];
    this.flight = null;
    // The frame-time governor (web/governor.js): while the camera moves, the
    // render scale, shadows and LoD step down to hold the target; at rest, all back.
    this.governor = new Governor();
    this.userShadows = 'high';
    this.userLod = 1;
    // The user's light parts (bits) and turbidity; the governor may leave the soft shadows out.
    this.userLight = [(1 << LIGHT_PARTS.length) - 1, 3];
    this.applied = { scale: 1, shadows: 'high', lod: 1, impostors: 'full', light: this.userLight[0] };
    this.readySettled = false;
    this.ready = new Promise((resolve, reject) => { this.resolveReady = resolve; this.rejectReady = reject; });
    this.ready.catch(() => {}); // observed through 'error' events too
    this.resize();
    if (options.quality !== undefined) this.setQuality(options.quality);
    if (options.controls !== false) this.bindControls();
    this.resizeObserver = new ResizeObserver(() => { this.resize(); this.dirty = SETTLE_FRAMES; });
    this.resizeObserver.observe(canvas);
    this.loop = this.loop.bind(this);
    this.raf = requestAnimationFrame(this.loop);
  }

  on(event, fn) { (this.handlers[event] ||= []).push(fn); return this; }

  /** The tree drawn at canvas CSS pixel (x, y), or null: {id, species (the
   * model), attributes (the inventory's columns the bake kept), lon, lat,
   * height (m), position (scene CRS metres)}. The id pass runs once, for that
   * pixel: alpha-tested like the image, so a click through a gap in a crown
   * hits the tree behind. */
  async pick(x, y) {
    if (this.destroyed) return null;
    const c = this.canvas;
    const sx = c.width / Math.max(1, c.clientWidth), sy = c.height / Math.max(1, c.clientHeight);
    const hit = await this.viewer.pick(Math.floor(x * sx), Math.floor(y * sy));
    if (!hit || this.destroyed) return null;
    const at = JSON.parse(hit);
    // The last few tiles' files are kept: hovering over one tile fetches them once.
    this.fileCache ||= new Map();
    const get = async (url) => {
      if (this.fileCache.has(url)) return this.fileCache.get(url);
      const r = await fetch(url);
      if (!r.ok) throw new Error(`${url}: HTTP ${r.status}`);
      const bytes = new Uint8Array(await r.arrayBuffer());
      this.fileCache.set(url, bytes);
      while (this.fileCache.size > 12) this.fileCache.delete(this.fileCache.keys().next().value);
      return bytes;
    };
    const [tile, ids, attr] = await Promise.all([get(at.tile), get(at.ids),
      this.viewer.has_attributes() ? get(at.attributes) : null]);
    if (this.destroyed) return null;
    return JSON.parse(this.viewer.describe_tree(tile, ids, attr ?? undefined, at.index));
  }

  /** Trees matching `filter` (attributes the bake kept, and `id`), read from
   * the tiles' id and attribute sidecars; tiles whose code ranges cannot match
   * are skipped. Resolves to {count, ids (at most `limit`), bounds ({min, max},
   * metres relative to the scene origin, or null), tiles, skipped}. */
  async query(filter = {}, { limit = 10000 } = {}) {
    const sceneUrl = new URL(this.options.scene || 'scene/scene.json', location.href);
    const base = sceneUrl.href.endsWith('.json') ? sceneUrl : new URL('scene.json', sceneUrl.href.replace(/\/?$/, '/'));
    const get = async (url) => {
      const r = await fetch(new URL(url, base));
      if (!r.ok) throw new Error(`${new URL(url, base)}: HTTP ${r.status}`);
      return new Uint8Array(await r.arrayBuffer());
    };
    // The manifest and index nodes go through the wasm walker: the decoders'
    // URL checks, no node twice, no more nodes than declared (as `sylva query`).
    const walk = new TileWalk(await get(base.href));
    let tiles, schema, species;
    const f = JSON.stringify(filter);
    try {
      schema = walk.schema();
      species = walk.species();
      queryMayMatch(schema, f, 'null'); // a filter that does not fit the scene throws here
      for (let url = walk.next(); url !== undefined; url = walk.next()) walk.feed(await get(url));
      tiles = JSON.parse(walk.tiles());
    } finally {
      walk.free();
    }
    const out = { count: 0, ids: [], bounds: null, tiles: 0, skipped: 0 };
    const needsAttributes = schema !== 'null' && Object.keys(filter).some((k) => k !== 'id');
    for (const t of tiles) {
      if (!queryMayMatch(schema, f, JSON.stringify(t.attribute_codes ?? null))) { out.skipped++; continue; }
      const [tile, ids, attr] = await Promise.all([get(t.url), get(t.ids_url), needsAttributes ? get(t.attr_url) : null]);
      const r = JSON.parse(queryTile(schema, f, species, tile, ids, attr ?? undefined, t.url,
        Math.max(0, limit - out.ids.length)));
      out.count += r.count;
      out.ids.push(...r.ids);
      out.tiles += 1;
      if (r.bounds) {
        out.bounds = out.bounds
          ? { min: out.bounds.min.map((v, k) => Math.min(v, r.bounds.min[k])), max: out.bounds.max.map((v, k) => Math.max(v, r.bounds.max[k])) }
          : r.bounds;
      }
    }
    return out;
  }
  /** Colours and filters the trees (see the header; null: the trees' own
   * look). Throws on a style that does not fit the scene; returns the legend. */
  setStyle(style) {
    this.legend = JSON.parse(this.viewer.set_style(JSON.stringify(style ?? null)));
    this.style = style ?? null;
    this.dirty = SETTLE_FRAMES;
    this.emit('style', { style: this.style, legend: this.legend });
    return this.legend;
  }

  /** Highlights the trees with these ids ([] or null: none). */
  select(ids) {
    this.selection = [...(ids || [])];
    this.viewer.select(JSON.stringify(this.selection));
    this.dirty = SETTLE_FRAMES;
  }

  /** The scene's timeline (censuses, planting and removal dates): `{censuses,
   * latest, first, last}` (YYYY-MM-DD; setDate across first–last shows the
   * trees standing then), or null (none, or not loaded yet). */
  timeline() {
    return JSON.parse(this.viewer.timeline_json());
  }

  /** The scene's attribute columns, or null (no attributes, or not loaded yet). */
  attributes() {
    const a = JSON.parse(this.viewer.attributes_json());
    return a && a.columns;
  }

  /** Selects tree `id` and flies to look at it from `distance` metres
   * (south of it, 30° down). Rejects when the scene has no such tree. */
  async flyToTree(id, { seconds = 1.5, distance = 40 } = {}) {
    const q = await this.query({ id: [id] }, { limit: 1 });
    if (!q.count) throw new Error(`no tree with id ${id} in the scene`);
    const [x, y, z] = q.bounds.min;
    const pitch = -30, d = distance;
    this.select([id]);
    this.flyTo({ x, y: y - d * Math.cos(pitch * Math.PI / 180), z: z + 8 + d * Math.sin(-pitch * Math.PI / 180), heading: 0, pitch }, seconds);
    return q;
  }

  /** Whether the wasm viewer can be called now: not destroyed, not being recreated after a device loss. */
  get live() { return !this.destroyed && !this.recovering; }

  emit(event, data) { for (const fn of this.handlers[event] || []) { try { fn(data); } catch (e) { console.error(e); } } }

  resize() {
    // The governor's render scale: fewer pixels drawn, the browser upscales.
    const dpr = (window.devicePixelRatio || 1) * this.applied.scale;
    const w = Math.max(1, Math.round(this.canvas.clientWidth * dpr));
    const h = Math.max(1, Math.round(this.canvas.clientHeight * dpr));
    if (this.canvas.width !== w || this.canvas.height !== h) {
      this.canvas.width = w;
      this.canvas.height = h;
    }
    this.viewer.resize(w, h);
  }

  /** Ground height (metres, the scene's vertical datum) at WGS 84 lon/lat: the
   * terrain's where loaded, else the trees' bases nearby; null where unknown. */
  heightAt(lon, lat) {
    if (!this.live) return null;
    const h = this.viewer.height_at(lon, lat);
    return Number.isFinite(h) ? h : null;
  }

  /** Ground height at `(x, y)` metres relative to the scene origin, relative
   * to the origin like `camera().z` (for 2D overviews in scene coordinates);
   * null where unknown. */
  heightAtLocal(x, y) {
    const h = this.viewer.height_at_local(x, y);
    return Number.isFinite(h) ? h : null;
  }

  /** Terrain on or off (off: neither fetched nor drawn); `errorPx` is the
   * projected geometric error in pixels up to which coarser terrain is kept. */
  setTerrain(on, errorPx = 2) {
    this.terrain = [!!on, errorPx];
    this.viewer.set_terrain(!!on, errorPx);
    this.dirty = SETTLE_FRAMES;
  }
  setCanopy(on) { this.viewer.set_canopy(!!on); this.dirty = SETTLE_FRAMES; }

  /** Camera: {x, y, z, heading, pitch} relative to the scene origin (+ origin, epsg, ground under the eye). */
  camera() { return JSON.parse(this.viewer.camera_json()); }

  setCamera(c) {
    this.flight = null;
    if (c.lon !== undefined) {
      this.viewer.set_camera_geo(c.lon, c.lat, c.height ?? 300, c.heading ?? 0, c.pitch ?? -30);
    } else {
      this.viewer.set_camera(c.x, c.y, c.z, c.heading ?? 0, c.pitch ?? -30);
    }
    this.dirty = SETTLE_FRAMES;
  }

  /** Looks from `eye` at `target` (both {lon, lat, height}: WGS 84 degrees,
   * metres in the scene's datum), as a map or a globe poses its camera;
   * `bearing` (degrees clockwise from true north) turns a view straight
   * down. Redraws only when the pose changed. */
  lookAt(eye, target, bearing = 0) {
    if (!this.live) return;
    this.look = [eye, target, bearing];
    const key = `${eye.lon},${eye.lat},${eye.height},${target.lon},${target.lat},${target.height},${bearing}`;
    if (key === this.lookKey) return;
    this.lookKey = key;
    this.flight = null;
    this.viewer.set_camera_look_geo(eye.lon, eye.lat, eye.height, target.lon, target.lat, target.height, bearing);
    this.dirty = SETTLE_FRAMES;
  }

  /** The WGS 84 box [west, south, east, north] around where the scene's
   * views aim first (its home, else its densest trees): resolves once the
   * scene's manifest has arrived. */
  async focusBounds({ timeoutMs = 120000 } = {}) {
    let failed = null;
    this.on('error', (e) => { failed = e.message; });
    const t0 = performance.now();
    for (;;) {
      if (this.destroyed) throw new Error('the viewer was destroyed');
      const b = this.live && JSON.parse(this.viewer.focus_geo_json());
      if (b) return b;
      if (performance.now() - t0 > timeoutMs) {
        throw new Error(`the scene's manifest did not arrive in ${timeoutMs / 1000} s${failed ? `: ${failed}` : ''}`);
      }
      await new Promise((r) => setTimeout(r, 50));
    }
  }

  /** Vertical field of view in degrees. */
  setFov(degrees) {
    if (degrees === this.fov || !this.live) return;
    this.fov = degrees;
    this.viewer.set_fov(degrees);
    this.dirty = SETTLE_FRAMES;
  }

  /** Where the current camera draws WGS 84 `lon`, `lat` at `height` metres:
   * {x, y} in canvas CSS pixels from the top left, or null (behind the eye,
   * or before the scene's CRS is known). */
  project(lon, lat, height) {
    if (!this.live) return null;
    const p = JSON.parse(this.viewer.project_geo(lon, lat, height));
    if (!p) return null;
    const c = this.canvas;
    return { x: p[0] * c.clientWidth / Math.max(1, c.width), y: p[1] * c.clientHeight / Math.max(1, c.height) };
  }

  /** Scene-relative {x, y, z} of a geographic point (null before the scene CRS is known). */
  toLocal(lon, lat, height) {
    const p = JSON.parse(this.viewer.geo_to_local_json(lon, lat, height));
    return p && { x: p[0], y: p[1], z: p[2] };
  }

  setFly(on) { this.viewer.set_fly(!!on); this.dirty = SETTLE_FRAMES; }
  get fly() { return this.viewer.fly(); }

  flyTo(c, seconds = 1.5) {
    const from = this.camera();
    const above = c.lon !== undefined ? c.aboveGround : undefined;
    if (c.lon !== undefined && c.aboveGround !== undefined) {
      // A height above the ground there (where the ground is known).
      const g = this.heightAt(c.lon, c.lat);
      if (g !== null) c = { ...c, height: g + c.aboveGround };
    }
    if (c.lon !== undefined) {
      const p = this.toLocal(c.lon, c.lat, c.height ?? from.z);
      if (!p) { this.setCamera(c); return; }
      c = { ...c, ...p };
    }
    const to = { heading: from.heading, pitch: from.pitch, ...c };
    const start = performance.now();
    let dh = ((to.heading - from.heading + 540) % 360) - 180;
    this.flight = (now) => {
      const t = Math.min(1, (now - start) / (seconds * 1000));
      const s = t * t * (3 - 2 * t);
      const lerp = (a, b) => a + (b - a) * s;
      if (above !== undefined) {
        // The ground there is read again as finer terrain arrives during the
        // flight (at the start only a coarse tile may be resident).
        const g = this.heightAtLocal(to.x, to.y);
        if (g !== null) to.z = g + above;
      }
      this.viewer.set_camera(lerp(from.x, to.x), lerp(from.y, to.y), lerp(from.z, to.z), from.heading + dh * s, lerp(from.pitch, to.pitch));
      if (t >= 1) this.flight = null;
    };
    this.dirty = SETTLE_FRAMES;
  }

  /** The sun: `{date: '2026-06-21', time: '15:00', utcOffset: '+02:00'}` (local
   * time of the scene's place; without `utcOffset` the whole hour of its
   * longitude), or `{azimuth, elevation}` in degrees, or null for the default
   * light. Returns `{azimuth, elevation}`. Throws with the reason for a bad
   * date or time, or before the scene is loaded. */
  setSun(sun) {
    let result = null;
    if (!sun) {
      this.viewer.set_sun_time('');
      this.sunTime = undefined;
      this.sunAngles = false;
    } else if (sun.azimuth !== undefined) {
      this.viewer.set_sun_angles(Number(sun.azimuth), Number(sun.elevation));
      result = { azimuth: Number(sun.azimuth), elevation: Number(sun.elevation) };
      this.sunTime = undefined;
      this.sunAngles = true;
    } else {
      result = JSON.parse(this.viewer.set_sun_time(`${sun.date}T${sun.time}${sun.utcOffset ?? ''}`));
      this.sunTime = { time: sun.time, utcOffset: sun.utcOffset };
      this.sunAngles = false;
    }
    this.sun = result;
    this.dirty = SETTLE_FRAMES;
    return result;
  }

  /** Light settings: `shadows` 'off' | 'low' (2 cascades over 300 m, maps of
   * 0.8 texels per canvas pixel) | 'high' (3 over 600 m, 1.6 texels per pixel,
   * softer; the default); `ao` true (the default: crowns darker inside, as
   * baked into each species' pack) | false; `parts` 'all' (the default: the
   * light judged against the path-traced reference) | 'none' (the light before
   * it) | a comma-separated list of 'sky' (the clear sky of Preetham et
   * al.), 'aerial' (the air between the eye and the forest), 'sky-light' (the
   * sky's light on every surface), 'transmission' (leaves that let light
   * through), 'soft-shadows' (penumbrae as wide as the sun makes them);
   * `turbidity` 1.7–10 (3, clear, by default). Throws for an unknown key or value. */
  setLighting(options = {}) {
    const known = ['shadows', 'ao', 'parts', 'turbidity'];
    // (Settings left undefined are not changed.)
    options = Object.fromEntries(Object.entries(options).filter(([, v]) => v !== undefined));
    for (const key of Object.keys(options)) {
      if (!known.includes(key)) throw new Error(`setLighting: unknown setting ${key} (known: ${known.join(', ')})`);
    }
    // Every value checked before any is applied: a bad one changes nothing.
    if (options.ao !== undefined && typeof options.ao !== 'boolean') {
      throw new Error(`setLighting: ao must be true or false, not ${JSON.stringify(options.ao)}`);
    }
    let light = null;
    if (options.parts !== undefined || options.turbidity !== undefined) {
      const merged = { parts: 'all', turbidity: 3, ...this.lighting, ...options };
      const turbidity = Number(merged.turbidity);
      if (!(turbidity >= 1.7 && turbidity <= 10)) {
        throw new Error(`setLighting: turbidity ${merged.turbidity}: the clear sky is fitted for 1.7–10 (2 very clear, 3 clear, 6 hazy)`);
      }
      light = [lightParts(merged.parts), turbidity]; // (throws for an unknown part)
    }
    if (options.shadows !== undefined) {
      const shadows = String(options.shadows).trim().toLowerCase();
      this.viewer.set_shadows(shadows); // (throws for an unknown quality)
      this.userShadows = shadows;
      this.applied.shadows = shadows;
      this.applyGovernor(); // (while governed, at most the governor's level)
    }
    if (options.ao !== undefined) this.viewer.set_ao(options.ao);
    this.lighting = { ...this.lighting, ...options };
    if (light) {
      this.userLight = light;
      this.applied.light = -1; // (set again below, with the turbidity)
      this.applyGovernor();
    }
    this.dirty = SETTLE_FRAMES;
  }

  /** The season deciduous species are drawn in: 'leaf-on' (the default),
   * 'autumn' (their leaves in their genus's autumn colour) or 'leaf-off' (bare
   * wood). Evergreens, and packs baked without seasons, look the same in all.
   * Throws for any other value. */
  setSeason(season) {
    this.viewer.set_season(String(season));
    this.season = String(season);
    this.dirty = SETTLE_FRAMES;
  }

  /** The date ('2026-10-20'): each deciduous species in the state its genus's
   * leaf calendar gives at the scene's latitude and elevation then (over
   * setSeason), the sun at that date (at the time of day setSun last gave,
   * else noon), and in a scene with a timeline (censuses, planting and
   * removal dates: `timeline()`) the trees standing then, each at its size
   * then. null: no date (setSeason's season again; the sun as it is; the
   * trees of the latest census).
   * Returns the state of a typical deciduous tree then ('leaf-on', 'autumn',
   * 'leaf-off'). Throws for a bad date or before the scene is loaded. */
  setDate(date) {
    if (date === null || date === undefined || date === '') {
      this.viewer.set_date('');
      this.date = undefined;
      this.pendingDate = undefined;
      this.dirty = SETTLE_FRAMES;
      return null;
    }
    if (!this.manifestSeen) {
      // Before the scene's manifest (a page's ?date=, an element's date=""):
      // kept, and placed when the manifest comes (the place is the scene's).
      if (!/^\d{4}-\d{2}-\d{2}$/.test(String(date))) throw new Error(`setDate: date "${date}": expected YYYY-MM-DD, e.g. 2026-10-20`);
      this.pendingDate = String(date);
      this.date = String(date);
      return null;
    }
    const state = this.viewer.set_date(String(date));
    this.date = String(date);
    // One control: the sun moves to the date (at the time of day setSun last
    // gave, else noon) unless it was set by angles.
    if (!this.sunAngles) this.setSun({ ...(this.sunTime ?? { time: '12:00' }), date: this.date });
    return state;
  }

  stats() {
    const s = JSON.parse(this.viewer.stats_json());
    // The governor's level and why (web/governor.js); which impostors the frame
    // drew, from the viewer itself.
    return { ...s, governor: { ...this.governor.report(), impostors: s.governor.impostors } };
  }
  setDebug(lod, bounds) { this.viewer.set_debug(!!lod, !!bounds); this.dirty = SETTLE_FRAMES; }
  /** A number: the LoD quality factor (1, 0.5, 0.25: projected sizes are
   * scaled by it). An object `{target_ms, min_scale, enabled}`: the frame-time
   * governor — while the camera moves, quality steps down (impostors, shadows
   * and their softness, render scale, then LoD) until frames take `target_ms` (default 33), never below
   * `min_scale` (0.25–1, default 0.35), and back up; at rest all is restored.
   * `'off'` turns the governor off. `stats().governor` says its level and why. */
  setQuality(q) {
    if (typeof q === 'number') {
      this.viewer.set_quality(q);
      this.userLod = q;
      this.applied.lod = q;
      this.applyGovernor();
    } else if (q === 'off') {
      this.governor.set({ enabled: false });
      this.applyGovernor();
    } else if (typeof q === 'object' && q !== null) {
      for (const key of Object.keys(q)) {
        if (!['target_ms', 'min_scale', 'enabled'].includes(key)) throw new Error(`setQuality: unknown setting ${key} (known: target_ms, min_scale, enabled)`);
      }
      this.governor.set(q);
      this.applyGovernor();
    } else {
      throw new Error(`setQuality: a LoD factor, {target_ms, min_scale, enabled} or 'off', not ${JSON.stringify(q)}`);
    }
    this.dirty = SETTLE_FRAMES;
  }

  /** Applies the governor's level: render scale, shadows, LoD quality, impostors, soft shadows. */
  applyGovernor() {
    const a = this.governor.apply(this.userShadows, this.userLod);
    if (a.scale !== this.applied.scale) {
      // The canvas keeps its CSS size while its pixels are scaled (one sized by
      // its pixels alone would shrink): held in px, given back at full scale.
      const st = this.canvas.style;
      if (a.scale !== 1 && !this.savedSize) {
        this.savedSize = { width: st.width, height: st.height };
        st.width = `${this.canvas.clientWidth}px`;
        st.height = `${this.canvas.clientHeight}px`;
      }
      this.applied.scale = a.scale;
      if (a.scale === 1 && this.savedSize) {
        st.width = this.savedSize.width;
        st.height = this.savedSize.height;
        this.savedSize = null;
      }
      this.resize();
    }
    if (a.shadows !== this.applied.shadows) { this.viewer.set_shadows(a.shadows); this.applied.shadows = a.shadows; }
    if (a.lod !== this.applied.lod) { this.viewer.set_quality(a.lod); this.applied.lod = a.lod; }
    if (a.impostors !== this.applied.impostors) {
      this.viewer.set_moving_impostors(a.impostors === 'moving');
      this.applied.impostors = a.impostors;
    }
    const light = a.softShadows ? this.userLight[0] : this.userLight[0] & ~(1 << LIGHT_PARTS.indexOf('soft-shadows'));
    if (light !== this.applied.light) {
      this.viewer.set_light(light, this.userLight[1]);
      this.applied.light = light;
    }
    this.dirty = SETTLE_FRAMES;
  }
  /**
   * Progressive refinement while the camera rests (on by default): jittered
   * frames accumulate into an anti-aliased image while the level of detail
   * rises (`levels` steps, 0–4, the last one full meshes for what is in view),
   * `frames` per step (1–256); then the viewer stops drawing until something
   * changes. Any camera move starts over at once. `stats()` reports
   * `refine_step`, `refine_level` and `refine_converged`.
   */
  setRefine(on = true, { frames = 16, levels = 3 } = {}) {
    this.refine = { on: !!on, frames, levels };
    this.viewer.set_refine(!!on, Math.max(1, frames | 0), Math.max(0, levels | 0));
    this.dirty = SETTLE_FRAMES;
  }
  /**
   * The renderer: 'raster' (streamed levels of detail, the default) or
   * 'path-trace' — the view traced at full detail (issue 48): every tree
   * within `reach` metres of the eye (0, the default: twice the distance the
   * camera looks at + 200 m, within 300–4000 m) at its full mesh and the terrain under
   * them (fetched and built in the browser; the raster view is drawn
   * meanwhile), the sun as a disk of its true size, a clear sky of
   * `turbidity` (`light: 'raster'`: the raster's own simple light), `bounces`
   * bounces; each frame while the camera rests adds a sample a pixel up to
   * `spp`, then the viewer idles; a move starts over. `photo()` says how far
   * it is. Throws on an unknown renderer or settings out of range.
   */
  setRenderer(renderer = 'raster', { spp = 256, reach = 0, bounces = 2, light = 'physical', turbidity = 3 } = {}) {
    if (light !== 'physical' && light !== 'raster') throw new Error(`light: ${light}: expected physical or raster`);
    this.viewer.set_renderer(String(renderer), spp | 0, Number(reach), bounces | 0, light === 'raster', Number(turbidity));
    this.renderer = renderer === 'path-trace' ? { renderer, spp, reach, bounces, light, turbidity } : undefined;
    this.dirty = SETTLE_FRAMES;
  }
  /** The path-traced view's state, or null with the raster renderer (see setRenderer). */
  photo() { return JSON.parse(this.viewer.photo_json()); }
  /** Ground imagery on the terrain: 'scene' (the scene's baked imagery), null
   * (none: the ground material), or an XYZ/WMTS raster source in Web Mercator
   * as a URL template, reprojected onto the scene's terrain. Throws for a
   * template without {z}/{x}/{y} (or {TileMatrix}/{TileCol}/{TileRow}). */
  setImagery(source, { maxZoom = 19 } = {}) {
    const s = source === null || source === undefined || source === false ? 'off' : String(source);
    this.viewer.set_imagery(s, Math.max(0, Math.min(24, maxZoom | 0)));
    this.dirty = SETTLE_FRAMES;
  }
  /**
   * Level-of-detail policy: `ellipsoidMinPx` (default 40; Infinity: no ellipsoids),
   * `only` ('meshes' | 'ellipsoids' | 'billboards' | 'clouds': every baked level of one family; default 'all', mixed by size and the bake's LoD policy),
   * `exactDepth` (default false: ellipsoids keep their proxy's front-most depth,
   * which keeps early depth tests; true writes the exact ray-cast depth, slower),
   * `thinPx` (default 8; 0 off): far batches whose trees are below this many
   * pixels tall draw an even subset of them, scaled up to keep canopy coverage.
   * Throws on an `only` that is none of these.
   */
  setLod({ ellipsoidMinPx = 40, only = 'all', exactDepth = false, thinPx = 8 } = {}) {
    this.viewer.set_lod(ellipsoidMinPx, only, !!exactDepth, Number(thinPx));
    this.dirty = SETTLE_FRAMES;
  }

  /**
   * Budgets the viewer degrades gracefully within (coarser levels, shorter reach
   * for new tiles; `stats().degraded` says what is held back): `gpuMB` for pools
   * and packs (0: none), `bytesPerSecond` of downloads (0: none), `inFlight`
   * requests at once (default 6).
   */
  setBudget({ gpuMB = 0, bytesPerSecond = 0, inFlight = 6 } = {}) {
    this.viewer.set_budget(Number(gpuMB), Number(bytesPerSecond), Math.max(1, inFlight | 0));
    this.dirty = SETTLE_FRAMES;
  }

  /** Device lost (driver reset, GPU process crash): a new viewer on the same canvas, same camera. */
  async recover() {
    if (this.recovering) return;
    this.recovering = true;
    const cam = this.camera();
    this.emit('warning', { message: 'The GPU device was lost; recreating the viewer.' });
    try { this.viewer.free(); } catch (_) { /* gone with the device */ }
    try {
      const viewer = await Viewer.create(this.canvas, this.options.scene || 'scene/scene.json');
      if (this.destroyed) { viewer.free(); return; }
      this.viewer = viewer;
      if (this.options.textures && this.options.textures !== 'auto') viewer.set_textures(String(this.options.textures));
      this.resize();
      if (this.options.overlay) this.viewer.set_overlay(true);
      if (this.fov ?? this.options.fov) this.viewer.set_fov(this.fov ?? this.options.fov);
      this.lookKey = undefined; // a map layer poses the new viewer again on its next render
      if (this.look) {
        const [eye, target, bearing] = this.look;
        this.viewer.set_camera_look_geo(eye.lon, eye.lat, eye.height, target.lon, target.lat, target.height, bearing);
      } else {
        this.viewer.set_camera(cam.x, cam.y, cam.z, cam.heading, cam.pitch);
      }
      if (this.lighting) this.setLighting(this.lighting);
      if (this.season) this.setSeason(this.season);
      this.manifestSeen = false;
      if (this.date) this.pendingDate = this.date; // placed when the new viewer has the manifest
      if (this.terrain) this.setTerrain(...this.terrain);
      if (this.refine) this.setRefine(this.refine.on, this.refine);
      if (this.renderer) this.setRenderer(this.renderer.renderer, this.renderer);
      // The new viewer starts at full quality: the governor's level (and the
      // user's LoD factor and shadows) applied to it again.
      this.applied = { ...this.applied, shadows: 'high', lod: 1, impostors: 'full', light: (1 << LIGHT_PARTS.length) - 1 };
      this.applyGovernor();
      this.dirty = SETTLE_FRAMES;
      this.emit('recovered', {});
    } catch (e) {
      this.emit('error', { message: `The GPU device was lost and could not be recreated: ${e}` });
    }
    this.recovering = false;
  }

  loop(now) {
    if (this.destroyed) return;
    this.raf = requestAnimationFrame(this.loop);
    // A map layer's tick may have run in this animation frame already (its
    // render runs in the map's callback): once a frame is enough.
    if (this.tickedOutsideAt >= now) return;
    this.tick(now);
  }

  /** Draws a frame now when anything asks for one (loading, moving, a change,
   * refinement), then hands out events: the render loop calls it every
   * animation frame; a map layer calls it (without `now`) in the map's own render. */
  tick(now) {
    if (now === undefined) {
      now = performance.now();
      this.tickedOutsideAt = now;
    }
    if (this.destroyed || this.recovering) return;
    if (this.viewer.is_lost()) { this.recover(); return; }
    if (this.flight) this.flight(now);
    const progress = JSON.parse(this.viewer.progress_json());
    // Render on demand: while loading, moving or just after a change, until the
    // first complete frame's counters are back, and while a resting camera's
    // image refines; idle otherwise.
    if (!progress.settled || this.flight || this.dirty > 0 || this.viewer.refining() ||
        (!this.readySettled && !this.viewer.is_ready())) {
      const t0 = performance.now();
      let drawn;
      try {
        // False while the GPU is still busy with earlier frames (a slow GPU): try again next time.
        drawn = this.viewer.frame(now);
      } catch (e) {
        this.emit('error', { message: String(e) });
        this.rejectReady(new Error(String(e)));
        this.destroy();
        return;
      }
      if (drawn) {
        this.frameTimes.push(performance.now() - t0);
        if (this.frameTimes.length > 60) this.frameTimes.shift();
        if (this.dirty > 0) this.dirty--;
      }
      if (!progress.settled) this.dirty = Math.max(this.dirty, SETTLE_FRAMES);
    }
    for (const e of JSON.parse(this.viewer.take_events_json())) {
      if (e.kind === 'error') { this.emit('error', e); this.rejectReady(new Error(e.message)); }
      else if (e.kind === 'warning') this.emit('warning', e);
      else if (e.kind === 'manifest') {
        this.manifestSeen = true;
        // A date set before the scene came (a page's, a recovered viewer's): now it can be placed.
        if (this.pendingDate) { const d = this.pendingDate; this.pendingDate = undefined; try { this.setDate(d); } catch (err) { this.emit('error', { message: String(err.message || err) }); } }
        this.emit('manifest', e);
      }
    }
    this.emit('progress', progress);
    const cam = this.viewer.camera_json();
    let moved = false;
    if (cam !== this.lastCamera) {
      this.lastCamera = cam;
      const c = JSON.parse(cam);
      this.emit('camerachange', c);
      // (The pose, not the ground height under it, which changes as terrain arrives.)
      const pose = [c.x, c.y, c.z, c.heading, c.pitch].join();
      moved = pose !== this.lastPose;
      this.lastPose = pose;
    }
    // The governor: each finished frame's GPU time while moving; at rest, full
    // quality. (The first view placing itself while loading is no motion.)
    if (!this.readySettled && !this.flight) moved = false;
    const frameMs = this.viewer.take_frame_ms();
    if (this.governor.frame(now, frameMs > 0 ? frameMs : undefined, moved || !!this.flight)) this.applyGovernor();
    // Ready after a frame drawn with everything settled, once its counters are read back.
    if (!this.readySettled && this.viewer.is_ready()) {
      this.readySettled = true;
      this.resolveReady(this.stats());
      this.emit('ready', this.stats());
    }
    if (now - this.lastStatsMs > 500) {
      this.lastStatsMs = now;
      const s = this.stats();
      const avg = this.frameTimes.reduce((a, b) => a + b, 0) / Math.max(1, this.frameTimes.length);
      s.frame_ms = avg;
      this.emit('stats', s);
    }
  }

  bindControls() {
    const c = this.canvas;
    c.tabIndex = c.tabIndex >= 0 ? c.tabIndex : 0;
    c.style.touchAction = 'none';
    let drag = null;
    const pointers = new Map();
    c.addEventListener('contextmenu', (e) => e.preventDefault());
    c.addEventListener('pointerdown', (e) => {
      c.setPointerCapture(e.pointerId);
      pointers.set(e.pointerId, { x: e.clientX, y: e.clientY });
      drag = { x: e.clientX, y: e.clientY, pan: e.button === 2 || e.shiftKey || e.ctrlKey };
      this.flight = null;
    });
    c.addEventListener('pointermove', (e) => {
      if (!pointers.has(e.pointerId)) return;
      const prev = pointers.get(e.pointerId);
      pointers.set(e.pointerId, { x: e.clientX, y: e.clientY });
      if (pointers.size === 2) {
        // Two fingers: pinch zooms, twist rotates.
        const [a, b] = [...pointers.values()];
        const other = [...pointers.entries()].find(([id]) => id !== e.pointerId)[1];
        const before = Math.hypot(prev.x - other.x, prev.y - other.y);
        const after = Math.hypot(a.x - b.x, a.y - b.y);
        if (before > 0 && after > 0) this.viewer.zoom(before / after);
        const angBefore = Math.atan2(prev.y - other.y, prev.x - other.x);
        const angAfter = Math.atan2(e.clientY - other.y, e.clientX - other.x);
        this.viewer.orbit(angAfter - angBefore, 0);
      } else if (drag) {
        const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
        drag.x = e.clientX; drag.y = e.clientY;
        const h = Math.max(1, c.clientHeight);
        if (this.viewer.fly()) this.viewer.look(-dx * 0.004, -dy * 0.004);
        else if (drag.pan) this.viewer.pan(-dx / h, dy / h);
        else this.viewer.orbit(dx * 0.005, -dy * 0.005);
      }
      this.dirty = SETTLE_FRAMES;
    });
    // A click (a press and release that barely moved) picks the tree under it.
    let press = null;
    c.addEventListener('pointerdown', (e) => { press = { x: e.clientX, y: e.clientY, t: performance.now() }; });
    const pointAt = (e) => { const r = c.getBoundingClientRect(); return { x: e.clientX - r.left, y: e.clientY - r.top }; };
    c.addEventListener('pointerup', (e) => {
      if (!press || !(this.handlers.click?.length)) return;
      const moved = Math.hypot(e.clientX - press.x, e.clientY - press.y);
      if (moved > 4 || performance.now() - press.t > 800) return;
      const p = pointAt(e);
      // Only the latest click's answer counts (an earlier one may come later).
      const seq = (this.clickSeq = (this.clickSeq || 0) + 1);
      this.pick(p.x, p.y).then((tree) => { if (seq === this.clickSeq) this.emit('click', { ...p, tree }); },
        (err) => this.emit('warning', { message: `pick: ${err.message || err}` }));
    });
    // Hover: one pick at a time, the latest pointer position when it is done.
    let hover = null, hovering = false;
    const hoverPick = () => {
      if (!hover || hovering) return;
      const p = hover; hover = null; hovering = true;
      this.pick(p.x, p.y).then((tree) => this.emit('hover', { ...p, tree }), () => {})
        .finally(() => { hovering = false; setTimeout(hoverPick, 50); });
    };
    c.addEventListener('pointermove', (e) => {
      if (pointers.size > 0 || !(this.handlers.hover?.length)) return;
      hover = pointAt(e);
      hoverPick();
    });
    const up = (e) => { pointers.delete(e.pointerId); if (pointers.size === 0) drag = null; };
    c.addEventListener('pointerup', up);
    c.addEventListener('pointercancel', up);
    c.addEventListener('wheel', (e) => {
      e.preventDefault();
      if (this.viewer.fly()) this.viewer.walk(-e.deltaY * 0.02, 0);
      else this.viewer.zoom(Math.exp(e.deltaY * 0.0015));
      this.dirty = SETTLE_FRAMES;
    }, { passive: false });
    c.addEventListener('keydown', (e) => {
      const step = 0.05;
      const walk = e.shiftKey ? 6 : 1.5;
      const flyKeys = {
        ArrowUp: () => this.viewer.walk(walk, 0), w: () => this.viewer.walk(walk, 0),
        ArrowDown: () => this.viewer.walk(-walk, 0), s: () => this.viewer.walk(-walk, 0),
        ArrowLeft: () => this.viewer.look(0.05, 0), a: () => this.viewer.walk(0, -walk),
        ArrowRight: () => this.viewer.look(-0.05, 0), d: () => this.viewer.walk(0, walk),
        q: () => this.viewer.look(0.05, 0), e: () => this.viewer.look(-0.05, 0),
      };
      const keys = this.viewer.fly() ? flyKeys : {
        ArrowUp: () => this.viewer.pan(0, step), w: () => this.viewer.pan(0, step),
        ArrowDown: () => this.viewer.pan(0, -step), s: () => this.viewer.pan(0, -step),
        ArrowLeft: () => this.viewer.pan(-step, 0), a: () => this.viewer.pan(-step, 0),
        ArrowRight: () => this.viewer.pan(step, 0), d: () => this.viewer.pan(step, 0),
        q: () => this.viewer.orbit(-0.05, 0), e: () => this.viewer.orbit(0.05, 0),
        '+': () => this.viewer.zoom(0.8), '=': () => this.viewer.zoom(0.8), '-': () => this.viewer.zoom(1.25),
      };
      if (e.key === 'f') { this.setFly(!this.viewer.fly()); e.preventDefault(); return; }
      const fn = keys[e.key];
      if (fn) { fn(); this.dirty = SETTLE_FRAMES; e.preventDefault(); }
    });
  }

  destroy() {
    if (this.destroyed) return;
    this.destroyed = true;
    cancelAnimationFrame(this.raf);
    this.resizeObserver.disconnect();
    if (this.savedSize) { this.canvas.style.width = this.savedSize.width; this.canvas.style.height = this.savedSize.height; }
    try { this.viewer.free(); } catch (_) { /* already freed */ }
  }
}

/** Escapes text for HTML. */
const esc = (s) => String(s).replace(/[&<>"']/g, (c) => `&#${c.charCodeAt(0)};`);

/**
 * A popup over `host` (positioned: relative, absolute or fixed) with the
 * attributes of the tree clicked in viewer `v`; a click on no tree closes it.
 * Returns the popup element (class `sylva-popup`; `data-id` the tree's id).
 */
export function attachTreePopup(v, host) {
  const box = document.createElement('div');
  box.className = 'sylva-popup';
  box.setAttribute('role', 'dialog');
  box.style.cssText = 'position:absolute;z-index:10;display:none;max-width:22em;max-height:60%;overflow:auto;' +
    'background:#fffffff0;color:#1d2a22;border:1px solid #8a9a8a;border-radius:6px;padding:8px 10px;' +
    'font:12px/1.45 system-ui,sans-serif;box-shadow:0 2px 10px #0005;pointer-events:auto';
  host.appendChild(box);
  // The popup's own selection (the clicked tree); a selection made otherwise is left alone.
  let own = null;
  const unselect = () => {
    if (own !== null && v.selection?.length === 1 && v.selection[0] === own) v.select([]);
    own = null;
  };
  const show = ({ x, y, tree }) => {
    if (!tree) { box.style.display = 'none'; box.removeAttribute('data-id'); unselect(); return; }
    // (A tree without an id in the inventory is known by its row.)
    if (tree.id !== null) { v.select([tree.id]); own = tree.id; } else unselect();
    const fmt = (n, d) => (n === null || n === undefined ? '—' : Number(n).toFixed(d));
    // The inventory's own columns; the drawn species model and height where it has none.
    // A scene with censuses: the tree's timeline in place of its per-census columns.
    const t = tree.timeline;
    const timelineColumn = (k) => t && (k === 'standing_from' || k === 'standing_until' ||
      t.censuses.some((c) => [`height_${c.date}`, `dbh_${c.date}`, `crown_${c.date}`].includes(k)));
    const attrs = Object.entries(tree.attributes || {}).filter(([k]) => !timelineColumn(k));
    const has = (name) => attrs.some(([k]) => k.toLowerCase() === name);
    const timeline = t ? [['standing', `${t.from ?? 'before the first census'} – ${t.until ?? 'now'}`],
      ...t.censuses.filter((c) => c.height !== null || c.dbh !== null).map((c) =>
        [c.date, [c.height !== null ? `${fmt(c.height, 1)} m` : null, c.dbh !== null ? `DBH ${fmt(c.dbh, 0)} cm` : null,
          c.crown ? `crown ${fmt(c.crown, 1)} m` : null].filter(Boolean).join(', ')])] : [];
    const rows = [...(has('species') ? [] : [['species', tree.species]]),
      ...(has('height') ? [] : [['height', `${fmt(tree.height, 1)} m`]]),
      ...attrs.map(([k, val]) => [k, val === null ? '—' : val]),
      ...timeline,
      ['lon, lat', `${fmt(tree.lon, 6)}, ${fmt(tree.lat, 6)}`]];
    box.innerHTML = `<div style="display:flex;justify-content:space-between;gap:8px;font-weight:600">` +
      `<span>${tree.id !== null ? `Tree ${esc(tree.id)}` : `Tree in row ${esc(tree.row)}`}</span><button aria-label="Close" style="border:none;background:none;cursor:pointer">✕</button></div>` +
      `<table style="border-collapse:collapse">${rows.map(([k, val]) =>
        `<tr><td style="padding-right:10px;color:#4b5d50">${esc(k)}</td><td>${esc(val)}</td></tr>`).join('')}</table>`;
    box.querySelector('button').onclick = () => { box.style.display = 'none'; unselect(); };
    box.dataset.id = String(tree.id ?? `row ${tree.row}`);
    box.style.display = 'block';
    // Beside the click, inside the host.
    const w = host.clientWidth, h = host.clientHeight;
    box.style.left = `${Math.min(x + 12, Math.max(0, w - box.offsetWidth - 4))}px`;
    box.style.top = `${Math.min(y + 12, Math.max(0, h - box.offsetHeight - 4))}px`;
  };
  v.on('click', show);
  return box;
}

/**
 * A style selector ("Colour by": the trees' own look, species, or an
 * attribute) and the legend of the current style, appended to `container`.
 * Returns {select, legend} (the elements).
 */
export function attachStyleControls(v, container) {
  const wrap = document.createElement('div');
  wrap.className = 'sylva-style';
  wrap.innerHTML = '<label>Colour by <select aria-label="Colour trees by"></select></label><div class="sylva-legend" aria-live="polite"></div>';
  container.appendChild(wrap);
  const select = wrap.querySelector('select');
  const legend = wrap.querySelector('.sylva-legend');
  const fill = () => {
    const columns = v.attributes() || [];
    const options = [['', 'own colours'], ['species', 'species'],
      ...columns.filter((c) => c.name.toLowerCase() !== 'species').map((c) => [c.name, c.name])];
    select.innerHTML = options.map(([value, label]) => `<option value="${esc(value)}">${esc(label)}</option>`).join('');
  };
  const showLegend = ({ legend: l }) => {
    legend.innerHTML = (l?.entries || []).map((e) =>
      `<div><span style="display:inline-block;width:10px;height:10px;margin-right:6px;background:${esc(e.color)}"></span>${esc(e.label)}</div>`).join('');
  };
  select.onchange = () => {
    const filter = v.style?.filter;
    try {
      v.setStyle(select.value || filter ? { ...(select.value ? { color: { by: select.value } } : {}), ...(filter ? { filter } : {}) } : null);
    } catch (e) { v.emit('warning', { message: `style: ${e.message || e}` }); }
  };
  v.on('style', showLegend);
  fill();
  v.ready.then(fill, () => {});
  return { select, legend };
}

/**
 * Creates a viewer in `target` (a canvas, or an element that gets a canvas).
 * Rejects with an Error whose message says what to do when WebGPU is missing.
 */
export async function create(target, options = {}) {
  let canvas = target;
  if (!(target instanceof HTMLCanvasElement)) {
    canvas = document.createElement('canvas');
    canvas.style.width = '100%';
    canvas.style.height = '100%';
    canvas.style.display = 'block';
    target.appendChild(canvas);
  }
  if (!navigator.gpu) throw new Error(webgpuHelp());
  await loadWasm();
  const scene = options.scene || 'scene/scene.json';
  const viewer = await Viewer.create(canvas, scene);
  // textures: 'plain' fetches RGBA8 packs where the GPU would take BC7 or ETC2
  // ones (to compare); 'bc7' / 'etc2' that encoding alone where the GPU samples it.
  if (options.textures && options.textures !== 'auto') viewer.set_textures(String(options.textures));
  if (options.overlay) viewer.set_overlay(true);
  if (options.fov) viewer.set_fov(options.fov);
  const v = new SylvaViewer(canvas, viewer, { ...options, scene });
  if (options.camera) v.setCamera(options.camera);
  if (options.lighting) v.setLighting(options.lighting);
  if (options.season) v.setSeason(options.season);
  if (options.date) v.setDate(options.date);
  if (options.refine !== undefined) {
    const r = options.refine;
    if (typeof r === 'object' && r !== null) v.setRefine(r.on !== false, r);
    else v.setRefine(!!r);
  }
  if (options.renderer) v.setRenderer(options.renderer, options.photo || {});
  return v;
}

/** `<sylva-viewer src="…/scene.json" camera="lon,lat,height,heading,pitch" refine="off" shadows="low" season="autumn" date="2026-10-20">`
 * (refine: progressive refinement at rest, on unless "off"; shadows: the sun's
 * shadows, off | low | high, high unless given; season: leaf-on | autumn |
 * leaf-off for deciduous species, leaf-on unless given; date: YYYY-MM-DD, each
 * deciduous species as its leaf calendar has it there then, and the sun at that date). */
class SylvaElement extends HTMLElement {
  static get observedAttributes() { return ['refine', 'shadows', 'season', 'date']; }
  attributeChangedCallback(name) {
    if (!this.viewer) return;
    if (name === 'refine') this.viewer.setRefine(this.getAttribute('refine') !== 'off');
    if (name === 'shadows') this.applyShadows();
    if (name === 'season') this.applySeason();
    if (name === 'date') this.applyDate();
  }
  applyDate() {
    const date = this.getAttribute('date');
    try { this.viewer.setDate(date); } catch (e) {
      this.dispatchEvent(new CustomEvent('sylva-error', { detail: { message: `date="${date}": ${e.message || e}` } }));
    }
  }
  applySeason() {
    // (No attribute: leaf-on, the default.)
    const season = this.getAttribute('season') ?? 'leaf-on';
    try { this.viewer.setSeason(season); } catch (e) {
      this.dispatchEvent(new CustomEvent('sylva-error', { detail: { message: `season="${season}": ${e.message || e}` } }));
    }
  }
  applyShadows() {
    const shadows = this.getAttribute('shadows');
    if (shadows === null) return;
    try { this.viewer.setLighting({ shadows }); } catch (e) {
      this.dispatchEvent(new CustomEvent('sylva-error', { detail: { message: `shadows="${shadows}": ${e.message || e}` } }));
    }
  }
  async connectedCallback() {
    if (this.viewer || this.starting) return;
    this.starting = true;
    this.style.display ||= 'block';
    // camera="lon,lat,height,heading,pitch" (WGS 84 degrees, metres, degrees)
    const cam = this.getAttribute('camera');
    const camera = cam ? (([lon, lat, height, heading, pitch]) => ({ lon, lat, height, heading, pitch }))(cam.split(',').map(Number)) : undefined;
    try {
      this.viewer = await create(this, { scene: this.getAttribute('src') || undefined, camera });
      if (this.getAttribute('refine') === 'off') this.viewer.setRefine(false);
      this.applyShadows();
      this.applySeason();
      if (this.getAttribute('date') !== null) this.applyDate();
      this.dispatchEvent(new CustomEvent('sylva-ready', { detail: this.viewer }));
    } catch (e) {
      this.textContent = String(e.message || e);
      this.dispatchEvent(new CustomEvent('sylva-error', { detail: { message: String(e.message || e) } }));
    }
  }
  disconnectedCallback() { this.viewer?.destroy(); this.viewer = null; this.starting = false; }
}
if (!customElements.get('sylva-viewer')) customElements.define('sylva-viewer', SylvaElement);

export const Sylva = { create, webgpuHelp, attachTreePopup, attachStyleControls };
export default Sylva;
