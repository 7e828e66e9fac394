// Browser benchmark: time to first complete frame and bytes fetched for a
// scene's default view, served by `sylva serve` on 127.0.0.1, in headless Chromium
// (SwiftShader WebGPU: a CPU rasteriser ~13x slower than lavapipe; compare runs, not GPUs).
// Usage: node web/bench.mjs SCENE_DIR [runs] [?query]    (after `make web` and `make release`;
// e.g. ?textures=plain to compare with the RGBA8 packs)
import { join } from 'node:path';
import { root, serveAndLaunch } from './headless.mjs';

const scene = process.argv[2] || join(root, 'demo-scene');
const runs = Number(process.argv[3] || 3);
const query = process.argv[4] || '';
const { base, browser, close } = await serveAndLaunch(scene);
const rows = [];
for (let i = 0; i < runs; i++) {
  const page = await browser.newPage({ viewport: { width: 960, height: 540 } });
  const t0 = Date.now();
  await page.goto(base + query);
  await page.waitForFunction(() => window.sylva, null, { timeout: 600000 });
  const stats = await page.evaluate(() => window.sylva.ready);
  rows.push({ ms: Date.now() - t0, scene_bytes: stats.bytes_fetched, drawn: stats.instances, textures: stats.textures, gpu_bytes: stats.gpu_bytes });
  await page.close();
}
await close();
console.log(`scene ${scene}${query}, 960x540, ${runs} runs (cold page each time)`);
for (const r of rows) console.log(`time to first complete frame ${r.ms} ms; scene bytes ${r.scene_bytes}; drawn ${JSON.stringify(r.drawn)}; textures ${r.textures}, GPU bytes ${r.gpu_bytes}`);
const sorted = rows.map((r) => r.ms).sort((a, b) => a - b);
console.log(`median ${sorted[Math.floor(sorted.length / 2)]} ms`);
