// Browser test of textured assets against the real `dend serve`,
// in headless Chromium: an uploaded glTF with a base-colour texture is
// drawn with it, on its own UVs, and follows the pose.
//
//   DEND_BIN=target/debug/dend node web/tests/texture.test.mjs
//
// - first open (a generated creature): no texture, and none of the test
//   texture's colours on screen;
// - upload, through the editor's file input, of skinned_tube.mjs's tube
//   with a 2 × 2 texture of four colours unlike the region colours: every
//   welded triangle gets UVs, and they are the file's, checked against the
//   tube's own parametrisation (u the angle around, v = 1 - z / 3, the cap
//   0.5 + (x, y)), which no triangle across the UV seam satisfies unless
//   each corner keeps its own copy's UV; the screenshot shows each colour
//   the view sees (chromaticity within 0.05 of the texel's) on a
//   measurable share of the mesh's pixels;
// - regions set (feet fixed, top a handle) and one gizmo drag: the pose
//   moved, the picture changed, the texture's colours are still there;
// - the same tube placed by its node's transform (no skin: the server has
//   it in world space) gets its file UVs too;
// - a generated mesh afterwards is untextured again.
// The posed tube's screenshot goes to web/test-artifacts/ (and to
// docs/editor-textured.png with DEND_UPDATE_SCREENSHOT=1).

import { copyFileSync, mkdtempSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import assert from 'node:assert/strict';
import { root, artifacts, log, launch, startServer, waitFor, pixelDiff, presetsMissing, shutdown, runTest } from './lib.mjs';
import { skinnedTubeGlb, TUBE } from './skinned_tube.mjs';

/** The test texture: magenta, orange / cyan, yellow (rows at v = 0, 1). */
const TEXELS = [[210, 40, 200], [245, 140, 20], [20, 180, 200], [215, 215, 30]];
const NAMES = ['magenta', 'orange', 'cyan', 'yellow'];

/** Per texel, the share of the mesh's pixels (those not the background)
 * whose chromaticity r:g:b is within 0.05 of the texel's (shading scales
 * a colour, so its chromaticity stays), and the mesh's pixel count. */
async function texelShares(page, png) {
  return page.evaluate(async ([b64, texels]) => {
    const img = new Image();
    img.src = `data:image/png;base64,${b64}`;
    await img.decode();
    const c = document.createElement('canvas');
    [c.width, c.height] = [img.width, img.height];
    const g = c.getContext('2d');
    g.drawImage(img, 0, 0);
    const d = g.getImageData(0, 0, c.width, c.height).data;
    const chroma = (r, gr, b) => { const s = r + gr + b || 1; return [r / s, gr / s, b / s]; };
    const want = texels.map((t) => chroma(...t));
    const hits = texels.map(() => 0);
    let mesh = 0;
    for (let i = 0; i < d.length; i += 4) {
      const [r, gr, b] = [d[i], d[i + 1], d[i + 2]];
      // the background (clear colour 0.93, 0.94, 0.96)
      if (Math.abs(r - 237) < 6 && Math.abs(gr - 240) < 6 && Math.abs(b - 245) < 6) continue;
      mesh++;
      if (r + gr + b < 60) continue;
      const q = chroma(r, gr, b);
      want.forEach((w, k) => {
        if (Math.max(Math.abs(q[0] - w[0]), Math.abs(q[1] - w[1]), Math.abs(q[2] - w[2])) < 0.05) hits[k]++;
      });
    }
    return { mesh, shares: hits.map((h) => h / Math.max(mesh, 1)) };
  }, [png.toString('base64'), TEXELS]);
}

/** The worst departure of the drawn UVs from the tube's parametrisation,
 * and the widest u span of a tube triangle (1/16 when each corner keeps
 * its own seam copy's UV; near 1 across the seam otherwise). */
function uvErrors(pos, tri, uv, textured) {
  // (tube positions in the tube's own frame)
  const { radius, length, around } = TUBE;
  let worst = 0, span = 0, cap = 0;
  for (let f = 0; f < tri.length / 3; f++) {
    assert.equal(textured[f], 1, `triangle ${f} has UVs`);
    const p = [0, 1, 2].map((k) => pos.slice(3 * tri[3 * f + k], 3 * tri[3 * f + k] + 3));
    const t = [0, 1, 2].map((k) => uv.slice(2 * (3 * f + k), 2 * (3 * f + k) + 2));
    if (p.every((q) => Math.abs(q[2] - length) < 1e-5)) {
      cap++;
      for (let k = 0; k < 3; k++) worst = Math.max(worst, Math.abs(t[k][0] - (0.5 + p[k][0])), Math.abs(t[k][1] - (0.5 + p[k][1])));
      continue;
    }
    for (let k = 0; k < 3; k++) {
      const a = 2 * Math.PI * t[k][0];
      worst = Math.max(worst, Math.abs(radius * Math.cos(a) - p[k][0]), Math.abs(radius * Math.sin(a) - p[k][1]), Math.abs(t[k][1] - (1 - p[k][2] / length)));
    }
    const us = t.map((x) => x[0]);
    span = Math.max(span, Math.max(...us) - Math.min(...us));
  }
  assert.equal(cap, around, 'the cap has its triangles');
  return { worst, span };
}

async function main() {
  const dataDir = mkdtempSync(join(tmpdir(), 'dend-texture-test-'));
  const { proc, base } = await startServer(dataDir);
  log('server at', base);
  const browser = await launch();
  const pageErrors = [];
  try {
    const ctx = await browser.newContext({ viewport: { width: 1200, height: 760 } });
    const page = await ctx.newPage();
    page.on('pageerror', (e) => pageErrors.push(`page: ${e.message}`));
    page.on('console', (m) => { if (m.type() === 'error' && !presetsMissing(m)) pageErrors.push(`console: ${m.text()}`); });
    const view = page.locator('#view');

    // first open: the generated creature, untextured
    await page.goto(base + '/');
    await waitFor(page, () => window.dend && window.dend.app.opened && window.dend.app.state === 'ready', null, 'the creature', 90000);
    await page.locator('#helpClose').click();
    await page.waitForTimeout(300);
    assert.equal(await page.evaluate(() => window.dend.texture()), null, 'a generated mesh has no texture');
    const plain = await texelShares(page, await view.screenshot());
    log('creature: mesh pixels', plain.mesh, 'texel shares', plain.shares.map((s) => s.toFixed(4)).join(' '));
    assert.ok(plain.mesh > 5000, 'the creature is drawn');
    assert.ok(plain.shares.every((s) => s < 0.01), 'no texture colours on an untextured mesh');

    // upload the textured tube through the file input
    await page.setInputFiles('#upload', { name: 'tube.glb', mimeType: 'model/gltf-binary', buffer: skinnedTubeGlb(TEXELS) });
    await waitFor(page, () => window.dend.texture() !== null, null, 'the texture', 90000);
    const n = await page.evaluate(() => window.dend.positions().length / 3);
    const tex = await page.evaluate(() => window.dend.texture());
    const pos = await page.evaluate(() => window.dend.positions());
    const tri = await page.evaluate(() => Array.from(window.dend.app.mesh.triangles));
    log('tube:', n, 'welded vertices,', tri.length / 3, 'triangles, texture', tex.size.join('×'));
    assert.equal(n, 209, 'the welded tube (seam and cap ring welded)');
    assert.deepEqual(tex.size, [2, 2]);
    const { worst, span } = uvErrors(pos, tri, tex.uv, tex.textured);
    log('UVs against the tube\'s parametrisation: worst', worst.toExponential(2), '; widest u span of a tube triangle', span.toFixed(4));
    assert.ok(worst < 1e-4, `every corner has its file vertex's UV (${worst})`);
    assert.ok(span <= 1 / TUBE.around + 1e-6, `seam triangles keep their own copy's UV (u span ${span})`);

    await page.waitForTimeout(300);
    const rest = await view.screenshot();
    const textured = await texelShares(page, rest);
    log('textured tube: mesh pixels', textured.mesh, 'texel shares', textured.shares.map((s, k) => `${NAMES[k]} ${s.toFixed(3)}`).join(', '));
    const seen = textured.shares.filter((s) => s > 0.03).length;
    const total = textured.shares.reduce((a, b) => a + b, 0);
    assert.ok(textured.mesh > 5000, 'the tube is drawn');
    assert.ok(seen >= 3, `at least three of the four texels show (on > 3 % of the mesh each): ${textured.shares}`);
    assert.ok(total > 0.6, `the texture covers most of the mesh (${total})`);

    // regions (feet fixed, top a handle, by index as the editor paints), then a drag
    const s = await page.evaluate(() => window.dend.app.session);
    const ids = (pred) => [...Array(n).keys()].filter((i) => pred(pos[3 * i + 2]));
    const handle = ids((z) => z > 2.7);
    const r = await fetch(`${base}/v1/sessions/${s.id}/constraints`, {
      method: 'PUT',
      headers: { Authorization: `Bearer ${s.token}`, 'Content-Type': 'application/json' },
      body: JSON.stringify({ fixed: ids((z) => z < 0.3), handles: [{ name: 'top', vertices: handle }] }),
    });
    assert.equal(r.status, 202, `PUT constraints: ${r.status}`);
    await waitFor(page, () => window.dend.labels().some((l) => l === 1) && window.dend.app.state === 'ready', null, 'the regions, ready', 90000);
    await page.selectOption('#target', 'h0');
    await page.waitForTimeout(300);
    const before = await view.screenshot();
    const tinted = await texelShares(page, before);
    log('with regions: texel shares', tinted.shares.map((x) => x.toFixed(3)).join(' '));
    await waitFor(page, () => window.dend.gizmo() !== null, null, 'the gizmo');
    const [gx, gy] = await page.evaluate(() => window.dend.gizmo().center);
    const box = await view.boundingBox();
    const p0 = await page.evaluate(() => window.dend.positions());
    await page.mouse.move(box.x + gx, box.y + gy);
    await page.mouse.down();
    await page.mouse.move(box.x + gx + 150, box.y + gy - 40, { steps: 12 });
    await page.mouse.up();
    const seq = await page.evaluate(() => window.dend.app.seq);
    await waitFor(page, (q) => { const f = window.dend.app.last; return f && f.ackSeq >= q && f.settled; }, seq, 'the pose to settle', 90000);
    await page.waitForTimeout(300);
    const p1 = await page.evaluate(() => window.dend.positions());
    const moved = handle.reduce((m, i) => Math.max(m, Math.hypot(p1[3 * i] - p0[3 * i], p1[3 * i + 1] - p0[3 * i + 1], p1[3 * i + 2] - p0[3 * i + 2])), 0);
    const posed = await view.screenshot();
    const diff = await pixelDiff(page, before, posed);
    const after = await texelShares(page, posed);
    log('drag: handle moved', moved.toFixed(3), '; pixels changed', diff.toFixed(3), '; texel shares', after.shares.map((x) => x.toFixed(3)).join(' '));
    assert.ok(moved > 0.2, `the handle moved (${moved})`);
    assert.ok(diff > 0.01, `the picture follows the pose (${diff} of the pixels changed)`);
    assert.ok(after.shares.filter((x) => x > 0.02).length >= 2, `the posed tube still shows the texture: ${after.shares}`);
    await page.screenshot({ path: join(artifacts, 'editor-textured.png') });
    if (process.env.DEND_UPDATE_SCREENSHOT) copyFileSync(join(artifacts, 'editor-textured.png'), join(root, 'docs', 'editor-textured.png'));

    // the tube placed by its node (moved, turned 90° about x, scaled 2, no
    // skin): the server has it in world space, the file's POSITION is local
    const s45 = Math.SQRT1_2;
    await page.setInputFiles('#upload', {
      name: 'placed.glb', mimeType: 'model/gltf-binary',
      buffer: skinnedTubeGlb(TEXELS, { translation: [1, 2, -0.5], rotation: [s45, 0, 0, s45], scale: [2, 2, 2] }),
    });
    await waitFor(page, (old) => window.dend.app.session.id !== old && window.dend.texture() !== null, s.id, 'the placed tube\'s texture', 90000);
    const placed = await page.evaluate(() => ({ pos: window.dend.positions(), tri: Array.from(window.dend.app.mesh.triangles), tex: window.dend.texture() }));
    // world → the tube's frame: l = (w - t) / 2, then the turn undone
    const local = [];
    for (let i = 0; i < placed.pos.length; i += 3) {
      const [x, y, z] = [(placed.pos[i] - 1) / 2, (placed.pos[i + 1] - 2) / 2, (placed.pos[i + 2] + 0.5) / 2];
      local.push(x, z, -y);
    }
    const pe = uvErrors(local, placed.tri, placed.tex.uv, placed.tex.textured);
    await page.waitForTimeout(300);
    const placedShares = await texelShares(page, await view.screenshot());
    log('placed tube: UVs worst', pe.worst.toExponential(2), '; u span', pe.span.toFixed(4), '; texel shares', placedShares.shares.map((x) => x.toFixed(3)).join(' '));
    assert.ok(pe.worst < 1e-4 && pe.span <= 1 / TUBE.around + 1e-6, 'the placed tube has its file UVs');
    assert.ok(placedShares.shares.filter((x) => x > 0.03).length >= 2, `the placed tube shows the texture: ${placedShares.shares}`);

    // a generated mesh afterwards: untextured again
    await page.selectOption('#shape', { index: 0 });
    await page.click('#generate');
    await waitFor(page, (m) => window.dend.positions().length / 3 !== m && window.dend.app.state !== 'creating', n, 'the generated mesh', 90000);
    await page.waitForTimeout(300);
    assert.equal(await page.evaluate(() => window.dend.texture()), null, 'no texture on the generated mesh');
    const again = await texelShares(page, await view.screenshot());
    await page.screenshot({ path: join(artifacts, 'tex-generated-after.png') });
    log('generated after the tube: texel shares', again.shares.map((x) => x.toFixed(4)).join(' '));
    assert.ok(again.shares.every((x) => x < 0.01), 'no texture colours after the tube');

    assert.deepEqual(pageErrors, [], 'no page or console errors');
    log('texture ok');
  } finally {
    await shutdown(browser, proc, dataDir);
  }
}

runTest(main);
