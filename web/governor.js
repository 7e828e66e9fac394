// The frame-time governor (issue 47): while the camera moves, quality steps
// down until frames take the target time, and back up with hysteresis; at rest
// everything is restored (the refinement then converges at full quality).
// Pure logic, no DOM: `web/sylva.js` applies the levels (the canvas's render
// scale, the shadows, the LoD quality, the impostors) and
// `web/tests/governor.test.mjs` tests it.

/** The ladder, cheapest last: render scale (the canvas's backing store, which
 * the browser upscales), shadows at most this ('high' | 'low' | 'off'), a
 * factor on the LoD quality (projected sizes), and the impostors ('full':
 * three views blended, each pixel's own depth; 'moving': the nearest view at
 * the depth of the tree's quad, so hidden crowns cost nothing), and the
 * light's parts ('all', or 'no-soft-shadows': the penumbrae's blocker search
 * and wide filter, 1.16× of a close frame's GPU time with high shadows, go
 * with the high shadows). Ordered by what
 * each step costs in image error for what it saves (`make bench-governor`,
 * docs/BENCHMARKS.md): the moving impostors first (6× cheaper draws for
 * 0.008 MS-RMSE), then shadows, then pixels, the LoD quality last. Thinning
 * more was measured and left out: a moving frame's cost is its pixels, not
 * its trees. */
export const LEVELS = [
  { scale: 1.0, shadows: 'high', lod: 1.0, impostors: 'full', light: 'all' },
  { scale: 1.0, shadows: 'high', lod: 1.0, impostors: 'moving', light: 'all' },
  { scale: 0.85, shadows: 'low', lod: 1.0, impostors: 'moving', light: 'no-soft-shadows' },
  { scale: 0.7, shadows: 'off', lod: 1.0, impostors: 'moving', light: 'no-soft-shadows' },
  { scale: 0.5, shadows: 'off', lod: 1.0, impostors: 'moving', light: 'no-soft-shadows' },
  { scale: 0.42, shadows: 'off', lod: 0.5, impostors: 'moving', light: 'no-soft-shadows' },
  { scale: 0.35, shadows: 'off', lod: 0.25, impostors: 'moving', light: 'no-soft-shadows' },
];

const SHADOW_RANK = { off: 0, low: 1, high: 2 };

/** Frames over `target × DOWN_OVER` this many times in a row step down; one
 * frame over `target × FAR_OVER` goes to the lowest level at once (a software
 * GPU's frames take seconds: a step a frame would take minutes). */
const DOWN_FRAMES = 2;
const DOWN_OVER = 1.25;
const FAR_OVER = 4;
/** Frames already on the GPU when the level changed are not the new level's:
 * this many are not counted after a change. */
const IN_FLIGHT = 2;
/** Frames under `target × UP_UNDER` this many times in a row step up (hysteresis). */
const UP_FRAMES = 12;
const UP_UNDER = 0.6;
/** The camera at rest this long (ms): full quality again. */
export const REST_MS = 400;

export class Governor {
  /** `target_ms`: the frame time held while moving (default 33); `min_scale`:
   * the smallest render scale used (0.25–1, default 0.35); `enabled`. */
  constructor({ target_ms = 33, min_scale = 0.35, enabled = true } = {}) {
    this.set({ target_ms, min_scale, enabled });
    this.level = 0;
    this.over = 0;
    this.under = 0;
    this.skip = 0;
    this.lastMoveMs = -Infinity;
    this.reason = 'at rest';
  }

  /** Changes the settings (any of target_ms, min_scale, enabled); throws on a bad value. */
  set({ target_ms, min_scale, enabled } = {}) {
    if (target_ms !== undefined) {
      if (!(Number.isFinite(target_ms) && target_ms > 0 && target_ms <= 10000)) {
        throw new Error(`setQuality: target_ms must be a number of milliseconds, 0–10000, not ${JSON.stringify(target_ms)}`);
      }
      this.target_ms = target_ms;
    }
    if (min_scale !== undefined) {
      if (!(Number.isFinite(min_scale) && min_scale >= 0.25 && min_scale <= 1)) {
        throw new Error(`setQuality: min_scale must be 0.25–1, not ${JSON.stringify(min_scale)}`);
      }
      this.min_scale = min_scale;
    }
    if (enabled !== undefined) this.enabled = !!enabled;
    if (this.enabled === false) { this.level = 0; this.reason = 'off'; }
  }

  /** The deepest level allowed by `min_scale`. */
  maxLevel() {
    let l = 0;
    while (l + 1 < LEVELS.length && LEVELS[l + 1].scale >= this.min_scale - 1e-9) l++;
    return l;
  }

  /** One drawn frame: `now` (ms), the frame's time (ms, submitted to done;
   * undefined when not known yet) and whether the camera moved since the last.
   * Returns true when the level changed. */
  frame(now, frameMs, moving) {
    if (!this.enabled) return false;
    const before = this.level;
    if (moving) this.lastMoveMs = now;
    // At rest: no move for REST_MS, or for two frames' time on a GPU whose
    // frames take longer (its animation frames come that far apart).
    const rest = Math.max(REST_MS, 2 * (this.lastFrameMs || 0));
    if (frameMs !== undefined) this.lastFrameMs = frameMs;
    if (now - this.lastMoveMs >= rest) {
      this.level = 0;
      this.over = this.under = this.skip = 0;
      this.reason = 'at rest';
      return this.level !== before;
    }
    if (frameMs === undefined) return false;
    if (frameMs > this.target_ms * FAR_OVER && this.level < this.maxLevel()) {
      this.level = this.maxLevel();
      this.over = this.under = 0;
      this.reason = `frames of ${frameMs.toFixed(0)} ms, far over the ${this.target_ms} ms target`;
    } else if (this.skip > 0) {
      this.skip--;
    } else {
      if (frameMs > this.target_ms * DOWN_OVER) { this.over++; this.under = 0; }
      else if (frameMs < this.target_ms * UP_UNDER) { this.under++; this.over = 0; }
      else { this.over = this.under = 0; }
      if (this.over >= DOWN_FRAMES && this.level < this.maxLevel()) {
        this.level++;
        this.over = 0;
        this.reason = `frames of ${frameMs.toFixed(0)} ms over the ${this.target_ms} ms target`;
      } else if (this.under >= UP_FRAMES && this.level > 0) {
        this.level--;
        this.under = 0;
        this.reason = `frames of ${frameMs.toFixed(0)} ms well under the ${this.target_ms} ms target`;
      } else if (this.level === this.maxLevel() && this.over > 0) {
        this.reason = `at the lowest level (min_scale ${this.min_scale}) and still over the ${this.target_ms} ms target`;
      }
    }
    if (this.level !== before) this.skip = IN_FLIGHT;
    return this.level !== before;
  }

  /** What the current level draws, given the user's own shadows and LoD quality
   * (`softShadows`: whether the level keeps the light's soft shadows, which
   * the user's own light parts may still leave off). */
  apply(userShadows = 'high', userLod = 1) {
    const l = LEVELS[this.level];
    const shadows = SHADOW_RANK[l.shadows] < SHADOW_RANK[userShadows] ? l.shadows : userShadows;
    return { scale: l.scale, shadows, lod: userLod * l.lod, impostors: l.impostors, softShadows: l.light === 'all' };
  }

  /** For `stats()`: `{enabled, level, scale, impostors, light, target_ms, min_scale, reason}`. */
  report() {
    const l = LEVELS[this.level];
    return { enabled: this.enabled, level: this.level, scale: l.scale, impostors: l.impostors, light: l.light,
      target_ms: this.target_ms, min_scale: this.min_scale, reason: this.reason };
  }
}
