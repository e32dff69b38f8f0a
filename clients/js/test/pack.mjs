// `npm pack`, then the packed package used as an application would: its
// `exports` map resolves the core, `./frame` and `./three` entry points in
// Node (from a node_modules folder, three.js beside it) and in Chromium
// through a bundler-free import map built from that same map; paths it
// does not export are refused; the tarball holds the sources and their
// types and no tests.
// `node test/pack.mjs` (CHROMIUM: the browser; default /usr/bin/chromium).

import assert from 'node:assert/strict';
import { execFileSync } from 'node:child_process';
import { createServer } from 'node:http';
import { cpSync, mkdirSync, mkdtempSync, readFileSync, rmSync, writeFileSync, existsSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { dirname, extname, join, normalize, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';

const pkgDir = resolve(dirname(fileURLToPath(import.meta.url)), '..');
const tmp = mkdtempSync(join(tmpdir(), 'dend-pack-'));
try {
  const [packed] = JSON.parse(execFileSync('npm', ['pack', '--json', '--pack-destination', tmp], { cwd: pkgDir, encoding: 'utf8' }));
  const files = packed.files.map((f) => f.path).sort();
  for (const want of ['package.json', 'README.md', 'src/index.js', 'src/index.d.ts', 'src/three/index.js', 'src/three/index.d.ts',
    'src/frame.js', 'src/frame.d.ts', 'src/api.js', 'src/session.js', 'src/errors.js', 'examples/three/index.html']) {
    assert.ok(files.includes(want), `the package holds ${want} (it holds ${files.join(', ')})`);
  }
  assert.ok(!files.some((f) => f.startsWith('test/')), 'no tests in the package');
  const app = join(tmp, 'app');
  const nm = join(app, 'node_modules');
  mkdirSync(nm, { recursive: true });
  execFileSync('tar', ['xzf', join(tmp, packed.filename), '-C', nm]);
  execFileSync('mv', [join(nm, 'package'), join(nm, 'dend-client')]);
  cpSync(join(pkgDir, 'node_modules', 'three'), join(nm, 'three'), { recursive: true });
  const pkg = JSON.parse(readFileSync(join(nm, 'dend-client', 'package.json'), 'utf8'));
  assert.deepEqual(pkg.dependencies || {}, {}, 'no runtime dependencies');

  // Node: by name, through the exports map
  writeFileSync(join(app, 'main.mjs'), `
    const core = await import('dend-client');
    const three = await import('dend-client/three');
    const frame = await import('dend-client/frame');
    let refused = null;
    try { await import('dend-client/src/api.js'); } catch (e) { refused = e.code; }
    console.log(JSON.stringify({ core: Object.keys(core), three: Object.keys(three), frame: Object.keys(frame), refused,
      same: core.FrameDecoder === frame.FrameDecoder }));`);
  const node = JSON.parse(execFileSync(process.execPath, ['main.mjs'], { cwd: app, encoding: 'utf8' }));
  for (const name of ['Client', 'Session', 'SessionSocket', 'FrameDecoder', 'parseFrame', 'ApiError', 'FrameError']) {
    assert.ok(node.core.includes(name), `dend-client exports ${name}`);
  }
  for (const name of ['SessionGeometry', 'HandleDragControls', 'geometryFromMesh']) {
    assert.ok(node.three.includes(name), `dend-client/three exports ${name}`);
  }
  assert.ok(node.same, 'dend-client/frame is the core module, not a copy');
  assert.equal(node.refused, 'ERR_PACKAGE_PATH_NOT_EXPORTED');
  console.log(`[pack] ${packed.filename}: ${files.length} files, ${packed.size} bytes; Node resolves ${Object.keys(pkg.exports).join(', ')}`);

  // Chromium: an import map made from the exports map, the files served as a static site would
  const imports = { three: '/node_modules/three/build/three.module.js' };
  for (const [sub, target] of Object.entries(pkg.exports)) {
    if (sub.endsWith('.json')) continue;
    const to = typeof target === 'string' ? target : target.default;
    imports[sub === '.' ? 'dend-client' : `dend-client/${sub.slice(2)}`] = `/node_modules/dend-client/${to.slice(2)}`;
  }
  writeFileSync(join(app, 'index.html'), `<!doctype html><script type="importmap">${JSON.stringify({ imports })}</script>
    <script type="module">
      const core = await import('dend-client');
      const three = await import('dend-client/three');
      const frame = await import('dend-client/frame');
      const f = await new core.FrameDecoder().decode(new Uint8Array([68,69,78,68,2,0,0,0, 1,0,0,0,0,0,0,0, 0,0,0,0,0,0,0,0, 0,0,0,0, 0,0,0,0, 0,0,0,0,0,0,248,127]).buffer);
      window.result = { core: Object.keys(core), three: Object.keys(three), same: core.FrameDecoder === frame.FrameDecoder, revision: f.revision };
    </script>`);
  const types = { '.js': 'text/javascript', '.html': 'text/html' };
  const server = createServer((req, res) => {
    const path = normalize(join(app, decodeURIComponent(new URL(req.url, 'http://x').pathname)));
    if (!path.startsWith(app) || !existsSync(path)) { res.writeHead(404).end(); return; }
    res.writeHead(200, { 'Content-Type': types[extname(path)] || 'application/octet-stream' }).end(readFileSync(path));
  });
  await new Promise((r) => server.listen(0, '127.0.0.1', r));
  const { chromium } = await import('playwright-core');
  const browser = await chromium.launch({
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
    args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-background-networking'],
  });
  try {
    const page = await browser.newPage();
    const errors = [];
    page.on('pageerror', (e) => errors.push(e.message));
    await page.goto(`http://127.0.0.1:${server.address().port}/index.html`);
    await page.waitForFunction(() => window.result || null, null, { timeout: 15000 }).catch(() => {});
    const result = await page.evaluate(() => window.result);
    assert.ok(result, `the page imported the package (${errors.join('; ')})`);
    assert.ok(result.core.includes('SessionSocket') && result.three.includes('SessionGeometry'));
    assert.ok(result.same);
    assert.equal(result.revision, 1);
    console.log(`[pack] Chromium resolves ${Object.keys(imports).join(', ')} through an import map`);
  } finally {
    await browser.close();
    server.close();
  }
} finally {
  rmSync(tmp, { recursive: true, force: true });
}
console.log('1 passed, 0 failed');
