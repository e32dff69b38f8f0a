// The binary pose frames of the session socket (api/ws-protocol.md,
// "Binary pose frames"): versions 2 and 3, encodings f32, q16 and delta.
// Decodes exactly as the server's own decoder (dend_protocol::FrameDecoder):
// the same checks in the same order, the same typed errors, the same f32
// positions; the package's tests compare the two on frames the Rust
// encoder wrote.

import { FrameError } from './errors.js';

export { FrameError };

/** Magic bytes `DEND`. */
export const FRAME_MAGIC = 'DEND';
/** Header bytes of a version 2 frame. */
export const FRAME_HEADER_BYTES = 40;
/** Header bytes of a version 3 frame. */
export const FRAME_V3_HEADER_BYTES = 96;
/** Offset of the deflated stream in a `delta` frame. */
export const DELTA_STREAM_OFFSET = 148;
/** Level of a frame of the full mesh's solve. */
export const LEVEL_FULL = 0;
/** Level of a coarse preview (a coarse solve prolongated to every vertex). */
export const LEVEL_COARSE = 1;
/** The frame format versions this decoder reads. */
export const FRAME_VERSIONS = Object.freeze([2, 3]);
/** Version 3 encodings by their header byte. */
export const ENCODINGS = Object.freeze(['f32', 'q16', 'delta']);

const Q16_MAX = 65535;

/** A Uint8Array over `buf` (an ArrayBuffer or any ArrayBufferView). */
function bytesOf(buf) {
  if (buf instanceof Uint8Array) return buf;
  if (ArrayBuffer.isView(buf)) return new Uint8Array(buf.buffer, buf.byteOffset, buf.byteLength);
  if (buf instanceof ArrayBuffer || (typeof SharedArrayBuffer !== 'undefined' && buf instanceof SharedArrayBuffer)) {
    return new Uint8Array(buf);
  }
  throw new TypeError('a frame is an ArrayBuffer or a typed array');
}

/** `n` f32 triples from `b` at `offset` (a view when aligned, else a copy). */
function f32s(b, offset, count) {
  const at = b.byteOffset + offset;
  if (at % 4 === 0) return new Float32Array(b.buffer, at, count);
  return new Float32Array(b.slice(offset, offset + 4 * count).buffer);
}

/** The header of a frame and, except for `delta`, its positions; the
 * checks of `dend_protocol::decode_frame_full` up to the payload. */
function parse(buf) {
  const b = bytesOf(buf);
  if (b.length < FRAME_HEADER_BYTES) {
    throw new FrameError('length', `frame has ${b.length} bytes, expected ${FRAME_HEADER_BYTES}`, { got: b.length, expected: FRAME_HEADER_BYTES });
  }
  if (b[0] !== 68 || b[1] !== 69 || b[2] !== 78 || b[3] !== 68) {
    throw new FrameError('magic', 'not a DEND frame (wrong magic)');
  }
  const dv = new DataView(b.buffer, b.byteOffset, b.byteLength);
  const version = dv.getUint16(4, true);
  const flags = dv.getUint16(6, true);
  const n = dv.getUint32(28, true);
  const frame = {
    version,
    encoding: 'f32',
    level: LEVEL_FULL,
    converged: (flags & 1) !== 0,
    settled: (flags & 2) !== 0,
    revision: Number(dv.getBigUint64(8, true)),
    ackSeq: Number(dv.getBigUint64(16, true)),
    iteration: dv.getUint32(24, true),
    vertexCount: n,
    objective: dv.getFloat64(32, true),
    bbox: null,
    key: false,
    bytes: b.length,
    positions: null,
  };
  let start = FRAME_HEADER_BYTES;
  if (version === 3) {
    if (b.length < FRAME_V3_HEADER_BYTES) {
      throw new FrameError('length', `frame has ${b.length} bytes, expected ${FRAME_V3_HEADER_BYTES}`, { got: b.length, expected: FRAME_V3_HEADER_BYTES });
    }
    frame.level = b[40];
    if (frame.level > LEVEL_COARSE) throw new FrameError('level', `unknown frame level ${frame.level}`, { value: frame.level });
    if (b[41] > 2) throw new FrameError('encoding', `unknown frame encoding ${b[41]}`, { value: b[41] });
    frame.encoding = ENCODINGS[b[41]];
    const lo = [0, 1, 2].map((k) => dv.getFloat64(48 + 8 * k, true));
    const hi = [0, 1, 2].map((k) => dv.getFloat64(72 + 8 * k, true));
    if (![0, 1, 2].every((k) => Number.isFinite(lo[k]) && Number.isFinite(hi[k]) && lo[k] <= hi[k])) {
      throw new FrameError('box', "the frame's box is not a finite box (min above max or NaN)");
    }
    frame.bbox = [lo, hi];
    start = FRAME_V3_HEADER_BYTES;
  } else if (version !== 2) {
    throw new FrameError('version', `frame format version ${version} is not supported (2 and 3 are)`, { value: version });
  }
  if (frame.encoding === 'delta') return { frame, b, dv };
  const expected = start + n * (frame.encoding === 'q16' ? 6 : 12);
  if (b.length !== expected) {
    throw new FrameError('length', `frame has ${b.length} bytes, expected ${expected}`, { got: b.length, expected });
  }
  if (frame.encoding === 'f32') {
    frame.positions = f32s(b, start, 3 * n);
    return { frame, b, dv };
  }
  const [lo, hi] = frame.bbox;
  const step = [0, 1, 2].map((k) => (hi[k] - lo[k]) / Q16_MAX);
  const out = new Float32Array(3 * n);
  for (let i = 0; i < 3 * n; i += 3) {
    const at = start + 2 * i;
    out[i] = lo[0] + dv.getUint16(at, true) * step[0];
    out[i + 1] = lo[1] + dv.getUint16(at + 2, true) * step[1];
    out[i + 2] = lo[2] + dv.getUint16(at + 4, true) * step[2];
  }
  frame.positions = out;
  return { frame, b, dv };
}

/** Parses a frame on its own: version 2, or version 3 in `f32` or `q16`
 * with its positions; a `delta` frame comes back with `positions: null`
 * (only a connection's {@link FrameDecoder} can compute them). Throws a
 * {@link FrameError} on a malformed frame. */
export function parseFrame(buf) {
  return parse(buf).frame;
}

/** Decodes one frame on its own, a `delta` one only if it is a key frame
 * (as `dend_protocol::decode_frame_full`). */
export function decodeFrame(buf) {
  return new FrameDecoder().decode(buf);
}

/** Reads the inflated `bytes` until end of stream or `limit` bytes, so a
 * frame that inflates to more than it announces costs no more than that. */
async function inflateRaw(bytes, limit) {
  if (typeof DecompressionStream !== 'function') {
    throw new FrameError('delta', 'bad delta frame: this platform has no DecompressionStream');
  }
  const reader = new Blob([bytes]).stream().pipeThrough(new DecompressionStream('deflate-raw')).getReader();
  const parts = [];
  let got = 0;
  try {
    for (;;) {
      const { done, value } = await reader.read();
      if (done) break;
      parts.push(value);
      got += value.length;
      if (got > limit) {
        reader.cancel().catch(() => {});
        break;
      }
    }
  } catch (_) {
    throw new FrameError('delta', 'bad delta frame: the stream does not inflate');
  }
  const out = new Uint8Array(got);
  let at = 0;
  for (const p of parts) {
    out.set(p, at);
    at += p.length;
  }
  return out;
}

const bad = (why) => new FrameError('delta', `bad delta frame: ${why}`);

/** A connection's frame decoder: it holds the grid indices of the last
 * `delta` frame, which the next frame's changes apply to (api/ws-protocol.md,
 * "The delta encoding"). Give it every frame of a connection, in order;
 * frames of other encodings pass through. After a frame that failed to
 * decode it holds nothing, and only a key frame decodes again (the
 * connection is then reopened: its first frame is a key frame). */
export class FrameDecoder {
  constructor() {
    /** @type {bigint | null} the revision of the delta frame held */
    this.held = null;
    this.q = new Int32Array(0);
    this.dq = new Int32Array(0);
    // decodes run one after another even if the caller does not wait
    this.queue = Promise.resolve();
  }

  /** The revision of the `delta` frame the next one may apply to, or null. */
  get base() {
    return this.held === null ? null : Number(this.held);
  }

  /** Decodes the next frame of the connection (a Promise: `delta` frames
   * inflate asynchronously). Rejects with a {@link FrameError}. */
  decode(buf) {
    const run = this.queue.then(() => this.decodeNow(buf));
    this.queue = run.catch(() => {});
    return run;
  }

  async decodeNow(buf) {
    const { frame, b, dv } = parse(buf);
    if (frame.encoding !== 'delta') return frame;
    // held again only if this frame decodes whole
    const held = this.held;
    this.held = null;
    const n = frame.vertexCount;
    if (b.length < DELTA_STREAM_OFFSET) {
      throw new FrameError('length', `frame has ${b.length} bytes, expected ${DELTA_STREAM_OFFSET}`, { got: b.length, expected: DELTA_STREAM_OFFSET });
    }
    const p = FRAME_V3_HEADER_BYTES;
    if (b[p] > 1) throw bad('the key byte is neither 0 nor 1');
    const key = b[p] === 1;
    if (b[p + 1] > 1 || (key && b[p + 1] !== 0)) throw bad('unknown prediction');
    const predict = b[p + 1] === 1;
    const base = dv.getBigUint64(p + 8, true);
    const step = dv.getFloat64(p + 16, true);
    const origin = [0, 1, 2].map((k) => dv.getFloat64(p + 24 + 8 * k, true));
    if (!(Number.isFinite(step) && step > 0 && origin.every(Number.isFinite))) throw bad('the grid is not a finite grid');
    const len = dv.getUint32(p + 48, true);
    const need = 3 * n;
    if (len < need || len > 5 * need) throw bad('the stream length does not fit the vertex count');
    if (!key && (held !== base || this.q.length !== need)) {
      throw new FrameError('base', `the delta frame applies to revision ${base}, the decoder holds ${held === null ? 'None' : `Some(${held})`}`, {
        base: Number(base), have: held === null ? null : Number(held),
      });
    }
    const stream = await inflateRaw(b.subarray(DELTA_STREAM_OFFSET), len);
    if (stream.length !== len) throw bad('the stream is not as long as announced');
    if (key) {
      this.q = new Int32Array(need);
      this.dq = new Int32Array(need);
    }
    const { q, dq } = this;
    let at = 0;
    for (let k = 0; k < 3; k++) {
      for (let i = 0; i < n; i++) {
        let z = 0;
        let shift = 0;
        for (;;) {
          if (at >= len) throw bad('the stream ends inside a varint');
          const byte = stream[at++];
          if (shift === 28 && byte > 0x0f) throw bad('a varint overflows 32 bits');
          z += (byte & 0x7f) * 2 ** shift;
          if (!(byte & 0x80)) break;
          shift += 7;
        }
        // zigzag, then wrapping i32 arithmetic as the encoder's
        const v = (z % 2 === 0 ? z / 2 : -(z + 1) / 2) | 0;
        const j = 3 * i + k;
        if (key) {
          q[j] = v;
        } else {
          const d = predict ? (v + dq[j]) | 0 : v;
          q[j] = (q[j] + d) | 0;
          dq[j] = d;
        }
      }
    }
    if (at !== len) throw bad('the stream has bytes past its last varint');
    this.held = dv.getBigUint64(8, true);
    const out = new Float32Array(need);
    for (let i = 0; i < need; i += 3) {
      out[i] = origin[0] + q[i] * step;
      out[i + 1] = origin[1] + q[i + 1] * step;
      out[i + 2] = origin[2] + q[i + 2] * step;
    }
    frame.key = key;
    frame.positions = out;
    return frame;
  }
}
