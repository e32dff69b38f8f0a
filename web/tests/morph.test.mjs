// The morph-target GLB export in three.js's GLTFLoader, in headless
// Chromium, against the real `dend serve`:
//
//   DEND_BIN=target/debug/dend node web/tests/morph.test.mjs
//
// Uploads a generated textured skinned tube (skinned_tube.mjs: two
// primitives, a UV seam, a texture, a two-joint skin), poses it with two
// HTTP drags, each followed, once the pose settled, by a named pose
// ("twist", "lean"), and exports it with `as=morph-targets&animation=1`.
// The page (three's ES modules from web/node_modules/three, served by this
// test's own route, never from the network) loads it with GLTFLoader and
// the test checks: each primitive's morph target dictionary holds the two
// names in save order with weights 0; at weight 1 on one target, three's
// own morph code (Mesh.getVertexPosition, the primitive's local space)
// gives that saved pose (`GET …/poses/{name}`, each file vertex mapped to
// its welded server vertex by its rest position: the weld merges only
// bit-identical positions) within 1e-4 of the mesh diagonal, and so does
// the skinned position at the skeleton's rest (the skin still applies on
// top); the texture loaded; the `poses` animation keys weight 1 on each
// target in turn.

import { mkdtempSync, readFileSync, existsSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join, normalize } from 'node:path';
import assert from 'node:assert/strict';
import { root, log, launch, startServer, shutdown, runTest } from './lib.mjs';
import { skinnedTubeGlb } from './skinned_tube.mjs';

const threeDir = join(root, 'web', 'node_modules', 'three');
/** The page's origin: every request to it is answered by `page.route`. */
const origin = 'http://morph.test';
const page = `<!doctype html><meta charset="utf-8"><title>morph targets</title>
<script type="importmap">{"imports": {"three": "/three/build/three.module.js", "three/addons/": "/three/examples/jsm/"}}</script>
<script type="module">
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
window.lib = { THREE, GLTFLoader };
</script>`;

async function api(base, method, path, { token, body, json } = {}) {
  const headers = {};
  if (token) headers.Authorization = `Bearer ${token}`;
  if (json !== undefined) headers['Content-Type'] = 'application/json';
  const r = await fetch(base + path, { method, headers, body: json !== undefined ? JSON.stringify(json) : body });
  return r;
}

async function ok(r, what, status = 200) {
  if (r.status !== status) throw new Error(`${what}: HTTP ${r.status} ${await r.text()}`);
  return r;
}

/** Waits until the session's pose has settled; returns it (JSON). */
async function settled(base, s, what) {
  const end = Date.now() + 60000;
  for (;;) {
    const p = await (await ok(await api(base, 'GET', `/v1/sessions/${s.id}/pose`, { token: s.token }), 'GET pose')).json();
    if (p.settled) return p;
    if (Date.now() > end) throw new Error(`${what}: not settled after 60 s`);
    await new Promise((r) => setTimeout(r, 50));
  }
}

const key = (x, y, z) => `${Math.fround(x)},${Math.fround(y)},${Math.fround(z)}`;

async function main() {
  const dataDir = mkdtempSync(join(tmpdir(), 'dend-morph-test-'));
  const { proc, base } = await startServer(dataDir);
  log('server at', base);
  const browser = await launch();
  try {
    // upload, constraints (bottom two rings fixed, the top ring and cap the handle)
    const input = skinnedTubeGlb();
    const mesh = await (await ok(await api(base, 'POST', '/v1/meshes?format=glb', { body: input }), 'upload', 201)).json();
    const s = await (await ok(await api(base, 'POST', '/v1/sessions', { json: { mesh_id: mesh.id, params: {} } }), 'session', 201)).json();
    // the welded rest positions (before any solve)
    const rest = (await (await ok(await api(base, 'GET', `/v1/sessions/${s.id}/pose`, { token: s.token }), 'rest pose')).json()).positions;
    const n = rest.length;
    log('welded vertices', n);
    await ok(await api(base, 'PUT', `/v1/sessions/${s.id}/constraints`, {
      token: s.token,
      json: {
        fixed: { box: { min: [-9, -9, -0.01], max: [9, 9, 0.3] } },
        handles: [{ name: 'top', vertices: { box: { min: [-9, -9, 2.7], max: [9, 9, 3.1] } } }],
      },
    }), 'constraints', 202);
    const end = Date.now() + 120000;
    for (;;) {
      const info = await (await ok(await api(base, 'GET', `/v1/sessions/${s.id}`, { token: s.token }), 'session info')).json();
      if (info.state === 'ready') break;
      assert.notEqual(info.state, 'failed', 'the factor build failed');
      assert.ok(Date.now() < end, 'session not ready after 120 s');
      await new Promise((r) => setTimeout(r, 50));
    }

    // two drags, each saved as a named pose once settled
    const drags = [
      ['twist', { rotate: { axis: [0, 0, 1], degrees: 60 } }],
      ['lean', { translate: [0.6, 0, -0.2] }],
    ];
    const poses = {};
    for (const [name, delta] of drags) {
      await ok(await api(base, 'POST', `/v1/sessions/${s.id}/drag`, { token: s.token, json: { handle: 'top', max_iters: 40, ...delta } }), `drag ${name}`);
      await settled(base, s, name);
      await ok(await api(base, 'POST', `/v1/sessions/${s.id}/poses`, { token: s.token, json: { name } }), `save ${name}`, 201);
      const got = await (await ok(await api(base, 'GET', `/v1/sessions/${s.id}/poses/${encodeURIComponent(name)}`, { token: s.token }), `GET pose ${name}`)).json();
      assert.equal(got.positions.length, n);
      poses[name] = got.positions;
    }
    const moved = (a, b) => Math.max(...a.map((p, i) => Math.hypot(p[0] - b[i][0], p[1] - b[i][1], p[2] - b[i][2])));
    log('pose distances: twist-rest', moved(poses.twist, rest).toFixed(4), 'lean-twist', moved(poses.lean, poses.twist).toFixed(4));
    assert.ok(moved(poses.twist, rest) > 0.1 && moved(poses.lean, poses.twist) > 0.1, 'the two poses differ from rest and from each other');

    const r = await ok(await api(base, 'GET', `/v1/sessions/${s.id}/export?format=glb&as=morph-targets&animation=1`, { token: s.token }), 'export');
    assert.equal(r.headers.get('content-type'), 'model/gltf-binary');
    const glb = Buffer.from(await r.arrayBuffer());
    log('morph-target GLB', glb.length, 'bytes (input', input.length, ')');

    // three.js in the page, its files from web/node_modules/three
    const ctx = await browser.newContext();
    const pg = await ctx.newPage();
    const pageErrors = [];
    pg.on('pageerror', (e) => pageErrors.push(`page: ${e.message}`));
    pg.on('console', (m) => { if (m.type() === 'error') pageErrors.push(`console: ${m.text()}`); });
    const served = [];
    await pg.route(`${origin}/**`, async (route) => {
      const path = new URL(route.request().url()).pathname;
      if (path === '/') return route.fulfill({ status: 200, contentType: 'text/html', body: page });
      const file = normalize(join(threeDir, path.replace(/^\/three\//, '')));
      if (path.startsWith('/three/') && file.startsWith(threeDir) && existsSync(file)) {
        served.push(path);
        return route.fulfill({ status: 200, contentType: 'text/javascript', body: readFileSync(file) });
      }
      return route.fulfill({ status: 404, body: 'not found' });
    });
    await pg.goto(`${origin}/`);
    await pg.waitForFunction(() => window.lib, null, { timeout: 30000 });
    log('three.js files served by the test:', served.length);

    const out = await pg.evaluate(async (b64) => {
      const { THREE, GLTFLoader } = window.lib;
      const bytes = Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
      const gltf = await new GLTFLoader().parseAsync(bytes.buffer, '');
      gltf.scene.updateMatrixWorld(true);
      const meshes = [];
      gltf.scene.traverse((o) => { if (o.isMesh) meshes.push(o); });
      const v = new THREE.Vector3();
      const prims = meshes.map((m) => {
        const count = m.geometry.attributes.position.count;
        const read = (skinned) => {
          const a = [];
          for (let i = 0; i < count; i++) {
            if (skinned) m.getVertexPosition(i, v); else THREE.Mesh.prototype.getVertexPosition.call(m, i, v);
            a.push([v.x, v.y, v.z]);
          }
          return a;
        };
        const weights = Array.from(m.morphTargetInfluences);
        const rest = Array.from(m.geometry.attributes.position.array);
        const targets = {};
        for (const [name, t] of Object.entries(m.morphTargetDictionary)) {
          m.morphTargetInfluences.fill(0);
          m.morphTargetInfluences[t] = 1;
          targets[name] = { index: t, local: read(false), skinned: read(true) };
        }
        m.morphTargetInfluences.fill(0);
        return {
          skinned: !!m.isSkinnedMesh,
          relative: m.geometry.morphTargetsRelative,
          dictionary: m.morphTargetDictionary,
          weights,
          rest,
          targets,
          texture: m.material.map && m.material.map.image ? [m.material.map.image.width, m.material.map.image.height] : null,
        };
      });
      // the `poses` animation: weight 1 on target k at k + 1 seconds
      const clip = gltf.animations.find((a) => a.name === 'poses');
      const keyed = [];
      if (clip) {
        const mixer = new THREE.AnimationMixer(gltf.scene);
        const action = mixer.clipAction(clip);
        action.setLoop(THREE.LoopOnce, 1);
        action.clampWhenFinished = true; // t = 2 is the last key, not a wrap to 0
        action.play();
        for (const t of [0, 1, 2]) {
          mixer.setTime(t);
          keyed.push(meshes.map((m) => Array.from(m.morphTargetInfluences)));
        }
      }
      return { prims, animations: gltf.animations.map((a) => a.name), keyed };
    }, glb.toString('base64'));
    assert.deepEqual(pageErrors, [], 'no page errors');

    // file vertex -> welded server vertex, by rest position
    const welded = new Map(rest.map((p, i) => [key(...p), i]));
    assert.equal(welded.size, n, 'welded rest positions are distinct');
    let lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    for (const p of rest) for (let k = 0; k < 3; k++) { lo[k] = Math.min(lo[k], p[k]); hi[k] = Math.max(hi[k], p[k]); }
    const diag = Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
    assert.equal(out.prims.length, 2, 'the tube and its cap: two primitives');
    const names = drags.map(([name]) => name);
    const used = new Set();
    const worst = { local: 0, skinned: 0 };
    for (const [pi, p] of out.prims.entries()) {
      assert.ok(p.skinned, `primitive ${pi} is a SkinnedMesh`);
      assert.deepEqual(p.dictionary, Object.fromEntries(names.map((nm, i) => [nm, i])), `primitive ${pi}: morph target dictionary`);
      assert.deepEqual(p.weights, [0, 0], `primitive ${pi}: default weights`);
      assert.deepEqual(p.texture, [2, 2], `primitive ${pi}: the base-colour texture loaded`);
      const map = [];
      for (let i = 0; i < p.rest.length / 3; i++) {
        const w = welded.get(key(p.rest[3 * i], p.rest[3 * i + 1], p.rest[3 * i + 2]));
        assert.notEqual(w, undefined, `primitive ${pi} vertex ${i}: its rest position ${p.rest.slice(3 * i, 3 * i + 3)} is a server vertex (${JSON.stringify(rest.filter((q) => Math.hypot(q[0] - p.rest[3 * i], q[1] - p.rest[3 * i + 1], q[2] - p.rest[3 * i + 2]) < 1e-3))})`);
        map.push(w);
        used.add(w);
      }
      for (const name of names) {
        const t = p.targets[name];
        for (const [i, w] of map.entries()) {
          const want = poses[name][w];
          for (const kind of ['local', 'skinned']) {
            const got = t[kind][i];
            worst[kind] = Math.max(worst[kind], Math.hypot(got[0] - want[0], got[1] - want[1], got[2] - want[2]));
          }
        }
      }
    }
    assert.equal(used.size, n, 'every server vertex is in the file');
    log(`weight 1 vs the saved pose (diagonal ${diag.toFixed(4)}): local ${worst.local.toExponential(3)}, skinned at rest ${worst.skinned.toExponential(3)}`);
    assert.ok(worst.local <= 1e-4 * diag, `morph at weight 1 is the saved pose: ${worst.local}`);
    assert.ok(worst.skinned <= 1e-4 * diag, `skinned at rest, morph at weight 1 is the saved pose: ${worst.skinned}`);
    assert.ok(out.animations.includes('poses'), `animations: ${out.animations}`);
    assert.deepEqual(out.keyed, [[[0, 0], [0, 0]], [[1, 0], [1, 0]], [[0, 1], [0, 1]]], 'the poses animation keys each target in turn');
    log('morph test: OK');
    await ctx.close();
  } finally {
    await shutdown(browser, proc, dataDir);
  }
}

runTest(main);
