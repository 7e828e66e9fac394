// Sylva as a layer of a MapLibre GL JS map (docs/DEPLOY.md "In a MapLibre portal").
//
//   import { SylvaLayer } from './sylva-maplibre.js';
//   const layer = new SylvaLayer({ scene: 'scene/scene.json' });
//   map.addLayer(layer);                 // any maplibregl.Map (the portal's own maplibre-gl, 5 or later; tested with 6.20)
//   await layer.ready;                   // the first complete frame; rejects with what to do when WebGPU is missing
//   map.on('click', async (e) => console.log(await layer.pick(e.point.x, e.point.y)));
//
// The forest is drawn by Sylva's WebGPU renderer on a canvas of its own, stacked over the
// map's and transparent where no tree is; pointer events pass through it to the map. Every
// map render poses Sylva's camera as the map's: the map's centre, zoom, bearing, pitch and
// field of view give the eye (on MapLibre's Web Mercator sphere, R = 6 371 008.8 m) and the
// point it looks at, both as WGS 84 lon/lat and heights, and Sylva takes them through the
// scene's CRS — so trees stay glued to the basemap while panning, zooming, rotating and
// tilting.
//
// Options: {scene (URL of scene.json), id ('sylva'), heightOffset, lighting ({shadows, ao}),
// refine (false: a resting map is not refined further), terrain (false: the map is the
// ground; true draws the scene's own terrain, hiding the basemap under it)}.
// heightOffset: the scene height drawn at the map's ground. 'auto' (the default): 0 on a map
// with terrain (its heights are absolute), else the scene's ground at the map's centre, read
// again whenever the map comes to rest and as finer ground arrives until the view settles —
// a flat map cannot hold a hilly forest, so the trees around the centre stand on it. A
// number fixes it.
//
// Limits: trees are drawn over the whole map, its labels included (two canvases share no
// depth); the map's padding and roll are not followed; a globe projection is not (mercator only).

import { create } from './sylva.js';

/** MapLibre's Earth radius (metres): its mercator world and altitudes are on this sphere. */
const EARTH_RADIUS_M = 6371008.8;
/** MapLibre's tile size: the world is 512 · 2^zoom pixels wide. */
const TILE_SIZE = 512;

const rad = Math.PI / 180;
const mercatorX = (lng) => (180 + lng) / 360;
const mercatorY = (lat) => (180 - Math.log(Math.tan(Math.PI / 4 + lat * rad / 2)) / rad) / 360;
const lngOf = (x) => x * 360 - 180;
const latOf = (y) => Math.atan(Math.exp((180 - y * 360) * rad)) * 2 / rad - 90;

/**
 * The camera of a MapLibre map as Sylva takes it: {eye, target ({lon, lat, height}, heights
 * in metres above the map's ground datum), bearing, fov (vertical, degrees)}. The camera
 * looks at the map's centre from the distance at which the map's field of view spans its
 * height in pixels at this zoom (MapLibre's own camera model). `scale`: the scene's metres
 * per metre of MapLibre's sphere at the centre — the eye's height over the centre is scaled
 * by it, so the scene (on the ellipsoid, in its CRS's metres) is seen at the map's scale.
 */
export function mapCamera(map, scale = 1) {
  const centre = map.getCenter();
  const bearing = map.getBearing();
  const pitch = map.getPitch() * rad;
  // (MapLibre 5+; its default, 36.87°, before.)
  const fov = map.getVerticalFieldOfView?.() ?? map.transform?.fov ?? 36.87;
  const height = map.getCanvas().clientHeight;
  // Metres on the ground at the centre's latitude per world pixel, and the camera distance.
  const circumference = 2 * Math.PI * EARTH_RADIUS_M * Math.cos(centre.lat * rad);
  const pxPerMetre = TILE_SIZE * 2 ** map.getZoom() / circumference;
  const distance = 0.5 * height / Math.tan(fov * rad / 2) / pxPerMetre;
  // Back from the centre, against the bearing, on the mercator plane.
  const back = distance * Math.sin(pitch) / circumference;
  const x = mercatorX(centre.lng) - Math.sin(bearing * rad) * back;
  const y = mercatorY(centre.lat) + Math.cos(bearing * rad) * back;
  const ground = map.getCenterElevation?.() ?? 0;
  return {
    eye: { lon: lngOf(x), lat: latOf(y), height: ground + scale * distance * Math.cos(pitch) },
    target: { lon: centre.lng, lat: centre.lat, height: ground },
    bearing,
    fov,
  };
}

/** A MapLibre custom layer that adds a Sylva forest to the map (see the top of this file). */
export class SylvaLayer {
  constructor(options = {}) {
    this.id = options.id || 'sylva';
    this.type = 'custom';
    this.renderingMode = '3d';
    this.options = { heightOffset: 'auto', refine: false, terrain: false, ...options };
    this.viewer = null;
    this.offset = typeof this.options.heightOffset === 'number' ? this.options.heightOffset : null;
    this.ready = new Promise((resolve, reject) => { this.resolveReady = resolve; this.rejectReady = reject; });
    this.ready.catch(() => {}); // shown on the map and through layer.ready
  }

  onAdd(map) {
    this.map = map;
    const canvas = document.createElement('canvas');
    canvas.className = 'sylva-layer';
    Object.assign(canvas.style, {
      position: 'absolute', left: '0', top: '0', width: '100%', height: '100%', pointerEvents: 'none',
    });
    // Right after the map's canvas: over the map, under its markers, popups and controls.
    map.getCanvas().after(canvas);
    this.canvas = canvas;
    this.onMoveEnd = () => { this.offsetSettled = false; this.readOffset(); map.triggerRepaint(); };
    map.on('moveend', this.onMoveEnd);
    map.on('terrain', this.onMoveEnd);
    // Hidden (visibility none): MapLibre stops calling render, so hide the canvas too.
    this.onRender = () => {
      const hidden = map.getLayoutProperty(this.id, 'visibility') === 'none';
      canvas.style.display = hidden ? 'none' : '';
    };
    map.on('render', this.onRender);
    const o = this.options;
    this.created = create(canvas, { scene: o.scene, overlay: true, controls: false, quality: { enabled: false }, refine: o.refine,
      lighting: o.lighting });
    this.created.catch(() => {});
    this.created
      .then((v) => {
        if (!this.map) { v.destroy(); return; }
        this.viewer = v;
        if (!o.terrain) v.setTerrain(false);
        // Ground heights arrive with the first tiles, finer ones after: the offset is read
        // as they come until the view settles (then it holds still until the map moves;
        // a first coarse tile's height alone left the trees metres off the map's ground).
        v.on('progress', (p) => {
          if (this.offset === null || !this.offsetSettled) this.readOffset();
          if (p.settled && this.offset !== null) this.offsetSettled = true;
        });
        v.on('error', (e) => console.error(`sylva: ${e.message}`));
        v.on('recovered', () => map.triggerRepaint());
        this.pose();
        map.triggerRepaint();
        return v.ready;
      })
      .then((stats) => this.resolveReady(stats), (e) => {
        this.notice(String(e.message || e));
        this.rejectReady(e instanceof Error ? e : new Error(String(e)));
      });
  }

  /** MapLibre calls it on every map frame: Sylva draws the same camera now. */
  render() {
    this.pose();
  }

  onRemove(map) {
    map.off('moveend', this.onMoveEnd);
    map.off('terrain', this.onMoveEnd);
    map.off('render', this.onRender);
    this.viewer?.destroy();
    this.viewer = null;
    this.canvas?.remove();
    this.noticeBox?.remove();
    this.map = null;
  }

  /** The scene height at the map's ground: see `heightOffset` (null until known). */
  get heightOffset() { return this.offset; }

  /** The tree drawn at map CSS pixel (x, y) (as `e.point` of a map event), or null: as
   * Sylva's `pick` ({id, species, attributes, lon, lat, height, position}). */
  async pick(x, y) {
    return this.viewer ? this.viewer.pick(x, y) : null;
  }

  /** Where the forest draws WGS 84 `lon`, `lat` at `height` metres over the map's ground:
   * {x, y} map CSS pixels, or null. */
  project(lon, lat, height = 0) {
    if (!this.viewer) return null;
    return this.viewer.project(lon, lat, height + (this.offset ?? this.originHeight()));
  }

  /** The WGS 84 box [west, south, east, north] around the scene's first view (its home,
   * else its densest trees), once its manifest arrived: `map.fitBounds(await layer.sceneBounds())`. */
  async sceneBounds() {
    if (!this.created) throw new Error('add the layer to a map first');
    return (await this.created).focusBounds();
  }

  /** The Sylva viewer (null until created): styles, queries, lighting as `Sylva.create` gives. */
  get sylva() { return this.viewer; }

  pose() {
    const v = this.viewer;
    if (!v?.live || !this.map) return;
    try {
      const c = mapCamera(this.map, this.groundScale());
      const up = this.offset ?? this.originHeight();
      v.setFov(c.fov);
      v.lookAt({ ...c.eye, height: c.eye.height + up }, { ...c.target, height: c.target.height + up }, c.bearing);
      v.tick();
    } catch (e) {
      // Never into the map's render loop: the map goes on without the forest.
      console.error(`sylva: ${e.message || e}`);
    }
  }

  /** The scene's metres per metre of MapLibre's sphere at the map's centre (the mean of
   * east and north; the ellipsoid and the CRS's scale factor make it differ from 1 by a few
   * parts in a thousand), read again when the centre moved by more than a kilometre. */
  groundScale() {
    const c = this.map.getCenter();
    if (this.scaleAt && Math.abs(this.scaleAt[0] - c.lng) + Math.abs(this.scaleAt[1] - c.lat) < 0.01) return this.scale;
    const d = 1e-4;
    const at = this.viewer.toLocal(c.lng, c.lat, 0);
    const east = this.viewer.toLocal(c.lng + d, c.lat, 0);
    const north = this.viewer.toLocal(c.lng, c.lat + d, 0);
    if (!at || !east || !north) return 1; // before the scene's CRS is known
    const sphere = EARTH_RADIUS_M * d * rad;
    const sx = Math.hypot(east.x - at.x, east.y - at.y) / (sphere * Math.cos(c.lat * rad));
    const sy = Math.hypot(north.x - at.x, north.y - at.y) / sphere;
    this.scaleAt = [c.lng, c.lat];
    this.scale = (sx + sy) / 2;
    return this.scale;
  }

  /** Before the ground is known: the scene origin's height (read once the manifest gave it). */
  originHeight() {
    if (this.origin === undefined && this.viewer?.live) {
      const o = this.viewer.camera().origin;
      if (o) this.origin = o[2];
    }
    return this.origin ?? 0;
  }

  readOffset() {
    if (!this.viewer?.live || typeof this.options.heightOffset === 'number') return;
    let h = null;
    if (this.map.getTerrain?.()) h = 0;
    else {
      const c = this.map.getCenter();
      h = this.viewer.heightAt(c.lng, c.lat);
    }
    if (h !== null && h !== this.offset) {
      this.offset = h;
      this.map?.triggerRepaint();
    }
  }

  notice(message) {
    if (!this.map) return;
    const box = document.createElement('div');
    box.className = 'sylva-layer-error';
    box.setAttribute('role', 'alert');
    box.textContent = `The forest layer cannot be shown: ${message}`;
    Object.assign(box.style, {
      position: 'absolute', left: '10px', bottom: '30px', maxWidth: '60%', padding: '6px 10px',
      background: 'rgba(160, 0, 0, 0.85)', color: '#fff', font: '13px sans-serif', borderRadius: '4px',
    });
    this.map.getContainer().appendChild(box);
    this.noticeBox = box;
  }
}

export default SylvaLayer;
