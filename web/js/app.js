// The dend reference client: session set-up, region labels, constraints,
// WebSocket pose frames and the UI panel. Mouse handling is in interact.js.
// Everything goes through the public API (api.js); `window.dend` exposes a
// read-only view of the state for the browser test.

import { Api, ApiError } from './api.js';
import { OrbitCamera } from './camera.js';
import { parseObj, vertexNormals, edgeList, bbox, parseGlb, glbTexture, glbImage } from './mesh.js';
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
  texture: null, // an uploaded glTF's base-colour texture as drawn: {uv, textured, size}
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
  presets: null, // GET /v1/presets: {default, presets: [{name, label, description, params}]}
  settingsUndo: [], // earlier sessions a settings change left: [{session, settings}]
  canUndo: false, // the session's own history has an earlier entry
  held: new Map(), // server handle index → client id holding it (another client's grab)
  notices: [], // each quiet status shown (the browser test counts them)
  opened: false, // the first open (the creature, or the session of the URL) is done
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

/** A quiet status line (not an error): `text`, or '' to clear it. The
 * same text shown again is not a new notice. */
export function notice(text) {
  const el = $('notice');
  if (text && (el.hidden || el.textContent !== text)) app.notices.push(text);
  el.textContent = text;
  el.hidden = !text;
}

/** Another client holds server handle `handle` (a `handle_grabbed` event,
 * or the error of a drag it refused): one quiet status until released. */
export function showHeld(handle, client) {
  if (client !== undefined && client === app.you) return;
  if (handle === undefined || handle === null) {
    // a refused drag: the grab's own status is shown already, if any
    if (app.held.size === 0) notice('the handle is held by another client');
    return;
  }
  app.held.set(handle, client);
  notice(`handle ${handle} held by ${client === undefined ? 'another client' : `client ${client}`}`);
}

/** `handle` was released (or every handle, when the socket changes). */
export function clearHeld(handle) {
  if (handle === undefined) app.held.clear();
  else app.held.delete(handle);
  if (app.held.size === 0) notice('');
}

/** Whether another client holds the handle of UI handle `k`. */
export function heldByOther(k) {
  return app.held.has(serverHandle(k));
}

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
      ? f.level === 1 ? 'coarse preview…' : 'iterating…'
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
    const { rgb, hatch, tint } = faceColors(app.faceLabels);
    app.renderer.setFaceColors(rgb, hatch, tint);
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

// ---------- settings: the server's presets, a stiffness, the paper's parameters ----------

/** The preset chosen in the menu ({name, label, description, params}), or
 * null when the server lists none. */
function currentPreset() {
  const list = app.presets ? app.presets.presets : [];
  return list.find((p) => p.name === $('preset').value) || null;
}

/** The stiffness slider's factor on the preset's bending weight β
 * (`bending` in the session parameters): 2^slider, 0.25× to 4×. */
function stiffnessFactor() {
  return 2 ** Number($('stiffness').value);
}

/** The Advanced fold's fields as session parameters. */
function advancedParams() {
  const e = $('energy').value;
  const energy = e === 'combined' ? { combined: { ks: +$('ks').value, kb: +$('kb').value } } : e;
  const mode = $('mode').value;
  // the default (elastic) formulation has total curvature or thin plate as
  // its bending energy and no paper mode: the other choices are the
  // paper's eq. (24) least squares
  const elastic = (e === 'total' || e === 'thin-plate') && mode !== 'paper';
  return {
    energy,
    lambda1: $('hard').checked ? 0 : +$('lambda1').value,
    lambda2: +$('lambda2').value,
    detail: $('detail').value,
    mode,
    formulation: elastic ? 'elastic' : 'least_squares',
  };
}

/** Fills the Advanced fold from a preset's parameters (what the server
 * sends; fields it does not name keep their value). */
function showAdvanced(p) {
  if (!p) return;
  if (typeof p.energy === 'string') $('energy').value = p.energy;
  else if (p.energy && p.energy.combined) {
    $('energy').value = 'combined';
    $('ks').value = p.energy.combined.ks;
    $('kb').value = p.energy.combined.kb;
  }
  $('combinedRow').hidden = $('energy').value !== 'combined';
  if (typeof p.lambda1 === 'number') {
    $('hard').checked = p.lambda1 === 0;
    $('lambda1').disabled = p.lambda1 === 0;
    if (p.lambda1 > 0) $('lambda1').value = p.lambda1;
  }
  if (typeof p.lambda2 === 'number') $('lambda2').value = p.lambda2;
  if (typeof p.detail === 'string') $('detail').value = p.detail;
  if (typeof p.mode === 'string') $('mode').value = p.mode;
}

/** The session parameters of the panel: the preset by name, the fields of
 * the Advanced fold that differ from the preset's (explicit fields
 * override a preset), and the stiffness as the preset's `bending` scaled. */
function params() {
  const preset = currentPreset();
  const adv = advancedParams();
  if (!preset) return adv;
  const out = { preset: preset.name };
  const same = (a, b) => JSON.stringify(a) === JSON.stringify(b);
  for (const [k, v] of Object.entries(adv)) if (!same(v, preset.params[k])) out[k] = v;
  const f = stiffnessFactor();
  if (f !== 1 && typeof preset.params.bending === 'number') out.bending = preset.params.bending * f;
  return out;
}

/** The panel's settings, to restore them on undo. */
function settingsSnapshot() {
  const ids = ['preset', 'stiffness', 'energy', 'ks', 'kb', 'lambda1', 'lambda2', 'detail', 'mode'];
  return { values: Object.fromEntries(ids.map((id) => [id, $(id).value])), hard: $('hard').checked };
}

function restoreSettings(s) {
  for (const [id, v] of Object.entries(s.values)) $(id).value = v;
  $('hard').checked = s.hard;
  $('lambda1').disabled = s.hard;
  $('combinedRow').hidden = $('energy').value !== 'combined';
  showStiffness();
  showPresetInfo();
}

function showStiffness() {
  const f = stiffnessFactor();
  $('stiffnessOut').textContent = `${f < 1 ? f.toFixed(2) : f.toFixed(f % 1 ? 2 : 0)}×`;
}

function showPresetInfo() {
  const p = currentPreset();
  $('presetInfo').textContent = p ? p.description || '' : 'the server lists no presets: its defaults';
}

/** The preset menu, built from the server's list (GET /v1/presets). */
async function loadPresets() {
  try {
    app.presets = await app.api.json('GET', '/v1/presets');
  } catch (e) {
    app.presets = null; // an older server: its defaults, no menu
  }
  const list = app.presets ? app.presets.presets || [] : [];
  $('preset').replaceChildren(...list.map((p) => {
    const o = document.createElement('option');
    o.value = p.name;
    o.textContent = p.label || p.name;
    o.title = p.description || '';
    return o;
  }));
  $('preset').disabled = list.length === 0;
  $('stiffness').disabled = list.length === 0;
  if (list.length) {
    $('preset').value = list.some((p) => p.name === app.presets.default) ? app.presets.default : list[0].name;
    showAdvanced(currentPreset().params);
  }
  showStiffness();
  showPresetInfo();
}

function setMesh(obj) {
  app.mesh = { triangles: obj.triangles, edges: edgeList(obj.triangles) };
  app.positions = obj.positions;
  app.normals = new Float32Array(obj.positions.length);
  app.colors = new Float32Array(obj.positions.length);
  app.labels = new Int32Array(obj.positions.length / 3);
  app.renderer.setTopology(app.mesh.triangles, app.mesh.edges); // untextured
  app.texture = null;
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

/** An uploaded glTF/GLB (`info`: its mesh info) is drawn with its
 * base-colour texture, on its own UVs (from the session's GLB export of
 * the pose `obj` shows); other meshes keep their flat colours. */
async function showTexture(s, info, obj) {
  const a = info && info.asset;
  if (!a || (a.format !== 'glb' && a.format !== 'gltf')) return;
  const mesh = app.mesh;
  try {
    const glb = parseGlb(await (await app.api.exportAs(s.id, s.token, 'glb')).arrayBuffer());
    const t = glbTexture(glb, obj.positions, obj.triangles);
    if (!t || !t.image) return;
    const image = await glbImage(glb, t.image);
    if (app.mesh !== mesh) return; // another mesh since
    app.renderer.setTexture(image, t.sampler, t.factor, t.uv, t.textured);
    app.texture = { uv: t.uv, textured: t.textured, size: [image.width, image.height] };
    recolor();
  } catch (e) {
    notice(`the texture is not shown: ${e.message}`);
  }
}

async function openSession(id, token, meshId) {
  if (app.ws) {
    app.ws.onclose = null;
    app.ws.close();
    app.ws = null;
  }
  app.session = { id, token, meshId };
  app.canUndo = false;
  clearHeld();
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

async function startSession(meshId, info) {
  progress('computing the mesh operators…');
  const s = await app.api.createSession(meshId, params()).finally(() => progress(''));
  // The triangles come from the OBJ export of the rest pose (the API has no
  // route for the mesh itself); then the socket, whose frames need them.
  const obj = parseObj(await app.api.exportObj(s.id, s.token));
  setMesh(obj);
  setState(s.state || 'empty');
  await openSession(s.id, s.token, meshId);
  await showTexture(s, info, obj);
}

/** Generates the menu's shape and opens a session on it; a shape with a
 * default edit (the creature: feet fixed, head a handle) gets it applied,
 * its handle selected for the gizmo. */
async function generateShape(shape) {
  $('error').hidden = true;
  setState('creating');
  const m = await app.api.generate(shape);
  app.settingsUndo = [];
  await startSession(m.id);
  resetPaint();
  if (m.constraints) {
    const r = await app.api.setConstraints(app.session.id, app.session.token, m.constraints, app.constraintsRevision);
    showConstraints({ constraints: m.constraints, constraints_revision: r.constraints_revision });
    app.gizmo.handle = 0;
    $('prompt').hidden = false;
    app.needsDraw = true;
  }
}

const generate = guarded(() => generateShape($('shape').value));

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
  app.settingsUndo = [];
  await startSession(m.id, m);
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

/** The constraint set of the painted labels pinned where the pose has
 * its vertices (`fixed_positions`, each handle's `positions`): a new
 * session with other parameters starts from the same regions and handle
 * targets, so the pose is kept (the free vertices are solved again with
 * the new parameters). */
function pinnedConstraints() {
  const c = constraintsJson();
  const at = (i) => [app.positions[3 * i], app.positions[3 * i + 1], app.positions[3 * i + 2]];
  const json = {
    fixed: c.json.fixed,
    fixed_positions: c.json.fixed.map(at),
    handles: c.json.handles.map((h) => ({ ...h, positions: h.vertices.map(at) })),
  };
  return { json, serverIndexOf: c.serverIndexOf };
}

let settingsBusy = null;

/** A settings change (preset, stiffness, an Advanced field): a session
 * with the new parameters on the same mesh, given the current regions and
 * pose; the previous session is kept as the undo step (Undo returns to
 * it). Only the constraint set of this tab is sent, to a session no one
 * else edits: no `stale_constraints`. */
const changeSettings = guarded(async (previous) => {
  if (!app.session) return;
  while (settingsBusy) await settingsBusy;
  let done;
  settingsBusy = new Promise((r) => { done = r; });
  try {
    const old = app.session;
    const hasRegions = app.labels.some((l) => l > 0);
    const pinned = hasRegions ? pinnedConstraints() : null;
    progress('applying the new settings…');
    const s = await app.api.createSession(old.meshId, params());
    let revision = 0;
    if (pinned) {
      const r = await app.api.setConstraints(s.id, s.token, pinned.json);
      revision = r && r.constraints_revision !== undefined ? r.constraints_revision : 0;
    }
    app.settingsUndo.push({ session: old, settings: previous });
    if (pinned) {
      // the same regions (the explicit positions are this session's anchor)
      app.applied = { json: constraintsJson().json, serverIndexOf: pinned.serverIndexOf };
      app.dirtyLabels = false;
      app.constraintsRevision = revision;
    } else {
      app.applied = null;
      app.constraintsRevision = 0;
    }
    setState(pinned ? 'building' : 'empty');
    await openSession(s.id, s.token, old.meshId);
    recolor();
  } finally {
    progress('');
    settingsBusy = null;
    done();
  }
});

/** Undo: the session's own history first; at its start, the last
 * settings change (back to the session and settings before it). */
export const undo = guarded(async () => {
  if (app.canUndo || app.settingsUndo.length === 0) {
    send({ type: 'undo' });
    return;
  }
  const { session, settings } = app.settingsUndo.pop();
  const dropped = app.session;
  restoreSettings(settings);
  lastSettings = settings;
  const info = await app.api.session(session.id, session.token);
  await openSession(session.id, session.token, session.meshId);
  showConstraints(info);
  setState(info.state);
  // the abandoned session: nobody else has its token
  if (dropped) app.api.json('DELETE', `/v1/sessions/${dropped.id}`, undefined, dropped.token).catch(() => {});
});

/** The settings before the last change (the undo step's). */
let lastSettings = null;

function settingsChanged() {
  const previous = lastSettings;
  lastSettings = settingsSnapshot();
  showPresetInfo();
  showStiffness();
  if (previous) changeSettings(previous);
}

/** Joins an existing session from a share link (#session=…&token=…). */
async function join(id, token) {
  setState('joining');
  const info = await app.api.session(id, token);
  const obj = parseObj(await app.api.exportObj(id, token));
  setMesh(obj);
  resetPaint();
  showConstraints(info);
  // a set with handles: the first one gets the gizmo
  if (app.labels.some((l) => l > 0)) app.gizmo.handle = 0;
  setState(info.state);
  await openSession(id, token, info.mesh_id);
  await showTexture({ id, token }, await app.api.json('GET', `/v1/meshes/${info.mesh_id}`).catch(() => null), obj);
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
  $('prompt').hidden = true;
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
for (const id of ['stiffness', 'energy', 'ks', 'kb', 'hard', 'lambda1', 'lambda2', 'detail', 'mode']) {
  $(id).addEventListener('change', settingsChanged);
}
$('preset').addEventListener('change', () => {
  // a preset brings its own parameters: the Advanced fold shows them
  showAdvanced(currentPreset() && currentPreset().params);
  settingsChanged();
});
$('stiffness').addEventListener('input', showStiffness);
$('helpClose').onclick = () => { $('helpOverlay').hidden = true; };
$('undo').onclick = undo;
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
  (async () => {
    await loadPresets();
    lastSettings = settingsSnapshot();
    if (h.get('session') && h.get('token')) await guarded(join)(h.get('session'), h.get('token'));
    // first open: a posable creature with its feet fixed and its head a handle
    else await guarded(generateShape)('creature');
    app.opened = true;
  })();
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
  /** The glTF texture as drawn: its size, per triangle corner its UV (2
   * numbers) and per triangle whether it has one; null when untextured. */
  texture: () => (app.texture ? { size: app.texture.size, uv: Array.from(app.texture.uv), textured: Array.from(app.texture.textured) } : null),
  /** The gizmo's screen geometry (CSS px: center, tips, rings) and its
   * arrow length in mesh units, or null when no handle shows one. */
  gizmo: () => app.gizmo.geometry(),
  /** CSS-pixel [x, y] of each vertex index in the current view. */
  project: (indices) => {
    const c = $('view');
    const s = project(app.positions, Renderer.mvp(app.camera, c.clientWidth / c.clientHeight), c.clientWidth, c.clientHeight);
    return indices.map((i) => [s[3 * i], s[3 * i + 1]]);
  },
  stats: () => ({ events: [...app.eventLog], warnings: app.warnings.map((w) => w.code), state: app.state, frames: app.frames, last: app.last && { ...app.last, positions: undefined }, latencies: [...app.latencies], flow: app.flow, notices: [...app.notices] }),
};
