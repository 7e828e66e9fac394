// Loading timeline of a scene's first view in headless Chromium (SwiftShader):
// every second, frames submitted, frames in flight and whether the stream settled,
// until the viewer is ready. Usage: node web/probe-load.mjs SCENE_DIR [extra query]
import { spawn } from 'node:child_process';
import { join, dirname } from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

const root = join(dirname(fileURLToPath(import.meta.url)), '..');
const scene = process.argv[2] || join(root, 'demo-scene');
const query = process.argv[3] || '';
const flags = ['--no-sandbox', '--enable-unsafe-webgpu', '--enable-features=Vulkan', '--use-vulkan=swiftshader',
  '--use-webgpu-adapter=swiftshader', '--use-angle=swiftshader', '--disable-quic', '--no-first-run'];
const server = spawn(join(root, 'target/release/sylva'), ['serve', scene, '--port', '0'], { stdio: ['ignore', 'pipe', 'inherit'] });
const base = await new Promise((resolve) => server.stdout.on('data', (d) => {
  const m = /http:\/\/[0-9.:]+\//.exec(String(d)); if (m) resolve(m[0]);
}));
const browser = await chromium.launch({ executablePath: process.env.CHROMIUM || '/usr/bin/chromium', args: flags });
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
await browser.close();
server.kill();
