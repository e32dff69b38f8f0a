// Browser test of the editor's first minutes against the real
// `dend serve`, in headless Chromium:
// - first open: the page opens to the generated creature with its feet
//   fixed and its head a handle, a prompt on the canvas and a help
//   overlay; one drag (no click before it) poses it;
// - the gizmo grabs: a press at the handle's projected centre moves the
//   handle from the front, the side and at 45° (pitch 0: two rings are
//   seen edge-on through the centre);
// - settings never lose work: after posing, a preset change (the server's
//   list; an Advanced field when the server lists none) keeps the regions
//   and the pose, shows no error, and is one undo step; the next Undo
//   undoes the drag before it;
// - two tabs: while one holds the handle, the other's drag on it shows at
//   most one quiet status and no error, and the status clears on release.
// Screenshots of the first open and of a posed creature go to
// web/test-artifacts/ (and to docs/ with DEND_UPDATE_SCREENSHOT=1).

import { copyFileSync, mkdtempSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import assert from 'node:assert/strict';
import { root, artifacts, log, launch, startServer, waitFor, maxDiff, presetsMissing, shutdown, runTest } from './lib.mjs';

const dataDir = mkdtempSync(join(tmpdir(), 'dend-editor-test-'));

/** Indices of the vertices with label `l` (-1 fixed, k + 1 handle k). */
async function labelled(page, l) {
  const labels = await page.evaluate(() => window.dend.labels());
  return labels.flatMap((x, i) => (x === l ? [i] : []));
}

/** Waits until the last frame acknowledges every drag sent and settled. */
async function settled(page, what) {
  const seq = await page.evaluate(() => window.dend.app.seq);
  await waitFor(page, (s) => {
    const f = window.dend.app.last;
    return f && f.ackSeq >= s && f.settled;
  }, seq, what, 90000);
}

/** Mean displacement of `idx` between two flat position arrays. */
function meanMove(a, b, idx) {
  let s = 0;
  for (const i of idx) s += Math.hypot(a[3 * i] - b[3 * i], a[3 * i + 1] - b[3 * i + 1], a[3 * i + 2] - b[3 * i + 2]);
  return s / idx.length;
}

/** Page coordinates of the gizmo's centre (the handle's projected centroid). */
async function gizmoCentre(page) {
  await waitFor(page, () => window.dend.gizmo() !== null, null, 'the gizmo to show');
  const [x, y] = await page.evaluate(() => window.dend.gizmo().center);
  const c = await page.locator('#view').boundingBox();
  return [c.x + x, c.y + y];
}

/** Presses at the gizmo's centre and drags by (dx, dy) px. */
async function dragCentre(page, dx, dy) {
  const [x, y] = await gizmoCentre(page);
  await page.mouse.move(x, y);
  await page.mouse.down();
  await page.mouse.move(x + dx, y + dy, { steps: 12 });
  await page.mouse.up();
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
    let clicks = 0;

    // First open: nothing clicked yet.
    await page.goto(base + '/');
    await waitFor(page, () => window.dend && window.dend.app.opened && window.dend.app.state === 'ready', null, 'the creature, ready to pose', 90000);
    const rest = await page.evaluate(() => window.dend.positions());
    const fixed = await labelled(page, -1);
    const head = await labelled(page, 1);
    log('first open:', rest.length / 3, 'vertices,', fixed.length, 'fixed,', head.length, 'in the head handle');
    assert.ok(rest.length / 3 > 500, 'a creature, not a test bar');
    assert.ok(fixed.length > 0 && head.length > 0, 'default regions set');
    assert.ok(await page.locator('#prompt').isVisible(), 'the prompt on the canvas');
    assert.match(await page.locator('#prompt').textContent(), /drag the blue handle/i);
    assert.ok(await page.locator('#helpOverlay').isVisible(), 'the help overlay');
    assert.ok(await page.locator('#error').isHidden(), 'no error on first open');
    await page.waitForTimeout(300);
    await page.screenshot({ path: join(artifacts, 'editor-first-open.png') });
    if (process.env.DEND_UPDATE_SCREENSHOT) copyFileSync(join(artifacts, 'editor-first-open.png'), join(root, 'docs', 'editor-first-open.png'));

    // One drag at the handle's centre poses it: up and towards the viewer's right.
    await dragCentre(page, 140, -90);
    await settled(page, 'the first pose');
    let pose = await page.evaluate(() => window.dend.positions());
    const firstMove = meanMove(rest, pose, head);
    log('first drag: head moved', firstMove.toFixed(3), 'fixed moved', maxDiff(rest, pose, fixed).toExponential(1), 'after', clicks, 'clicks');
    assert.ok(firstMove > 0.2, `the head moved (${firstMove})`);
    assert.ok(maxDiff(rest, pose, fixed) < 1e-5, 'the feet stay put');
    assert.ok(clicks <= 3, 'posed within 3 clicks');
    // the status bar tells how the drag went: frames/s, the settle time
    // (last drag → its settled frame) and the level of the frame shown;
    // the settled frame came in f32 (exact), the frames before it in delta
    const bar = await page.evaluate(() => ({
      fps: document.getElementById('stFps').textContent,
      settle: document.getElementById('stSettle').textContent,
      level: document.getElementById('stLevel').textContent,
      flow: window.dend.app.flow,
    }));
    log('status bar after the first drag:', JSON.stringify(bar));
    assert.ok(Number(bar.fps) >= 1, `frames/s shown (${bar.fps})`);
    assert.match(bar.settle, /^\d+ ms$/, 'the settle time shown');
    assert.ok(bar.level.length > 0 && bar.level !== '–', `the level shown (${bar.level})`);
    assert.equal(bar.flow.encoding, 'f32', 'the settled frame is full precision');
    assert.ok((bar.flow.encodings.delta || 0) > 0, `the drag's frames came in delta (${JSON.stringify(bar.flow.encodings)})`);
    assert.equal(bar.flow.level, 0, 'the settled frame is the full mesh');
    assert.ok(await page.locator('#prompt').isHidden(), 'the prompt goes once the user drags');
    await page.locator('#helpClose').click();
    clicks++;
    await page.waitForTimeout(300);
    await page.screenshot({ path: join(artifacts, 'editor-posed.png') });
    if (process.env.DEND_UPDATE_SCREENSHOT) copyFileSync(join(artifacts, 'editor-posed.png'), join(root, 'docs', 'editor-posed.png'));

    // The gizmo grabs from the front, the side and at 45°, at pitch 0
    // (two of its rings pass through the centre edge-on).
    for (const [name, yaw] of [['front', Math.PI / 2], ['side', 0], ['45°', Math.PI / 4]]) {
      await page.evaluate((y) => {
        const c = window.dend.app.camera;
        c.yaw = y;
        c.pitch = 0;
        window.dend.app.needsDraw = true;
      }, yaw);
      await page.waitForTimeout(150);
      const before = await page.evaluate(() => window.dend.positions());
      await dragCentre(page, 0, -60);
      await settled(page, `the ${name} drag`);
      const after = await page.evaluate(() => window.dend.positions());
      const m = meanMove(before, after, head);
      log(`gizmo centre press, ${name} view: head moved`, m.toFixed(3));
      assert.ok(m > 0.1, `a press at the centre moves the handle in the ${name} view (${m})`);
    }
    await page.screenshot({ path: join(artifacts, 'e1-gizmo-views.png') });

    // A settings change after posing keeps the regions and the pose.
    pose = await page.evaluate(() => window.dend.positions());
    const labels = await page.evaluate(() => window.dend.labels());
    const oldSession = await page.evaluate(() => window.dend.app.session.id);
    const presets = await page.evaluate(() => window.dend.app.presets);
    let change;
    if (presets && presets.presets && presets.presets.length >= 2) {
      const current = await page.inputValue('#preset');
      const other = presets.presets.find((p) => p.name !== current).name;
      change = async () => page.selectOption('#preset', other);
      log('settings change: preset', current, '→', other);
    } else {
      // an older server without GET /v1/presets: the same path, from the Advanced fold
      log('the server lists no presets: changing Detail in the Advanced fold instead');
      await page.click('#advanced summary');
      clicks++;
      change = async () => page.selectOption('#detail', 'linear');
    }
    const [req] = await Promise.all([
      page.waitForRequest((r) => r.method() === 'POST' && new URL(r.url()).pathname === '/v1/sessions'),
      change(),
    ]);
    const sent = JSON.parse(req.postData()).params;
    log('new session asked for', JSON.stringify(sent));
    await waitFor(page, (id) => window.dend.app.session.id !== id && window.dend.app.state === 'ready', oldSession, 'the session with the new settings', 90000);
    // a new session: its frames acknowledge none of this tab's earlier drags
    await waitFor(page, () => window.dend.app.last && window.dend.app.last.settled, null, 'the pose under the new settings', 90000);
    const repose = await page.evaluate(() => window.dend.positions());
    assert.deepEqual(await page.evaluate(() => window.dend.labels()), labels, 'the regions are kept');
    const handleDrift = maxDiff(pose, repose, head);
    const fixedDrift = maxDiff(pose, repose, fixed);
    log('after the change: head off by', handleDrift.toExponential(1), 'feet off by', fixedDrift.toExponential(1), '; whole pose within', maxDiff(pose, repose, [...Array(pose.length / 3).keys()]).toFixed(3));
    assert.ok(handleDrift < 1e-4 && fixedDrift < 1e-4, 'the handle and the feet stay where they were posed');
    assert.ok(meanMove(rest, repose, head) > 0.2, 'still posed, not back at rest');
    assert.ok(await page.locator('#error').isHidden(), `no error banner (${await page.locator('#errorText').textContent()})`);
    const events = (await page.evaluate(() => window.dend.stats())).events;
    assert.ok(!events.some((e) => e === 'error'), `no error event: ${events.join(' ')}`);

    // Undo returns to the settings and pose before the change, then undoes the drag.
    assert.ok(await page.locator('#undo').isEnabled(), 'Undo is offered');
    await page.click('#undo');
    clicks++;
    await waitFor(page, (id) => window.dend.app.session.id === id && window.dend.app.last, oldSession, 'the session before the change');
    await waitFor(page, (e) => {
      const p = window.dend.positions();
      let m = 0;
      for (let i = 0; i < p.length; i++) m = Math.max(m, Math.abs(p[i] - e[i]));
      return m < 1e-4;
    }, pose, 'the pose before the change');
    assert.deepEqual(await page.evaluate(() => window.dend.labels()), labels, 'the regions after the undo');
    const lastDrag = await page.evaluate(() => window.dend.positions());
    await page.click('#undo');
    await waitFor(page, (e) => {
      const p = window.dend.positions();
      let m = 0;
      for (let i = 0; i < p.length; i++) m = Math.max(m, Math.abs(p[i] - e[i]));
      return m > 1e-2;
    }, lastDrag, 'the drag before the change undone');
    assert.ok(await page.locator('#error').isHidden(), 'no error banner after the undos');
    log('settings change: regions and pose kept, one undo step, no error');

    // Two tabs: the first holds the handle; the second's drag on it gets one quiet status.
    const link = await page.inputValue('#shareLink');
    const page2 = await ctx.newPage();
    page2.on('pageerror', (e) => pageErrors.push(`page2: ${e.message}`));
    await page2.goto(link);
    await waitFor(page2, () => window.dend.app.opened && window.dend.app.state === 'ready' && window.dend.app.ws, null, 'the second tab');
    const [ax, ay] = await gizmoCentre(page);
    await page.mouse.move(ax, ay);
    await page.mouse.down();
    await page.mouse.move(ax + 10, ay - 10, { steps: 3 });
    await waitFor(page2, () => !document.getElementById('notice').hidden, null, 'the held status in the second tab');
    const [bx, by] = await gizmoCentre(page2);
    await page2.mouse.move(bx, by);
    await page2.mouse.down();
    for (let k = 1; k <= 21; k++) await page2.mouse.move(bx + 4 * k, by);
    await page2.mouse.up();
    await page2.waitForTimeout(500);
    const notices = (await page2.evaluate(() => window.dend.stats())).notices;
    log('second tab while held:', JSON.stringify(notices));
    assert.ok(notices.length <= 1, `at most one status message: ${notices}`);
    assert.match(notices[0] || '', /held by/);
    assert.ok(await page2.locator('#error').isHidden(), `no error banner in the second tab (${await page2.locator('#errorText').textContent()})`);
    await page.mouse.up();
    await waitFor(page2, () => document.getElementById('notice').hidden, null, 'the status to clear on release');
    log('two tabs: one quiet status while held, cleared on release');

    assert.deepEqual(pageErrors, [], 'no page or console errors');
    log('editor ok');
  } finally {
    await shutdown(browser, proc, dataDir);
  }
}

runTest(main);
