// The decoder against the Rust encoder and decoder: every frame the
// fixtures hold (streams of v2, v3 f32/q16 and delta frames, malformed
// variants of each, the fuzz corpus) decodes to exactly what
// dend_protocol::FrameDecoder decoded from it: the same header, the same
// f32 positions bit for bit, or the same error (kind, data and message).

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { readFileSync } from 'node:fs';
import { join } from 'node:path';
import { FrameDecoder, FrameError, DendError, parseFrame } from '../src/index.js';
import { fixtureDir } from './fixtures.mjs';

const dir = fixtureDir();
const manifest = JSON.parse(readFileSync(join(dir, 'manifest.json'), 'utf8'));
const read = (f) => {
  const b = readFileSync(join(dir, f));
  // an ArrayBuffer of its own, as a WebSocket message is
  return b.buffer.slice(b.byteOffset, b.byteOffset + b.byteLength);
};
const num = (x) => (x === 'NaN' ? NaN : x === 'inf' ? Infinity : x === '-inf' ? -Infinity : x);

function samePositions(got, file, what) {
  const want = new Float32Array(read(file));
  assert.equal(got.length, want.length, `${what}: coordinate count`);
  const a = new Uint32Array(Float32Array.from(got).buffer);
  const b = new Uint32Array(want.buffer);
  for (let i = 0; i < a.length; i++) {
    if (a[i] !== b[i] && !(Number.isNaN(got[i]) && Number.isNaN(want[i]))) {
      assert.fail(`${what}: coordinate ${i} is ${got[i]}, the Rust decoder's ${want[i]}`);
    }
  }
}

function sameFrame(f, want, what) {
  assert.equal(f.version, want.version, `${what}: version`);
  assert.equal(f.encoding, want.encoding, `${what}: encoding`);
  assert.equal(f.level, want.level, `${what}: level`);
  assert.equal(f.converged, want.converged, `${what}: converged`);
  assert.equal(f.settled, want.settled, `${what}: settled`);
  assert.equal(f.revision, Number(BigInt(want.revision)), `${what}: revision`);
  assert.equal(f.ackSeq, Number(BigInt(want.ack_seq)), `${what}: ackSeq`);
  assert.equal(f.iteration, want.iteration, `${what}: iteration`);
  assert.equal(f.vertexCount, want.vertex_count, `${what}: vertexCount`);
  assert.ok(Object.is(f.objective, num(want.objective)), `${what}: objective ${f.objective} vs ${want.objective}`);
  assert.deepEqual(f.bbox, want.bbox && want.bbox.map((c) => c.map(num)), `${what}: bbox`);
  samePositions(f.positions, want.positions, what);
}

test('every fixture frame decodes as the Rust decoder decodes it', async () => {
  let frames = 0;
  let refused = 0;
  const kinds = new Set();
  for (const c of manifest.cases) {
    const dec = new FrameDecoder();
    for (const [i, { file, expect }] of c.frames.entries()) {
      const what = `${c.name} frame ${i} (${file})`;
      frames++;
      let got;
      try {
        got = await dec.decode(read(file));
      } catch (e) {
        if (!(e instanceof FrameError)) throw e;
        assert.ok(expect.error, `${what}: refused (${e.message}), the Rust decoder took it`);
        assert.ok(e instanceof DendError);
        assert.equal(e.kind, expect.error.kind, `${what}: error kind (${e.message})`);
        assert.equal(e.code, `frame_${expect.error.kind}`);
        assert.equal(e.message, expect.error.message, what);
        for (const [k, v] of Object.entries(expect.error.details)) assert.equal(e[k], v, `${what}: ${k}`);
        refused++;
        kinds.add(e.kind);
        continue;
      }
      assert.ok(expect.ok, `${what}: decoded, the Rust decoder refused it (${expect.error && expect.error.message})`);
      sameFrame(got, expect.ok, what);
    }
  }
  assert.equal(frames, manifest.frames);
  assert.equal(refused, manifest.errors);
  // every kind of error was exercised
  assert.deepEqual([...kinds].sort(), ['base', 'box', 'delta', 'encoding', 'length', 'level', 'magic', 'version']);
});

test('parseFrame reads every non-delta fixture without a decoder', () => {
  let n = 0;
  for (const c of manifest.cases) {
    const { file, expect } = c.frames[0];
    if (!expect.ok || expect.ok.encoding === 'delta') continue;
    sameFrame(parseFrame(read(file)), expect.ok, c.name);
    n++;
  }
  assert.ok(n > 20, `${n} frames`);
});

test('the fuzz corpus: ok_ files decode, the others are refused with a FrameError', async () => {
  const corpus = manifest.cases.filter((c) => c.name.startsWith('corpus:'));
  assert.ok(corpus.length >= 5);
  for (const c of corpus) {
    const name = c.name.split('/').pop();
    const run = new FrameDecoder().decode(read(c.frames[0].file));
    if (name.startsWith('ok_')) await run;
    else if (!name.startsWith('any_') && !c.name.includes('/corpus/')) await assert.rejects(run, FrameError, name);
    else await run.catch((e) => assert.ok(e instanceof FrameError, name));
  }
});

test('frames given as typed arrays at any offset decode alike', async () => {
  const c = manifest.cases.find((x) => x.name === 'v3-f32');
  const buf = new Uint8Array(read(c.frames[0].file));
  const shifted = new Uint8Array(buf.length + 3);
  shifted.set(buf, 3);
  const f = await new FrameDecoder().decode(shifted.subarray(3));
  sameFrame(f, c.frames[0].expect.ok, 'unaligned');
});
