// The dend reference client: session set-up, region labels, constraints,
// WebSocket pose frames and the UI panel. Mouse handling is in interact.js.
// Everything goes through the public API (api.js); `window.dend` exposes a
// read-only view of the state for the browser test.

import { Api, ApiError } from './api.js';
import { OrbitCamera } from './camera.js';
import { parseObj, vertexNormals, edgeList, bbox } from './mesh.js';
import { Renderer } from './renderer.js';
import { attachInteraction } from './interact.js';
import { Gizmo, wireNumeric, gizmoLabel } from './gizmo.js';
import { attachKeys } from './keys.js';
import { socketHandlers } from './socket.js';
import { project } from './select.js';
import { FREE, FIXED, MIXED, faceLabels, faceColors, fieldColors } from './regions.js';

const $ = (id) => document.getElementById(id);

export const app = {
  api: new Api(),
  camera: new OrbitCamera(),
  renderer: null,
  session: null, // {id, token, meshId}
  ws: null,
  you: null,
  state: 'none',
  mesh: null, // {triangles, edges, rest}
  positions: null,
  normals: null,
  colors: null,
  labels: null,
  faceLabels: null, // per triangle: its vertices' label, or MIXED (regions.js)
  handles: 0,
  applied: null, // {serverIndexOf: Map(uiHandle → server index), json}
  constraintsRevision: 0, // the session's constraint set these labels show
  dirtyLabels: false,
  seq: 0,
  sent: new Map(), // seq → send time (ms)
  latencies: [],
  frames: 0,
  last: null, // last frame header
  needsDraw: true,
  eventLog: [],
  progressLog: [],
  warnings: [],
  colorMode: 'regions', // or a field of GET …/curvature: mean, gaussian, g
  curvature: null,
};

let curvatureTimer = null;

/** Fetches the pose's curvatures (GET …/curvature) for the colour map,
 * at most once per settled pose. */
export function refreshCurvature() {
  if (app.colorMode === 'regions' || !app.session) return;
  clearTimeout(curvatureTimer);
  curvatureTimer = setTimeout(guarded(async () => {
    const s = app.session;
    app.curvature = await app.api.curvature(s.id, s.token);
    recolor();
  }), 100);
}

// ---------- errors and status ----------

export function showError(e) {
  const text = e instanceof ApiError || (e && e.code) ? `${e.code}: ${e.message}` : String(e && e.message ? e.message : e);
  $('errorText').textContent = text;
  $('error').hidden = false;
}
$('errorClose').onclick = () => { $('error').hidden = true; };

/** The progress line of the status bar (upload, session set-up, the
 * factor build's stages from the server); '' hides it. Each text shown
 * is kept in `app.progressLog` (the last 20) for the browser test. */
export function progress(text) {
  $('stProgress').textContent = text;
  $('stProgress').hidden = !text;
  if (text) {
    app.progressLog.push(text);
    if (app.progressLog.length > 20) app.progressLog.shift();
  }
}

function guarded(fn) {
  return async (...a) => {
    try {
      await fn(...a);
    } catch (e) {
      showError(e);
    }
  };
}

export function setState(s) {
  app.eventLog.push(`setState:${s}`);
  app.state = s;
  $('stState').textContent = `session: ${s}`;
}

export function updateStats() {
  const f = app.last;
  $('stIter').textContent = f ? String(f.iteration) : '–';
  $('stConv').textContent = !f
    ? '–'
    : !f.settled
      ? 'iterating…'
      : f.converged
        ? 'settled'
        : `not settled after ${f.iteration} iterations`;
  $('stFrames').textContent = String(app.frames);
  const l = app.latencies;
  $('stLatency').textContent = '–';
  if (l.length) {
    const s = [...l].sort((a, b) => a - b);
    $('stLatency').textContent = `${l[l.length - 1].toFixed(0)} ms (median ${s[s.length >> 1].toFixed(0)})`;
  }
}

/** The server's warnings about the constraint set (nothing fixed, a loose
 * part, stray picks), shown until the set changes. */
export function showWarnings(list) {
  app.warnings = list;
  const box = $('warnings');
  box.replaceChildren(...list.map((w) => {
    const p = document.createElement('p');
    p.textContent = `⚠ ${w.message}`;
    p.dataset.code = w.code;
    return p;
  }));
  box.hidden = list.length === 0;
}

// ---------- colours and labels ----------

function recolor() {
  const field = app.colorMode !== 'regions' && app.curvature ? app.curvature[app.colorMode] : null;
  if (field && field.length === app.labels.length) {
    app.faceLabels = null;
    app.renderer.setColors(fieldColors(field, app.colors));
  } else {
    app.faceLabels = faceLabels(app.labels, app.mesh.triangles);
    const { rgb, hatch } = faceColors(app.faceLabels);
    app.renderer.setFaceColors(rgb, hatch);
  }
  app.needsDraw = true;
  const nf = app.labels.filter((l) => l === FIXED).length;
  const counts = [];
  for (let h = 1; h <= app.handles; h++) counts.push(app.labels.filter((l) => l === h).length);
  const mixed = app.faceLabels ? app.faceLabels.filter((l) => l === MIXED).length : 0;
  $('selinfo').textContent = `fixed ${nf}; handles [${counts.join(', ')}]; ${mixed} border faces${app.dirtyLabels ? ' — not applied' : ''}`;
}

/** Grows (adds every neighbour) or shrinks (removes every vertex with a
 * neighbour outside) the region of the current paint target by one ring. */
function growShrink(grow) {
  const t = $('target').value;
  if (!app.labels || t === 'erase') return;
  const label = t === 'fixed' ? FIXED : Number(t.slice(1)) + 1;
  const change = [];
  const e = app.mesh.edges; // flat [a, b, a, b, ...]
  for (let k = 0; k < e.length; k += 2) {
    const [a, b] = [e[k], e[k + 1]];
    const [la, lb] = [app.labels[a], app.labels[b]];
    if (grow) {
      if (la === label && lb === FREE) change.push(b);
      if (lb === label && la === FREE) change.push(a);
    } else if ((la === label) !== (lb === label)) {
      change.push(la === label ? a : b);
    }
  }
  for (const i of change) app.labels[i] = grow ? label : FREE;
  app.dirtyLabels = true;
  recolor();
  strokeEnded();
}

/** Paints vertex indices with the current target (fixed, a handle, erase). */
export function paint(indices, erase = false) {
  const t = $('target').value;
  const label = erase || t === 'erase' ? FREE : t === 'fixed' ? FIXED : Number(t.slice(1)) + 1;
  for (const i of indices) app.labels[i] = label;
  app.dirtyLabels = true;
  recolor();
}

function addHandle() {
  const k = app.handles++;
  const o = document.createElement('option');
  o.value = `h${k}`;
  o.textContent = `handle ${k}`;
  $('target').appendChild(o);
  $('target').value = o.value;
}

/** The constraints JSON of the painted labels (empty handles are skipped). */
function constraintsJson() {
  const fixed = [];
  const groups = Array.from({ length: app.handles }, () => []);
  app.labels.forEach((l, i) => {
    if (l === FIXED) fixed.push(i);
    else if (l > 0) groups[l - 1].push(i);
  });
  const serverIndexOf = new Map();
  const handles = [];
  groups.forEach((g, k) => {
    if (g.length) {
      serverIndexOf.set(k, handles.length);
      handles.push({ name: `handle${k}`, vertices: g });
    }
  });
  return { json: { fixed, handles }, serverIndexOf };
}

export const applyConstraints = guarded(async () => {
  if (!app.session) throw new ApiError('no_session', 'generate or upload a mesh first');
  const c = constraintsJson();
  const before = app.state;
  // before the request: its `ready` event may come before its response
  setState('building');
  try {
    // based on the set these labels came from: a collaborator's edit in
    // between is refused instead of silently replaced
    const r = await app.api.setConstraints(app.session.id, app.session.token, c.json, app.constraintsRevision);
    app.applied = c;
    app.dirtyLabels = false;
    if (r && r.constraints_revision !== undefined) app.constraintsRevision = r.constraints_revision;
    recolor();
  } catch (e) {
    setState(before);
    if (e.code === 'stale_constraints') {
      // show the collaborator's set; the user's strokes are gone
      const info = await app.api.session(app.session.id, app.session.token);
      showConstraints(info);
      throw new ApiError(e.code, 'another collaborator changed the constraints: their regions are shown now; paint again to edit them');
    }
    throw e;
  }
});

/** Labels from the session's constraint set (the `constraints` of a state
 * message or of GET session): index lists as painted; box and sphere
 * selectors are not shown (this client paints index lists). */
export function showConstraints(info) {
  if (!app.labels || info.constraints_revision === undefined) return;
  app.constraintsRevision = info.constraints_revision;
  const c = info.constraints;
  app.labels.fill(FREE);
  for (const o of [...$('target').options]) if (o.value.startsWith('h')) o.remove();
  app.handles = 0;
  const serverIndexOf = new Map();
  const n = app.labels.length;
  const inRange = (i) => Number.isInteger(i) && i >= 0 && i < n;
  if (c && Array.isArray(c.fixed)) for (const i of c.fixed) if (inRange(i)) app.labels[i] = FIXED;
  for (const [k, h] of ((c && c.handles) || []).entries()) {
    addHandle();
    serverIndexOf.set(k, k);
    if (Array.isArray(h.vertices)) for (const i of h.vertices) if (inRange(i)) app.labels[i] = k + 1;
  }
  if (app.handles === 0) addHandle();
  $('target').value = 'fixed';
  app.applied = c ? { json: c, serverIndexOf } : null;
  app.dirtyLabels = false;
  recolor();
}

let autoApplyTimer = null;

/** Called by the painting tools when a stroke ends: with "auto" on, the
 * set is applied once painting pauses (400 ms), and only when it can be
 * solved (some handle has vertices): a fixed-only stroke builds nothing. */
export function strokeEnded() {
  if (!$('autoApply').checked || !app.session) return;
  clearTimeout(autoApplyTimer);
  autoApplyTimer = setTimeout(() => {
    if (app.labels && app.labels.some((l) => l > 0)) applyConstraints();
  }, 400);
}

// ---------- session ----------

function params() {
  const e = $('energy').value;
  const energy = e === 'combined' ? { combined: { ks: +$('ks').value, kb: +$('kb').value } } : e;
  const mode = $('mode').value;
  // the default (elastic) formulation has total curvature or thin plate as
  // its bending energy and no paper mode: the other choices are the
  // paper's eq. (24) least squares
  const elastic = (e === 'total' || e === 'thin-plate') && mode !== 'paper';
  // the characters' weights (Params::for_characters; README,
  // docs/posing.md: 11 of the suite's 12 character edits pass against 7
  // with the defaults, 14 of its 20 edits against 8)
  const characters = elastic && $('weights').value === 'characters'
    ? { stretch: 3, laplacian: 0.1, coarse_ratio: 3, corrections: 'while-gaining', correction_period: 5 }
    : {};
  return {
    energy,
    lambda1: $('hard').checked ? 0 : +$('lambda1').value,
    lambda2: +$('lambda2').value,
    detail: $('detail').value,
    mode,
    formulation: elastic ? 'elastic' : 'least_squares',
    ...characters,
  };
}

function setMesh(obj) {
  app.mesh = { triangles: obj.triangles, edges: edgeList(obj.triangles) };
  app.positions = obj.positions;
  app.normals = new Float32Array(obj.positions.length);
  app.colors = new Float32Array(obj.positions.length);
  app.labels = new Int32Array(obj.positions.length / 3);
  app.renderer.setTopology(app.mesh.triangles, app.mesh.edges);
  app.gizmo.handle = null;
  // a fresh camera per mesh: the default orbit, framed on it
  const fresh = new OrbitCamera();
  app.camera.yaw = fresh.yaw;
  app.camera.pitch = fresh.pitch;
  app.camera.fit(bbox(obj.positions), viewAspect());
  uploadPose();
  recolor();
  $('meshinfo').textContent = `${obj.positions.length / 3} vertices, ${obj.triangles.length / 3} triangles`;
}

export function uploadPose() {
  vertexNormals(app.positions, app.mesh.triangles, app.normals);
  app.renderer.setPositions(app.positions, app.normals);
  app.needsDraw = true;
}

async function openSession(id, token, meshId) {
  if (app.ws) {
    app.ws.onclose = null;
    app.ws.close();
    app.ws = null;
  }
  app.session = { id, token, meshId };
  app.frames = 0;
  app.last = null;
  app.latencies = [];
  app.sent.clear();
  updateStats();
  const link = `${location.origin}${location.pathname}#session=${id}&token=${token}`;
  $('shareLink').value = link;
  // the session in the URL: a reload or a bookmark reopens it
  history.replaceState(null, '', `#session=${id}&token=${token}`);
  app.ws = await app.api.connect(id, token, socketHandlers);
}

async function startSession(meshId) {
  progress('computing the mesh operators…');
  const s = await app.api.createSession(meshId, params()).finally(() => progress(''));
  // The triangles come from the OBJ export of the rest pose (the API has no
  // route for the mesh itself); then the socket, whose frames need them.
  setMesh(parseObj(await app.api.exportObj(s.id, s.token)));
  setState(s.state || 'empty');
  await openSession(s.id, s.token, meshId);
}

const generate = guarded(async () => {
  $('error').hidden = true;
  setState('creating');
  const m = await app.api.generate($('shape').value);
  await startSession(m.id);
  resetPaint();
});

const upload = guarded(async (ev) => {
  const file = ev.target.files[0];
  if (!file) return;
  $('error').hidden = true;
  const before = app.state;
  setState('uploading');
  progress(`uploading and parsing ${file.name} (${(file.size / 1e6).toFixed(1)} MB)…`);
  let m;
  try {
    m = await app.api.upload(file);
  } catch (e) {
    setState(before);
    throw e;
  } finally {
    progress('');
    ev.target.value = ''; // the same file can be picked again
  }
  await startSession(m.id);
  resetPaint();
});

function resetPaint() {
  app.handles = 0;
  app.applied = null;
  app.constraintsRevision = 0;
  app.dirtyLabels = false;
  for (const o of [...$('target').options]) if (o.value.startsWith('h')) o.remove();
  addHandle();
  $('target').value = 'fixed';
  recolor();
}

const restartWithParams = guarded(async () => {
  if (!app.session) throw new ApiError('no_session', 'generate or upload a mesh first');
  const s = await app.api.createSession(app.session.meshId, params());
  setState(s.state || 'empty');
  await openSession(s.id, s.token, app.session.meshId);
  if (app.applied) await applyConstraints();
});

/** Joins an existing session from a share link (#session=…&token=…). */
async function join(id, token) {
  setState('joining');
  const info = await app.api.session(id, token);
  setMesh(parseObj(await app.api.exportObj(id, token)));
  resetPaint();
  showConstraints(info);
  setState(info.state);
  await openSession(id, token, info.mesh_id);
}

// ---------- WebSocket ----------

/** Sends a JSON message on the session socket. */
export function send(msg) {
  if (!app.ws || app.ws.readyState !== WebSocket.OPEN) {
    showError({ code: 'not_connected', message: 'no session: generate or upload a mesh first' });
    return false;
  }
  app.ws.send(JSON.stringify(msg));
  return true;
}

/** Server handle index of a painted UI handle (its painted index when the
 * constraints were never applied, so the server can say what is wrong). */
export function serverHandle(uiHandle) {
  if (app.applied && app.applied.serverIndexOf.has(uiHandle)) return app.applied.serverIndexOf.get(uiHandle);
  return uiHandle;
}

/** Sends one drag delta and records its send time for the latency. */
export function sendDrag(uiHandle, translate, rotate) {
  const seq = ++app.seq;
  const msg = { type: 'drag', handle: serverHandle(uiHandle), translate, seq };
  if (rotate) msg.rotate = rotate;
  if (send(msg)) app.sent.set(seq, performance.now());
}

// ---------- pose buttons ----------

async function download(name, blob) {
  const a = document.createElement('a');
  a.href = URL.createObjectURL(blob);
  a.download = name;
  a.click();
  setTimeout(() => URL.revokeObjectURL(a.href), 1000);
}

function needSession() {
  if (!app.session) throw new ApiError('no_session', 'generate or upload a mesh first');
  return app.session;
}

$('generate').onclick = generate;
$('upload').onchange = upload;
$('addHandle').onclick = addHandle;
// a handle chosen as the paint target gets the gizmo
$('target').onchange = (e) => {
  const v = e.target.value;
  if (v.startsWith('h')) app.gizmo.handle = Number(v.slice(1));
  app.needsDraw = true;
};
$('apply').onclick = applyConstraints;
$('clearSel').onclick = () => { app.labels.fill(FREE); app.dirtyLabels = true; recolor(); };
$('growSel').onclick = () => growShrink(true);
$('colorMode').onchange = (e) => {
  app.colorMode = e.target.value;
  app.curvature = null;
  recolor();
  refreshCurvature();
};
$('shrinkSel').onclick = () => growShrink(false);
$('saveCons').onclick = guarded(async () => {
  if (!app.applied) throw new ApiError('no_constraints', 'apply a constraint set first');
  await download('constraints.json', new Blob([JSON.stringify(app.applied.json, null, 1)], { type: 'application/json' }));
});
$('loadCons').onchange = guarded(async (ev) => {
  const file = ev.target.files[0];
  ev.target.value = '';
  if (!file) return;
  needSession();
  let json;
  try {
    json = JSON.parse(await file.text());
  } catch (e) {
    throw new ApiError('invalid_json', `${file.name} is not JSON: ${e.message}`);
  }
  const r = await app.api.setConstraints(app.session.id, app.session.token, json, app.constraintsRevision);
  showConstraints({ constraints: json, constraints_revision: r.constraints_revision });
});
$('panelToggle').onclick = () => {
  const p = $('panel');
  p.classList.toggle('collapsed');
  $('panelToggle').setAttribute('aria-expanded', String(!p.classList.contains('collapsed')));
  app.needsDraw = true;
};
$('applyParams').onclick = restartWithParams;
$('undo').onclick = () => send({ type: 'undo' });
$('redo').onclick = () => send({ type: 'redo' });
$('reset').onclick = guarded(async () => { const s = needSession(); await app.api.reset(s.id, s.token); });
$('export').onclick = guarded(async () => {
  const s = needSession();
  const f = $('exportFormat').value;
  await download(`dend-${s.id.slice(0, 8)}.${f}`, await app.api.exportAs(s.id, s.token, f));
});
$('share').onclick = guarded(async () => {
  needSession();
  $('shareLink').select();
  if (navigator.clipboard) await navigator.clipboard.writeText($('shareLink').value).catch(() => {});
});
$('wireframe').onchange = (e) => { app.renderer.wireframe = e.target.checked; app.needsDraw = true; };
$('energy').onchange = (e) => { $('combinedRow').hidden = e.target.value !== 'combined'; };
$('hard').onchange = (e) => { $('lambda1').disabled = e.target.checked; };

/** Width / height of the canvas. */
function viewAspect() {
  const c = $('view');
  return c.clientHeight > 0 ? c.clientWidth / c.clientHeight : 1;
}

/** Frames the current pose: the camera fits its bounding box. */
export function frameView() {
  if (!app.positions) return;
  app.camera.fit(bbox(app.positions), viewAspect());
  app.needsDraw = true;
}

// ---------- start ----------

function loop() {
  if (app.needsDraw && app.renderer) {
    app.renderer.draw(app.camera);
    app.gizmo.draw();
    $('gizmoInfo').textContent = gizmoLabel(app);
    app.needsDraw = false;
  }
  requestAnimationFrame(loop);
}

try {
  app.renderer = new Renderer($('view'));
  app.gizmo = new Gizmo(app, $('gizmo'));
  wireNumeric(app);
  attachInteraction(app, $('view'));
  attachKeys();
  new ResizeObserver(() => { app.needsDraw = true; }).observe($('view'));
  requestAnimationFrame(loop);
  const h = new URLSearchParams(location.hash.slice(1));
  if (h.get('session') && h.get('token')) guarded(join)(h.get('session'), h.get('token'));
} catch (e) {
  showError(e);
}

/** Read-only state for tests and the console. */
window.dend = {
  app,
  positions: () => (app.positions ? Array.from(app.positions) : null),
  labels: () => (app.labels ? Array.from(app.labels) : null),
  /** Per-face labels as drawn (-2: a face whose vertices disagree, hatched). */
  faceLabels: () => (app.faceLabels ? Array.from(app.faceLabels) : null),
  /** The gizmo's screen geometry (CSS px: center, tips, rings) and its
   * arrow length in mesh units, or null when no handle shows one. */
  gizmo: () => app.gizmo.geometry(),
  /** CSS-pixel [x, y] of each vertex index in the current view. */
  project: (indices) => {
    const c = $('view');
    const s = project(app.positions, Renderer.mvp(app.camera, c.clientWidth / c.clientHeight), c.clientWidth, c.clientHeight);
    return indices.map((i) => [s[3 * i], s[3 * i + 1]]);
  },
  stats: () => ({ events: [...app.eventLog], warnings: app.warnings.map((w) => w.code), state: app.state, frames: app.frames, last: app.last && { ...app.last, positions: undefined }, latencies: [...app.latencies], flow: app.flow }),
};
