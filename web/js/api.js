// The dend public API as the client uses it: HTTP `/v1` JSON routes
// (api/openapi.yaml) and the session WebSocket (api/ws-protocol.md).

/** An API error with the server's `code` and readable `message`. */
export class ApiError extends Error {
  constructor(code, message, status) {
    super(message);
    this.code = code;
    this.status = status;
  }
}

async function checked(res) {
  if (res.ok) return res;
  let body = null;
  try {
    body = await res.json();
  } catch (_) {
    // not JSON: fall through
  }
  if (body && body.code) throw new ApiError(body.code, body.message || body.code, res.status);
  throw new ApiError('http_' + res.status, `${res.status} ${res.statusText}`, res.status);
}

/** How the editor's socket streams frames (api/ws-protocol.md, "Stream
 * options"): one frame in flight, acknowledged once drawn, in the compact
 * q16 encoding (16 bits per coordinate in the frame's box). */
export const STREAM = { window: 1, encoding: 'q16' };

/** Parses a binary pose frame: version 2 (40-byte header, f32 xyz) or
 * version 3 (96-byte header with level, encoding and box; f32 or q16 xyz).
 * Throws on anything else. */
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
  if (enc > 1) throw new Error(`unknown frame encoding ${enc}`);
  frame.encoding = enc === 0 ? 'f32' : 'q16';
  const lo = [0, 1, 2].map((k) => dv.getFloat64(48 + 8 * k, true));
  const hi = [0, 1, 2].map((k) => dv.getFloat64(72 + 8 * k, true));
  if (![0, 1, 2].every((k) => Number.isFinite(lo[k]) && Number.isFinite(hi[k]) && lo[k] <= hi[k])) {
    throw new Error('the frame box is not a finite box');
  }
  frame.bbox = [lo, hi];
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

export class Api {
  constructor(base = '') {
    this.base = base;
  }

  async json(method, path, body, token, extra = {}) {
    const headers = { ...extra };
    if (body !== undefined) headers['Content-Type'] = 'application/json';
    if (token) headers.Authorization = `Bearer ${token}`;
    const res = await checked(await fetch(this.base + path, {
      method,
      headers,
      body: body === undefined ? undefined : JSON.stringify(body),
    }));
    return res.status === 204 ? null : res.json();
  }

  generate(shape) { return this.json('POST', '/v1/meshes/generate', { shape }); }

  async upload(file) {
    const ext = file.name.split('.').pop().toLowerCase();
    const res = await checked(await fetch(`${this.base}/v1/meshes?format=${encodeURIComponent(ext)}`, {
      method: 'POST',
      headers: { 'Content-Type': 'application/octet-stream' },
      body: file,
    }));
    return res.json();
  }

  createSession(meshId, params) { return this.json('POST', '/v1/sessions', { mesh_id: meshId, params }); }

  session(id, token) { return this.json('GET', `/v1/sessions/${id}`, undefined, token); }

  /** PUT constraints; with `ifRevision`, only if the session's constraints
   * revision still is that one (else ApiError `stale_constraints`). */
  setConstraints(id, token, c, ifRevision) {
    const extra = ifRevision === undefined || ifRevision === null ? {} : { 'If-Match': `"${ifRevision}"` };
    return this.json('PUT', `/v1/sessions/${id}/constraints`, c, token, extra);
  }

  curvature(id, token) { return this.json('GET', `/v1/sessions/${id}/curvature`, undefined, token); }

  undo(id, token) { return this.json('POST', `/v1/sessions/${id}/undo`, undefined, token); }

  redo(id, token) { return this.json('POST', `/v1/sessions/${id}/redo`, undefined, token); }

  reset(id, token) { return this.json('POST', `/v1/sessions/${id}/reset`, undefined, token); }

  async exportObj(id, token) {
    return (await this.exportAs(id, token, 'obj')).text();
  }

  /** The pose in one of the export formats (obj, off, ply, stl) as a Blob. */
  async exportAs(id, token, format) {
    const res = await checked(await fetch(`${this.base}/v1/sessions/${id}/export?format=${encodeURIComponent(format)}`, {
      headers: { Authorization: `Bearer ${token}` },
    }));
    return res.blob();
  }

  /** Opens the session socket with flow control ([STREAM]); `on.frame(frame)`,
   * `on.event(json)`, `on.close(code, reason)`. A frame is acknowledged on
   * the animation frame after `on.frame` took it (drawn), so the server
   * sends the next one only then and never queues frames for a slow tab.
   * Resolves once open. */
  connect(id, token, on) {
    const proto = location.protocol === 'https:' ? 'wss:' : 'ws:';
    const host = this.base ? new URL(this.base).host : location.host;
    const q = `token=${encodeURIComponent(token)}&window=${STREAM.window}&encoding=${STREAM.encoding}`;
    const ws = new WebSocket(`${proto}//${host}/v1/sessions/${id}/ws?${q}`);
    ws.binaryType = 'arraybuffer';
    const ack = (revision) => {
      if (ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify({ type: 'ack', revision }));
    };
    ws.onmessage = (m) => {
      if (typeof m.data === 'string') {
        on.event(JSON.parse(m.data));
        return;
      }
      let frame;
      try {
        frame = parseFrame(m.data);
      } catch (e) {
        // a frame that does not parse is taken too (acknowledging every
        // frame sent so far): the stream goes on
        ack(Number.MAX_SAFE_INTEGER);
        console.error(e);
        return;
      }
      if (typeof requestAnimationFrame === 'function') requestAnimationFrame(() => ack(frame.revision));
      else ack(frame.revision);
      on.frame(frame);
    };
    ws.onclose = (e) => on.close(e.code, e.reason);
    return new Promise((resolve, reject) => {
      ws.onopen = () => resolve(ws);
      ws.onerror = () => reject(new ApiError('ws_failed', 'could not open the session WebSocket'));
    });
  }
}
