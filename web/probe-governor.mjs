// Frames while moving the camera, with the frame-time governor and without:
// loads a scene's first view in headless Chromium (SwiftShader), waits for it,
// then orbits for `seconds` (a move every animation frame) and counts the
// frames drawn. Usage: node web/probe-governor.mjs SCENE_DIR [seconds] [target_ms]
import { join } from 'node:path';
import { root, serveAndLaunch } from './headless.mjs';

const scene = process.argv[2] || join(root, 'demo-scene');
const seconds = Number(process.argv[3] || 30);
const target = process.argv[4] || '33';
const { base, browser, close } = await serveAndLaunch(scene);
for (const quality of ['off', target]) {
  const page = await browser.newPage({ viewport: { width: 960, height: 540 } });
  await page.goto(`${base}?ui=0&quality=${quality}`);
  await page.waitForFunction(() => window.sylva, null, { timeout: 600000 });
  await page.evaluate(() => window.sylva.ready);
  const r = await page.evaluate(async (ms) => {
    const v = window.sylva;
    const c = v.camera();
    const f0 = v.viewer.frames_drawn();
    const t0 = performance.now();
    const levels = {};
    const trace = [];
    let lastTrace = -1e9;
    while (performance.now() - t0 < ms) {
      if (performance.now() - lastTrace > 3000) {
        lastTrace = performance.now();
        const s = v.stats();
        trace.push(`${((lastTrace - t0) / 1000).toFixed(1)}s L${s.governor.level} f${v.viewer.frames_drawn() - f0} w${v.canvas.width} draw ${Math.round(s.gpu_ms.draw)} trees ${s.instances.billboard}`);
      }
      v.setCamera({ x: c.x, y: c.y, z: c.z, pitch: c.pitch, heading: c.heading + (performance.now() - t0) / 200 });
      await new Promise((res) => requestAnimationFrame(res));
      const g = v.stats().governor;
      levels[g.level] = (levels[g.level] || 0) + 1;
    }
    const frames = v.viewer.frames_drawn() - f0;
    return { frames, seconds: (performance.now() - t0) / 1000, levels, governor: v.stats().governor, trace };
  }, seconds * 1000);
  if (process.env.TRACE) console.log(r.trace.join('\n'));
  console.log(`quality=${quality}: ${r.frames} frames in ${r.seconds.toFixed(1)} s while moving (${(1000 * r.seconds / Math.max(1, r.frames)).toFixed(0)} ms a frame); animation frames per level ${JSON.stringify(r.levels)}; ${JSON.stringify(r.governor)}`);
  await page.close();
}
await close();
