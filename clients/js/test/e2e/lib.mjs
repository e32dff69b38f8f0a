// Helpers of the package's end-to-end tests: the real `dend serve` (the
// binary in $DEND_BIN, else target/debug/dend) on a port of this machine,
// the example's tube, headless Chromium.

import { spawn } from 'node:child_process';
import { createServer } from 'node:net';
import { mkdirSync } from 'node:fs';
import { dirname, join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
export const pkgDir = resolve(here, '..', '..');
export const repo = resolve(pkgDir, '..', '..');
export const artifacts = join(repo, 'web', 'test-artifacts');
mkdirSync(artifacts, { recursive: true });
const bin = process.env.DEND_BIN || join(process.env.CARGO_TARGET_DIR || join(repo, 'target'), 'debug', 'dend');

export function log(...a) { console.log('[dend-client]', ...a); }

/** A free TCP port on 127.0.0.1. */
export function freePort() {
  return new Promise((res, rej) => {
    const s = createServer();
    s.on('error', rej);
    s.listen(0, '127.0.0.1', () => {
      const { port } = s.address();
      s.close(() => res(port));
    });
  });
}

/** Starts `dend serve` on `port` with its SQLite store in `dataDir`; the
 * web files from the work tree (DEND_WEB_DIR) and three.js from this
 * package's node_modules. Resolves with {proc, base} once it listens. */
export function startServer(dataDir, port) {
  const env = {
    ...process.env,
    DEND_WEB_DIR: join(repo, 'web'),
    DEND_THREE_DIR: join(pkgDir, 'node_modules', 'three', 'build'),
  };
  const proc = spawn(bin, ['serve', '--addr', `127.0.0.1:${port}`, '--data-dir', dataDir], { stdio: ['ignore', 'pipe', 'pipe'], env });
  let stderr = '';
  proc.stderr.on('data', (d) => { stderr += d; });
  return new Promise((res, rej) => {
    const timer = setTimeout(() => rej(new Error(`server did not start in 60 s:\n${stderr}`)), 60000);
    let out = '';
    proc.stdout.on('data', (d) => {
      out += d;
      const m = out.match(/listening on (http:\/\/[^\s]+)/);
      if (m) {
        clearTimeout(timer);
        res({ proc, base: m[1] });
      }
    });
    proc.on('exit', (code, sig) => { clearTimeout(timer); rej(new Error(`server exited (${code ?? sig}):\n${stderr}`)); });
  });
}

/** Stops a server with `signal` and waits for its exit. */
export function stopServer(proc, signal = 'SIGTERM') {
  if (proc.exitCode !== null || proc.signalCode !== null) return Promise.resolve();
  return new Promise((res) => {
    proc.removeAllListeners('exit');
    proc.on('exit', () => res());
    proc.kill(signal);
  });
}

/** The example's tube: M rings of K vertices along x (length 4, radius
 * 0.3), the first three rings fixed and the last three the handle. */
export function tube(M = 41, K = 16) {
  const positions = [];
  const triangles = [];
  for (let i = 0; i < M; i++) {
    for (let j = 0; j < K; j++) {
      const a = (2 * Math.PI * j) / K;
      positions.push([(4 * i) / (M - 1), 0.3 * Math.cos(a), 0.3 * Math.sin(a)]);
    }
  }
  for (let i = 0; i + 1 < M; i++) {
    for (let j = 0; j < K; j++) {
      const a = i * K + j;
      const b = i * K + ((j + 1) % K);
      triangles.push([a, b, b + K], [a, b + K, a + K]);
    }
  }
  const rings = (...is) => is.flatMap((i) => Array.from({ length: K }, (_, j) => i * K + j));
  return { positions, triangles, constraints: { fixed: rings(0, 1, 2), handles: [{ name: 'end', vertices: rings(M - 3, M - 2, M - 1) }] } };
}

/** Headless Chromium (Debian's). */
export async function launch() {
  const { chromium } = await import('playwright-core');
  return chromium.launch({
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
    args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-background-networking',
      '--disable-component-update', '--disable-sync', '--no-first-run'],
  });
}

/** Runs `main`; a failure is printed and exits with status 1. */
export function run(name, main) {
  main().then(() => {
    console.log(`${name}: 1 passed, 0 failed`);
    process.exit(0);
  }, (e) => {
    console.error(`[dend-client] ${name} FAILED:`, e && e.stack ? e.stack : e);
    process.exit(1);
  });
}
