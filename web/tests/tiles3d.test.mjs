// The 3D Tiles export: every GLB that `sylva-bake export-3dtiles`
// writes passes the Khronos glTF validator (npm gltf-validator) with no error,
// its external mesh buffers and textures read through the validator too.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { execFileSync } from 'node:child_process';
import { mkdtempSync, readFileSync, readdirSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join, dirname } from 'node:path';
import validator from 'gltf-validator';
import { root, sylvaBin, sylvaBakeBin, pagePixels } from './helpers.mjs';

test('every exported GLB passes the Khronos glTF validator', async () => {
  const out = join(mkdtempSync(join(tmpdir(), 'sylva-3dtiles-')), 'tileset');
  execFileSync(sylvaBakeBin, ['export-3dtiles', join(root, 'tests', 'fixtures', 'forest-small'), '--out', out],
    { stdio: ['ignore', 'ignore', 'pipe'] });
  const tileset = JSON.parse(readFileSync(join(out, 'tileset.json')));
  assert.equal(tileset.asset.version, '1.1');
  const list = (dir) => readdirSync(join(out, dir)).filter((f) => f.endsWith('.glb')).map((f) => `${dir}/${f}`);
  const trees = list('tiles');
  const ground = list('ground');
  const glbs = [...trees, ...ground];
  // Each of the 16 tiles: far quads, (coarse meshes,) full meshes; each of the
  // 21 terrain tiles a ground GLB; every GLB is some tile's content.
  const contents = [];
  const walk = (node) => {
    if (node.content) contents.push(node.content.uri);
    for (const c of node.children ?? []) walk(c);
  };
  walk(tileset.root);
  assert.deepEqual([...contents].sort(), [...glbs].sort());
  assert.equal(trees.filter((f) => f.endsWith('_far.glb')).length, 16, 'a far tier for each of the 16 tiles');
  assert.ok(trees.length >= 32, `GLBs: ${trees.length}`);
  assert.equal(ground.length, 21, 'a ground GLB for each of the 21 terrain tiles');
  let read = 0;
  for (const f of glbs) {
    const report = await validator.validateBytes(new Uint8Array(readFileSync(join(out, f))), {
      uri: f,
      externalResourceFunction: async (uri) => {
        read += 1;
        return new Uint8Array(readFileSync(join(out, dirname(f), decodeURIComponent(uri))));
      },
    });
    const errors = report.issues.messages.filter((m) => m.severity === 0);
    assert.equal(report.issues.numErrors, 0, `${f}: ${JSON.stringify(errors.slice(0, 5))}`);
    assert.equal(report.issues.numWarnings, 0, `${f}: ${JSON.stringify(report.issues.messages.slice(0, 5))}`);
    // The trees are there: instanced meshes with vertices.
    assert.ok(report.info.totalVertexCount > 0, `${f}: no vertices`);
    const ext = f.startsWith('ground/') ? 'KHR_materials_unlit' : 'EXT_mesh_gpu_instancing';
    assert.ok(report.info.extensionsUsed.includes(ext), `${f}: ${report.info.extensionsUsed}`);
  }
  assert.ok(read >= trees.length * 2, `external buffers and textures were read: ${read}`);
  rmSync(dirname(out), { recursive: true, force: true });
});

/** The ECEF point `up` metres over the trunk of instance `k` of node `n` in a
 * full tile GLB, with the tile's transform (column-major ENU → ECEF). */
function treePoint(glb, transform, n, k, upShare) {
  const jlen = glb.readUInt32LE(12);
  const doc = JSON.parse(glb.subarray(20, 20 + jlen).toString());
  const bin = glb.subarray(20 + jlen + 8);
  const floats = (a, per) => {
    const acc = doc.accessors[a];
    const view = doc.bufferViews[acc.bufferView];
    return [...Array(per).keys()].map((i) => bin.readFloatLE(view.byteOffset + (k * per + i) * 4));
  };
  const node = doc.nodes[n];
  const attrs = node.extensions.EXT_mesh_gpu_instancing.attributes;
  const [x, yUp, z] = floats(attrs.TRANSLATION, 3);
  const scale = floats(attrs.SCALE, 3)[1];
  const height = doc.accessors[doc.meshes[node.mesh].primitives[0].attributes.POSITION].max[1];
  const enu = [x, -z, yUp + height * scale * upShare];
  const m = transform;
  // Its row in the property table (node 0's trees come first): the tree's id.
  const table = doc.extensions.EXT_structural_metadata.propertyTables[0];
  const ids = doc.bufferViews[table.properties.id.values];
  const id = bin.readBigUInt64LE(ids.byteOffset + k * 8).toString();
  return { at: [0, 1, 2].map((r) => m[12 + r] + m[r] * enu[0] + m[4 + r] * enu[1] + m[8 + r] * enu[2]), id, model: node.name };
}

test('CesiumJS loads the exported tileset from sylva serve and draws the trees where they belong', async (t) => {
  const { chromium } = await import('playwright-core');
  const { spawn } = await import('node:child_process');
  const out = join(mkdtempSync(join(tmpdir(), 'sylva-cesium-')), 'tileset');
  execFileSync(sylvaBakeBin, ['export-3dtiles', join(root, 'tests', 'fixtures', 'forest-small'), '--out', out],
    { stdio: ['ignore', 'ignore', 'pipe'] });
  const proc = spawn(sylvaBin, ['serve', out, '--port', '0'], { stdio: ['ignore', 'pipe', 'inherit'] });
  const base = await new Promise((resolve, reject) => {
    proc.on('exit', (code) => reject(new Error(`sylva serve exited with ${code}`)));
    proc.stdout.on('data', (d) => {
      const m = /http:\/\/[0-9.:]+\//.exec(String(d));
      if (m) resolve(m[0]);
    });
  });
  const browser = await chromium.launch({
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
    args: ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--disable-quic', '--no-first-run',
      '--disable-background-networking', '--disable-component-update', '--disable-sync'],
  });
  t.after(async () => {
    await browser.close();
    proc.kill();
    rmSync(dirname(out), { recursive: true, force: true });
  });
  const page = await browser.newPage({ viewport: { width: 640, height: 400 } });
  const errors = [];
  page.on('pageerror', (e) => errors.push(String(e)));
  page.on('console', (m) => { if (m.type() === 'error') errors.push(m.text()); });
  await page.goto(`${base}cesium.html`);
  await page.waitForFunction(() => window.cesiumTilesLoaded !== undefined || window.cesiumError, null,
    { timeout: 180000, polling: 250 });
  assert.equal(await page.evaluate(() => window.cesiumError), undefined);
  const loaded = await page.evaluate(() => window.cesiumTilesLoaded);
  assert.ok(loaded >= 16, `tiles loaded: ${loaded}`);
  assert.deepEqual(errors, []);
  // Foliage on the screen: green-dominant pixels (the globe is beige, the sky blue or black).
  const green = await pagePixels(page, await page.screenshot({ timeout: 180000 }), (d) => {
    let n = 0;
    for (let i = 0; i < d.length; i += 4) if (d[i + 1] > d[i] + 8 && d[i + 1] > d[i + 2] + 8) n += 1;
    return n / (d.length / 4);
  });
  assert.ok(green > 0.05, `foliage covers ${green} of the view`);
  // Trees where they belong: the crowns of trees read back from the GLBs, projected
  // by Cesium, are picked as the tileset's; the sky corner is not.
  const tileset = JSON.parse(readFileSync(join(out, 'tileset.json')));
  const points = [];
  const walk = (node) => {
    if (node.transform && node.content?.uri.startsWith('tiles/')) {
      // The full meshes: the last tier (far quads, coarse meshes, full meshes).
      let leaf = node;
      while (leaf.children?.length) leaf = leaf.children[0];
      const uri = leaf.content.uri;
      const glb = readFileSync(join(out, uri));
      for (let k = 0; k < 8; k++) points.push(treePoint(glb, node.transform, 0, k, 0.6));
    }
    for (const c of node.children ?? []) walk(c);
  };
  walk(tileset.root);
  const picks = await page.evaluate((points) => {
    const { Cesium, viewer, tileset } = window.cesium;
    const ours = (p) => p !== undefined && (p.primitive === tileset || p.content?.tileset === tileset
      || p.tileset === tileset);
    const hits = [];
    const misses = [];
    const same = [];
    for (const { at: [x, y, z], id, model } of points) {
      const p = new Cesium.Cartesian3(x, y, z);
      const w = Cesium.SceneTransforms.worldToWindowCoordinates(viewer.scene, p);
      if (!w || w.x < 2 || w.y < 2 || w.x > viewer.canvas.clientWidth - 2 || w.y > viewer.canvas.clientHeight - 2) continue;
      const picked = viewer.scene.pick(w);
      hits.push(ours(picked));
      // How far the surface drawn at that pixel is from the crown point (a tree in
      // front of it, or a tree drawn elsewhere, is metres away).
      const drawn = viewer.scene.pickPosition(w);
      const miss = drawn ? Cesium.Cartesian3.distance(drawn, p) : Infinity;
      misses.push(miss);
      // Where that tree's own crown is drawn there, the pick is that tree: its id and model.
      if (miss < 0.5 && picked instanceof Cesium.Cesium3DTileFeature) {
        same.push(String(picked.getProperty('id')) === id && picked.getProperty('model') === model);
      }
    }
    const sky = viewer.scene.pick(new Cesium.Cartesian2(3, 3));
    // The ground: picks over the lower half of the view that are the tileset's
    // but no tree (the terrain's GLBs carry no features).
    let ground = 0;
    for (let i = 0; i < 8; i++) {
      for (let j = 0; j < 4; j++) {
        const p = viewer.scene.pick(new Cesium.Cartesian2((i + 0.5) * viewer.canvas.clientWidth / 8,
          (0.5 + (j + 0.5) / 8) * viewer.canvas.clientHeight));
        if (ours(p) && !(p instanceof Cesium.Cesium3DTileFeature)) ground += 1;
      }
    }
    return { hits, misses, same, sky: ours(sky), ground };
  }, points);
  const inView = picks.hits.length;
  const hit = picks.hits.filter(Boolean).length;
  assert.ok(inView >= 64, `trees projected into the view: ${inView} of ${points.length}`);
  assert.ok(hit >= inView * 0.8, `picked as the tileset's: ${hit} of ${inView}`);
  assert.equal(picks.sky, false, 'the corner above the forest is not a tree');
  assert.ok(picks.ground >= 3, `picks of the exported ground among 32 over the lower half: ${picks.ground}`);
  // Trees in front hide some crowns (tens of metres away); most crowns are drawn
  // where they are: a quarter within 3 m (about 1 m here; trees moved 60 m east: 12 m).
  const misses = picks.misses.sort((a, b) => a - b);
  const quartile = misses[Math.floor(misses.length / 4)];
  assert.ok(quartile < 3, `a quarter of the crowns' pixels lie within ${quartile} m of their crown points`);
  // A pick returns the tree's attributes (EXT_instance_features + EXT_structural_metadata).
  const same = picks.same.filter(Boolean).length;
  assert.ok(picks.same.length >= 5 && same >= picks.same.length * 0.8,
    `picks that name the tree drawn there: ${same} of ${picks.same.length}`);
});
