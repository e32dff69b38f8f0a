// Browser test of the editor's posing tools against the real `dend serve`
// (headless Chromium, as browser.test.mjs):
//
//   DEND_BIN=target/debug/dend node web/tests/tools.test.mjs
//
// Occlusion-aware brush on a torus seen edge-on (the far tube's inner side
// faces the camera but is hidden: not painted; "through" paints it);
// lasso on the bar against an expectation computed here from projected
// positions and face orientation; a stray fixed vertex shown as marked
// faces (the renderer's per-face labels and the pixels); the handle gizmo
// (numeric +0.1 along z and its Undo, an arrow drag along y only, a ring
// drag turning the handle about z); touch orbit, pinch-zoom and two-finger
// pan with CDP touch events. Screenshots go to web/test-artifacts/.

import { mkdtempSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import assert from 'node:assert/strict';
import { artifacts, log, launch, startServer, waitFor, waitForPose, serverPose, screenBox, boxSelect, pngStats, presetsMissing, shutdown, runTest } from './lib.mjs';

const dataDir = mkdtempSync(join(tmpdir(), 'dend-web-tools-'));

/** Sets the orbit camera (yaw, pitch) and waits for a frame. */
async function view(page, yaw, pitch) {
  await page.evaluate(([y, p]) => {
    const c = window.dend.app.camera;
    c.yaw = y;
    c.pitch = p;
    window.dend.app.needsDraw = true;
  }, [yaw, pitch]);
  await page.waitForTimeout(100);
}

async function generate(page, shape) {
  const before = await page.evaluate(() => window.dend.app.session && window.dend.app.session.id);
  await page.selectOption('#shape', shape);
  await page.click('#generate');
  await waitFor(page, (b) => window.dend.app.session && window.dend.app.session.id !== b && window.dend.app.ws,
    before, `the ${shape}`);
  await page.uncheck('#autoApply');
  return Float32Array.from(await page.evaluate(() => window.dend.positions()));
}

const labelled = (labels, l) => labels.flatMap((x, i) => (x === l ? [i] : []));

/** Even-odd point in polygon, written here independently of the client. */
function inside(poly, x, y) {
  let c = false;
  for (let i = 0; i < poly.length; i++) {
    const [x0, y0] = poly[i];
    const [x1, y1] = poly[(i + 1) % poly.length];
    if ((y0 > y) !== (y1 > y) && x < x0 + ((y - y0) * (x1 - x0)) / (y1 - y0)) c = !c;
  }
  return c;
}

/** Distance from (x, y) to the polygon's boundary. */
function edgeDistance(poly, x, y) {
  let d = Infinity;
  for (let i = 0; i < poly.length; i++) {
    const [ax, ay] = poly[i];
    const [bx, by] = poly[(i + 1) % poly.length];
    const [ux, uy] = [bx - ax, by - ay];
    const t = Math.max(0, Math.min(1, ((x - ax) * ux + (y - ay) * uy) / (ux * ux + uy * uy)));
    d = Math.min(d, Math.hypot(x - ax - t * ux, y - ay - t * uy));
  }
  return d;
}

async function occlusionBrush(page) {
  // The torus lies in the xy plane; seen from +x edge-on, the line of
  // sight through the screen centre crosses the near tube (x > 0) and then
  // the far tube, whose inner side (x ≈ -0.6) faces the camera: a normals
  // test would paint it, the depth test must not.
  const p = await generate(page, 'torus');
  const n = p.length / 3;
  await view(page, Math.PI / 2, 0);
  const cb = await page.locator('#view').boundingBox();
  const [ox, oy] = await page.evaluate(() => {
    const c = document.getElementById('view');
    return [c.clientWidth / 2, c.clientHeight / 2];
  });
  await page.check('input[name=tool][value=brush]');
  await page.selectOption('#target', 'fixed');
  await page.evaluate(() => { document.getElementById('brushRadius').value = '40'; });
  await page.mouse.click(cb.x + ox, cb.y + oy);
  const painted = labelled(await page.evaluate(() => window.dend.labels()), -1);
  // front-facing (vertex normal towards the eye) but on the far tube
  const eye = await page.evaluate(() => window.dend.app.camera.eye());
  const normals = await page.evaluate(() => Array.from(window.dend.app.normals));
  const screen = await page.evaluate((k) => window.dend.project([...Array(k).keys()]), n);
  const under = [...Array(n).keys()].filter((i) => Math.hypot(screen[i][0] - ox, screen[i][1] - oy) < 38);
  const facing = (i) => [0, 1, 2].reduce((s, k) => s + normals[3 * i + k] * (eye[k] - p[3 * i + k]), 0) > 0;
  const hiddenFacing = under.filter((i) => p[3 * i] < 0 && facing(i));
  const nearOuter = under.filter((i) => p[3 * i] > 1.3);
  log('torus brush: painted', painted.length, 'of', under.length, 'under the brush;', hiddenFacing.length, 'facing the eye behind the near tube');
  assert.ok(hiddenFacing.length > 0, 'the test sees front-facing vertices behind the near tube');
  assert.ok(nearOuter.length > 0 && nearOuter.every((i) => painted.includes(i)), 'the visible near side is painted');
  const behind = painted.filter((i) => p[3 * i] < 0);
  assert.deepEqual(behind, [], 'no vertex of the far tube (hidden) is painted');
  await page.screenshot({ path: join(artifacts, 't1-torus-brush.png') });

  // "through" paints what is under the brush on every side
  await page.click('#clearSel');
  await page.check('#throughSel');
  await page.mouse.click(cb.x + ox, cb.y + oy);
  const through = labelled(await page.evaluate(() => window.dend.labels()), -1);
  assert.ok(hiddenFacing.every((i) => through.includes(i)), '"through" paints the hidden far tube too');
  await page.uncheck('#throughSel');
  await page.click('#clearSel');
}

async function lassoSelect(page) {
  const p = await generate(page, 'bar');
  const n = p.length / 3;
  await view(page, Math.PI / 2, 0.3);
  const cb = await page.locator('#view').boundingBox();
  const screen = await page.evaluate((k) => window.dend.project([...Array(k).keys()]), n);
  const tris = await page.evaluate(() => Array.from(window.dend.app.mesh.triangles));
  const eye = await page.evaluate(() => window.dend.app.camera.eye());
  // a pentagon over the middle third of the bar, reaching past its edges
  const zmax = Math.max(...Array.from({ length: n }, (_, i) => p[3 * i + 2]));
  const midIdx = [...Array(n).keys()].filter((i) => Math.abs(p[3 * i + 2] - zmax / 2) < zmax / 6);
  const xs = midIdx.map((i) => screen[i][0]), ys = midIdx.map((i) => screen[i][1]);
  const [x0, x1, y0, y1] = [Math.min(...xs), Math.max(...xs), Math.min(...ys) - 20, Math.max(...ys) + 20];
  const cx = (x0 + x1) / 2;
  const poly = [[x0, y0], [x1, y0 + 10], [x1 - 15, y1], [cx, y1 - 25], [x0 + 10, y1]].map(([x, y]) => [Math.round(x), Math.round(y)]);
  // visibility of the convex bar from its faces: a vertex all of whose
  // triangles face the eye is visible, one with all facing away is hidden
  const front = new Array(n).fill(0), back = new Array(n).fill(0);
  for (let t = 0; t < tris.length; t += 3) {
    const [a, b, c] = [tris[t], tris[t + 1], tris[t + 2]].map((i) => [p[3 * i], p[3 * i + 1], p[3 * i + 2]]);
    const u = [0, 1, 2].map((k) => b[k] - a[k]), v = [0, 1, 2].map((k) => c[k] - a[k]);
    const nrm = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
    const s = [0, 1, 2].reduce((acc, k) => acc + nrm[k] * (eye[k] - a[k]), 0) / Math.hypot(...nrm);
    for (const i of [tris[t], tris[t + 1], tris[t + 2]]) {
      if (s > 1e-3) front[i]++;
      else if (s < -1e-3) back[i]++;
    }
  }
  const clear = (i) => edgeDistance(poly, screen[i][0], screen[i][1]) > 1.5;
  const inPoly = [...Array(n).keys()].filter((i) => clear(i) && inside(poly, screen[i][0], screen[i][1]));
  const outPoly = [...Array(n).keys()].filter((i) => clear(i) && !inside(poly, screen[i][0], screen[i][1]));
  const mustSee = inPoly.filter((i) => back[i] === 0);
  const mustNot = [...outPoly, ...inPoly.filter((i) => front[i] === 0)];

  await page.check('input[name=tool][value=lasso]');
  await page.selectOption('#target', 'fixed');
  const draw = async (alt) => {
    if (alt) await page.keyboard.down('Alt');
    await page.mouse.move(cb.x + poly[0][0], cb.y + poly[0][1]);
    await page.mouse.down();
    for (const q of [...poly.slice(1), poly[0]]) await page.mouse.move(cb.x + q[0], cb.y + q[1], { steps: 8 });
    await page.mouse.up();
    if (alt) await page.keyboard.up('Alt');
  };
  await draw(false);
  const sel = labelled(await page.evaluate(() => window.dend.labels()), -1);
  log('lasso: selected', sel.length, '— must see', mustSee.length, ', must not see', inPoly.length - mustSee.length, 'hidden inside +', outPoly.length, 'outside');
  assert.ok(mustSee.length > 10 && inPoly.some((i) => front[i] === 0), 'the lasso covers visible and hidden vertices');
  assert.deepEqual(mustSee.filter((i) => !sel.includes(i)), [], 'every visible vertex inside the lasso is selected');
  assert.deepEqual(mustNot.filter((i) => sel.includes(i)), [], 'no hidden vertex, none outside the lasso');
  await page.screenshot({ path: join(artifacts, 't2-lasso.png') });
  // Alt+lasso removes what it encloses
  await draw(true);
  assert.deepEqual(labelled(await page.evaluate(() => window.dend.labels()), -1), [], 'Alt+lasso erases');
  // "through": exactly the vertices inside, hidden or not
  await page.check('#throughSel');
  await draw(false);
  const all = labelled(await page.evaluate(() => window.dend.labels()), -1);
  assert.deepEqual(inPoly.filter((i) => !all.includes(i)), [], '"through" lasso selects every vertex inside');
  assert.deepEqual(outPoly.filter((i) => all.includes(i)), [], 'and none outside');
  await page.uncheck('#throughSel');
  await page.click('#clearSel');
}

async function strayVertex(page) {
  // The bar (from lassoSelect), side view; one vertex in the middle of the
  // +x side painted fixed with the smallest brush: the faces around it
  // have mixed labels and are drawn hatched.
  const p = Float32Array.from(await page.evaluate(() => window.dend.positions()));
  const n = p.length / 3;
  const tris = await page.evaluate(() => Array.from(window.dend.app.mesh.triangles));
  const ys = Array.from({ length: n }, (_, i) => p[3 * i + 1]);
  const ymid = (Math.min(...ys) + Math.max(...ys)) / 2;
  const v = [...Array(n).keys()].filter((i) => Math.abs(p[3 * i + 2] - 3) < 0.2 && Math.abs(p[3 * i + 1] - ymid) < 0.2)
    .sort((a, b) => p[3 * b] - p[3 * a])[0];
  const [sx, sy] = (await page.evaluate((i) => window.dend.project([i]), v))[0];
  const cb = await page.locator('#view').boundingBox();
  const clip = { x: cb.x + sx - 30, y: cb.y + sy - 30, width: 60, height: 60 };
  await page.waitForTimeout(100);
  const before = await page.screenshot({ clip });
  assert.ok((await page.evaluate(() => window.dend.faceLabels())).every((l) => l === 0), 'nothing painted: every face free');
  await page.check('input[name=tool][value=brush]');
  await page.selectOption('#target', 'fixed');
  await page.evaluate(() => { document.getElementById('brushRadius').value = '4'; });
  await page.mouse.click(cb.x + sx, cb.y + sy);
  const labels = await page.evaluate(() => window.dend.labels());
  assert.deepEqual(labelled(labels, -1), [v], 'the small brush painted the one vertex');
  const faces = await page.evaluate(() => window.dend.faceLabels());
  const around = [];
  for (let f = 0; f < tris.length / 3; f++) if ([0, 1, 2].some((k) => tris[3 * f + k] === v)) around.push(f);
  const mixed = faces.flatMap((l, f) => (l === -2 ? [f] : []));
  log('stray vertex', v, ':', mixed.length, 'hatched faces of', around.length, 'around it');
  assert.deepEqual(mixed, around, 'exactly the faces around the stray vertex are marked');
  await page.waitForTimeout(100);
  const after = await page.screenshot({ clip, path: join(artifacts, 't3-stray-vertex.png') });
  const [d0, d1] = [(await pngStats(page, before)).dark, (await pngStats(page, after)).dark];
  log('dark (hatch) pixels around it:', d0, 'before,', d1, 'after');
  assert.ok(d1 > d0 + 40, `the hatch is drawn around the stray vertex (${d0} → ${d1} dark pixels)`);
  await page.click('#clearSel');
  assert.ok((await page.evaluate(() => window.dend.faceLabels())).every((l) => l === 0), 'cleared: no face marked');
}

/** Centroid of vertices `idx` in pose `p`. */
const centroidOf = (p, idx) => [0, 1, 2].map((k) => idx.reduce((a, i) => a + p[3 * i + k], 0) / idx.length);

/** Waits until the server acknowledged every drag sent and settled. */
async function settled(page, what) {
  const seq = await page.evaluate(() => window.dend.app.seq);
  await waitFor(page, (q) => window.dend.app.last && window.dend.app.last.ackSeq >= q && window.dend.app.last.settled, seq, what, 60000);
}

async function gizmo(page, base) {
  // The bar: fixed end and handle 0 at the far end, painted and applied.
  const p = Float32Array.from(await page.evaluate(() => window.dend.positions()));
  const n = p.length / 3;
  const fixedIdx = [...Array(n).keys()].filter((i) => p[3 * i + 2] < 0.5);
  const far = [...Array(n).keys()].filter((i) => p[3 * i + 2] > 5.5);
  await page.check('input[name=tool][value=box]');
  await page.check('#throughSel');
  await page.selectOption('#target', 'fixed');
  await boxSelect(page, await screenBox(page, fixedIdx, 6));
  // the bar has no handle yet: "+ handle" makes handle 0, the paint target
  await page.click('#addHandle');
  assert.equal(await page.inputValue('#target'), 'h0');
  await boxSelect(page, await screenBox(page, far, 6));
  await page.uncheck('#throughSel');
  const handle = labelled(await page.evaluate(() => window.dend.labels()), 1);
  assert.ok(far.every((i) => handle.includes(i)) && handle.length < n / 4, 'handle 0 painted at the far end');
  await page.click('#apply');
  await waitFor(page, () => window.dend.app.state === 'ready', null, 'constraints ready', 60000);
  // the server reported the factor build's stages and the page showed them
  const { events } = await page.evaluate(() => window.dend.stats());
  // this apply's build: the events since it set the state to building (the
  // first open's creature had a build of its own)
  const since = events.lastIndexOf('setState:building');
  const stages = events.slice(since).filter((e) => e.startsWith('build_progress:')).map((e) => e.slice(15));
  log('factor build stages:', stages.join(' → '), '; progress lines:', (await page.evaluate(() => window.dend.app.progressLog)).join(' | '));
  assert.deepEqual(stages, ['assembly', 'symbolic', 'numeric'], 'the build stages arrive in order');
  assert.ok((await page.evaluate(() => window.dend.app.progressLog)).includes('factor: numeric factorisation…'), 'the progress line showed them');
  assert.ok(await page.locator('#stProgress').isHidden(), 'and is gone once ready');
  await page.check('input[name=tool][value=navigate]');
  // an oblique view: every arrow and ring shows
  await view(page, 1.0, 0.5);
  const session = await page.evaluate(() => window.dend.app.session);
  // handle 0 is the paint target: the gizmo shows at its centroid
  await waitFor(page, () => window.dend.gizmo() !== null, null, 'the gizmo');
  assert.equal((await page.locator('#gizmoInfo').textContent()).trim(), 'handle 0');
  await page.screenshot({ path: join(artifacts, 't4-gizmo.png') });

  // Numeric entry: +0.1 along z, one drag, one undo step.
  const before = await serverPose(base, session);
  await page.fill('#numDz', '0.1');
  await page.click('#numApply');
  await page.fill('#numDz', '0');
  await settled(page, 'the numeric move');
  await waitFor(page, () => !document.getElementById('undo').disabled, null, 'Undo enabled');
  const moved = await serverPose(base, session);
  const [c0, c1] = [centroidOf(before, handle), centroidOf(moved, handle)];
  const d = [0, 1, 2].map((k) => c1[k] - c0[k]);
  log('numeric dz 0.1: handle centroid moved by', d.map((x) => x.toFixed(5)).join(', '));
  assert.ok(Math.abs(d[2] - 0.1) < 1e-3 && Math.abs(d[0]) < 1e-3 && Math.abs(d[1]) < 1e-3, `the centroid moved 0.1 along z (${d})`);
  await page.click('#undo');
  await waitForPose(page, before, 'Undo of the numeric move');
  const undone = await serverPose(base, session);
  const back = centroidOf(undone, handle);
  assert.ok(Math.max(...[0, 1, 2].map((k) => Math.abs(back[k] - c0[k]))) < 1e-5, 'one Undo returns the handle');

  // Drag the y arrow (up on screen) by 40 px along its direction.
  const geo = await page.evaluate(() => window.dend.gizmo());
  const cb = await page.locator('#view').boundingBox();
  const [cx, cy] = geo.center;
  const [tx, ty] = geo.tips[1];
  const len = Math.hypot(tx - cx, ty - cy);
  const [ux, uy] = [(tx - cx) / len, (ty - cy) / len];
  const [sx, sy] = [cx + 0.6 * (tx - cx), cy + 0.6 * (ty - cy)];
  await page.mouse.move(cb.x + sx, cb.y + sy);
  await page.mouse.down();
  await page.mouse.move(cb.x + sx + 40 * ux, cb.y + sy + 40 * uy, { steps: 8 });
  await page.mouse.up();
  await settled(page, 'the gizmo drag');
  const dragged = await serverPose(base, session);
  const c2 = centroidOf(dragged, handle);
  const e = [0, 1, 2].map((k) => c2[k] - back[k]);
  const expect = (40 / len) * geo.length;
  log('y arrow dragged 40 px: centroid moved by', e.map((x) => x.toFixed(5)).join(', '), `(expected y ${expect.toFixed(4)})`);
  assert.ok(Math.abs(e[1] - expect) < 0.05 * expect, `the handle moved along y by the arrow's scale (${e[1]} vs ${expect})`);
  assert.ok(Math.abs(e[0]) < 1e-4 && Math.abs(e[2]) < 1e-4, `and not along x or z (${e})`);

  // Drag the z ring a quarter turn around the centre: the handle turns
  // about z through its centroid (the centroid stays).
  const g2 = await page.evaluate(() => window.dend.gizmo());
  const ring = g2.rings[2];
  // from 45° to 135° (the arrows lie on the ring at 0° and 90°)
  const r0 = ring[6];
  await page.mouse.move(cb.x + r0[0], cb.y + r0[1]);
  await page.mouse.down();
  for (const q of ring.slice(7, 19)) await page.mouse.move(cb.x + q[0], cb.y + q[1], { steps: 2 });
  await page.mouse.up();
  await settled(page, 'the ring drag');
  const turned = await serverPose(base, session);
  const c3 = centroidOf(turned, handle);
  const ang = (pp, i, c) => Math.atan2(pp[3 * i + 1] - c[1], pp[3 * i] - c[0]);
  const spread = handle.filter((i) => Math.hypot(dragged[3 * i] - c2[0], dragged[3 * i + 1] - c2[1]) > 0.2);
  const turns = spread.map((i) => (((ang(turned, i, c3) - ang(dragged, i, c2)) * 180) / Math.PI + 540) % 360 - 180);
  const mean = turns.reduce((a, b) => a + b, 0) / turns.length;
  log('z ring dragged a quarter: handle turned', mean.toFixed(2), '° about z; centroid moved', Math.hypot(...[0, 1, 2].map((k) => c3[k] - c2[k])).toExponential(2));
  assert.ok(Math.abs(Math.abs(mean) - 90) < 3, `the ring turns the handle a quarter about z (${mean}°)`);
  assert.ok(Math.hypot(...[0, 1, 2].map((k) => c3[k] - c2[k])) < 1e-3, 'about its centroid');
  await page.screenshot({ path: join(artifacts, 't5-gizmo-dragged.png') });
  return session;
}

/** Touch on a phone-sized page (CDP touch events, which Chromium turns
 * into touch pointer events): one finger orbits, two pan and pinch-zoom. */
async function touch(browser, base, session) {
  const ctx = await browser.newContext({ viewport: { width: 390, height: 844 }, hasTouch: true, isMobile: true });
  const page = await ctx.newPage();
  const errors = [];
  page.on('pageerror', (e) => errors.push(e.message));
  await page.goto(`${base}/#session=${session.id}&token=${session.token}`);
  await waitFor(page, () => window.dend.app.positions && window.dend.app.state === 'ready', null, 'the touch page');
  const cdp = await ctx.newCDPSession(page);
  const cb = await page.locator('#view').boundingBox();
  const cam = () => page.evaluate(() => {
    const c = window.dend.app.camera;
    return { yaw: c.yaw, pitch: c.pitch, distance: c.distance, target: [...c.target] };
  });
  const t = (type, pts) => cdp.send('Input.dispatchTouchEvent', { type, touchPoints: pts.map(([x, y], id) => ({ x: cb.x + x, y: cb.y + y, id })) });
  // one finger from an empty corner of the view: orbit
  const c0 = await cam();
  const [x0, y0] = [20, 20];
  await t('touchStart', [[x0, y0]]);
  for (let k = 1; k <= 6; k++) await t('touchMove', [[x0 + 10 * k, y0 + 5 * k]]);
  await t('touchEnd', []);
  const c1 = await cam();
  log('one-finger drag: yaw', c0.yaw.toFixed(3), '→', c1.yaw.toFixed(3), 'pitch', c0.pitch.toFixed(3), '→', c1.pitch.toFixed(3));
  assert.ok(Math.abs(c1.yaw - c0.yaw) > 0.2 && Math.abs(c1.pitch - c0.pitch) > 0.1, 'one finger orbits');
  assert.equal(c1.distance, c0.distance, 'without zooming');
  // two fingers apart: pinch-zoom in
  const [mx, my] = [cb.width / 2, cb.height / 2];
  await t('touchStart', [[mx - 40, my]]);
  await t('touchStart', [[mx - 40, my], [mx + 40, my]]);
  for (let k = 1; k <= 6; k++) await t('touchMove', [[mx - 40 - 10 * k, my], [mx + 40 + 10 * k, my]]);
  await t('touchEnd', [[mx - 100, my]]);
  await t('touchEnd', []);
  const c2 = await cam();
  log('pinch 80 → 200 px: distance', c1.distance.toFixed(3), '→', c2.distance.toFixed(3));
  assert.ok(Math.abs(c2.distance / c1.distance - 0.4) < 0.02, `spreading the fingers 2.5× zooms in 2.5× (${c2.distance / c1.distance})`);
  assert.ok(Math.abs(c2.yaw - c1.yaw) < 1e-9 && Math.abs(c2.pitch - c1.pitch) < 1e-9, 'a pinch does not orbit');
  // two fingers moved together: pan (the target moves), no zoom
  await t('touchStart', [[mx - 40, my]]);
  await t('touchStart', [[mx - 40, my], [mx + 40, my]]);
  for (let k = 1; k <= 5; k++) await t('touchMove', [[mx - 40, my + 12 * k], [mx + 40, my + 12 * k]]);
  await t('touchEnd', [[mx - 40, my + 60]]);
  await t('touchEnd', []);
  const c3 = await cam();
  const moved = Math.hypot(...[0, 1, 2].map((k) => c3.target[k] - c2.target[k]));
  log('two-finger pan 60 px: target moved', moved.toFixed(3), 'distance', c3.distance.toFixed(3));
  assert.ok(moved > 0.05 && Math.abs(c3.distance - c2.distance) < 1e-9, 'two fingers pan without zooming');
  await page.screenshot({ path: join(artifacts, 't6-touch.png') });
  assert.deepEqual(errors, [], 'no page errors on the touch page');
  await ctx.close();
}

async function main() {
  const { proc, base } = await startServer(dataDir);
  log('server at', base);
  const browser = await launch();
  const pageErrors = [];
  try {
    const ctx = await browser.newContext({ viewport: { width: 1200, height: 760 } });
    const page = await ctx.newPage();
    page.on('pageerror', (e) => pageErrors.push(`page: ${e.message}`));
    page.on('console', (m) => { if (m.type() === 'error' && !presetsMissing(m)) pageErrors.push(`console: ${m.text()}`); });
    await page.goto(base + '/');
    await waitFor(page, () => window.dend && window.dend.app.renderer && window.dend.app.opened, null, 'the client to start');

    await occlusionBrush(page);
    await lassoSelect(page);
    await strayVertex(page);
    const session = await gizmo(page, base);
    await touch(browser, base, session);

    assert.deepEqual(pageErrors, [], 'no page or console errors');
    log('tools ok');
  } finally {
    await shutdown(browser, proc, dataDir);
  }
}

runTest(main);
