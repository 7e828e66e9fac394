// Sylva's viewer against CesiumJS with the scene's 3D Tiles export, side
// by side in one headless Chromium (SwiftShader: WebGPU for Sylva, WebGL for
// Cesium, both CPU rasterisers; compare the two, not GPUs): the same camera (Sylva's
// first view of the scene), 640x360, progressive refinement off, Sylva's shadows off (Cesium draws none by default). Per viewer: time to the first complete frame
// (Sylva: `ready`; Cesium: every tile the view needs loaded, then one frame drawn),
// bytes fetched (the scene's or tileset's files; and everything, the viewers' own
// code included), frame time over 20 redraws of the settled view (or 4 minutes' worth), and the image
// error (multi-scale RMSE, `sylva compare`) against Sylva's native render of the
// same camera (`sylva render`: full meshes where trees are big, lavapipe).
// Usage: node web/bench-cesium.mjs SCENE_DIR TILESET_DIR OUT_DIR [VIEW]
//   (after `make release`, `make web`, and `sylva-bake export-3dtiles SCENE_DIR --out TILESET_DIR`);
//   VIEW: a named view of `sylva render` (far, medium, close, top) instead of the viewer's first view.
//   `make bench-cesium` runs the medium view.
import { spawn, execFileSync } from 'node:child_process';
import { mkdirSync, readFileSync, writeFileSync } from 'node:fs';
import { join, dirname } from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

const root = join(dirname(fileURLToPath(import.meta.url)), '..');
const [scene, tileset, out, view] = process.argv.slice(2);
if (!scene || !tileset || !out) {
  console.error('usage: node web/bench-cesium.mjs SCENE_DIR TILESET_DIR OUT_DIR [far|medium|close|top]');
  process.exit(2);
}
mkdirSync(out, { recursive: true });
const sylva = join(root, 'target/release/sylva');
const size = { width: 640, height: 360 };
// A named view: its camera from `sylva render --stats` (scene CRS), as metres from the scene origin.
let hash = '';
if (view) {
  execFileSync(sylva, ['render', '--scene', scene, '--view', view, '--size', '64x36', '--shadows', 'off',
    '--out', join(out, 'view.png'), '--stats', join(out, 'view.json')], { stdio: ['ignore', 'ignore', 'inherit'] });
  const abs = JSON.parse(readFileSync(join(out, 'view.json'))).camera.split(',').map(Number);
  const origin = JSON.parse(readFileSync(join(scene, 'scene.json'))).origin_m;
  hash = `#local=${[abs[0] - origin[0], abs[1] - origin[1], abs[2] - origin[2], abs[3], abs[4]].join(',')}`;
}
const flags = ['--no-sandbox', '--enable-unsafe-webgpu', '--enable-features=Vulkan', '--use-vulkan=swiftshader',
  '--use-webgpu-adapter=swiftshader', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--disable-quic',
  '--no-first-run', '--disable-background-networking', '--disable-component-update', '--disable-sync'];

function serve(dir) {
  const proc = spawn(sylva, ['serve', dir, '--port', '0'], { stdio: ['ignore', 'pipe', 'inherit'] });
  const url = new Promise((resolve) => proc.stdout.on('data', (d) => {
    const m = /http:\/\/[0-9.:]+\//.exec(String(d)); if (m) resolve(m[0]);
  }));
  return { proc, url };
}

/** A page that counts the bytes of every response: the scene's (/scene/…) and all. */
async function countingPage(browser) {
  const page = await browser.newPage({ viewport: size });
  const bytes = { scene: 0, all: 0 };
  page.on('requestfinished', async (req) => {
    const s = await req.sizes().catch(() => null);
    if (!s) return;
    bytes.all += s.responseBodySize;
    if (new URL(req.url()).pathname.startsWith('/scene/')) bytes.scene += s.responseBodySize;
  });
  page.on('pageerror', (e) => console.error('page error:', String(e)));
  return { page, bytes };
}

const browser = await chromium.launch({ executablePath: process.env.CHROMIUM || '/usr/bin/chromium', args: flags });
const results = {};

// Sylva's viewer: its first view.
{
  const s = serve(scene);
  const base = await s.url;
  const { page, bytes } = await countingPage(browser);
  const t0 = Date.now();
  await page.goto(`${base}?ui=0&refine=off&shadows=off${hash}`);
  await page.waitForFunction(() => window.sylva, null, { timeout: 600000 });
  // Progress every 15 s while the first complete frame is awaited.
  const progress = setInterval(async () => {
    const p = await page.evaluate(() => window.sylva.viewer.progress_json()).catch(() => null);
    console.error(`sylva, ${((Date.now() - t0) / 1000).toFixed(0)} s: ${p}`);
  }, 15000);
  await page.evaluate(() => window.sylva.ready);
  clearInterval(progress);
  const first = Date.now() - t0;
  console.error(`sylva: first complete frame in ${first} ms`);
  // (A resting view refines progressively: it may not go idle soon; 60 s at most.)
  await page.waitForFunction(() => window.sylva.dirty === 0 && window.sylva.viewer.frames_in_flight() === 0,
    null, { timeout: 60000, polling: 100 }).catch(() => {});
  const camera = await page.evaluate(() => {
    const s = window.sylva;
    const c = s.camera();
    // Sylva's heading is from the scene's grid north; Cesium's from true north.
    const eye = s.toLocal(c.lon, c.lat, c.z);
    const north = s.toLocal(c.lon, c.lat + 1e-3, c.z);
    c.convergence = Math.atan2(north.x - eye.x, north.y - eye.y) * 180 / Math.PI;
    c.true_heading = c.heading - c.convergence;
    return c;
  });
  const frameMs = await page.evaluate(async () => {
    const s = window.sylva;
    const cam = s.camera();
    const t = performance.now();
    for (let i = 0; i < 20; i++) {
      s.setCamera({ x: cam.x, y: cam.y, z: cam.z, heading: cam.heading, pitch: cam.pitch });
      await new Promise((r) => requestAnimationFrame(r));
    }
    while (s.viewer.frames_in_flight() > 0) await new Promise((r) => requestAnimationFrame(r));
    return (performance.now() - t) / 20;
  });
  console.error(`sylva: frame time ${frameMs.toFixed(1)} ms; bytes: ${JSON.stringify(bytes)}`);
  await page.screenshot({ path: join(out, 'sylva.png'), timeout: 600000 });
  results.sylva = { first_frame_ms: first, scene_bytes: bytes.scene, all_bytes: bytes.all, frame_ms: frameMs, camera };
  await page.close();
  s.proc.kill();
}

// CesiumJS with the tileset, at Sylva's camera.
{
  const c = results.sylva.camera;
  const s = serve(tileset);
  const base = await s.url;
  const { page, bytes } = await countingPage(browser);
  const t0 = Date.now();
  await page.goto(`${base}cesium.html?render=continuous&camera=${[c.lon, c.lat, c.height, c.true_heading, c.pitch].join(',')}&fov_y=50`);
  await page.waitForFunction(() => window.cesiumTilesLoaded !== undefined || window.cesiumError, null,
    { timeout: 600000, polling: 100 });
  const error = await page.evaluate(() => window.cesiumError);
  if (error) throw new Error(`Cesium: ${error}`);
  await page.evaluate(() => new Promise((r) => window.cesium.viewer.scene.postRender.addEventListener(function once() {
    window.cesium.viewer.scene.postRender.removeEventListener(once); r();
  })));
  const first = Date.now() - t0;
  console.error(`cesium: first complete frame in ${first} ms`);
  const frameMs = await page.evaluate(async () => {
    const { viewer } = window.cesium;
    let frames = 0;
    const count = () => { frames += 1; };
    viewer.scene.postRender.addEventListener(count);
    const t = performance.now();
    // 20 frames, or as many as 4 minutes hold (a CPU rasteriser can take a minute a frame).
    while (frames < 20 && !(frames >= 2 && performance.now() - t > 240000)) {
      await new Promise((r) => requestAnimationFrame(r));
    }
    viewer.scene.postRender.removeEventListener(count);
    return (performance.now() - t) / frames;
  });
  const loaded = await page.evaluate(() => window.cesiumTilesLoaded);
  console.error(`cesium: frame time ${frameMs.toFixed(1)} ms; bytes: ${JSON.stringify(bytes)}`);
  results.cesium = { first_frame_ms: first, scene_bytes: bytes.scene, all_bytes: bytes.all, frame_ms: frameMs, tiles_loaded: loaded };
  writeFileSync(join(out, 'side-by-side.json'), JSON.stringify(results, null, 2));
  // (A screenshot waits for a new frame: under a CPU rasteriser Cesium's may not come in 10 minutes.)
  results.cesium.shot = await page.screenshot({ path: join(out, 'cesium.png'), timeout: 600000 }).then(() => true, () => false);
  await page.close();
  s.proc.kill();
}
await browser.close();

// The native reference of the same camera, and each viewer's error against it.
const c = results.sylva.camera;
const eye = [c.x + c.origin[0], c.y + c.origin[1], c.z + c.origin[2], c.heading, c.pitch].join(',');
execFileSync(sylva, ['render', '--scene', scene, '--camera', eye, '--size', `${size.width}x${size.height}`,
  '--out', join(out, 'native.png')], { stdio: ['ignore', 'ignore', 'inherit'] });
for (const v of ['sylva', 'cesium']) {
  if (results[v].shot === false) { results[v].ms_rmse = NaN; continue; }
  results[v].ms_rmse = Number(execFileSync(sylva, ['compare', join(out, 'native.png'), join(out, `${v}.png`)]).toString());
}
writeFileSync(join(out, 'side-by-side.json'), JSON.stringify(results, null, 2));
console.log(`scene ${scene}, tileset ${tileset}, ${size.width}x${size.height}, ${view ?? 'first'} view, camera ${eye}`);
console.log('| viewer | first complete frame | scene bytes | all bytes | frame time | ms-rmse vs native |');
for (const v of ['sylva', 'cesium']) {
  const r = results[v];
  console.log(`| ${v} | ${r.first_frame_ms} ms | ${(r.scene_bytes / 1e6).toFixed(2)} MB | ${(r.all_bytes / 1e6).toFixed(2)} MB | ${r.frame_ms.toFixed(1)} ms | ${r.ms_rmse.toFixed(4)} |`);
}
