// Browser benchmark: time to first complete frame and bytes fetched for a
// scene's default view, served by `sylva serve` on 127.0.0.1, in headless Chromium
// (SwiftShader WebGPU: a CPU rasteriser ~13x slower than lavapipe; compare runs, not GPUs).
// Usage: node web/bench.mjs SCENE_DIR [runs]    (after `make web` and `make release`)
import { spawn } from 'node:child_process';
import { join, dirname } from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

const root = join(dirname(fileURLToPath(import.meta.url)), '..');
const scene = process.argv[2] || join(root, 'demo-scene');
const runs = Number(process.argv[3] || 3);
const flags = ['--no-sandbox', '--enable-unsafe-webgpu', '--enable-features=Vulkan', '--use-vulkan=swiftshader',
  '--use-webgpu-adapter=swiftshader', '--use-angle=swiftshader', '--disable-quic', '--no-first-run',
  '--disable-background-networking', '--disable-component-update', '--disable-sync'];
const server = spawn(join(root, 'target/release/sylva'), ['serve', scene, '--port', '0'], { stdio: ['ignore', 'pipe', 'inherit'] });
const base = await new Promise((resolve) => server.stdout.on('data', (d) => {
  const m = /http:\/\/[0-9.:]+\//.exec(String(d)); if (m) resolve(m[0]);
}));
const browser = await chromium.launch({ executablePath: process.env.CHROMIUM || '/usr/bin/chromium', args: flags });
const rows = [];
for (let i = 0; i < runs; i++) {
  const page = await browser.newPage({ viewport: { width: 960, height: 540 } });
  const t0 = Date.now();
  await page.goto(base);
  await page.waitForFunction(() => window.sylva, null, { timeout: 600000 });
  const stats = await page.evaluate(() => window.sylva.ready);
  rows.push({ ms: Date.now() - t0, scene_bytes: stats.bytes_fetched, drawn: stats.instances });
  await page.close();
}
await browser.close();
server.kill();
console.log(`scene ${scene}, 960x540, ${runs} runs (cold page each time)`);
for (const r of rows) console.log(`time to first complete frame ${r.ms} ms; scene bytes ${r.scene_bytes}; drawn ${JSON.stringify(r.drawn)}`);
const sorted = rows.map((r) => r.ms).sort((a, b) => a - b);
console.log(`median ${sorted[Math.floor(sorted.length / 2)]} ms`);
