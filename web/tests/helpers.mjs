// Helpers shared by the browser tests: Chromium's WebGPU flags, a local XYZ
// tile server, `sylva serve` started on a folder.
import { spawn } from 'node:child_process';
import { createServer } from 'node:http';
import { deflateSync } from 'node:zlib';
import { existsSync, readFileSync, statSync } from 'node:fs';
import { join, dirname, normalize, extname } from 'node:path';
import { fileURLToPath } from 'node:url';

export const root = join(dirname(fileURLToPath(import.meta.url)), '..', '..');
/** A binary of the workspace: `$env` if set, else the debug build (`make test`
 * builds it with the Rust tests: no separate release build for the browser
 * tests), else the release build. */
function workspaceBin(name, env) {
  if (process.env[env]) return process.env[env];
  const built = ['debug', 'release'].map((p) => join(root, 'target', p, name));
  return built.find((f) => existsSync(f)) || built[0];
}
export const sylvaBin = workspaceBin('sylva', 'SYLVA_BIN');
export const sylvaBakeBin = workspaceBin('sylva-bake', 'SYLVA_BAKE_BIN');
export const WEBGPU_FLAGS = ['--no-sandbox', '--enable-unsafe-webgpu', '--enable-features=Vulkan', '--use-vulkan=swiftshader',
  '--use-webgpu-adapter=swiftshader', '--use-angle=swiftshader', '--disable-quic', '--no-first-run',
  '--disable-background-networking', '--disable-component-update', '--disable-sync'];

/** A PNG of w×h RGB pixels from `rgb(x, y)` (node's zlib; no dependency). */
export function png(w, h, rgb) {
  const crcTable = Array.from({ length: 256 }, (_, n) => {
    let c = n;
    for (let k = 0; k < 8; k++) c = c & 1 ? 0xedb88320 ^ (c >>> 1) : c >>> 1;
    return c >>> 0;
  });
  const crc = (buf) => {
    let c = 0xffffffff;
    for (const b of buf) c = crcTable[(c ^ b) & 0xff] ^ (c >>> 8);
    return (c ^ 0xffffffff) >>> 0;
  };
  const chunk = (type, data) => {
    const head = Buffer.alloc(8);
    head.writeUInt32BE(data.length, 0);
    head.write(type, 4, 'ascii');
    const tail = Buffer.alloc(4);
    tail.writeUInt32BE(crc(Buffer.concat([head.subarray(4), data])), 0);
    return Buffer.concat([head, data, tail]);
  };
  const ihdr = Buffer.alloc(13);
  ihdr.writeUInt32BE(w, 0);
  ihdr.writeUInt32BE(h, 4);
  ihdr.set([8, 2, 0, 0, 0], 8); // 8-bit RGB
  const raw = Buffer.alloc((w * 3 + 1) * h);
  for (let y = 0; y < h; y++) {
    for (let x = 0; x < w; x++) raw.set(rgb(x, y), y * (w * 3 + 1) + 1 + x * 3);
  }
  return Buffer.concat([Buffer.from([0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a]), chunk('IHDR', ihdr),
    chunk('IDAT', deflateSync(raw)), chunk('IEND', Buffer.alloc(0))]);
}

/** A local XYZ tile server (never the internet): /{z}/{x}/{y}.png is magenta
 * where x + y is even and cyan where odd; anything else 404. CORS open, as
 * public tile servers are. Resolves with {url, requests(), close()}. */
export function tileServer() {
  let requests = 0;
  const tiles = [png(256, 256, () => [210, 40, 210]), png(256, 256, () => [40, 200, 210])];
  const srv = createServer((req, res) => {
    const m = /^\/(\d+)\/(\d+)\/(\d+)\.png$/.exec(req.url);
    if (!m) { res.writeHead(404, { 'Access-Control-Allow-Origin': '*' }); res.end(); return; }
    requests++;
    res.writeHead(200, { 'Content-Type': 'image/png', 'Access-Control-Allow-Origin': '*' });
    res.end(tiles[(Number(m[2]) + Number(m[3])) % 2]);
  });
  return new Promise((resolve) => srv.listen(0, '127.0.0.1', () => resolve({
    url: `http://127.0.0.1:${srv.address().port}/{z}/{x}/{y}.png`, requests: () => requests, close: () => srv.close(),
  })));
}

/** Starts `sylva serve DIR --port 0 ...flags` and resolves with its base URL. */
export function startServer(dir, flags = []) {
  const proc = spawn(sylvaBin, ['serve', dir, '--port', '0', ...flags], { stdio: ['ignore', 'pipe', 'inherit'] });
  const url = new Promise((resolve, reject) => {
    proc.on('error', reject);
    proc.on('exit', (code) => reject(new Error(`sylva serve exited with ${code}`)));
    proc.stdout.on('data', (d) => {
      const m = /http:\/\/[0-9.:]+\//.exec(String(d));
      if (m) resolve(m[0]);
    });
  });
  return { proc, url };
}

/** Decodes `png` (a screenshot's bytes) in the page and returns
 * `reduce(d, width, height, arg)` run there, `d` the RGBA bytes: `reduce` is a
 * function (its source goes to the page; it sees only its arguments). */
export function pagePixels(page, png, reduce, arg = null) {
  return page.evaluate(async ({ b64, src, arg }) => {
    const img = await createImageBitmap(await (await fetch(`data:image/png;base64,${b64}`)).blob());
    const c = new OffscreenCanvas(img.width, img.height).getContext('2d');
    c.drawImage(img, 0, 0);
    const d = c.getImageData(0, 0, img.width, img.height).data;
    // eslint-disable-next-line no-new-func
    return new Function(`return (${src})`)()(d, img.width, img.height, arg);
  }, { b64: Buffer.from(png).toString('base64'), src: reduce.toString(), arg });
}

/** A page on another origin: any path answers `html` (an empty page by
 * default). Resolves with {origin, close()}. */
export function pageServer(html = '<!doctype html><title>another site</title><body></body>') {
  const requests = [];
  const srv = createServer((req, res) => {
    requests.push(req.url);
    res.writeHead(200, { 'Content-Type': 'text/html; charset=utf-8' });
    res.end(html);
  });
  // (Another port on 127.0.0.1 is another origin; `requests`: the paths asked for.)
  return new Promise((resolve) => srv.listen(0, '127.0.0.1', () => resolve({
    origin: `http://127.0.0.1:${srv.address().port}`, requests, close: () => srv.close(),
  })));
}

/** A static host that sends no Content-Security-Policy (as a plain bucket or
 * file server does): web/ at / and `sceneDir` at /scene/. Resolves with
 * {url, close()}. */
export function staticHost(sceneDir) {
  const types = { '.html': 'text/html', '.js': 'text/javascript', '.wasm': 'application/wasm', '.json': 'application/json' };
  const webDir = join(root, 'web');
  const srv = createServer((req, res) => {
    const path = normalize(decodeURIComponent(new URL(req.url, 'http://x').pathname));
    const [base, rest] = path.startsWith('/scene/') ? [sceneDir, path.slice(7)] : [webDir, path.slice(1) || 'index.html'];
    const file = join(base, rest);
    if (path.includes('..') || !existsSync(file) || !statSync(file).isFile()) { res.writeHead(404); res.end(); return; }
    res.writeHead(200, { 'Content-Type': types[extname(file)] || 'application/octet-stream' });
    res.end(readFileSync(file));
  });
  return new Promise((resolve) => srv.listen(0, '127.0.0.1', () => resolve({
    url: `http://127.0.0.1:${srv.address().port}/`, close: () => srv.close(),
  })));
}
