// Browser test of getting meshes in and out of the editor, against the real
// `dend serve` in headless Chromium (1280 × 720):
//
//   DEND_BIN=target/debug/dend node web/tests/uploads.test.mjs
//
// - drag and drop on the view: an OBJ, a GLB, and a .gltf dropped with the
//   .bin it names (embedded by the editor: the server reads one file) each
//   open a session on the dropped mesh; a .gltf dropped without its .bin
//   says which file is missing;
// - a mesh with a coordinate of 1e30 is accepted with a warning next to
//   the upload control, which stays until dismissed;
// - an OBJ export of the textured, skinned glTF (skinned_tube.mjs) says
//   that UVs and skins are left out; a GLB export says nothing;
// - the morph-target export is disabled, with the reason as its tooltip,
//   for a mesh not uploaded as glTF, and enabled for the glTF;
// - a named-pose error stays beside its control past the pose list's
//   refresh (every 3 s) until dismissed.

import { mkdtempSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import assert from 'node:assert/strict';
import { log, launch, startServer, waitFor, presetsMissing, shutdown, runTest } from './lib.mjs';
import { skinnedTubeGlb } from './skinned_tube.mjs';

const dataDir = mkdtempSync(join(tmpdir(), 'dend-uploads-test-'));

/** A GLB split into a .gltf naming its binary chunk as `bin`, and that
 * chunk (the .bin file). */
function splitGlb(glb, bin) {
  const jsonLen = glb.readUInt32LE(12);
  const json = JSON.parse(glb.subarray(20, 20 + jsonLen).toString('utf8'));
  const binLen = glb.readUInt32LE(20 + jsonLen);
  const data = glb.subarray(28 + jsonLen, 28 + jsonLen + binLen);
  json.buffers[0].uri = bin;
  return { gltf: Buffer.from(JSON.stringify(json)), bin: Buffer.from(data) };
}

/** Drops files ({name, type, b64}) on the view as a person's drag and drop does. */
async function drop(page, files) {
  await page.evaluate((list) => {
    const dt = new DataTransfer();
    for (const f of list) {
      const bytes = Uint8Array.from(atob(f.b64), (c) => c.charCodeAt(0));
      dt.items.add(new File([bytes], f.name, { type: f.type }));
    }
    const view = document.getElementById('view');
    for (const type of ['dragenter', 'dragover', 'drop']) {
      view.dispatchEvent(new DragEvent(type, { dataTransfer: dt, bubbles: true, cancelable: true }));
    }
  }, files.map((f) => ({ ...f, b64: f.buffer.toString('base64') })));
}

/** Waits for a session on a mesh of `vertices` vertices other than `before`. */
async function opened(page, before, vertices, what) {
  await waitFor(page, ([b, n]) => {
    const a = window.dend.app;
    return a.session && a.session.id !== b && a.ws && a.positions && a.positions.length === 3 * n;
  }, [before, vertices], what, 60000);
}

const sessionId = (page) => page.evaluate(() => window.dend.app.session && window.dend.app.session.id);

const TETRA = (far) => `v 0 0 0\nv 1 0 0\nv 0 1 0\nv ${far} 0 1\nf 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n`;

async function dragAndDrop(page) {
  let before = await sessionId(page);
  await drop(page, [{ name: 'tetra.obj', type: 'text/plain', buffer: Buffer.from(TETRA(0)) }]);
  await opened(page, before, 4, 'the dropped OBJ');
  before = await sessionId(page);
  const glb = skinnedTubeGlb();
  await drop(page, [{ name: 'tube.glb', type: 'model/gltf-binary', buffer: glb }]);
  await opened(page, before, 209, 'the dropped GLB');
  // a .gltf and its .bin, dropped together
  const { gltf, bin } = splitGlb(glb, 'tube%20data.bin');
  before = await sessionId(page);
  await drop(page, [
    { name: 'tube.gltf', type: 'model/gltf+json', buffer: gltf },
    { name: 'tube data.bin', type: 'application/octet-stream', buffer: bin },
  ]);
  await opened(page, before, 209, 'the dropped .gltf with its .bin');
  const info = await page.evaluate(() => window.dend.app.meshInfo);
  assert.equal(info.asset.format, 'gltf', 'kept as a glTF asset');
  // without its .bin: the reason, beside the upload control
  before = await sessionId(page);
  await drop(page, [{ name: 'tube.gltf', type: 'model/gltf+json', buffer: gltf }]);
  await waitFor(page, () => document.getElementById('uploadMsg') !== null, null, 'the missing file named');
  const msg = await page.locator('#uploadMsg').textContent();
  log('a .gltf alone:', msg);
  assert.match(msg, /tube%20data\.bin/);
  assert.equal(await sessionId(page), before, 'the open session stays');
  await page.click('#uploadMsg button');
}

async function absurdCoordinates(page) {
  const before = await sessionId(page);
  await page.setInputFiles('#upload', { name: 'far.obj', mimeType: 'text/plain', buffer: Buffer.from(TETRA(1e30)) });
  await opened(page, before, 4, 'the mesh with a 1e30 coordinate');
  await waitFor(page, () => document.getElementById('uploadMsg') !== null, null, 'a warning about the extent');
  const msg = await page.locator('#uploadMsg').textContent();
  log('1e30 upload:', msg);
  assert.match(msg, /1\.000e30/, 'the warning gives the extent');
  await page.waitForTimeout(3500);
  assert.ok(await page.locator('#uploadMsg').isVisible(), 'it stays');
  await page.click('#uploadMsg button');
  assert.equal(await page.locator('#uploadMsg').count(), 0, 'until dismissed');
}

async function exportWarnings(page) {
  const before = await sessionId(page);
  await page.setInputFiles('#upload', { name: 'tube.glb', mimeType: 'model/gltf-binary', buffer: skinnedTubeGlb() });
  await opened(page, before, 209, 'the textured tube');
  await waitFor(page, () => !document.getElementById('poseMorph').disabled, null, 'the morph export offered for the glTF');
  await page.selectOption('#exportFormat', 'obj');
  const download = page.waitForEvent('download');
  await page.click('#export');
  const file = await download;
  const text = await (await file.createReadStream()).toArray().then((c) => Buffer.concat(c).toString());
  const vt = text.split('\n').filter((l) => l.startsWith('vt ')).length;
  log('OBJ export:', text.split('\n').filter((l) => l.startsWith('v ')).length, 'v lines,', vt, 'vt lines');
  await waitFor(page, () => document.getElementById('exportMsg') !== null, null, 'the export warning');
  const msg = await page.locator('#exportMsg').textContent();
  log('export warning:', msg);
  assert.equal(vt, 0, 'the OBJ has no UVs');
  assert.match(msg, /TEXCOORD_0/, 'the warning names the UVs');
  assert.match(msg, /skins/, 'and the skin');
  await page.selectOption('#exportFormat', 'glb');
  const again = page.waitForEvent('download');
  await page.click('#export');
  await again;
  await waitFor(page, () => document.getElementById('exportMsg') === null, null, 'no warning for a GLB');
}

async function poseErrors(page) {
  await page.selectOption('#shape', 'creature');
  const before = await sessionId(page);
  await page.click('#generate');
  await waitFor(page, (b) => window.dend.app.session.id !== b && window.dend.app.state === 'ready', before, 'the creature');
  const morph = page.locator('#poseMorph');
  await waitFor(page, () => document.getElementById('poseMorph').disabled, null, 'the morph export disabled for a generated mesh');
  const why = await morph.getAttribute('title');
  log('morph export on the creature:', why);
  assert.match(why, /glTF/, 'the tooltip gives the reason');
  // an error of the pose tools: a blank name
  await page.fill('#poseName', '   ');
  await page.click('#poseSave');
  await waitFor(page, () => document.getElementById('poseSaveMsg') !== null, null, 'the save error');
  await page.waitForTimeout(4000); // past the list's refresh
  const msg = page.locator('#poseSaveMsg');
  assert.ok(await msg.isVisible(), 'the error is still shown after the refresh');
  log('pose error kept:', await msg.textContent());
  assert.match(await msg.textContent(), /invalid_pose_name/);
  await page.click('#poseSaveMsg button');
  assert.equal(await msg.count(), 0, 'dismissed');
}

async function main() {
  const { proc, base } = await startServer(dataDir);
  log('server at', base);
  const browser = await launch();
  const pageErrors = [];
  try {
    const ctx = await browser.newContext({ viewport: { width: 1280, height: 720 }, acceptDownloads: true });
    const page = await ctx.newPage();
    page.on('pageerror', (e) => pageErrors.push(`page: ${e.message}`));
    // (the blank pose name's request is refused on purpose: the browser logs its 422)
    const refused = (m) => /status of 422/.test(m.text()) && /\/poses$/.test((m.location() && m.location().url) || '');
    page.on('console', (m) => { if (m.type() === 'error' && !presetsMissing(m) && !refused(m)) pageErrors.push(`console: ${m.text()}`); });
    await page.goto(base + '/');
    await waitFor(page, () => window.dend && window.dend.app.opened && window.dend.app.state === 'ready', null, 'the creature', 90000);
    await dragAndDrop(page);
    log('drag and drop uploads');
    await absurdCoordinates(page);
    log('absurd coordinates warned about');
    await exportWarnings(page);
    log('export warnings shown');
    await poseErrors(page);
    log('pose errors stay; the morph export says when it cannot apply');
    assert.deepEqual(pageErrors, [], 'no page errors');
  } finally {
    await shutdown(browser, proc, dataDir);
  }
  log('uploads test passed');
}

runTest(main);
