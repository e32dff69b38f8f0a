// Every HTTP route of the dend API (api/openapi.yaml): meshes, generated
// meshes, sessions, constraints, drags, poses, exports, curvature,
// undo/redo/reset, named poses and presets. A refused request throws an
// ApiError carrying the server's `code`.

import { ApiError } from './errors.js';
import { SessionSocket, deltaBody } from './session.js';

export { deltaBody };

/** Mesh file formats `uploadFile` accepts. */
export const MESH_FORMATS = Object.freeze(['json', 'obj', 'off', 'ply', 'stl', 'gltf', 'glb']);
/** Export formats. */
export const EXPORT_FORMATS = Object.freeze(['obj', 'off', 'ply', 'stl', 'gltf', 'glb']);

/** The error of a refused answer: the server's JSON `{code, message}`, or
 * `http_<status>` for a body that is not one. */
export async function errorOf(res) {
  let body = null;
  try {
    body = await res.json();
  } catch (_) {
    // not JSON
  }
  const retry = Number(res.headers && res.headers.get('retry-after'));
  const retryAfter = Number.isFinite(retry) && retry > 0 ? retry : null;
  if (body && typeof body.code === 'string') return new ApiError(body.code, body.message || body.code, res.status, retryAfter);
  return new ApiError(`http_${res.status}`, `${res.status} ${res.statusText || ''}`.trim(), res.status, retryAfter);
}

const enc = encodeURIComponent;

/** A client of one dend server. `base` is its URL (`http://127.0.0.1:8080`;
 * empty in a page the server serves itself). Options: `fetch` (another
 * fetch implementation), `WebSocket` (a constructor for the session socket,
 * e.g. the `ws` package's on a Node without a global WebSocket). */
export class Client {
  constructor(base = '', options = {}) {
    this.base = String(base).replace(/\/+$/, '');
    this.fetchImpl = options.fetch || ((...a) => globalThis.fetch(...a));
    this.WebSocket = options.WebSocket || null;
  }

  /** Sends a request; resolves with the Response, rejects with an ApiError
   * (code `network` when the server could not be reached). */
  async request(method, path, { body, json, token, headers = {}, signal } = {}) {
    const h = { ...headers };
    let payload = body;
    if (json !== undefined) {
      h['Content-Type'] = 'application/json';
      payload = JSON.stringify(json);
    }
    if (token) h.Authorization = `Bearer ${token}`;
    let res;
    try {
      res = await this.fetchImpl(this.base + path, { method, headers: h, body: payload, signal });
    } catch (e) {
      if (e && e.name === 'AbortError') throw e;
      const err = new ApiError('network', `${method} ${path}: ${e && e.message ? e.message : e}`, 0);
      err.cause = e;
      throw err;
    }
    if (!res.ok) throw await errorOf(res);
    return res;
  }

  /** A JSON request; resolves with the parsed answer (null for 204). */
  async json(method, path, body, token, headers) {
    const res = await this.request(method, path, { json: body, token, headers });
    return res.status === 204 ? null : res.json();
  }

  /** `GET /healthz`: `{status, instance}`. */
  healthz() { return this.json('GET', '/healthz'); }

  /** `GET /healthz/ready` (503 `store_unavailable` while the store is down). */
  ready() { return this.json('GET', '/healthz/ready'); }

  /** `GET /metrics`: the Prometheus text. */
  async metrics() { return (await this.request('GET', '/metrics')).text(); }

  /** `GET /v1/presets`: the named parameter sets. */
  presets() { return this.json('GET', '/v1/presets'); }

  /** Uploads a mesh as JSON (`positions` `[[x,y,z]…]` or a flat array,
   * `triangles` `[[a,b,c]…]` or a flat array). */
  uploadMesh(positions, triangles) {
    return this.json('POST', '/v1/meshes', { positions: triples(positions), triangles: triples(triangles) });
  }

  /** Uploads a mesh file (a Blob/File, ArrayBuffer, typed array or string)
   * in `format` (obj, off, ply, stl, gltf, glb; from a File's name when
   * omitted). */
  async uploadFile(data, format) {
    const fmt = (format || (data && data.name ? String(data.name).split('.').pop() : '')).toLowerCase();
    if (!MESH_FORMATS.includes(fmt)) {
      throw new ApiError('unsupported_format', `mesh format ${JSON.stringify(fmt)} is none of ${MESH_FORMATS.join(', ')}`, 0);
    }
    const res = await this.request('POST', `/v1/meshes?format=${enc(fmt)}`, {
      body: data, headers: { 'Content-Type': 'application/octet-stream' },
    });
    return res.json();
  }

  /** Generates a procedural shape (`bar`, `cylinder`, `flag`, `plane`,
   * `bumpy-plane`, `torus`, `creature`); `params`: nu, nv, size, size2,
   * amplitude. The creature comes with its default `constraints`. */
  generate(shape, params) {
    return this.json('POST', '/v1/meshes/generate', params === undefined ? { shape } : { shape, params });
  }

  /** `GET /v1/meshes/{id}`. */
  mesh(id) { return this.json('GET', `/v1/meshes/${enc(id)}`); }

  /** `DELETE /v1/meshes/{id}` (409 `mesh_in_use` while sessions use it). */
  deleteMesh(id) { return this.json('DELETE', `/v1/meshes/${enc(id)}`); }

  /** Creates a session on a mesh; resolves with a {@link Session}. */
  async createSession(meshId, params) {
    const body = { mesh_id: meshId };
    if (params !== undefined) body.params = params;
    const created = await this.json('POST', '/v1/sessions', body);
    return new Session(this, created.id, created.token);
  }

  /** An existing session, from its id and token. */
  session(id, token) {
    return new Session(this, id, token);
  }
}

/** `[[x,y,z]…]` from nested or flat arrays (typed arrays too). */
function triples(a) {
  if (!a || typeof a.length !== 'number') throw new TypeError('expected an array of triples or a flat array');
  if (a.length && typeof a[0] === 'object') return Array.from(a, (p) => [p[0], p[1], p[2]]);
  if (a.length % 3) throw new TypeError('a flat array of triples has a length divisible by 3');
  const out = [];
  for (let i = 0; i < a.length; i += 3) out.push([a[i], a[i + 1], a[i + 2]]);
  return out;
}

/** A session, with its token: every session route, and {@link Session#connect}
 * for its WebSocket. */
export class Session {
  constructor(client, id, token) {
    this.client = client;
    this.id = id;
    this.token = token;
  }

  path(tail = '') { return `/v1/sessions/${enc(this.id)}${tail}`; }

  call(method, tail, body, headers) { return this.client.json(method, this.path(tail), body, this.token, headers); }

  /** `GET /v1/sessions/{id}`: state, handles, constraints, poses, … */
  info() { return this.call('GET', ''); }

  /** Deletes the session (its sockets close with 4004). */
  delete() { return this.call('DELETE', ''); }

  /** Sets the constraints (202, the factor builds: wait with
   * {@link Session#waitReady}); with `ifRevision`, only if the session's
   * `constraints_revision` still is that (else ApiError `stale_constraints`).
   * Resolves with `{state, constraints_revision}`. */
  setConstraints(constraints, { ifRevision } = {}) {
    const h = ifRevision === undefined || ifRevision === null ? undefined : { 'If-Match': `"${ifRevision}"` };
    return this.call('PUT', '/constraints', constraints, h);
  }

  /** Polls until the session is `ready`; resolves with its info. Rejects
   * with ApiError `build_failed` when the build failed (state `failed`),
   * `timeout` after `timeoutMs`. */
  async waitReady({ timeoutMs = 120000 } = {}) {
    const end = Date.now() + timeoutMs;
    let pause = 5;
    for (;;) {
      const info = await this.info();
      if (info.state === 'ready') return info;
      if (info.state === 'failed') throw new ApiError('build_failed', 'the constraint set did not build (state failed)', 0);
      if (Date.now() > end) throw new ApiError('timeout', `the session was not ready in ${timeoutMs} ms (state ${info.state})`, 0);
      await new Promise((r) => setTimeout(r, pause));
      pause = Math.min(2 * pause, 100);
    }
  }

  /** An HTTP drag: the delta, then a solve to convergence or `maxIters`;
   * resolves with the pose (JSON). Interactive drags go over the socket. */
  drag(handle, delta, { maxIters } = {}) {
    const body = { handle, ...deltaBody(delta) };
    if (maxIters !== undefined) body.max_iters = maxIters;
    return this.call('POST', '/drag', body);
  }

  /** The pose as JSON (f64 positions). */
  pose() { return this.call('GET', '/pose'); }

  /** The pose as f32 `Float32Array` (x, y, z per vertex) with its revision. */
  async poseF32() {
    const res = await this.client.request('GET', this.path('/pose'), { token: this.token, headers: { Accept: 'application/octet-stream' } });
    return { revision: Number(res.headers.get('x-dend-revision')), positions: new Float32Array(await res.arrayBuffer()) };
  }

  /** The pose as a mesh file, an ArrayBuffer: `format` obj, off, ply,
   * stl, gltf or glb; `as: 'morph-targets'` (glTF/GLB uploads) with
   * `animation: true` for the named poses' animation. */
  async export(format = 'obj', { as, animation } = {}) {
    let q = `format=${enc(format)}`;
    if (as) q += `&as=${enc(as)}`;
    if (animation) q += '&animation=1';
    return (await this.client.request('GET', this.path(`/export?${q}`), { token: this.token })).arrayBuffer();
  }

  /** Per-vertex curvature of the pose: `{revision, mean, gaussian, g}`. */
  curvature() { return this.call('GET', '/curvature'); }

  /** Back to the previous history entry; resolves with the pose. */
  undo() { return this.call('POST', '/undo'); }

  /** Forward to the next history entry. */
  redo() { return this.call('POST', '/redo'); }

  /** The rest pose (undoable). */
  reset() { return this.call('POST', '/reset'); }

  /** The named poses, in save order. */
  async poses() { return (await this.call('GET', '/poses')).poses; }

  /** Saves the settled pose under `name`; a name in use is refused
   * (`pose_exists`) unless `replace` is true. */
  savePose(name, { replace } = {}) { return this.call('POST', '/poses', replace ? { name, replace: true } : { name }); }

  /** A named pose with its positions. */
  namedPose(name) { return this.call('GET', `/poses/${enc(name)}`); }

  /** Renames a named pose. */
  renamePose(name, to) { return this.call('PATCH', `/poses/${enc(name)}`, { name: to }); }

  /** Deletes a named pose. */
  deletePose(name) { return this.call('DELETE', `/poses/${enc(name)}`); }

  /** Makes a named pose the current one (an undo step). */
  restorePose(name) { return this.call('POST', `/poses/${enc(name)}/restore`); }

  /** The session's WebSocket URL with these stream options (token in the
   * query). */
  socketUrl({ window = 1, encoding = 'delta', maxFps, refineFps } = {}) {
    const base = this.client.base || (typeof location !== 'undefined' ? location.origin : '');
    if (!base) throw new TypeError('a client without a base URL needs a page location');
    const url = new URL(this.path('/ws'), base);
    url.protocol = url.protocol === 'https:' ? 'wss:' : 'ws:';
    const q = url.searchParams;
    q.set('token', this.token);
    if (window !== null && window !== undefined) q.set('window', String(window));
    if (encoding) q.set('encoding', encoding);
    if (maxFps) q.set('max_fps', String(maxFps));
    if (refineFps) q.set('refine_fps', String(refineFps));
    return url.toString();
  }

  /** Opens the session's WebSocket ({@link SessionSocket}): resolves once
   * it is open. */
  connect(options = {}) {
    const s = new SessionSocket(this, options);
    return s.open();
  }
}
