// Loading timeline of a scene's first view in headless Chromium (SwiftShader):
// every second, frames submitted, frames in flight and whether the stream settled,
// until the viewer is ready. Usage: node web/probe-load.mjs SCENE_DIR [extra query]
import { join } from 'node:path';
import { root, serveAndLaunch } from './headless.mjs';

const scene = process.argv[2] || join(root, 'demo-scene');
const query = process.argv[3] || '';
const { base, browser, close } = await serveAndLaunch(scene);
const page = await browser.newPage({ viewport: { width: 960, height: 540 } });
const t0 = Date.now();
page.on('request', (r) => { const t = (Date.now() - t0) / 1000; if (t > 3) console.log(`  ${t.toFixed(1)} s request ${r.url().replace(base, '')} ${r.headers().range || ''}`); });
await page.goto(base + query);
await page.waitForFunction(() => window.sylva, null, { timeout: 600000 });
let ready = false;
page.evaluate(() => window.sylva.ready).then(() => { ready = true; });
while (!ready) {
  const s = await page.evaluate(() => {
    const v = window.sylva.viewer;
    const p = JSON.parse(v.progress_json());
    return { frames: v.frames_drawn(), ahead: v.frames_in_flight(), settled: p.settled, bytes: p.bytes_fetched };
  });
  console.log(`${((Date.now() - t0) / 1000).toFixed(1)} s ${JSON.stringify(s)}`);
  await new Promise((r) => setTimeout(r, 2000));
}
console.log(`ready at ${((Date.now() - t0) / 1000).toFixed(1)} s`);
await close();
