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

/** Parses a binary pose frame (little-endian header + f32 xyz). */
export function parseFrame(buf) {
  const dv = new DataView(buf);
  const magic = String.fromCharCode(dv.getUint8(0), dv.getUint8(1), dv.getUint8(2), dv.getUint8(3));
  if (magic !== 'DEND') throw new Error(`bad frame magic ${JSON.stringify(magic)}`);
  const version = dv.getUint16(4, true);
  if (version !== 2) throw new Error(`unsupported frame version ${version}`);
  const flags = dv.getUint16(6, true);
  const n = dv.getUint32(28, true);
  if (buf.byteLength < 40 + 12 * n) throw new Error('truncated frame');
  return {
    converged: (flags & 1) !== 0,
    settled: (flags & 2) !== 0,
    revision: Number(dv.getBigUint64(8, true)),
    ackSeq: Number(dv.getBigUint64(16, true)),
    iteration: dv.getUint32(24, true),
    objective: dv.getFloat64(32, true),
    positions: new Float32Array(buf, 40, 3 * n),
  };
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

  /** Opens the session socket; `on.frame(frame)`, `on.event(json)`,
   * `on.close(code, reason)`. Resolves once open. */
  connect(id, token, on) {
    const proto = location.protocol === 'https:' ? 'wss:' : 'ws:';
    const host = this.base ? new URL(this.base).host : location.host;
    const ws = new WebSocket(`${proto}//${host}/v1/sessions/${id}/ws?token=${encodeURIComponent(token)}`);
    ws.binaryType = 'arraybuffer';
    ws.onmessage = (m) => {
      if (typeof m.data === 'string') {
        on.event(JSON.parse(m.data));
      } else {
        on.frame(parseFrame(m.data));
      }
    };
    ws.onclose = (e) => on.close(e.code, e.reason);
    return new Promise((resolve, reject) => {
      ws.onopen = () => resolve(ws);
      ws.onerror = () => reject(new ApiError('ws_failed', 'could not open the session WebSocket'));
    });
  }
}
