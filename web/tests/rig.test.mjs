// The editor's skeleton outliner and the skeleton exports in three.js's
// GLTFLoader, in headless Chromium, against the real `dend serve`:
//
//   DEND_BIN=target/debug/dend node web/tests/rig.test.mjs
//
// Uploads a rigged limb (skinned_limb.mjs: a chain bone0 → bone1 → bone2 →
// end) through the editor's upload control; the Skeleton section lists the
// joints as a tree. With "pin it" and without children a click on bone0
// fixes its region; with "grab it" and children a click on bone2 makes
// bone2's and end's regions a handle named bone2 that turns about bone2's
// head (the server's constraint set holds that pivot), and the gizmo sits
// there. A drag of the gizmo's z ring (the head stays) and one of its x
// arrow (the head follows), each saved as a named pose from the Named
// poses section; a second page joining by the share link shows the
// handle's gizmo at the same place. "Export animation" downloads as=skeleton-animation and
// shows the fit's residual; "Export skeleton" downloads as=skeleton. The
// Mesh menu's generated limb opens with its default edit shown as joints.
// The
// Khronos validator finds no error in either. A page with three.js
// (from web/node_modules/three, served by this test's own route) loads
// both with GLTFLoader: the skeleton file, skinned by three with its
// corrective at weight 1 (its default), is the session's solved pose, and
// the animation sampled at each keyframe (three's AnimationMixer, skinning
// and morph code: SkinnedMesh.getVertexPosition) is each named pose, both
// within 1e-4 of the mesh diagonal (each file vertex mapped to its welded
// server vertex by its rest position).

import { mkdtempSync, readFileSync, existsSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join, normalize } from 'node:path';
import assert from 'node:assert/strict';
import validator from 'gltf-validator';
import { root, artifacts, log, launch, startServer, waitFor, presetsMissing, shutdown, runTest } from './lib.mjs';
import { skinnedLimbGlb } from './skinned_limb.mjs';

const threeDir = join(root, 'web', 'node_modules', 'three');
/** The three.js page's origin: every request to it is answered by `page.route`. */
const origin = 'http://rig.test';
const threePage = `<!doctype html><meta charset="utf-8"><title>skeleton export</title>
<script type="importmap">{"imports": {"three": "/three/build/three.module.js", "three/addons/": "/three/examples/jsm/"}}</script>
<script type="module">
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
window.lib = { THREE, GLTFLoader };
</script>`;

const key = (x, y, z) => `${Math.fround(x)},${Math.fround(y)},${Math.fround(z)}`;

async function get(base, s, path) {
  const r = await fetch(`${base}/v1/sessions/${s.id}${path}`, { headers: { Authorization: `Bearer ${s.token}` } });
  assert.equal(r.status, 200, `GET ${path}: ${r.status}`);
  return r.json();
}

async function settled(page, what) {
  const seq = await page.evaluate(() => window.dend.app.seq);
  await waitFor(page, (q) => window.dend.app.last && window.dend.app.last.ackSeq >= q && window.dend.app.last.settled, seq, what, 90000);
}

async function savePose(page, name) {
  await page.fill('#poseName', name);
  await page.click('#poseSave');
  await waitFor(page, (n) => [...document.querySelectorAll('#poseList li')].some((li) => li.textContent.startsWith(`${n} `)), name, `the pose ${name} listed`);
}

async function download(page, button) {
  const [dl] = await Promise.all([page.waitForEvent('download'), page.click(button)]);
  return { name: dl.suggestedFilename(), bytes: readFileSync(await dl.path()) };
}

const dist = (a, b) => Math.hypot(a[0] - b[0], a[1] - b[1], a[2] - b[2]);

async function main() {
  const dataDir = mkdtempSync(join(tmpdir(), 'dend-rig-test-'));
  const { proc, base } = await startServer(dataDir);
  log('server at', base);
  const browser = await launch();
  try {
    const ctx = await browser.newContext({ viewport: { width: 1280, height: 900 }, acceptDownloads: true });
    const page = await ctx.newPage();
    const errors = [];
    page.on('pageerror', (e) => errors.push(`page: ${e.message}`));
    page.on('console', (m) => { if (m.type() === 'error' && !presetsMissing(m)) errors.push(`console: ${m.text()}`); });
    await page.goto(base + '/');
    await waitFor(page, () => window.dend && window.dend.app.opened && window.dend.app.state === 'ready', null, 'the creature', 120000);

    // the limb, through the upload control
    const before = await page.evaluate(() => window.dend.app.session.id);
    await page.setInputFiles('#upload', { name: 'limb.glb', mimeType: 'model/gltf-binary', buffer: skinnedLimbGlb() });
    await waitFor(page, (b) => window.dend.app.session.id !== b && window.dend.app.ws && window.dend.app.meshInfo
      && !document.getElementById('secRig').hidden, before, 'the limb opened with its skeleton', 90000);
    const session = await page.evaluate(() => window.dend.app.session);
    const info = await (await fetch(`${base}/v1/meshes/${session.meshId}`)).json();
    const joints = info.asset.skeleton.joints;
    assert.deepEqual(joints.map((j) => j.name), ['bone0', 'bone1', 'bone2', 'end']);
    const rest = (await get(base, session, '/pose')).positions;
    const n = rest.length;
    const lo = [0, 1, 2].map((k) => Math.min(...rest.map((p) => p[k])));
    const hi = [0, 1, 2].map((k) => Math.max(...rest.map((p) => p[k])));
    const diag = dist(lo, hi);
    log(`limb: ${n} welded vertices, diagonal ${diag.toFixed(4)}; regions`, joints.map((j) => `${j.name} ${j.region.length}`).join(', '));
    assert.equal(joints.reduce((s, j) => s + j.region.length, 0), n, 'the regions cover every vertex once');

    // the outliner: one root, each joint nested under its parent
    const tree = await page.evaluate(() => ({
      roots: [...document.querySelectorAll('#rigTree > li')].map((li) => li.querySelector('button').textContent),
      nested: [1, 2, 3].map((k) => document.getElementById(`joint-${k - 1}`).parentElement.querySelector(':scope > ul').contains(document.getElementById(`joint-${k}`))),
      names: [...document.querySelectorAll('#rigTree button.joint')].map((b) => b.textContent),
    }));
    assert.deepEqual(tree.roots, ['bone0'], 'bone0 is the only root');
    assert.deepEqual(tree.nested, [true, true, true], 'each joint under its parent');
    assert.deepEqual(tree.names, ['bone0', 'bone1', 'bone2', 'end']);

    // pin bone0 (its own region)
    await page.check('input[name=rigAction][value=pin]');
    await page.uncheck('#rigChildren');
    await page.click('#joint-0');
    const pinned = new Set(joints[0].region);
    await waitFor(page, (r) => {
      const l = window.dend.labels();
      return l.every((x, i) => (x === -1) === r.includes(i));
    }, joints[0].region, 'bone0 pinned');
    // grab bone2 with its children: a handle turning about bone2's head
    await page.check('input[name=rigAction][value=handle]');
    await page.check('#rigChildren');
    await page.click('#joint-2');
    const grabbed = [...joints[2].region, ...joints[3].region];
    await waitFor(page, (g) => {
      const l = window.dend.labels();
      return g.every((i) => l[i] === 1) && l.filter((x) => x === 1).length === g.length;
    }, grabbed, 'bone2 and end a handle');
    await waitFor(page, () => window.dend.app.state === 'ready', null, 'constraints ready', 90000);
    assert.ok(grabbed.every((i) => !pinned.has(i)));
    const states = await page.evaluate(() => [0, 1, 2, 3].map((k) => document.getElementById(`joint-${k}`).nextSibling.textContent.trim()));
    // end has no vertex of its own: nothing to show
    assert.deepEqual(states, ['pinned', '', 'handle 0', ''], 'the outliner shows what each joint is');
    const cons = (await get(base, session, '')).constraints;
    assert.equal(cons.handles.length, 1);
    assert.equal(cons.handles[0].name, 'bone2', 'the handle is named after the joint');
    const head = joints[2].head;
    assert.ok(dist(cons.handles[0].pivot, head) < 1e-9, `its pivot is bone2's head (${cons.handles[0].pivot})`);
    assert.deepEqual([...cons.fixed].sort((a, b) => a - b), [...pinned].sort((a, b) => a - b), 'bone0 is the fixed set');

    // the gizmo at the joint's head, seen obliquely
    await page.evaluate(() => { const c = window.dend.app.camera; c.yaw = 0.5; c.pitch = 0.3; window.dend.app.needsDraw = true; });
    await page.waitForTimeout(150);
    const g0 = await page.evaluate(() => window.dend.gizmo());
    assert.ok(g0 && dist(g0.world, head) < 1e-6, `the gizmo sits at bone2's head (${g0 && g0.world})`);
    assert.ok(!g0.edgeOn[2], 'the z ring is not edge-on');
    assert.equal((await page.locator('#gizmoInfo').textContent()).trim(), 'handle 0');
    await page.screenshot({ path: join(artifacts, 'rig-1-grabbed.png') });

    // drag the z ring 45° (ring points 6 → 12): the limb bends at bone2's head
    const cb = await page.locator('#view').boundingBox();
    const ring = g0.rings[2];
    await page.mouse.move(cb.x + ring[6][0], cb.y + ring[6][1]);
    await page.mouse.down();
    for (const q of ring.slice(7, 13)) await page.mouse.move(cb.x + q[0], cb.y + q[1], { steps: 3 });
    await page.mouse.up();
    await settled(page, 'the ring drag');
    const g1 = await page.evaluate(() => window.dend.gizmo());
    log('after the ring drag the gizmo is', dist(g1.world, head).toExponential(2), 'from the rest head');
    assert.ok(dist(g1.world, head) < 1e-4 * diag, 'a turn about the head keeps the gizmo there');
    await savePose(page, 'bend');
    // drag the x arrow 30 px: the head (and the gizmo) follow the handle
    const [cx, cy] = g1.center;
    const [tx, ty] = g1.tips[0];
    const len = Math.hypot(tx - cx, ty - cy);
    const [ux, uy] = [(tx - cx) / len, (ty - cy) / len];
    const [sx, sy] = [cx + 0.6 * (tx - cx), cy + 0.6 * (ty - cy)];
    await page.mouse.move(cb.x + sx, cb.y + sy);
    await page.mouse.down();
    await page.mouse.move(cb.x + sx + 30 * ux, cb.y + sy + 30 * uy, { steps: 8 });
    await page.mouse.up();
    await settled(page, 'the arrow drag');
    const g2 = await page.evaluate(() => window.dend.gizmo());
    const shift = (30 / len) * g1.length;
    log(`after the x arrow drag the gizmo moved ${(g2.world[0] - g1.world[0]).toFixed(4)} along x (the drag: ${shift.toFixed(4)})`);
    assert.ok(Math.abs(g2.world[0] - g1.world[0] - shift) < 0.05 * shift, 'the gizmo follows the head');
    assert.ok(Math.abs(g2.world[1] - g1.world[1]) < 1e-3 * diag && Math.abs(g2.world[2] - g1.world[2]) < 1e-3 * diag, 'along x only');
    await savePose(page, 'reach');
    await page.screenshot({ path: join(artifacts, 'rig-2-posed.png') });
    // a collaborator joining the posed session by its link: the handle is
    // bone2's again, and its gizmo at bone2's head in the pose (carried
    // from the rest the server gives, export?pose=rest)
    const peer = await ctx.newPage();
    peer.on('pageerror', (e) => errors.push(`peer page: ${e.message}`));
    await peer.goto(`${base}/#session=${session.id}&token=${session.token}`);
    await waitFor(peer, () => window.dend && window.dend.app.opened && window.dend.app.state === 'ready' && window.dend.gizmo() !== null,
      null, 'the joined session', 90000);
    const joined = await peer.evaluate(() => ({ joints: [...window.dend.app.handleJoints], gizmo: window.dend.gizmo().world }));
    log('the peer\'s gizmo is', dist(joined.gizmo, g2.world).toExponential(2), 'from the first page\'s');
    assert.deepEqual(joined.joints, [[0, 2]], 'the joined page knows handle 0 is bone2');
    assert.ok(dist(joined.gizmo, g2.world) < 1e-4 * diag, `the joined page's gizmo is at bone2's head too (${joined.gizmo} vs ${g2.world})`);
    await peer.close();
    const poses = {};
    for (const name of ['bend', 'reach']) poses[name] = (await get(base, session, `/poses/${name}`)).positions;
    const current = await get(base, session, '/pose');
    assert.ok(current.settled);
    const moved = (a, b) => Math.max(...a.map((p, i) => dist(p, b[i])));
    assert.ok(moved(poses.bend, rest) > 0.2 && moved(poses.reach, poses.bend) > 0.05, 'the poses differ from rest and from each other');

    // the exports, and the residual shown
    const anim = await download(page, '#rigExportAnim');
    const fit = await page.evaluate(() => window.dend.app.rigFit);
    const shown = await page.locator('#rigResidual').textContent();
    log('animation:', anim.name, anim.bytes.length, 'bytes; shown:', shown);
    assert.equal(fit.poses, 2);
    assert.ok(fit.max >= fit.mean && fit.mean > 0 && fit.max < 0.05, `a plausible fit residual (${JSON.stringify(fit)})`);
    assert.ok(shown.includes(fit.max.toExponential(2)) && shown.includes(fit.mean.toExponential(2)) && shown.includes('over 2 poses'), shown);
    const skel = await download(page, '#rigExport');
    const fit1 = await page.evaluate(() => window.dend.app.rigFit);
    log('skeleton:', skel.name, skel.bytes.length, 'bytes; residual', JSON.stringify(fit1));
    assert.equal(fit1.poses, 1);
    for (const [what, file] of [['skeleton', skel], ['skeleton-animation', anim]]) {
      const report = await validator.validateBytes(new Uint8Array(file.bytes));
      const { numErrors, numWarnings } = report.issues;
      log(`glTF validator on the ${what} export: ${numErrors} errors, ${numWarnings} warnings`);
      assert.equal(numErrors, 0, JSON.stringify(report.issues.messages.filter((m) => m.severity === 0)));
    }
    // the generated limb of the Mesh menu: the same rig, with its default
    // edit (bone0 fixed, bone2 a handle about its head) shown as joints
    const last = await page.evaluate(() => window.dend.app.session.id);
    await page.selectOption('#shape', 'limb');
    await page.click('#generate');
    await waitFor(page, (b) => window.dend.app.session.id !== b && window.dend.app.ws && window.dend.app.state === 'ready'
      && window.dend.gizmo() !== null, last, 'the generated limb', 90000);
    const gen = await page.evaluate(() => ({
      joints: [...window.dend.app.handleJoints],
      gizmo: window.dend.gizmo().world,
      tree: [...document.querySelectorAll('#rigTree button.joint')].map((b) => b.textContent),
      states: [0, 1, 2].map((k) => document.getElementById(`joint-${k}`).nextSibling.textContent.trim()),
    }));
    assert.deepEqual(gen.tree, ['bone0', 'bone1', 'bone2', 'end']);
    assert.deepEqual(gen.joints, [[0, 2]], 'its handle is bone2');
    assert.deepEqual(gen.states, ['pinned', '', 'handle 0']);
    assert.ok(dist(gen.gizmo, [0, 2, 0]) < 1e-6, `its gizmo at bone2's head (${gen.gizmo})`);
    assert.deepEqual(errors, [], 'no page errors');

    // three.js: the files as a game would load them
    const pg = await ctx.newPage();
    const pageErrors = [];
    pg.on('pageerror', (e) => pageErrors.push(`page: ${e.message}`));
    pg.on('console', (m) => { if (m.type() === 'error') pageErrors.push(`console: ${m.text()}`); });
    await pg.route(`${origin}/**`, async (route) => {
      const path = new URL(route.request().url()).pathname;
      if (path === '/') return route.fulfill({ status: 200, contentType: 'text/html', body: threePage });
      const file = normalize(join(threeDir, path.replace(/^\/three\//, '')));
      if (path.startsWith('/three/') && file.startsWith(threeDir) && existsSync(file)) {
        return route.fulfill({ status: 200, contentType: 'text/javascript', body: readFileSync(file) });
      }
      return route.fulfill({ status: 404, body: 'not found' });
    });
    await pg.goto(`${origin}/`);
    await pg.waitForFunction(() => window.lib, null, { timeout: 30000 });
    const out = await pg.evaluate(async ([skelB64, animB64]) => {
      const { THREE, GLTFLoader } = window.lib;
      const load = async (b64) => {
        const bytes = Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
        const gltf = await new GLTFLoader().parseAsync(bytes.buffer, '');
        gltf.scene.updateMatrixWorld(true);
        let mesh = null;
        gltf.scene.traverse((o) => { if (o.isSkinnedMesh) mesh = o; });
        return { gltf, mesh };
      };
      const v = new THREE.Vector3();
      /** Per file vertex: [rest, skinned and morphed world position]. */
      const read = (scene, m) => {
        scene.updateMatrixWorld(true);
        const out = [];
        for (let i = 0; i < m.geometry.attributes.position.count; i++) {
          m.getVertexPosition(i, v).applyMatrix4(m.matrixWorld);
          const a = m.geometry.attributes.position;
          out.push([[a.getX(i), a.getY(i), a.getZ(i)], [v.x, v.y, v.z]]);
        }
        return out;
      };
      const s = await load(skelB64);
      const skeleton = {
        skinned: !!s.mesh,
        influences: Array.from(s.mesh.morphTargetInfluences),
        dictionary: s.mesh.morphTargetDictionary,
        vertices: read(s.gltf.scene, s.mesh),
      };
      const a = await load(animB64);
      const clip = a.gltf.animations.find((c) => c.name === 'poses');
      const times = clip ? Array.from(clip.tracks[0].times) : [];
      const keys = [];
      if (clip) {
        const mixer = new THREE.AnimationMixer(a.gltf.scene);
        const action = mixer.clipAction(clip);
        action.setLoop(THREE.LoopOnce, 1);
        action.clampWhenFinished = true; // the last key is held, not wrapped to the first
        action.play();
        for (const t of times) {
          mixer.setTime(t);
          keys.push({ t, influences: Array.from(a.mesh.morphTargetInfluences), vertices: read(a.gltf.scene, a.mesh) });
        }
      }
      return { skeleton, animation: { names: a.gltf.animations.map((c) => c.name), dictionary: a.mesh.morphTargetDictionary, times, keys } };
    }, [skel.bytes.toString('base64'), anim.bytes.toString('base64')]);
    assert.deepEqual(pageErrors, [], 'no three.js page errors');

    const welded = new Map(rest.map((p, i) => [key(...p), i]));
    assert.equal(welded.size, n, 'welded rest positions are distinct');
    /** The largest distance from three's positions to the server's pose. */
    const worstOf = (vertices, pose) => {
      const used = new Set();
      let worst = 0;
      for (const [r, p] of vertices) {
        const w = welded.get(key(...r));
        assert.notEqual(w, undefined, `file vertex at ${r} is a server vertex`);
        used.add(w);
        worst = Math.max(worst, dist(p, pose[w]));
      }
      assert.equal(used.size, n, 'every server vertex is in the file');
      return worst;
    };
    assert.ok(out.skeleton.skinned, 'a SkinnedMesh');
    assert.deepEqual(out.skeleton.influences, [1], 'the corrective at weight 1 by default');
    const skelErr = worstOf(out.skeleton.vertices, current.positions) / diag;
    log(`three.js: the as=skeleton export with its corrective vs the solved pose: ${skelErr.toExponential(3)} of the diagonal`);
    assert.ok(skelErr < 1e-4, `as=skeleton in three.js is the solved pose (${skelErr} of the diagonal)`);
    assert.ok(out.animation.names.includes('poses'), `animations: ${out.animation.names}`);
    assert.deepEqual(out.animation.dictionary, { bend: 0, reach: 1 }, 'one corrective per named pose, in save order');
    assert.deepEqual(out.animation.times, [0, 1], 'one keyframe per named pose');
    const animErr = {};
    for (const [k, name] of ['bend', 'reach'].entries()) {
      const kf = out.animation.keys[k];
      assert.deepEqual(kf.influences, k === 0 ? [1, 0] : [0, 1], `keyframe ${k} plays ${name}'s corrective alone`);
      animErr[name] = worstOf(kf.vertices, poses[name]) / diag;
      assert.ok(animErr[name] < 1e-4, `keyframe ${k} in three.js is the pose ${name} (${animErr[name]} of the diagonal)`);
    }
    log('three.js: as=skeleton-animation at each keyframe vs the named pose:',
      Object.entries(animErr).map(([nm, e]) => `${nm} ${e.toExponential(3)}`).join(', '), 'of the diagonal');
    log('rig test: OK');
    await ctx.close();
  } finally {
    await shutdown(browser, proc, dataDir);
  }
}

runTest(main);
