// The page's Photo control on a scene, in headless Chromium (SwiftShader):
// the raster view, then the Photo button pressed — the view's scene loaded
// and built in the browser (load_ms, fetch rounds, bytes, trees, triangles)
// and traced until `SAMPLES` samples a pixel — with a screenshot of each
// (raster.png, photo.png) and the timings printed.
// Usage: node web/probe-photo.mjs SCENE_DIR OUT_DIR [SAMPLES] [#local=x,y,z,heading,pitch]
import { mkdirSync } from 'node:fs';
import { join } from 'node:path';
import { root, serveAndLaunch } from './headless.mjs';

const scene = process.argv[2] || join(root, 'demo-scene');
const out = process.argv[3] || '/tmp/probe-photo';
const samples = Number(process.argv[4] || 4);
const hash = process.argv[5] || '';
mkdirSync(out, { recursive: true });
const { base, browser, close } = await serveAndLaunch(scene);
const page = await browser.newPage({ viewport: { width: 480, height: 270 } });
await page.goto(`${base}?refine=0&quality=off&shadows=off${hash}`);
await page.waitForFunction(() => window.sylva, null, { timeout: 600000 });
await page.evaluate(() => window.sylva.ready);
await page.screenshot({ path: join(out, 'raster.png'), timeout: 600000 });
const t0 = Date.now();
await page.click('#photo-toggle');
await page.waitForFunction(() => window.sylva.photo()?.state !== 'loading', null, { timeout: 600000, polling: 200 });
const loaded = Date.now() - t0;
await page.waitForFunction((n) => window.sylva.photo().state !== 'ready' || window.sylva.photo().samples >= n, samples,
  { timeout: 1200000, polling: 500 });
const traced = Date.now() - t0;
const p = await page.evaluate(() => window.sylva.photo());
await page.waitForTimeout(500);
await page.screenshot({ path: join(out, 'photo.png'), timeout: 600000 });
console.log(JSON.stringify({ ...p, page_load_to_ready_ms: loaded, to_samples_ms: traced }));
await close();
