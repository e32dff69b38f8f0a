// The session socket's own logic, on a scripted WebSocket (no server):
// acknowledgements, drags kept until acknowledged and sent again after a
// reconnection from the first frame's ack_seq, refused drags sent again,
// close codes, figures. The real server's side: test/e2e/reconnect.mjs.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { SessionSocket, ApiError, ConnectionError, SessionError, shouldReconnect, Client, Session } from '../src/index.js';

/** A v2 frame of `n` vertices at x = revision. */
function frame(revision, ackSeq, { settled = false, n = 2 } = {}) {
  const b = new ArrayBuffer(40 + 12 * n);
  const dv = new DataView(b);
  [68, 69, 78, 68].forEach((c, i) => dv.setUint8(i, c));
  dv.setUint16(4, 2, true);
  dv.setUint16(6, settled ? 3 : 0, true);
  dv.setBigUint64(8, BigInt(revision), true);
  dv.setBigUint64(16, BigInt(ackSeq), true);
  dv.setUint32(28, n, true);
  for (let i = 0; i < 3 * n; i++) dv.setFloat32(40 + 4 * i, revision, true);
  return b;
}

class FakeWs {
  static all = [];

  constructor(url) {
    this.url = url;
    this.sent = [];
    this.readyState = 0;
    FakeWs.all.push(this);
    setTimeout(() => { this.readyState = 1; this.onopen && this.onopen(); }, 0);
  }

  send(d) { this.sent.push(JSON.parse(d)); }

  close(code = 1000, reason = '') { this.drop(code, reason); }

  drop(code, reason = '') {
    if (this.readyState === 3) return;
    this.readyState = 3;
    this.onclose && this.onclose({ code, reason });
  }

  receive(data) { this.onmessage({ data: typeof data === 'string' ? data : data }); }

  drags() { return this.sent.filter((m) => m.type === 'drag'); }
}

function fakeSession({ info = async () => ({ state: 'ready' }), pose = async () => ({ ack_seq: 0 }) } = {}) {
  const s = new Session(new Client('http://127.0.0.1:1'), 'sid', 'tok');
  s.info = info;
  s.pose = pose;
  return s;
}

const tick = (ms = 5) => new Promise((r) => setTimeout(r, ms));

test('frames are acknowledged once taken, and counted', async () => {
  FakeWs.all = [];
  const s = await new SessionSocket(fakeSession(), { WebSocket: FakeWs, ack: 'frame' }).open();
  const ws = FakeWs.all[0];
  assert.match(ws.url, /^ws:\/\/127\.0\.0\.1:1\/v1\/sessions\/sid\/ws\?token=tok&window=1&encoding=delta&refine_fps=30$/);
  const seen = [];
  s.on('frame', (f) => seen.push(f.revision));
  ws.receive(frame(5, 0));
  ws.receive(frame(6, 0, { settled: true }));
  await tick();
  assert.deepEqual(seen, [5, 6]);
  assert.deepEqual(ws.sent, [{ type: 'ack', revision: 5 }, { type: 'ack', revision: 6 }]);
  assert.equal(s.stats().maxUnacked, 1);
  assert.ok(s.settled && s.converged);
  assert.deepEqual(Array.from(s.positions), [6, 6, 6, 6, 6, 6]);
});

test('manual acks: frames pile up until acknowledged', async () => {
  FakeWs.all = [];
  const s = await new SessionSocket(fakeSession(), { WebSocket: FakeWs, ack: 'manual' }).open();
  const ws = FakeWs.all[0];
  ws.receive(frame(1, 0));
  ws.receive(frame(2, 0));
  await tick();
  assert.equal(s.stats().unacked, 2);
  s.ack();
  assert.deepEqual(ws.sent, [{ type: 'ack', revision: 2 }]);
  assert.equal(s.stats().unacked, 0);
});

test('drags are numbered, kept until a frame acknowledges them, latency measured', async () => {
  FakeWs.all = [];
  const s = await new SessionSocket(fakeSession(), { WebSocket: FakeWs, ack: 'frame' }).open();
  const ws = FakeWs.all[0];
  ws.receive(frame(10, 7));
  await tick();
  const a = s.drag(0, { translate: [1, 0, 0] });
  const b = s.drag('h', { rotate: { axis: [0, 0, 1], degrees: 5 } });
  assert.deepEqual([a, b], [8, 9], 'seqs continue above the session ack_seq');
  assert.deepEqual(ws.drags(), [
    { type: 'drag', handle: 0, translate: [1, 0, 0], seq: 8 },
    { type: 'drag', handle: 'h', rotate: { axis: [0, 0, 1], degrees: 5 }, seq: 9 },
  ]);
  assert.equal(s.stats().pendingDrags, 2);
  ws.receive(frame(11, 8));
  await tick();
  assert.equal(s.stats().pendingDrags, 1);
  assert.ok(s.stats().latencyMs >= 0);
  assert.throws(() => s.drag(0, { rotate: { axis: [1, 0, 0], degrees: 1 }, quaternion: [0, 0, 0, 1] }), TypeError);
});

test('after a reconnection only the drags past the first frame\'s ack_seq are sent again, grabs too', async () => {
  FakeWs.all = [];
  const s = await new SessionSocket(fakeSession(), { WebSocket: FakeWs, ack: 'frame' }).open();
  const first = FakeWs.all[0];
  s.grab(0);
  for (let k = 0; k < 5; k++) s.drag(0, { translate: [0, k, 0] });
  first.receive(frame(3, 2));
  await tick();
  const events = [];
  s.on('reconnecting', (c) => events.push(['reconnecting', c.code]));
  s.on('reconnected', (r) => events.push(['reconnected', r.ackSeq]));
  first.drop(1006);
  const late = s.drag(0, { translate: [0, 9, 0] });
  await tick(150);
  const second = FakeWs.all[1];
  assert.ok(second, 'reopened');
  assert.deepEqual(second.drags(), [], 'nothing is sent before the first frame says what the server holds');
  second.receive(frame(20, 4));
  await tick();
  assert.deepEqual(second.sent.filter((m) => m.type !== 'ack').map((m) => (m.type === 'drag' ? m.seq : m.type)), ['grab', 5, late]);
  assert.deepEqual(events, [['reconnecting', 1006], ['reconnected', 4]]);
  assert.equal(s.stats().reconnects, 1);
  assert.equal(s.stats().resentDrags, 1, 'drag 5 was sent before; drag 6 is sent for the first time');
});

test('a reopened socket without frames asks the pose for its ack_seq', async () => {
  FakeWs.all = [];
  const s = await new SessionSocket(fakeSession({ pose: async () => ({ ack_seq: 1 }) }), { WebSocket: FakeWs, ack: 'frame', resyncTimeoutMs: 20 }).open();
  s.drag(0, { translate: [1, 0, 0] });
  s.drag(0, { translate: [2, 0, 0] });
  FakeWs.all[0].drop(1012);
  await tick(200);
  assert.deepEqual(FakeWs.all[1].drags().map((m) => m.seq), [2]);
});

test('4012 reconnects at once; 4003 and a session that is gone end it', async () => {
  FakeWs.all = [];
  const s = await new SessionSocket(fakeSession(), { WebSocket: FakeWs }).open();
  FakeWs.all[0].drop(4012);
  await tick(20);
  assert.equal(FakeWs.all.length, 2);
  const closed = [];
  s.on('close', (c) => closed.push(c));
  FakeWs.all[1].drop(4003, 'forbidden');
  assert.equal(closed.length, 1);
  assert.ok(closed[0].error instanceof ConnectionError);
  assert.equal(closed[0].error.closeCode, 4003);
  assert.throws(() => s.drag(0, {}), ConnectionError);

  FakeWs.all = [];
  const gone = fakeSession({ info: async () => { throw new ApiError('session_not_found', 'no', 404); } });
  const t = await new SessionSocket(gone, { WebSocket: FakeWs }).open();
  const ends = [];
  t.on('close', (c) => ends.push(c));
  FakeWs.all[0].drop(4004);
  await tick(150);
  assert.equal(ends.length, 1);
  assert.equal(ends[0].error.code, 'session_not_found');
  assert.equal(FakeWs.all.length, 1);
  assert.ok(shouldReconnect(1006) && !shouldReconnect(1000) && !shouldReconnect(4001));
});

test('a drag refused as rate_limited is sent again with a new seq; other refusals are not', async () => {
  FakeWs.all = [];
  const s = await new SessionSocket(fakeSession(), { WebSocket: FakeWs, ack: 'frame' }).open();
  const ws = FakeWs.all[0];
  const errors = [];
  s.on('error', (e) => errors.push(e));
  const a = s.drag(0, { translate: [1, 0, 0] });
  const b = s.drag(0, { translate: [2, 0, 0] });
  ws.receive(JSON.stringify({ type: 'error', code: 'rate_limited', message: 'slow down', seq: a }));
  ws.receive(JSON.stringify({ type: 'error', code: 'unknown_handle', message: 'no', seq: b }));
  await tick(300);
  assert.ok(errors.every((e) => e instanceof SessionError));
  assert.deepEqual(errors.map((e) => [e.code, e.seq]), [['rate_limited', a], ['unknown_handle', b]]);
  const drags = ws.drags();
  assert.equal(drags.length, 3);
  assert.deepEqual(drags[2], { type: 'drag', handle: 0, translate: [1, 0, 0], seq: 3 });
  assert.equal(s.stats().pendingDrags, 1);
});

test('a frame that does not decode is reported and taken', async () => {
  FakeWs.all = [];
  const s = await new SessionSocket(fakeSession(), { WebSocket: FakeWs, ack: 'frame' }).open();
  const errors = [];
  s.on('error', (e) => errors.push(e.code));
  FakeWs.all[0].receive(new ArrayBuffer(12));
  await tick();
  assert.deepEqual(errors, ['frame_length']);
  assert.equal(FakeWs.all[0].sent[0].type, 'ack');
});
