// The binary pose frames of the session socket (api/ws-protocol.md,
// "Frames"): versions 2 and 3, encodings f32, q16 and delta.

/** Parses a binary pose frame: version 2 (40-byte header, f32 xyz) or
 * version 3 (96-byte header with level, encoding and box; f32 or q16 xyz).
 * A `delta` frame comes back without positions, which only a connection's
 * [FrameDecoder] can compute. Throws on anything else. */
export function parseFrame(buf) {
  const dv = new DataView(buf);
  if (buf.byteLength < 40) throw new Error('truncated frame header');
  const magic = String.fromCharCode(dv.getUint8(0), dv.getUint8(1), dv.getUint8(2), dv.getUint8(3));
  if (magic !== 'DEND') throw new Error(`bad frame magic ${JSON.stringify(magic)}`);
  const version = dv.getUint16(4, true);
  if (version !== 2 && version !== 3) throw new Error(`unsupported frame version ${version}`);
  const flags = dv.getUint16(6, true);
  const n = dv.getUint32(28, true);
  const frame = {
    version,
    converged: (flags & 1) !== 0,
    settled: (flags & 2) !== 0,
    revision: Number(dv.getBigUint64(8, true)),
    ackSeq: Number(dv.getBigUint64(16, true)),
    iteration: dv.getUint32(24, true),
    objective: dv.getFloat64(32, true),
    vertexCount: n,
    level: 0,
    encoding: 'f32',
    bytes: buf.byteLength,
  };
  if (version === 2) {
    if (buf.byteLength !== 40 + 12 * n) throw new Error('frame length does not match its vertex count');
    frame.positions = new Float32Array(buf, 40, 3 * n);
    return frame;
  }
  if (buf.byteLength < 96) throw new Error('truncated frame header');
  frame.level = dv.getUint8(40);
  if (frame.level > 1) throw new Error(`unknown frame level ${frame.level}`);
  const enc = dv.getUint8(41);
  if (enc > 2) throw new Error(`unknown frame encoding ${enc}`);
  frame.encoding = ['f32', 'q16', 'delta'][enc];
  const lo = [0, 1, 2].map((k) => dv.getFloat64(48 + 8 * k, true));
  const hi = [0, 1, 2].map((k) => dv.getFloat64(72 + 8 * k, true));
  if (![0, 1, 2].every((k) => Number.isFinite(lo[k]) && Number.isFinite(hi[k]) && lo[k] <= hi[k])) {
    throw new Error('the frame box is not a finite box');
  }
  frame.bbox = [lo, hi];
  if (enc === 2) return frame;
  if (buf.byteLength !== 96 + (enc === 0 ? 12 : 6) * n) throw new Error('frame length does not match its vertex count');
  if (enc === 0) {
    frame.positions = new Float32Array(buf, 96, 3 * n);
    return frame;
  }
  // q16: min + q * (max - min) / 65535 per axis (the payload starts at
  // offset 96, a multiple of 2: a typed view is aligned)
  const q = new Uint16Array(buf, 96, 3 * n);
  const out = new Float32Array(3 * n);
  const step = [0, 1, 2].map((k) => (hi[k] - lo[k]) / 65535);
  for (let i = 0; i < 3 * n; i += 3) {
    out[i] = lo[0] + q[i] * step[0];
    out[i + 1] = lo[1] + q[i + 1] * step[1];
    out[i + 2] = lo[2] + q[i + 2] * step[2];
  }
  frame.positions = out;
  return frame;
}

/** Inflates a raw deflate stream (RFC 1951) with the platform's
 * DecompressionStream. */
async function inflateRaw(bytes) {
  const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream('deflate-raw'));
  return new Uint8Array(await new Response(stream).arrayBuffer());
}

/** A connection's frame decoder: it holds the grid indices of the last
 * `delta` frame, which the next frame's changes apply to (api/ws-protocol.md,
 * "The delta encoding"). Frames must be given in the order they came. */
export class FrameDecoder {
  constructor() {
    this.base = null;
    this.q = null;
    this.dq = null;
  }

  /** The frame `buf` with its positions. Throws on a malformed frame, or on
   * changes against a frame this decoder does not hold. */
  async decode(buf) {
    const frame = parseFrame(buf);
    if (frame.encoding !== 'delta') return frame;
    const held = this.base;
    // held again only if this frame decodes whole
    this.base = null;
    const n = frame.vertexCount;
    if (buf.byteLength < 148) throw new Error('truncated delta frame');
    const dv = new DataView(buf);
    const key = dv.getUint8(96);
    if (key > 1) throw new Error('bad delta frame: the key byte is neither 0 nor 1');
    const predict = dv.getUint8(97);
    if (predict > 1 || (key && predict)) throw new Error('bad delta frame: unknown prediction');
    const base = Number(dv.getBigUint64(104, true));
    const step = dv.getFloat64(112, true);
    const origin = [0, 1, 2].map((k) => dv.getFloat64(120 + 8 * k, true));
    if (!(Number.isFinite(step) && step > 0 && origin.every(Number.isFinite))) throw new Error('bad delta frame: the grid is not a finite grid');
    const len = dv.getUint32(144, true);
    if (len < 3 * n || len > 15 * n) throw new Error('bad delta frame: the stream length does not fit the vertex count');
    if (!key && (held !== base || !this.q || this.q.length !== 3 * n)) {
      throw new Error(`the delta frame applies to revision ${base}, the decoder holds ${held}`);
    }
    const stream = await inflateRaw(new Uint8Array(buf, 148));
    if (stream.length !== len) throw new Error('bad delta frame: the stream is not as long as announced');
    const q = key ? new Int32Array(3 * n) : this.q;
    const dq = key ? new Int32Array(3 * n) : this.dq;
    let at = 0;
    for (let k = 0; k < 3; k++) {
      for (let i = 0; i < n; i++) {
        let z = 0;
        let shift = 0;
        for (;;) {
          if (at >= len) throw new Error('bad delta frame: the stream ends inside a varint');
          const byte = stream[at++];
          z += (byte & 0x7f) * 2 ** shift;
          if (!(byte & 0x80)) break;
          shift += 7;
          if (shift > 28) throw new Error('bad delta frame: a varint overflows 32 bits');
        }
        // zigzag, then wrapping i32 arithmetic as the encoder's
        const v = z % 2 === 0 ? z / 2 : -(z + 1) / 2;
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
    if (at !== len) throw new Error('bad delta frame: the stream has bytes past its last varint');
    this.q = q;
    this.dq = dq;
    this.base = frame.revision;
    const out = new Float32Array(3 * n);
    for (let i = 0; i < 3 * n; i += 3) {
      out[i] = origin[0] + q[i] * step;
      out[i + 1] = origin[1] + q[i + 1] * step;
      out[i + 2] = origin[2] + q[i + 2] * step;
    }
    frame.positions = out;
    return frame;
  }
}
