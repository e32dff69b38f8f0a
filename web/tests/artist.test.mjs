// Browser test of the editor as an artist works with it, against the real
// `dend serve` in headless Chromium at 1280 × 720 (a laptop):
//
//   DEND_BIN=target/debug/dend node web/tests/artist.test.mjs
//
// - the panel fits: the pose tools (Undo, the numeric move, Save pose and
//   the pose list) are on screen without scrolling, and each section
//   collapses and opens from its heading;
// - guidance from the session's state: a generated bar (no default
//   regions) gets a prompt and a help box about painting, not about a blue
//   handle or feet; the paint menu has no empty handle, "+ handle" makes
//   handle 0, and its gizmo shows as soon as it has vertices, unclicked;
// - a named pose is never overwritten silently: saving "up" again asks,
//   the stored pose is unchanged until "Replace", and is the new one after;
// - undo and redo cross settings changes both ways: a drag, a stiffness
//   change, a preset change and a drag are undone back to the first
//   session and redone to the last drag's pose;
// - a settle that runs out of iterations (a session budget of 2, set by
//   rewriting the page's session request) says so and offers "Keep
//   refining", which runs more iterations from that pose, and Undo.
// Screenshots of the panel at 1280 × 720 and 1920 × 1080 go to
// web/test-artifacts/ (and to docs/ with DEND_UPDATE_SCREENSHOT=1).

import { copyFileSync, mkdtempSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import assert from 'node:assert/strict';
import {
  root, artifacts, log, launch, startServer, waitFor, serverPose, screenBox, boxSelect, presetsMissing, shutdown,
  runTest,
} from './lib.mjs';

const dataDir = mkdtempSync(join(tmpdir(), 'dend-artist-test-'));

const labelled = (labels, l) => labels.flatMap((x, i) => (x === l ? [i] : []));

/** Waits until the last frame acknowledges every drag sent and settled. */
async function settled(page, what) {
  const seq = await page.evaluate(() => window.dend.app.seq);
  await waitFor(page, (s) => {
    const f = window.dend.app.last;
    return f && f.ackSeq >= s && f.settled && window.dend.app.state === 'ready';
  }, seq, what, 90000);
}

/** Presses at the gizmo's centre and drags by (dx, dy) px. */
async function dragHandle(page, dx, dy) {
  await waitFor(page, () => window.dend.gizmo() !== null, null, 'the gizmo');
  const [x, y] = await page.evaluate(() => window.dend.gizmo().center);
  const c = await page.locator('#view').boundingBox();
  await page.mouse.move(c.x + x, c.y + y);
  await page.mouse.down();
  await page.mouse.move(c.x + x + dx, c.y + y + dy, { steps: 10 });
  await page.mouse.up();
}

async function generate(page, shape) {
  const before = await page.evaluate(() => window.dend.app.session && window.dend.app.session.id);
  await page.selectOption('#shape', shape);
  await page.click('#generate');
  await waitFor(page, (b) => window.dend.app.session && window.dend.app.session.id !== b && window.dend.app.ws,
    before, `the ${shape}`);
}

async function namedPose(base, s, name) {
  const r = await fetch(`${base}/v1/sessions/${s.id}/poses/${encodeURIComponent(name)}`, {
    headers: { Authorization: `Bearer ${s.token}` },
  });
  assert.equal(r.status, 200, `GET pose ${name}`);
  return (await r.json()).positions.flat();
}

function maxAbs(a, b) {
  let m = 0;
  for (let i = 0; i < a.length; i++) m = Math.max(m, Math.abs(a[i] - b[i]));
  return m;
}

/** Whether the element is inside the viewport (no scrolling needed). */
async function onScreen(page, selector) {
  const box = await page.locator(selector).boundingBox();
  const vp = page.viewportSize();
  return !!box && box.y >= 0 && box.y + box.height <= vp.height && box.x + box.width <= vp.width;
}

async function panelFits(page) {
  for (const sel of ['#undo', '#redo', '#numApply', '#poseSave', '#poseName', '#export']) {
    assert.ok(await onScreen(page, sel), `${sel} is on screen at 1280 × 720 without scrolling`);
  }
  assert.equal(await page.evaluate(() => document.getElementById('panel').scrollTop), 0);
  // a section collapses from its heading and opens again
  await page.click('#secPaint > summary');
  assert.ok(await page.locator('#brushRadius').isHidden(), 'the Paint section collapsed');
  await page.click('#secPaint > summary');
  assert.ok(await page.locator('#brushRadius').isVisible(), 'and opened again');
}

async function guidance(page) {
  await generate(page, 'bar');
  await waitFor(page, () => !document.getElementById('prompt').hidden, null, 'a prompt for the bar');
  const prompt = await page.locator('#prompt').textContent();
  const help = await page.locator('#helpOverlay').textContent();
  log('bar prompt:', prompt, '| help:', help.trim().slice(0, 80));
  assert.doesNotMatch(prompt, /blue handle|creature/i, 'the bar has no handle yet');
  assert.match(prompt, /paint/i, 'the prompt says to paint regions');
  assert.doesNotMatch(help, /feet/i, 'the help box does not describe the creature');
  const handles = await page.evaluate(() => [...document.getElementById('target').options].map((o) => o.value).filter((v) => v.startsWith('h')));
  assert.deepEqual(handles, [], 'no empty handle in the paint menu');
  // fixed end, then a new handle painted: its gizmo shows unclicked
  await page.uncheck('#autoApply');
  await page.check('input[name=tool][value=box]');
  await page.check('#throughSel');
  const p = await page.evaluate(() => window.dend.positions());
  const n = p.length / 3;
  const ids = (pred) => [...Array(n).keys()].filter((i) => pred(p[3 * i + 2]));
  await boxSelect(page, await screenBox(page, ids((z) => z < 0.5), 6));
  assert.match(await page.locator('#prompt').textContent(), /handle/i, 'with a fixed part: add a handle');
  await page.click('#addHandle');
  assert.equal(await page.inputValue('#target'), 'h0', '"+ handle" makes handle 0');
  assert.equal(await page.evaluate(() => window.dend.gizmo()), null, 'no gizmo while the handle is empty');
  await boxSelect(page, await screenBox(page, ids((z) => z > 5.5), 6));
  await waitFor(page, () => window.dend.gizmo() !== null, null, 'the new handle\'s gizmo, with no click on it', 5000);
  const info = await page.locator('#selinfo').textContent();
  assert.match(info, /handles \[\d+\]/, `one handle listed (${info})`);
  await page.click('#apply');
  await waitFor(page, () => window.dend.app.state === 'ready', null, 'the bar ready');
  assert.match(await page.locator('#prompt').textContent(), /drag the blue handle/i);
  await page.uncheck('#throughSel');
  await page.check('input[name=tool][value=navigate]');
  await page.check('#autoApply');
}

async function namedPoses(page, base) {
  await generate(page, 'creature');
  await waitFor(page, () => window.dend.app.state === 'ready', null, 'the creature');
  await dragHandle(page, 90, -60);
  await settled(page, 'the first pose');
  const s = await page.evaluate(() => window.dend.app.session);
  await page.fill('#poseName', 'up');
  await page.click('#poseSave');
  await waitFor(page, () => /up/.test(document.getElementById('poseList').textContent), null, 'pose "up" listed');
  const first = await namedPose(base, s, 'up');
  await dragHandle(page, -120, 40);
  await settled(page, 'the second pose');
  const second = Array.from(await serverPose(base, s));
  assert.ok(maxAbs(first, second) > 0.1, 'the second pose differs');
  await page.click('#poseSave');
  await waitFor(page, () => !document.getElementById('poseConfirm').hidden, null, 'the question before replacing "up"', 5000);
  log('asked:', await page.locator('#poseConfirmText').textContent());
  await page.waitForTimeout(500);
  assert.equal(maxAbs(await namedPose(base, s, 'up'), first), 0, 'nothing replaced before the answer');
  await page.click('#poseReplace');
  await waitFor(page, () => document.getElementById('poseConfirm').hidden, null, 'the answer taken');
  let replaced = first;
  for (let k = 0; k < 50 && maxAbs(replaced, first) === 0; k++) {
    await page.waitForTimeout(100);
    replaced = await namedPose(base, s, 'up');
  }
  // (the served pose is float32)
  assert.ok(maxAbs(replaced, second) < 1e-5, `replaced with the current pose once confirmed (${maxAbs(replaced, second)})`);
}

/** Clicks `sel` and waits until the editor is idle: a session open and
 * ready, its last frame settled. */
async function step(page, sel) {
  await page.waitForFunction((s) => !document.querySelector(s).disabled, sel, { timeout: 10000 });
  const before = await page.evaluate(() => [window.dend.app.session.id, window.dend.app.frames]);
  await page.click(sel);
  await waitFor(page, ([id, frames]) => {
    const a = window.dend.app;
    return a.ws && a.state === 'ready' && a.last && a.last.settled && (a.session.id !== id || a.frames > frames);
  }, before, `${sel} done`, 60000);
  await page.waitForTimeout(250);
}

async function undoAcrossSettings(page) {
  await generate(page, 'creature');
  await waitFor(page, () => window.dend.app.state === 'ready', null, 'the creature');
  const first = await page.evaluate(() => window.dend.app.session.id);
  await dragHandle(page, 80, -50);
  await settled(page, 'a drag');
  const sessions = [first];
  const nextSession = async (what) => {
    await waitFor(page, (ids) => !ids.includes(window.dend.app.session.id) && window.dend.app.state === 'ready' && window.dend.app.last && window.dend.app.last.settled,
      sessions, what, 90000);
    sessions.push(await page.evaluate(() => window.dend.app.session.id));
  };
  // stiffness 4×, then another preset (an Advanced field when the server lists none)
  await page.evaluate(() => {
    const s = document.getElementById('stiffness');
    s.value = '2';
    s.dispatchEvent(new Event('change'));
  });
  await nextSession('the 4× session');
  const presets = await page.evaluate(() => [...document.getElementById('preset').options].map((o) => o.value));
  const current = await page.inputValue('#preset');
  const other = presets.find((p) => p !== current);
  if (other) await page.selectOption('#preset', other);
  else await page.evaluate(() => { const l = document.getElementById('lambda2'); l.value = '2'; l.dispatchEvent(new Event('change')); });
  await nextSession(`the ${other || 'λ2'} session`);
  await dragHandle(page, -60, -40);
  await settled(page, 'the drag after the settings');
  const last = await page.evaluate(() => window.dend.positions());
  const lastSession = sessions[sessions.length - 1];
  log('sessions:', sessions.length, 'the last', lastSession.slice(0, 8));
  // undo back to the first session
  let undos = 0;
  while ((await page.evaluate(() => window.dend.app.session.id)) !== first) {
    assert.ok(++undos <= 6, 'back to the first session within 6 undos');
    await step(page, '#undo');
  }
  log('undone to the first session in', undos, 'steps; stiffness', await page.inputValue('#stiffness'));
  assert.equal(await page.inputValue('#stiffness'), '0', 'the first session\'s settings are back');
  assert.ok(!(await page.locator('#redo').isDisabled()), 'Redo is offered');
  // redo to the last drag's pose
  let redos = 0;
  for (;;) {
    const here = await page.evaluate(() => window.dend.positions());
    const id = await page.evaluate(() => window.dend.app.session.id);
    if (id === lastSession && maxAbs(here, last) < 1e-5) break;
    assert.ok(++redos <= undos, `the last drag redone within ${undos} redos`);
    await step(page, '#redo');
  }
  log('redone in', redos, 'steps');
  assert.equal(redos, undos, 'every undo step has its redo');
  assert.equal(await page.inputValue('#stiffness'), '2', 'the 4× stiffness is back');
  assert.ok(await page.locator('#redo').isDisabled(), 'nothing left to redo');
  assert.ok(await page.locator('#error').isHidden(), 'no error on the way');
}

async function iterationCap(page) {
  // a session budget of 2 iterations: every settle of a drag runs out
  await page.route('**/v1/sessions', async (route) => {
    const req = route.request();
    if (req.method() !== 'POST') return route.continue();
    const body = JSON.parse(req.postData());
    body.params = { ...(body.params || {}), max_iters: 2 };
    return route.continue({ postData: JSON.stringify(body) });
  });
  await generate(page, 'creature');
  await waitFor(page, () => window.dend.app.state === 'ready', null, 'the creature, 2 iterations a settle');
  assert.ok(await page.locator('#stCap').isHidden(), 'nothing to offer before a drag');
  await dragHandle(page, 160, -120);
  await settled(page, 'the capped settle');
  const f = await page.evaluate(() => window.dend.app.last);
  assert.ok(!f.converged, 'the drag did not converge in 2 iterations');
  assert.ok(await page.locator('#stCap').isVisible(), 'the next steps are offered');
  const status = await page.locator('#stConv').textContent();
  log('capped status:', status);
  assert.match(status, /not settled after \d+ iterations/);
  assert.match(status, /budget/, 'the status says why it stopped');
  assert.ok(await page.locator('#capUndo').isVisible(), 'Undo is one of them');
  const before = await page.evaluate(() => window.dend.positions());
  await page.click('#refine');
  await settled(page, 'the refined pose');
  const after = await page.evaluate(() => window.dend.positions());
  log('keep refining moved the pose by', maxAbs(before, after).toExponential(2));
  assert.ok(maxAbs(before, after) > 0, 'more iterations ran from the capped pose');
  await page.unroute('**/v1/sessions');
}

async function main() {
  const { proc, base } = await startServer(dataDir);
  log('server at', base);
  const browser = await launch();
  const pageErrors = [];
  try {
    const ctx = await browser.newContext({ viewport: { width: 1280, height: 720 } });
    const page = await ctx.newPage();
    page.on('pageerror', (e) => pageErrors.push(`page: ${e.message}`));
    page.on('console', (m) => { if (m.type() === 'error' && !presetsMissing(m)) pageErrors.push(`console: ${m.text()}`); });
    await page.goto(base + '/');
    await waitFor(page, () => window.dend && window.dend.app.opened && window.dend.app.state === 'ready', null, 'the creature', 90000);
    await page.waitForTimeout(300);
    await page.screenshot({ path: join(artifacts, 'editor-1280x720.png') });
    await panelFits(page);
    log('panel fits at 1280 × 720');
    await guidance(page);
    log('guidance follows the mesh');
    await namedPoses(page, base);
    log('named poses ask before replacing');
    await undoAcrossSettings(page);
    log('undo and redo cross settings changes');
    await iterationCap(page);
    log('a capped settle offers the next steps');
    const wide = await browser.newContext({ viewport: { width: 1920, height: 1080 } });
    const big = await wide.newPage();
    await big.goto(base + '/');
    await waitFor(big, () => window.dend && window.dend.app.opened && window.dend.app.state === 'ready', null, 'the creature at 1920 × 1080', 90000);
    await dragHandle(big, 120, -80);
    await settled(big, 'a pose at 1920 × 1080');
    await big.waitForTimeout(300);
    await big.screenshot({ path: join(artifacts, 'editor-1920x1080.png') });
    if (process.env.DEND_UPDATE_SCREENSHOT) {
      for (const f of ['editor-1280x720.png', 'editor-1920x1080.png']) copyFileSync(join(artifacts, f), join(root, 'docs', f));
    }
    assert.deepEqual(pageErrors, [], 'no page errors');
  } finally {
    await shutdown(browser, proc, dataDir);
  }
  log('artist test passed');
}

runTest(main);
