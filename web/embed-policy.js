// Who may embed and drive the viewer page (index.html), and where it may load
// a scene or imagery from when a URL parameter or a message asks: the host's
// decision, in `sylva-embed.json` next to index.html (the framing page cannot
// write it; `sylva serve --allow-embed/--allow-source` answers it):
//
//   {"parents": ["https://portal.example.org"], "sources": ["https://tiles.example.org"]}
//
// parents: origins that may frame the page and talk to it by postMessage
//          (besides the page's own); "*" any. Replies and events go only to
//          the parent's origin, never to '*'.
// sources: origins besides the page's own that `?scene=`, `?imagery=` and the
//          `setImagery` message may load from; "*" any.
// No file (404): the page's own origin only, for both. A file that cannot be
// read or parsed: the same, and the page says why. docs/SECURITY.md, "The viewer
// in a frame"; docs/DEPLOY.md for the frame-ancestors header a static host sets.
// `attachFrameProtocol` is the iframe protocol itself (index.html uses it).

/** The policy file's name, next to the viewer page. */
export const POLICY_FILE = 'sylva-embed.json';

/** An origin as `location.origin` writes it (`scheme://host[:port]`, lower
 * case, default port dropped), or null for anything else (paths, queries,
 * credentials, other schemes). "*" stays "*". */
export function normalizeOrigin(s) {
  if (s === '*') return '*';
  if (typeof s !== 'string' || s.length > 300) return null;
  let u;
  try { u = new URL(s); } catch { return null; }
  if (u.protocol !== 'https:' && u.protocol !== 'http:') return null;
  if (u.username || u.password || u.search || u.hash || (u.pathname !== '/' && u.pathname !== '')) return null;
  // new URL() accepts 'https://a.org/' and 'https://a.org'; reject trailing junk it would drop.
  if (!/^https?:\/\/[^/?#]+\/?$/i.test(s)) return null;
  return u.origin;
}

export class EmbedPolicy {
  /** `own`: the page's origin; `parents`, `sources`: origins (see the file's format). */
  constructor(own, parents = [], sources = []) {
    this.own = own;
    this.parents = parents;
    this.sources = sources;
  }

  /** Parses the policy file's text; throws an Error saying what is wrong. */
  static parse(own, text) {
    let p;
    try { p = JSON.parse(text); } catch (e) { throw new Error(`${POLICY_FILE}: not JSON (${e.message})`); }
    if (!p || typeof p !== 'object' || Array.isArray(p)) throw new Error(`${POLICY_FILE}: expected an object {"parents": [...], "sources": [...]}`);
    const list = (key) => {
      const v = p[key] ?? [];
      if (!Array.isArray(v) || v.length > 1000) throw new Error(`${POLICY_FILE}: "${key}" must be a list of origins`);
      return v.map((o) => {
        const n = normalizeOrigin(o);
        if (n === null) throw new Error(`${POLICY_FILE}: ${JSON.stringify(o).slice(0, 80)} in "${key}" is no origin (expected scheme://host[:port] or "*")`);
        return n;
      });
    };
    for (const k of Object.keys(p)) {
      if (k !== 'parents' && k !== 'sources') throw new Error(`${POLICY_FILE}: unknown key "${k.slice(0, 40)}" (parents, sources)`);
    }
    return new EmbedPolicy(own, list('parents'), list('sources'));
  }

  /** Fetches the policy next to `pageUrl`. Resolves with {policy, error}:
   * without a file the page's own origin only; with a broken one the same and
   * the error to show. */
  static async load(pageUrl, fetchFn = fetch) {
    const own = new URL(pageUrl).origin;
    try {
      const r = await fetchFn(new URL(POLICY_FILE, pageUrl).href, { cache: 'no-cache', credentials: 'same-origin', redirect: 'error' });
      if (r.status === 404) return { policy: new EmbedPolicy(own), error: null };
      if (!r.ok) throw new Error(`${POLICY_FILE}: HTTP ${r.status}`);
      const text = await r.text();
      if (text.length > 65536) throw new Error(`${POLICY_FILE}: over 64 KiB`);
      return { policy: EmbedPolicy.parse(own, text), error: null };
    } catch (e) {
      return { policy: new EmbedPolicy(own), error: `${e.message || e} — embedding and foreign sources are off` };
    }
  }

  /** Whether a page of `origin` may frame this one and talk to it. An opaque
   * origin ("null": a sandboxed frame, a file:// page, a data: URL) never may. */
  mayTalk(origin) {
    if (typeof origin !== 'string' || origin === 'null') return false;
    return origin === this.own || this.parents.includes('*') || this.parents.includes(origin);
  }

  /** Whether the viewer may load `url` (a scene URL or an imagery template,
   * relative to `base`): its origin is the page's own or a listed source.
   * The URL is checked as it will be fetched: only the placeholders the
   * viewer fills in ({z} {x} {y} {-y} {TileMatrix} {TileCol} {TileRow}) are
   * replaced, any other brace is refused, as are credentials and any origin
   * that is not http(s) (data:, javascript:, blob: — opaque: "null"). */
  mayLoad(url, base) {
    // Filled twice with different numbers: a placeholder inside the host or port
    // (`:{z}443`) gives two origins and is refused.
    const origins = [];
    for (const n of ['0', '17']) {
      let u;
      try {
        const filled = String(url).replace(/\{(z|x|y|-y|TileMatrix|TileCol|TileRow)\}/g, n);
        if (/[{}]/.test(filled)) return false;
        u = new URL(filled, base);
      } catch { return false; }
      if ((u.protocol !== 'https:' && u.protocol !== 'http:') || u.username || u.password) return false;
      origins.push(u.origin);
    }
    const origin = origins[0];
    if (origin === 'null' || origins[1] !== origin) return false;
    return origin === this.own || this.sources.includes('*') || this.sources.includes(origin);
  }

  /** The error for a URL that `mayLoad` refuses. */
  refusal(what, url) {
    return `${what} ${String(url).slice(0, 200)} is not from this page's origin or a source listed in ${POLICY_FILE} (the host's "sources")`;
  }
}

/** The framing page's origin as the browser reports it (Chromium and Safari:
 * `location.ancestorOrigins`; otherwise the referrer's), or null. Used only
 * as the target of postMessage, which the browser delivers only when the
 * parent really has that origin. */
export function parentOriginHint(loc, referrer) {
  const a = loc.ancestorOrigins;
  if (a && a.length) return a[0];
  try { return referrer ? new URL(referrer).origin : null; } catch { return null; }
}

/** The events a framing page receives. */
export const FRAME_EVENTS = ['progress', 'stats', 'error', 'camerachange', 'ready', 'click'];

/** The iframe protocol of index.html: the parent drives `viewer` (the JS API)
 * with `{verb, args, id}` messages and receives `{sylva: 'reply' | event, ...}`.
 * Only messages from `win.parent` whose origin the policy allows are heard;
 * replies and events go to that origin alone. `hint` is the parent's origin
 * as the browser reported it ({@link parentOriginHint}) or null: without it,
 * events wait (the last of each kind) for the first allowed message. Verbs
 * that load URLs (setImagery) take only the page's own origin or a listed
 * source. Returns {parentOrigin()} for tests. */
export function attachFrameProtocol(viewer, { policy, hint = null, win = globalThis.window, base = globalThis.location?.href }) {
  let parentOrigin = hint && hint !== 'null' && policy.mayTalk(hint) ? hint : null;
  const waiting = new Map();
  const post = (msg) => {
    const m = { sylva: msg.kind, ...msg };
    if (parentOrigin) win.parent.postMessage(m, parentOrigin);
    else if (msg.kind !== 'reply') waiting.set(msg.kind, m);
  };
  for (const kind of FRAME_EVENTS) viewer.on(kind, (data) => post({ kind, data }));
  const imageryAllowed = (src) => src === null || src === 'scene' || policy.mayLoad(src, base);
  const verbs = {
    setCamera: (c) => viewer.setCamera(c), flyTo: (c, s) => viewer.flyTo(c, s),
    setDebug: (l, b) => viewer.setDebug(l, b), setQuality: (q) => viewer.setQuality(q), setLod: (o) => viewer.setLod(o),
    setBudget: (o) => viewer.setBudget(o), setTerrain: (on, px) => viewer.setTerrain(on, px),
    setCanopy: (on) => viewer.setCanopy(on),
    setImagery: (src, o) => {
      if (!imageryAllowed(src)) throw new Error(policy.refusal('setImagery:', src));
      return viewer.setImagery(src, o);
    },
    setSun: (sun) => viewer.setSun(sun),
    setLighting: (o) => viewer.setLighting(o),
    setSeason: (season) => viewer.setSeason(season),
    setDate: (date) => viewer.setDate(date),
    heightAt: (lon, lat) => viewer.heightAt(lon, lat),
    stats: () => viewer.stats(), camera: () => viewer.camera(), setFly: (on) => viewer.setFly(on),
    query: (filter, o) => viewer.query(filter, o), pick: (x, y) => viewer.pick(x, y),
    setStyle: (style) => viewer.setStyle(style), select: (ids) => viewer.select(ids),
    flyToTree: (id, o) => viewer.flyToTree(id, o), attributes: () => viewer.attributes(),
  };
  let warned = false;
  win.addEventListener('message', (e) => {
    if (e.source !== win.parent) return;
    if (e.origin === 'null' || !policy.mayTalk(e.origin)) {
      if (!warned) console.warn(`sylva: messages from ${e.origin} are ignored: not this page's origin or a parent listed in ${POLICY_FILE}`);
      warned = true;
      return;
    }
    if (!parentOrigin) {
      parentOrigin = e.origin;
      for (const m of waiting.values()) win.parent.postMessage(m, parentOrigin);
      waiting.clear();
    }
    const { verb, args = [], id } = e.data || {};
    if (typeof verb !== 'string' || !Object.hasOwn(verbs, verb) || !Array.isArray(args)) return;
    Promise.resolve().then(() => verbs[verb](...args)).then(
      (data) => post({ kind: 'reply', id, verb, data }),
      (err) => post({ kind: 'reply', id, verb, error: String(err) }));
  });
  return { parentOrigin: () => parentOrigin };
}
