// The dend public API as the client uses it: HTTP `/v1` JSON routes
// (api/openapi.yaml) and the session WebSocket (api/ws-protocol.md).

import { parseFrame, FrameDecoder } from './frame.js';

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
 * options"): one frame in flight, acknowledged once drawn, in the `delta`
 * encoding (grid-index changes since the previous frame, deflated: what
 * did not move costs nothing), and frames that only refine the pose
 * already shown (no new drag) at most 30 per second: a frame answering a
 * drag, and the settled one, come at once. */
export const STREAM = { window: 1, encoding: 'delta', refine_fps: 30 };

export { parseFrame, FrameDecoder };

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
    const q = `token=${encodeURIComponent(token)}&window=${STREAM.window}&encoding=${STREAM.encoding}&refine_fps=${STREAM.refine_fps}`;
    const ws = new WebSocket(`${proto}//${host}/v1/sessions/${id}/ws?${q}`);
    ws.binaryType = 'arraybuffer';
    const ack = (revision) => {
      if (ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify({ type: 'ack', revision }));
    };
    // frames decode asynchronously (a delta frame inflates): messages are
    // handled one after another, in the order they came
    const decoder = new FrameDecoder();
    let queue = Promise.resolve();
    const handle = async (m) => {
      if (typeof m.data === 'string') {
        on.event(JSON.parse(m.data));
        return;
      }
      let frame;
      try {
        frame = await decoder.decode(m.data);
      } catch (e) {
        console.error(e);
        if (m.data.byteLength > 41 && new DataView(m.data).getUint8(41) === 2) {
          // a delta stream that lost its base: reopen the socket (its first
          // frame is a key frame)
          ws.close(4000, 'frame_decode');
          return;
        }
        // a frame that does not parse is taken too (acknowledging every
        // frame sent so far): the stream goes on
        ack(Number.MAX_SAFE_INTEGER);
        return;
      }
      if (typeof requestAnimationFrame === 'function') requestAnimationFrame(() => ack(frame.revision));
      else ack(frame.revision);
      on.frame(frame);
    };
    ws.onmessage = (m) => {
      queue = queue.then(() => handle(m)).catch((e) => console.error(e));
    };
    ws.onclose = (e) => on.close(e.code, e.reason);
    return new Promise((resolve, reject) => {
      ws.onopen = () => resolve(ws);
      ws.onerror = () => reject(new ApiError('ws_failed', 'could not open the session WebSocket'));
    });
  }
}
