// The browser benchmarks' and probes' set-up: `sylva serve SCENE` on 127.0.0.1
// and headless Chromium on SwiftShader's WebGPU (a CPU rasteriser: compare runs,
// not GPUs). Used by bench.mjs, probe-load.mjs and probe-governor.mjs.
import { spawn } from 'node:child_process';
import { join, dirname } from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

export const root = join(dirname(fileURLToPath(import.meta.url)), '..');

const FLAGS = ['--no-sandbox', '--enable-unsafe-webgpu', '--enable-features=Vulkan', '--use-vulkan=swiftshader',
  '--use-webgpu-adapter=swiftshader', '--use-angle=swiftshader', '--disable-quic', '--no-first-run',
  '--disable-background-networking', '--disable-component-update', '--disable-sync'];

/** Serves `scene` and launches the browser: `{base, browser, close()}`. */
export async function serveAndLaunch(scene) {
  const server = spawn(join(root, 'target/release/sylva'), ['serve', scene, '--port', '0'], { stdio: ['ignore', 'pipe', 'inherit'] });
  const base = await new Promise((resolve) => server.stdout.on('data', (d) => {
    const m = /http:\/\/[0-9.:]+\//.exec(String(d)); if (m) resolve(m[0]);
  }));
  const browser = await chromium.launch({ executablePath: process.env.CHROMIUM || '/usr/bin/chromium', args: FLAGS });
  return { base, browser, close: async () => { await browser.close(); server.kill(); } };
}
