// The frame-time governor's logic (web/governor.js), without a browser.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { Governor, LEVELS, REST_MS } from '../governor.js';

/** Feeds `n` frames of `ms` each, 16 ms apart, moving; returns the time after. */
function run(g, t, n, ms, moving = true) {
  for (let i = 0; i < n; i++) { g.frame(t, ms, moving); t += 16; }
  return t;
}

test('slow frames while moving step down to the lowest allowed level, and say why', () => {
  const g = new Governor({ target_ms: 33, min_scale: 0.5 });
  let t = run(g, 0, 1, 60);
  assert.equal(g.level, 0, 'one slow frame is not a trend');
  t = run(g, t, 1, 60);
  assert.equal(g.level, 1);
  // The frames on the GPU when it stepped are not counted.
  t = run(g, t, 3, 60);
  assert.equal(g.level, 1);
  t = run(g, t, 1, 60);
  assert.equal(g.level, 2);
  // A frame far over the target (a software GPU's seconds) goes to the lowest level at once.
  t = run(g, t, 3, 200);
  assert.match(g.report().reason, /far over/);
  t = run(g, t, 40, 200);
  assert.equal(LEVELS[g.level].scale, 0.5, 'never below min_scale');
  assert.match(g.report().reason, /lowest level.*0\.5.*33 ms/);
  const a = g.apply('high', 1);
  assert.deepEqual(a, { scale: 0.5, shadows: 'off', lod: 1, impostors: 'moving', softShadows: false });
  // The user's own choices are ceilings, never raised.
  assert.deepEqual(g.apply('off', 0.25), { scale: 0.5, shadows: 'off', lod: 0.25, impostors: 'moving', softShadows: false });
  // The deepest level draws less where min_scale allows it.
  g.set({ min_scale: 0.35 });
  run(g, t, 3, 200);
  assert.deepEqual(g.apply('high', 1), { scale: 0.35, shadows: 'off', lod: 0.25, impostors: 'moving', softShadows: false });
});

test('fast frames step back up, with hysteresis; at rest everything is restored', () => {
  const g = new Governor({ target_ms: 33 });
  let t = run(g, 0, 12, 100);
  const low = g.level;
  assert.ok(low >= 2, `level ${low}`);
  // Frames near the target hold the level.
  t = run(g, t, 50, 30);
  assert.equal(g.level, low);
  // Frames well under it step up, one level per dozen frames.
  t = run(g, t, 11, 5);
  assert.equal(g.level, low);
  t = run(g, t, 1, 5);
  assert.equal(g.level, low - 1);
  assert.match(g.report().reason, /well under/);
  // The camera stops: full quality once it has rested REST_MS.
  g.frame(t, 100, false);
  assert.equal(g.level, low - 1);
  g.frame(t + REST_MS, undefined, false);
  assert.equal(g.level, 0);
  assert.equal(g.report().reason, 'at rest');
  assert.equal(g.apply('low', 1).shadows, 'low');
  assert.equal(g.apply('high', 1).impostors, 'full', 'at rest the impostors are whole again');
  assert.equal(g.apply('high', 1).softShadows, true, 'at rest the shadows are soft again');
});

test('the ladder gets cheaper at every step and never raises what a level before lowered', () => {
  const rank = { off: 0, low: 1, high: 2 };
  for (let i = 1; i < LEVELS.length; i++) {
    const [a, b] = [LEVELS[i - 1], LEVELS[i]];
    assert.ok(b.scale <= a.scale && rank[b.shadows] <= rank[a.shadows] && b.lod <= a.lod, `level ${i}`);
    assert.ok(!(a.impostors === 'moving' && b.impostors === 'full'), `level ${i}`);
    assert.ok(['all', 'no-soft-shadows'].includes(b.light) && !(a.light !== 'all' && b.light === 'all'), `level ${i}`);
    // Soft shadows go with the high shadows: a level with them off keeps none.
    assert.ok(b.shadows === 'high' || b.light !== 'all', `level ${i}`);
    assert.notDeepEqual(a, b, `level ${i} changes something`);
  }
  assert.equal(LEVELS[0].impostors, 'full');
  assert.deepEqual(LEVELS[0], { scale: 1, shadows: 'high', lod: 1, impostors: 'full', light: 'all' });
});

test('off, and settings checked', () => {
  const g = new Governor({ enabled: false });
  run(g, 0, 20, 1000);
  assert.equal(g.level, 0);
  assert.equal(g.report().enabled, false);
  g.set({ enabled: true, target_ms: 50 });
  run(g, 0, 4, 1000);
  assert.ok(g.level > 0);
  g.set({ enabled: false });
  assert.equal(g.level, 0, 'turned off: full quality at once');
  assert.throws(() => g.set({ target_ms: -1 }), /target_ms/);
  assert.throws(() => g.set({ target_ms: 'fast' }), /target_ms/);
  assert.throws(() => g.set({ min_scale: 0.1 }), /min_scale must be 0.25–1/);
});
