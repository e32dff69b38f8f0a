// Helpers shared by the browser tests (browser.test.mjs, tools.test.mjs):
// the real `dend serve` on a free port, headless Chromium, waiting for page
// state, the server's pose, pixel comparisons, screen boxes.

import { spawn } from 'node:child_process';
import { mkdirSync, rmSync } from 'node:fs';
import { dirname, join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';
import assert from 'node:assert/strict';
import { chromium } from 'playwright-core';

const here = dirname(fileURLToPath(import.meta.url));
export const root = resolve(here, '..', '..');
export const artifacts = join(root, 'web', 'test-artifacts');
const bin = process.env.DEND_BIN || join(root, 'target', 'debug', 'dend');
const chromiumPath = process.env.CHROMIUM || '/usr/bin/chromium';
mkdirSync(artifacts, { recursive: true });

export function log(...a) { console.log('[web-test]', ...a); }

/** The end of every browser test: closes the browser, stops the server
 * (SIGTERM, then 200 ms to exit) and removes its data folder. */
export async function shutdown(browser, proc, dataDir) {
  await browser.close();
  proc.kill('SIGTERM');
  await new Promise((res) => setTimeout(res, 200));
  rmSync(dataDir, { recursive: true, force: true });
}

/** Runs a test's `main`; any error is printed and exits with status 1. */
export function runTest(main) {
  main().catch((e) => {
    console.error('[web-test] FAILED:', e && e.stack ? e.stack : e);
    process.exit(1);
  });
}

/** Whether a console message is the browser's report of a 404 from
 * `GET /v1/presets`: a server without the presets route (the editor then
 * shows its defaults and no menu), not a page error. */
export function presetsMissing(m) {
  const url = (m.location && m.location().url) || '';
  return /\/v1\/presets$/.test(url) && /404/.test(m.text());
}

/** Headless Chromium (Debian's). */
export function launch() {
  return chromium.launch({
    executablePath: chromiumPath,
    args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-background-networking',
      '--disable-component-update', '--disable-sync', '--disable-quic', '--no-first-run'],
  });
}

/** Starts `dend serve` with its store in `dataDir` on `addr` (default: a
 * free port); resolves with {proc, base}. The page is served from web/ on
 * disk (`DEND_WEB_DIR`), so the tests run the client being edited even
 * with a binary built before the edit (its embedded copy is kept equal to
 * web/ by a unit test of the server). */
export function startServer(dataDir, addr = '127.0.0.1:0') {
  const env = { ...process.env, DEND_WEB_DIR: join(root, 'web') };
  const proc = spawn(bin, ['serve', '--addr', addr, '--data-dir', dataDir], { stdio: ['ignore', 'pipe', 'pipe'], env });
  let stderr = '';
  proc.stderr.on('data', (d) => { stderr += d; });
  return new Promise((res, rej) => {
    const timer = setTimeout(() => rej(new Error(`server did not print its URL in 60 s; stderr:\n${stderr}`)), 60000);
    let out = '';
    proc.stdout.on('data', (d) => {
      out += d;
      const m = out.match(/listening on (http:\/\/[^\s]+)/);
      if (m) {
        clearTimeout(timer);
        res({ proc, base: m[1] });
      }
    });
    proc.on('exit', (code) => rej(new Error(`server exited with ${code}; stderr:\n${stderr}`)));
    proc.on('error', rej);
  });
}

export async function waitFor(page, fn, arg, what, timeout = 30000) {
  try {
    await page.waitForFunction(fn, arg, { timeout, polling: 50 });
  } catch (e) {
    const stats = await page.evaluate(() => window.dend && window.dend.stats()).catch(() => null);
    const err = await page.locator('#error').textContent().catch(() => '');
    throw new Error(`timed out waiting for ${what}; stats ${JSON.stringify(stats)}; error banner "${err}"`);
  }
}

/** Waits until the page draws `expected` (every coordinate within 1e-5). */
export async function waitForPose(page, expected, what) {
  await waitFor(page, (e) => {
    const p = window.dend.positions();
    let m = 0;
    for (let i = 0; i < p.length; i++) m = Math.max(m, Math.abs(p[i] - e[i]));
    return m < 1e-5;
  }, Array.from(expected), what, 30000);
}

export async function serverPose(base, s) {
  const r = await fetch(`${base}/v1/sessions/${s.id}/pose`, {
    headers: { Authorization: `Bearer ${s.token}`, Accept: 'application/octet-stream' },
  });
  assert.equal(r.status, 200, `GET pose: ${r.status}`);
  return new Float32Array(await r.arrayBuffer());
}

export function maxDiff(a, b, idx) {
  let m = 0;
  for (const i of idx) for (let k = 0; k < 3; k++) m = Math.max(m, Math.abs(a[3 * i + k] - b[3 * i + k]));
  return m;
}

/** Fraction of pixels that differ (any channel by > 24) between two PNGs,
 * decoded by the browser. */
export async function pixelDiff(page, pngA, pngB) {
  return page.evaluate(async ([a, b]) => {
    const load = async (b64) => {
      const img = new Image();
      img.src = `data:image/png;base64,${b64}`;
      await img.decode();
      const c = document.createElement('canvas');
      c.width = img.width;
      c.height = img.height;
      const g = c.getContext('2d');
      g.drawImage(img, 0, 0);
      return g.getImageData(0, 0, c.width, c.height).data;
    };
    const [x, y] = [await load(a), await load(b)];
    if (x.length !== y.length) return 1;
    let n = 0;
    for (let i = 0; i < x.length; i += 4) {
      if (Math.abs(x[i] - y[i]) > 24 || Math.abs(x[i + 1] - y[i + 1]) > 24 || Math.abs(x[i + 2] - y[i + 2]) > 24) n++;
    }
    return n / (x.length / 4);
  }, [pngA.toString('base64'), pngB.toString('base64')]);
}

/** Pixel statistics of a PNG, decoded by the browser: `colours`, the
 * distinct colours (5 bits a channel, every 4th pixel; checks WebGL really
 * drew something), and `dark`, the pixels darker than 70 in every channel
 * (the region hatch's stripes). */
export async function pngStats(page, png) {
  return page.evaluate(async (b64) => {
    const img = new Image();
    img.src = `data:image/png;base64,${b64}`;
    await img.decode();
    const c = document.createElement('canvas');
    [c.width, c.height] = [img.width, img.height];
    const g = c.getContext('2d');
    g.drawImage(img, 0, 0);
    const d = g.getImageData(0, 0, c.width, c.height).data;
    const s = new Set();
    let dark = 0;
    for (let i = 0; i < d.length; i += 4) {
      if (i % 16 === 0) s.add((d[i] >> 3) * 1024 + (d[i + 1] >> 3) * 32 + (d[i + 2] >> 3));
      if (d[i] < 70 && d[i + 1] < 70 && d[i + 2] < 70) dark++;
    }
    return { colours: s.size, dark };
  }, png.toString('base64'));
}

/** Screen box (CSS px, page coordinates) around the given vertices. */
export async function screenBox(page, idx, pad) {
  const pts = await page.evaluate((i) => window.dend.project(i), idx);
  const canvas = await page.locator('#view').boundingBox();
  const xs = pts.map((p) => p[0]), ys = pts.map((p) => p[1]);
  return {
    x0: canvas.x + Math.min(...xs) - pad, y0: canvas.y + Math.min(...ys) - pad,
    x1: canvas.x + Math.max(...xs) + pad, y1: canvas.y + Math.max(...ys) + pad,
  };
}

export async function boxSelect(page, b) {
  await page.mouse.move(b.x0, b.y0);
  await page.mouse.down();
  await page.mouse.move(b.x1, b.y1, { steps: 5 });
  await page.mouse.up();
}

