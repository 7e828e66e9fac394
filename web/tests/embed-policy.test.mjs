// The viewer page's embedding policy (web/embed-policy.js), without a browser:
// what the host's sylva-embed.json may say, and what the page then allows.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { EmbedPolicy, normalizeOrigin, parentOriginHint, attachFrameProtocol } from '../embed-policy.js';

const OWN = 'https://viewer.example.org';
const PAGE = `${OWN}/forest/index.html?ui=0`;

test('origins are written as browsers write them; anything else is no origin', () => {
  assert.equal(normalizeOrigin('https://Portal.Example.org'), 'https://portal.example.org');
  assert.equal(normalizeOrigin('https://portal.example.org/'), 'https://portal.example.org');
  assert.equal(normalizeOrigin('https://portal.example.org:443'), 'https://portal.example.org');
  assert.equal(normalizeOrigin('http://127.0.0.1:8080'), 'http://127.0.0.1:8080');
  assert.equal(normalizeOrigin('*'), '*');
  for (const bad of ['portal.example.org', 'https://portal.example.org/app', 'ftp://a.org', 'javascript:alert(1)',
    'https://u:p@a.org', 'https://a.org?x', 'https://a.org#x', 'null', '', 42, null, 'x'.repeat(400)]) {
    assert.equal(normalizeOrigin(bad), null, String(bad));
  }
});

test('the policy file: parents and sources, and a clear error for anything else', () => {
  const p = EmbedPolicy.parse(OWN, '{"parents": ["https://portal.example.org/"], "sources": ["https://tiles.example.org"]}');
  assert.deepEqual(p.parents, ['https://portal.example.org']);
  assert.deepEqual(p.sources, ['https://tiles.example.org']);
  for (const [text, says] of [
    ['not json', /not JSON/],
    ['[]', /expected an object/],
    ['{"parents": "https://a.org"}', /must be a list/],
    ['{"parents": ["https://a.org/path"]}', /is no origin/],
    ['{"sources": [7]}', /is no origin/],
    ['{"parent": []}', /unknown key "parent"/],
  ]) {
    assert.throws(() => EmbedPolicy.parse(OWN, text), says, text);
  }
});

test('who may talk to the viewer and what it may load', () => {
  const none = new EmbedPolicy(OWN);
  assert.ok(none.mayTalk(OWN));
  assert.ok(!none.mayTalk('https://evil.example.com'));
  assert.ok(!none.mayTalk('null'));
  assert.ok(none.mayLoad('scene/scene.json', PAGE));
  assert.ok(none.mayLoad('/other/scene.json', PAGE));
  assert.ok(!none.mayLoad('https://evil.example.com/scene.json', PAGE));
  assert.ok(!none.mayLoad('//evil.example.com/scene.json', PAGE), 'a scheme-relative URL is another origin');
  assert.ok(!none.mayLoad('https://evil.example.com/{z}/{x}/{y}.png', PAGE));
  assert.ok(!none.mayLoad('https://{s}.evil.example.com/{z}/{x}/{y}.png', PAGE), 'placeholders in the host');
  assert.ok(!none.mayLoad('javascript:alert(1)', PAGE));
  const listed = EmbedPolicy.parse(OWN, '{"parents": ["https://portal.example.org"], "sources": ["https://tiles.example.org"]}');
  assert.ok(listed.mayTalk('https://portal.example.org'));
  assert.ok(!listed.mayTalk('https://portal.example.org.evil.com'));
  assert.ok(listed.mayLoad('https://tiles.example.org/{z}/{x}/{y}.png', PAGE));
  assert.ok(listed.mayLoad('https://tiles.example.org/wmts/{TileMatrix}/{TileRow}/{TileCol}.jpg', PAGE));
  // Checked as it is fetched: an unknown placeholder that hides another host, credentials,
  // opaque origins (a file:// page's "null" matches no data: or javascript: URL).
  assert.ok(!listed.mayLoad('https://{@evil.example/}@tiles.example.org/{z}/{x}/{y}.png', PAGE));
  assert.ok(!listed.mayLoad('https://user:pw@tiles.example.org/{z}/{x}/{y}.png', PAGE));
  assert.ok(!listed.mayLoad('https://tiles.example.org:{z}443/{x}/{y}.png', PAGE), 'a placeholder in the port');
  const fileOwn = new EmbedPolicy('null');
  assert.ok(!fileOwn.mayLoad('data:text/plain,hello', 'file:///viewer/index.html'));
  assert.ok(!fileOwn.mayLoad('javascript:alert(1)', 'file:///viewer/index.html'));
  assert.ok(!fileOwn.mayTalk('null'), 'an opaque origin never talks, even to an opaque page');
  assert.ok(!listed.mayLoad('https://tiles.example.org.evil.com/{z}/{x}/{y}.png', PAGE));
  assert.match(listed.refusal('?scene=', 'https://x.org/s.json'), /sylva-embed\.json/);
  const open = EmbedPolicy.parse(OWN, '{"parents": ["*"], "sources": ["*"]}');
  assert.ok(open.mayTalk('https://anyone.example.net') && open.mayLoad('https://anywhere.example.net/s.json', PAGE));
});

test('the policy is fetched next to the page; none is the own origin only, a broken one says why', async () => {
  const answer = (status, body) => async (url, init) => {
    assert.equal(url, `${OWN}/forest/sylva-embed.json`);
    assert.equal(init.redirect, 'error');
    return { status, ok: status >= 200 && status < 300, text: async () => body };
  };
  let r = await EmbedPolicy.load(PAGE, answer(404, ''));
  assert.equal(r.error, null);
  assert.deepEqual([r.policy.own, r.policy.parents, r.policy.sources], [OWN, [], []]);
  r = await EmbedPolicy.load(PAGE, answer(200, '{"parents": ["https://portal.example.org"]}'));
  assert.equal(r.error, null);
  assert.ok(r.policy.mayTalk('https://portal.example.org'));
  for (const [status, body, says] of [[500, '', /HTTP 500/], [200, '{', /not JSON/], [200, ' '.repeat(70000), /64 KiB/]]) {
    r = await EmbedPolicy.load(PAGE, answer(status, body));
    assert.match(r.error, says);
    assert.match(r.error, /embedding and foreign sources are off/);
    assert.ok(!r.policy.mayTalk('https://portal.example.org'));
  }
  r = await EmbedPolicy.load(PAGE, async () => { throw new TypeError('Failed to fetch'); });
  assert.match(r.error, /Failed to fetch/);
});

test('the framing page\'s origin as the browser reports it', () => {
  assert.equal(parentOriginHint({ ancestorOrigins: ['https://portal.example.org'] }, 'https://other.org/x'), 'https://portal.example.org');
  assert.equal(parentOriginHint({}, 'https://portal.example.org/page?q=1'), 'https://portal.example.org');
  assert.equal(parentOriginHint({ ancestorOrigins: [] }, ''), null);
  assert.equal(parentOriginHint({}, 'not a url'), null);
});

/** A viewer, a window and its parent, as the protocol sees them. */
function frame(policy, hint) {
  const handlers = {}, calls = [], posted = [];
  const viewer = {
    on: (kind, fn) => { handlers[kind] = fn; },
    camera: () => { calls.push('camera'); return { x: 1 }; },
    setCamera: (c) => { calls.push(['setCamera', c]); },
    setImagery: (src) => { calls.push(['setImagery', src]); },
    query: async () => { calls.push('query'); return { count: 2 }; },
  };
  const parent = { postMessage: (m, origin) => posted.push([m, origin]) };
  let listener;
  const win = { parent, addEventListener: (type, fn) => { assert.equal(type, 'message'); listener = fn; } };
  const channel = attachFrameProtocol(viewer, { policy, hint, win, base: PAGE });
  const send = async (origin, data, source = parent) => {
    listener({ source, origin, data });
    await new Promise((r) => setTimeout(r, 0));
  };
  return { handlers, calls, posted, send, channel };
}

test('the iframe protocol hears only an allowed parent and answers only to it', async () => {
  const PORTAL = 'https://portal.example.org';
  const policy = EmbedPolicy.parse(OWN, `{"parents": ["${PORTAL}"], "sources": ["https://tiles.example.org"]}`);
  // The browser named no parent: events wait; an unlisted origin is neither heard nor told anything.
  const f = frame(policy, null);
  f.handlers.ready({ ok: 1 });
  f.handlers.progress({ p: 1 });
  f.handlers.progress({ p: 2 });
  assert.deepEqual(f.posted, [], 'nothing sent before the parent is known');
  await f.send('https://evil.example.com', { verb: 'camera', id: 1 });
  await f.send('https://evil.example.com', { verb: 'setCamera', args: [{ x: 9 }], id: 2 });
  await f.send('null', { verb: 'camera', id: 3 });
  assert.deepEqual([f.calls, f.posted], [[], []], 'an unlisted or opaque origin is ignored');
  // Another window of the listed origin that is not the parent: ignored too.
  await f.send(PORTAL, { verb: 'camera', id: 4 }, { postMessage() {} });
  assert.deepEqual(f.calls, []);
  // The listed parent: the waiting events (the last of each kind), then the reply, all to its origin only.
  await f.send(PORTAL, { verb: 'camera', id: 5 });
  assert.deepEqual(f.calls, ['camera']);
  assert.deepEqual(f.posted.map(([m, o]) => [m.sylva, m.data, o]), [
    ['ready', { ok: 1 }, PORTAL], ['progress', { p: 2 }, PORTAL], ['reply', { x: 1 }, PORTAL]]);
  assert.equal(f.channel.parentOrigin(), PORTAL);
  // A promise settles into a reply; unknown verbs, prototype names and bad args are dropped.
  await f.send(PORTAL, { verb: 'query', args: [{}], id: 6 });
  await new Promise((r) => setTimeout(r, 0));
  assert.deepEqual(f.posted.at(-1)[0], { sylva: 'reply', kind: 'reply', id: 6, verb: 'query', data: { count: 2 } });
  const before = f.posted.length;
  for (const verb of ['constructor', 'toString', '__proto__', 'eval', 42]) await f.send(PORTAL, { verb, id: 7 });
  await f.send(PORTAL, { verb: 'setCamera', args: 'not a list', id: 8 });
  assert.equal(f.posted.length, before);
  // Imagery from a listed source or the page's own origin; anything else answered with an error.
  await f.send(PORTAL, { verb: 'setImagery', args: ['https://tiles.example.org/{z}/{x}/{y}.png'], id: 9 });
  await f.send(PORTAL, { verb: 'setImagery', args: ['https://evil.example.com/{z}/{x}/{y}.png'], id: 10 });
  await f.send(PORTAL, { verb: 'setImagery', args: [null], id: 11 });
  await new Promise((r) => setTimeout(r, 0));
  const replies = Object.fromEntries(f.posted.filter(([m]) => m.id >= 9).map(([m]) => [m.id, m]));
  assert.ok(!replies[9].error && !replies[11].error, JSON.stringify(replies));
  assert.match(replies[10].error, /sylva-embed\.json/);
  assert.deepEqual(f.calls.filter((c) => c[0] === 'setImagery').map((c) => c[1]), ['https://tiles.example.org/{z}/{x}/{y}.png', null]);
  // Named by the browser and allowed: events go out at once, to that origin.
  const g = frame(policy, PORTAL);
  g.handlers.ready({});
  assert.deepEqual(g.posted.map(([m, o]) => [m.sylva, o]), [['ready', PORTAL]]);
  // Named but not allowed (index.html refuses to start then): still nothing is sent.
  const h = frame(new EmbedPolicy(OWN), 'https://evil.example.com');
  h.handlers.ready({});
  assert.deepEqual(h.posted, []);
});
