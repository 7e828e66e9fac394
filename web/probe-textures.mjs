// The same first view with each texture encoding the page can take (plain
// RGBA8 packs, the BC7 variants, the ETC2 variants), in headless Chromium
// (SwiftShader samples all three): bytes fetched, GPU bytes, the encoding in
// use, and a screenshot of each for `sylva compare`. Shadows and refinement
// off, so what differs is the textures.
// Usage: node web/probe-textures.mjs SCENE_DIR OUT_DIR [#local=x,y,z,heading,pitch]
import { mkdirSync } from 'node:fs';
import { join } from 'node:path';
import { root, serveAndLaunch } from './headless.mjs';

const scene = process.argv[2] || join(root, 'demo-scene');
const out = process.argv[3] || '/tmp/probe-textures';
const hash = process.argv[4] || '';
mkdirSync(out, { recursive: true });
const { base, browser, close } = await serveAndLaunch(scene);
for (const textures of ['plain', 'bc7', 'etc2']) {
  const page = await browser.newPage({ viewport: { width: 960, height: 540 } });
  await page.goto(`${base}?ui=0&refine=0&quality=off&shadows=off&textures=${textures}${hash}`);
  await page.waitForFunction(() => window.sylva, null, { timeout: 600000 });
  const s = await page.evaluate(() => window.sylva.ready);
  await page.locator('canvas').first().screenshot({ path: join(out, `${textures}.png`), timeout: 600000 });
  console.log(`${textures}: textures in use ${s.textures}; scene bytes ${s.bytes_fetched}; GPU bytes ${s.gpu_bytes}; drawn ${JSON.stringify(s.instances)}`);
  await page.close();
}
await close();
