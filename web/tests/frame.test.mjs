// The editor's pose frame decoder (web/js/api.js `parseFrame`) on frames
// laid out as api/ws-protocol.md says: version 2, version 3 in f32 and in
// q16 (within 1e-4 of the box diagonal), a stream of delta frames (made
// here from the protocol's text, independently of the server's encoder),
// and malformed frames refused.
// Plain node, no browser: `node web/tests/frame.test.mjs`.

import assert from 'node:assert/strict';
import { parseFrame, FrameDecoder } from '../js/api.js';

function header(version, n, size) {
  const buf = new ArrayBuffer(size);
  const dv = new DataView(buf);
  [68, 69, 78, 68].forEach((c, i) => dv.setUint8(i, c));
  dv.setUint16(4, version, true);
  dv.setUint16(6, 2, true); // settled
  dv.setBigUint64(8, 11n, true);
  dv.setBigUint64(16, 4n, true);
  dv.setUint32(24, 9, true);
  dv.setUint32(28, n, true);
  dv.setFloat64(32, 0.5, true);
  return { buf, dv };
}

const pose = [[0, 1, 2], [3, -1, 0.5], [1.25, 0.3, 1.9]];
const lo = [0, 1, 2].map((k) => Math.min(...pose.map((p) => p[k])));
const hi = [0, 1, 2].map((k) => Math.max(...pose.map((p) => p[k])));

function v2() {
  const { buf, dv } = header(2, pose.length, 40 + 12 * pose.length);
  pose.flat().forEach((x, i) => dv.setFloat32(40 + 4 * i, x, true));
  return buf;
}

function v3(enc, level = 0) {
  const n = pose.length;
  const { buf, dv } = header(3, n, 96 + (enc ? 6 : 12) * n);
  dv.setUint8(40, level);
  dv.setUint8(41, enc);
  for (let k = 0; k < 3; k++) {
    dv.setFloat64(48 + 8 * k, lo[k], true);
    dv.setFloat64(72 + 8 * k, hi[k], true);
  }
  pose.flat().forEach((x, i) => {
    const k = i % 3;
    if (enc === 0) dv.setFloat32(96 + 4 * i, x, true);
    else dv.setUint16(96 + 2 * i, Math.round(((x - lo[k]) / (hi[k] - lo[k])) * 65535), true);
  });
  return buf;
}

const diag = Math.hypot(...[0, 1, 2].map((k) => hi[k] - lo[k]));
function near(f, tol) {
  pose.flat().forEach((x, i) => assert.ok(Math.abs(f.positions[i] - x) <= tol, `coordinate ${i}: ${f.positions[i]} vs ${x}`));
}

const a = parseFrame(v2());
assert.equal(a.version, 2);
assert.equal(a.level, 0);
assert.equal(a.revision, 11);
assert.equal(a.ackSeq, 4);
assert.ok(a.settled && !a.converged);
near(a, 1e-6);

const b = parseFrame(v3(0, 1));
assert.equal(b.version, 3);
assert.equal(b.encoding, 'f32');
assert.equal(b.level, 1);
near(b, 1e-6);

const c = parseFrame(v3(1));
assert.equal(c.encoding, 'q16');
assert.deepEqual(c.bbox, [lo, hi]);
near(c, 1e-4 * diag);

const broken = [
  ['short header', () => v2().slice(0, 30)],
  ['bad magic', () => { const f = v2(); new DataView(f).setUint8(0, 88); return f; }],
  ['version 4', () => { const f = v2(); new DataView(f).setUint16(4, 4, true); return f; }],
  ['truncated payload', () => v3(1).slice(0, 100)],
  ['unknown encoding', () => { const f = v3(1); new DataView(f).setUint8(41, 7); return f; }],
  ['unknown level', () => { const f = v3(1); new DataView(f).setUint8(40, 2); return f; }],
  ['NaN box', () => { const f = v3(1); new DataView(f).setFloat64(48, NaN, true); return f; }],
  ['one byte too many', () => { const f = new Uint8Array(v3(0).byteLength + 1); f.set(new Uint8Array(v3(0))); return f.buffer; }],
];
for (const [what, make] of broken) {
  assert.throws(() => parseFrame(make()), Error, what);
}
// delta: key frame then changes, written from api/ws-protocol.md's layout
async function deflateRaw(bytes) {
  const stream = new Blob([bytes]).stream().pipeThrough(new CompressionStream('deflate-raw'));
  return new Uint8Array(await new Response(stream).arrayBuffer());
}
function varints(values) {
  const out = [];
  for (const d of values) {
    let z = d >= 0 ? 2 * d : -2 * d - 1;
    while (z >= 0x80) { out.push((z & 0x7f) | 0x80); z = Math.floor(z / 128); }
    out.push(z);
  }
  return new Uint8Array(out);
}
const step = diag / 16384;
const grid = (p) => p.map((v) => v.map((x, k) => Math.round((x - lo[k]) / step)));
async function delta(p, revision, key, base, prev, prevChange) {
  const q = grid(p);
  const changes = [];
  for (let k = 0; k < 3; k++) {
    for (let i = 0; i < p.length; i++) {
      const d = q[i][k] - (key ? 0 : prev[i][k]);
      changes.push(prevChange ? d - prevChange[i][k] : d);
    }
  }
  const raw = varints(changes);
  const z = await deflateRaw(raw);
  const { buf, dv } = header(3, p.length, 148 + z.length);
  dv.setBigUint64(8, BigInt(revision), true);
  dv.setUint8(41, 2);
  for (let k = 0; k < 3; k++) {
    dv.setFloat64(48 + 8 * k, lo[k], true);
    dv.setFloat64(72 + 8 * k, hi[k], true);
    dv.setFloat64(120 + 8 * k, lo[k], true);
  }
  dv.setUint8(96, key ? 1 : 0);
  dv.setUint8(97, prevChange ? 1 : 0);
  dv.setBigUint64(104, BigInt(base), true);
  dv.setFloat64(112, step, true);
  dv.setUint32(144, raw.length, true);
  new Uint8Array(buf, 148).set(z);
  return { buf, q };
}
const dec = new FrameDecoder();
const k = await delta(pose, 20, true, 20);
const d0 = await dec.decode(k.buf);
assert.equal(d0.encoding, 'delta');
near(d0, 0.87 * step + 1e-6);
const moved = pose.map((p, i) => (i === 1 ? [p[0] - 0.4, p[1] + 0.25, p[2]] : p));
const m = await delta(moved, 21, false, 20, k.q);
const d1 = await dec.decode(m.buf);
moved.flat().forEach((x, i) => assert.ok(Math.abs(d1.positions[i] - x) <= 0.87 * step + 1e-6, `delta coordinate ${i}`));
// prediction 1: the change minus the vertex's previous change
const further = moved.map((p, i) => (i === 1 ? [p[0] - 0.35, p[1] + 0.3, p[2]] : p));
const change = grid(moved).map((v, i) => v.map((x, a) => x - k.q[i][a]));
const m2 = await delta(further, 22, false, 21, m.q, change);
const d2 = await dec.decode(m2.buf);
further.flat().forEach((x, i) => assert.ok(Math.abs(d2.positions[i] - x) <= 0.87 * step + 1e-6, `predicted coordinate ${i}`));
// changes against a frame the decoder does not hold are refused
const skip = await delta(pose, 24, false, 23, grid(moved));
await assert.rejects(dec.decode(skip.buf), /applies to revision 23/);
await assert.rejects(new FrameDecoder().decode(m.buf), /applies to revision 20/);
// a damaged stream is an error, and the decoder then wants a key frame
const bad = k.buf.slice(0);
new DataView(bad).setUint32(144, 999, true);
const dec2 = new FrameDecoder();
await assert.rejects(dec2.decode(bad), /stream/);
await assert.rejects(dec2.decode(m.buf), /applies to revision 20/);
await dec2.decode(k.buf);
await dec2.decode(m.buf);
console.log('frame.test.mjs: ok');
