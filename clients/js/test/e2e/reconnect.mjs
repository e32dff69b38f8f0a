// Reconnection against the real `dend serve` (SQLite store): a client
// drags the tube's handle (drag k moves it up by a distinct dy(k)) while
// the server is killed (SIGKILL) mid-drag and restarted, then stopped
// (SIGTERM) and restarted; drags sent to it while it is frozen (SIGSTOP,
// before the kill) are lost with it, and drags made while it is down wait. The client
// must reopen the socket by itself, resume from the first frame's ack_seq
// (never below the last drag acknowledged before the restart), send again
// the drags the server did not apply, and end with the handle exactly at
// the sum of every drag: none lost, none applied twice.
// Node: `node test/e2e/reconnect.mjs` (re-run with --experimental-websocket
// on a Node without a global WebSocket).

import assert from 'node:assert/strict';
import { execFileSync } from 'node:child_process';
import { mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { fileURLToPath } from 'node:url';
import { Client } from '../../src/index.js';
import { freePort, log, run, startServer, stopServer, tube } from './lib.mjs';

if (typeof WebSocket !== 'function') {
  try {
    execFileSync(process.execPath, ['--experimental-websocket', fileURLToPath(import.meta.url)], { stdio: 'inherit' });
    process.exit(0);
  } catch (e) {
    process.exit(e.status || 1);
  }
}

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
const dy = (k) => 0.002 * (1 + (k % 5));

run('reconnect', async () => {
  const dataDir = mkdtempSync(join(tmpdir(), 'dend-reconnect-'));
  const port = await freePort();
  let server = await startServer(dataDir, port);
  try {
    const client = new Client(server.base);
    const { positions, triangles, constraints } = tube(21, 12);
    const mesh = await client.uploadMesh(positions, triangles);
    const session = await client.createSession(mesh.id);
    await session.setConstraints(constraints);
    await session.waitReady();
    const socket = await session.connect({ encoding: 'delta', ack: 'frame' });
    const closes = [];
    const resyncs = [];
    let lastAcked = 0;
    socket.on('frame', (f) => { lastAcked = Math.max(lastAcked, f.ackSeq); });
    const t0 = Date.now();
    socket.on('reconnecting', (c) => { closes.push(c.code); log(`+${Date.now() - t0} ms: closed (${c.code}), reconnecting`); });
    socket.on('open', () => log(`+${Date.now() - t0} ms: open`));
    socket.on('reconnected', (r) => { resyncs.push(r); log(`+${Date.now() - t0} ms: resumed at ack_seq ${r.ackSeq}: ${r.sent} drags sent, ${r.resent} of them again`); });
    socket.on('error', (e) => log(`+${Date.now() - t0} ms: ${e.code}: ${e.message}`));

    const N = 120;
    const ackedAtRestart = [];
    let total = 0;
    for (let k = 1; k <= N; k++) {
      socket.drag('end', { translate: [0, dy(k), 0] });
      total += dy(k);
      if (k === 40 || k === 80) {
        const signal = k === 40 ? 'SIGKILL' : 'SIGTERM';
        if (signal === 'SIGKILL') {
          // frozen first: these drags leave on the open socket and are
          // never applied, so the client must send them again
          server.proc.kill('SIGSTOP');
          await sleep(50);
          for (let j = 0; j < 5; j++) {
            k++;
            socket.drag('end', { translate: [0, dy(k), 0] });
            total += dy(k);
          }
          await sleep(50);
        }
        ackedAtRestart.push(lastAcked);
        log(`${signal} at drag ${k} (acknowledged up to ${lastAcked}, ${socket.stats().pendingDrags} drags pending)`);
        await stopServer(server.proc, signal);
        // drags while the server is down wait in the client
        for (let j = 0; j < 5; j++) {
          k++;
          socket.drag('end', { translate: [0, dy(k), 0] });
          total += dy(k);
          await sleep(20);
        }
        server = await startServer(dataDir, port);
        log(`+${Date.now() - t0} ms: server restarted`);
      }
      await sleep(8);
    }
    const settled = await socket.settledFrame(60000).catch((e) => {
      throw new Error(`${e.message}: status ${socket.status}, seq ${socket.seq}, latest ${socket.latest && JSON.stringify({ ...socket.latest, positions: undefined })}, closes ${JSON.stringify(closes)}, resyncs ${JSON.stringify(resyncs)}, ${JSON.stringify(socket.stats())}`);
    });
    const stats = socket.stats();
    log(`settled at ack_seq ${settled.ackSeq} of ${socket.seq}; closes ${JSON.stringify(closes)}; resyncs ${JSON.stringify(resyncs)}; ${JSON.stringify(stats)}`);
    assert.equal(stats.reconnects, 2, 'reopened after each restart');
    assert.equal(resyncs.length, 2);
    resyncs.forEach((r, i) => assert.ok(r.ackSeq >= ackedAtRestart[i],
      `restart ${i}: the first frame's ack_seq ${r.ackSeq} is not below the last acknowledged ${ackedAtRestart[i]}`));
    assert.equal(stats.pendingDrags, 0);
    assert.ok(stats.resentDrags >= 5, `the drags the frozen server never applied were sent again (${stats.resentDrags})`);
    assert.equal(settled.ackSeq, socket.seq);

    const pose = await session.pose();
    const handle = constraints.handles[0].vertices;
    let worst = 0;
    for (const v of handle) {
      const want = [positions[v][0], positions[v][1] + total, positions[v][2]];
      worst = Math.max(worst, ...[0, 1, 2].map((k) => Math.abs(pose.positions[v][k] - want[k])));
    }
    log(`handle vs the sum of all ${socket.seq} drags (${total.toFixed(4)}): ${worst.toExponential(2)}`);
    assert.ok(worst < 1e-6, `every drag applied exactly once (handle off by ${worst})`);
    socket.close();
  } finally {
    await stopServer(server.proc);
    rmSync(dataDir, { recursive: true, force: true });
  }
});
