// The 3D Tiles export (issue 21): every GLB that `sylva-bake export-3dtiles`
// writes passes the Khronos glTF validator (npm gltf-validator) with no error,
// its external mesh buffers and textures read through the validator too.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { execFileSync } from 'node:child_process';
import { mkdtempSync, readFileSync, readdirSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join, dirname } from 'node:path';
import { fileURLToPath } from 'node:url';
import validator from 'gltf-validator';

const root = join(dirname(fileURLToPath(import.meta.url)), '..', '..');
const bake = process.env.SYLVA_BAKE_BIN || join(root, 'target', 'release', 'sylva-bake');

test('every exported GLB passes the Khronos glTF validator', async () => {
  const out = join(mkdtempSync(join(tmpdir(), 'sylva-3dtiles-')), 'tileset');
  execFileSync(bake, ['export-3dtiles', join(root, 'tests', 'fixtures', 'forest-small'), '--out', out],
    { stdio: ['ignore', 'ignore', 'pipe'] });
  const tileset = JSON.parse(readFileSync(join(out, 'tileset.json')));
  assert.equal(tileset.asset.version, '1.1');
  const glbs = readdirSync(join(out, 'tiles')).filter((f) => f.endsWith('.glb'));
  assert.equal(glbs.length, 32, 'a coarse and a full GLB for each of the 16 tiles');
  let read = 0;
  for (const f of glbs) {
    const report = await validator.validateBytes(new Uint8Array(readFileSync(join(out, 'tiles', f))), {
      uri: f,
      externalResourceFunction: async (uri) => {
        read += 1;
        return new Uint8Array(readFileSync(join(out, 'tiles', decodeURIComponent(uri))));
      },
    });
    const errors = report.issues.messages.filter((m) => m.severity === 0);
    assert.equal(report.issues.numErrors, 0, `${f}: ${JSON.stringify(errors.slice(0, 5))}`);
    assert.equal(report.issues.numWarnings, 0, `${f}: ${JSON.stringify(report.issues.messages.slice(0, 5))}`);
    // The trees are there: instanced meshes with vertices.
    assert.ok(report.info.totalVertexCount > 0, `${f}: no vertices`);
    assert.ok(report.info.extensionsUsed.includes('EXT_mesh_gpu_instancing'));
  }
  assert.ok(read >= glbs.length * 2, `external buffers and textures were read: ${read}`);
  rmSync(dirname(out), { recursive: true, force: true });
});
