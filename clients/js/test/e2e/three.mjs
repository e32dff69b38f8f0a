// The three.js example in Chromium against the real `dend serve`: the
// page at /examples/three/ uploads its tube and connects; the test drags
// the handle with the mouse through the binding (HandleDragControls) and
// checks that
// - "settled" arrives, acknowledging the last drag;
// - the geometry three.js draws is the server's pose (GET .../pose, f64)
//   within 1e-4 of the pose's box diagonal, and the handle followed the
//   pointer;
// - the socket never held more than one frame unacknowledged (counted by
//   a wrapper of the page's WebSocket, independently of the client).

import assert from 'node:assert/strict';
import { mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { artifacts, freePort, launch, log, run, startServer, stopServer } from './lib.mjs';

/** Counts, in the page, the frames received and not yet acknowledged. */
function instrument() {
  const Base = window.WebSocket;
  const w = { frames: 0, acks: 0, outstanding: [], maxOutstanding: 0 };
  window.__ws = w;
  window.WebSocket = class extends Base {
    constructor(...a) {
      super(...a);
      this.addEventListener('message', (m) => {
        if (typeof m.data === 'string') return;
        const rev = Number(new DataView(m.data).getBigUint64(8, true));
        w.frames++;
        w.outstanding.push(rev);
        w.maxOutstanding = Math.max(w.maxOutstanding, w.outstanding.length);
      });
    }

    send(d) {
      try {
        const j = JSON.parse(d);
        if (j.type === 'ack') {
          w.acks++;
          w.outstanding = w.outstanding.filter((r) => r > j.revision);
        }
      } catch (_) { /* not JSON */ }
      super.send(d);
    }
  };
}

run('three.js example', async () => {
  const dataDir = mkdtempSync(join(tmpdir(), 'dend-three-'));
  const { proc, base } = await startServer(dataDir, await freePort());
  const browser = await launch();
  try {
    const page = await browser.newPage({ viewport: { width: 1000, height: 640 } });
    const errors = [];
    page.on('pageerror', (e) => errors.push(e.message));
    page.on('console', (m) => {
      const url = (m.location() && m.location().url) || '';
      // a browser asks for /favicon.ico by itself
      if (m.type() === 'error' && !url.endsWith('/favicon.ico')) errors.push(`${m.text()} ${url}`);
    });
    await page.addInitScript(instrument);
    await page.goto(`${base}/examples/three/`);
    await page.waitForFunction(() => window.example && window.example.socket.latest, null, { timeout: 60000 })
      .catch((e) => { throw new Error(`the example did not start: ${errors.join('; ') || e.message}`); });

    // the handle's front vertex on the last-but-one ring, on the screen
    const handleVertex = 39 * 16 + 4;
    const at = await page.evaluate((v) => {
      const { object, camera } = window.example;
      const p = object.geometry.getAttribute('position');
      const V = camera.position.constructor;
      const s = new V(p.getX(v), p.getY(v), p.getZ(v)).applyMatrix4(object.matrixWorld).project(camera);
      const r = document.querySelector('canvas').getBoundingClientRect();
      return { x: r.left + ((s.x + 1) / 2) * r.width, y: r.top + ((1 - s.y) / 2) * r.height, rest: [p.getX(v), p.getY(v), p.getZ(v)] };
    }, handleVertex);
    log(`handle vertex ${handleVertex} at (${at.x.toFixed(0)}, ${at.y.toFixed(0)}) px`);

    await page.mouse.move(at.x, at.y);
    await page.mouse.down();
    const steps = 30;
    for (let k = 1; k <= steps; k++) {
      await page.mouse.move(at.x - 2 * k, at.y - 6 * k);
      await page.waitForTimeout(16);
    }
    await page.mouse.up();
    const sent = await page.evaluate(() => window.example.socket.seq);
    assert.ok(sent >= steps / 2, `the binding sent drags (${sent})`);

    await page.waitForFunction(() => {
      const s = window.example.socket;
      return s.latest && s.latest.settled && s.latest.ackSeq >= s.seq && s.stats().pendingDrags === 0;
    }, null, { timeout: 60000 }).catch(async () => {
      const st = await page.evaluate(() => ({ stats: window.example.socket.stats(), seq: window.example.socket.seq, ack: window.example.socket.latest.ackSeq }));
      throw new Error(`no settled frame acknowledged drag ${st.seq} (${JSON.stringify(st)})`);
    });
    log('settled after the drag');

    const { token, id, geometry, stats, ws } = await page.evaluate(() => {
      const { session, object, socket } = window.example;
      return {
        token: session.token, id: session.id, geometry: Array.from(object.geometry.getAttribute('position').array),
        stats: socket.stats(), ws: window.__ws,
      };
    });
    const res = await fetch(`${base}/v1/sessions/${id}/pose`, { headers: { Authorization: `Bearer ${token}` } });
    const pose = await res.json();
    assert.equal(pose.ack_seq, sent, 'the server applied every drag');
    const lo = [0, 1, 2].map((k) => Math.min(...pose.positions.map((p) => p[k])));
    const hi = [0, 1, 2].map((k) => Math.max(...pose.positions.map((p) => p[k])));
    const diag = Math.hypot(...[0, 1, 2].map((k) => hi[k] - lo[k]));
    let worst = 0;
    pose.positions.forEach((p, v) => {
      worst = Math.max(worst, Math.hypot(p[0] - geometry[3 * v], p[1] - geometry[3 * v + 1], p[2] - geometry[3 * v + 2]));
    });
    log(`geometry vs server pose: ${worst.toExponential(2)} (${(worst / diag).toExponential(2)} of the diagonal ${diag.toFixed(3)})`);
    assert.ok(worst <= 1e-4 * diag, `the geometry is the server's pose within 1e-4 of the diagonal (${worst / diag})`);
    const moved = geometry[3 * handleVertex + 1] - at.rest[1];
    assert.ok(moved > 0.5, `the handle followed the pointer up (${moved})`);

    log(`frames ${ws.frames}, acks ${ws.acks}, most unacknowledged at once ${ws.maxOutstanding}; client: ${JSON.stringify(stats)}`);
    assert.ok(ws.frames > 5, 'frames streamed');
    assert.equal(ws.maxOutstanding, 1, 'never more than one frame unacknowledged');
    assert.ok(stats.maxUnacked <= 1);
    assert.ok(stats.encodings.delta > 0, 'delta frames during the drag');
    assert.ok(stats.latencyP50Ms !== null, 'drag latencies measured');
    await page.screenshot({ path: join(artifacts, 'three-example.png') });
    assert.deepEqual(errors, [], 'no page errors');
  } finally {
    await browser.close();
    await stopServer(proc);
    rmSync(dataDir, { recursive: true, force: true });
  }
});
