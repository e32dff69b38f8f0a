// The dend public API as the editor uses it: a thin layer over the
// JavaScript client package (clients/js, served at /js/dend-client/) that
// keeps the editor's calling conventions (session id and token passed to
// each call, the raw WebSocket in `app.ws`).

import { Client, Session, ApiError, parseFrame, FrameDecoder, FrameError } from './dend-client/index.js';

export { ApiError, parseFrame, FrameDecoder };

/** How the editor's socket streams frames (api/ws-protocol.md, "Stream
 * options"): one frame in flight, acknowledged once drawn, in the `delta`
 * encoding (grid-index changes since the previous frame, deflated: what
 * did not move costs nothing), and frames that only refine the pose
 * already shown (no new drag) at most 30 per second: a frame answering a
 * drag, and the settled one, come at once. */
export const STREAM = { window: 1, encoding: 'delta', refine_fps: 30 };

export class Api {
  constructor(base = '') {
    this.base = base;
    this.client = new Client(base);
  }

  json(method, path, body, token, extra = {}) {
    return this.client.json(method, path, body, token, extra);
  }

  generate(shape) { return this.client.generate(shape); }

  /** Uploads a File in the format its name ends with (the server refuses
   * formats it does not read). */
  async upload(file) {
    const ext = file.name.split('.').pop().toLowerCase();
    const res = await this.client.request('POST', `/v1/meshes?format=${encodeURIComponent(ext)}`, {
      body: file, headers: { 'Content-Type': 'application/octet-stream' },
    });
    return res.json();
  }

  /** The created session's JSON (`id`, `token`, `state`). */
  createSession(meshId, params) { return this.json('POST', '/v1/sessions', { mesh_id: meshId, params }); }

  session(id, token) { return new Session(this.client, id, token).info(); }

  /** PUT constraints; with `ifRevision`, only if the session's constraints
   * revision still is that one (else ApiError `stale_constraints`). */
  setConstraints(id, token, c, ifRevision) {
    return new Session(this.client, id, token).setConstraints(c, { ifRevision });
  }

  curvature(id, token) { return new Session(this.client, id, token).curvature(); }

  undo(id, token) { return new Session(this.client, id, token).undo(); }

  redo(id, token) { return new Session(this.client, id, token).redo(); }

  reset(id, token) { return new Session(this.client, id, token).reset(); }

  async exportObj(id, token) {
    return (await this.exportAs(id, token, 'obj')).text();
  }

  /** The pose in one of the export formats (obj, off, ply, stl, glb) as a Blob. */
  async exportAs(id, token, format) {
    const path = `/v1/sessions/${encodeURIComponent(id)}/export?format=${encodeURIComponent(format)}`;
    return (await this.client.request('GET', path, { token })).blob();
  }

  /** Opens the session socket with flow control ([STREAM]); `on.frame(frame)`,
   * `on.event(json)`, `on.close(code, reason)`. A frame is acknowledged on
   * the animation frame after `on.frame` took it (drawn), so the server
   * sends the next one only then and never queues frames for a slow tab.
   * Resolves with the WebSocket once open. */
  connect(id, token, on) {
    const url = new Session(this.client, id, token).socketUrl({
      window: STREAM.window, encoding: STREAM.encoding, refineFps: STREAM.refine_fps,
    });
    const ws = new WebSocket(url);
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
        if (!(e instanceof FrameError)) throw e;
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
