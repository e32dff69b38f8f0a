// The editor's shared state and the actions every part of it uses: the
// `app` object (session, mesh, labels, stream figures), the status bar and
// error banner, painting labels and applying them as the session's
// constraint set, the colour map, and sending drags on the session socket.
// The UI parts (interact.js, gizmo.js, keys.js, socket.js, session.js)
// import this module and nothing imports them back: main.js wires them up.

import { Api, ApiError } from './api.js';
import { OrbitCamera } from './camera.js';
import { vertexNormals, bbox } from './mesh.js';
import { FREE, FIXED, MIXED, faceLabels, faceColors, fieldColors } from './regions.js';
import { headInPose } from './rig.js';

const $ = (id) => document.getElementById(id);

export const app = {
  api: new Api(),
  camera: new OrbitCamera(),
  renderer: null,
  session: null, // {id, token, meshId}
  ws: null,
  you: null,
  state: 'none',
  mesh: null, // {triangles, edges, rest}; rest: the rest positions when known (a session opened here from rest)
  texture: null, // an uploaded glTF's base-colour texture as drawn: {uv, textured, size}
  positions: null,
  normals: null,
  colors: null,
  labels: null,
  faceLabels: null, // per triangle: its vertices' label, or MIXED (regions.js)
  handles: 0,
  handleJoints: new Map(), // UI handle → index of the skeleton joint it is (outliner.js): its gizmo and pivot are the joint's head
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
  settingsRedo: [], // later sessions an undo across a settings change left: [{session, settings}]
  canUndo: false, // the session's own history has an earlier entry
  canRedo: false, // the session's own history has a later entry
  meshInfo: null, // GET /v1/meshes/{id} of the open session's mesh (its asset, its warnings), when known
  dragged: false, // the user dragged a handle since this mesh opened (the canvas prompt goes)
  held: new Map(), // server handle index → client id holding it (another client's grab)
  notices: [], // each quiet status shown (the browser test counts them)
  opened: false, // the first open (the creature, or the session of the URL) is done
};

/** Events of the shared state, for the parts that follow it (the
 * guidance, the named poses) without this module importing them:
 * `labels` (painted or applied labels changed), `session` (a session was
 * opened), `drag` (the user sent a drag). */
export const events = new EventTarget();

export function emit(type) {
  events.dispatchEvent(new Event(type));
}

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
  $('errorText').textContent = errorText(e);
  $('error').hidden = false;
}

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

export function guarded(fn) {
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
        : `not settled after ${f.iteration} iterations: the server stopped at its iteration budget`;
  // the iteration budget ran out before the pose converged: the next steps
  $('stCap').hidden = !(f && f.settled && !f.converged);
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

export function recolor() {
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
  emit('labels');
}

/** Grows (adds every neighbour) or shrinks (removes every vertex with a
 * neighbour outside) the region of the current paint target by one ring. */
export function growShrink(grow) {
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
  // a handle being painted gets the gizmo as soon as it has vertices
  if (label > 0 && app.gizmo) app.gizmo.handle = label - 1;
  recolor();
}

/** A new, empty handle in the paint menu, chosen as the paint target; the
 * gizmo follows it (it shows once the handle has vertices). */
export function addHandle() {
  const k = app.handles++;
  const o = document.createElement('option');
  o.value = `h${k}`;
  o.textContent = `handle ${k}`;
  $('target').appendChild(o);
  $('target').value = o.value;
  if (app.gizmo) app.gizmo.handle = k;
  app.needsDraw = true;
}

/** The joints of the open mesh's skeleton (GET /v1/meshes/{id}), or null. */
export function skeletonJoints() {
  const a = app.meshInfo && app.meshInfo.asset;
  return (a && a.skeleton && a.skeleton.joints) || null;
}

/** Where the joint UI handle `k` is (its joint's head in the current pose,
 * rig.js), or null when `k` is no joint's handle. */
export function jointHandleHead(k) {
  const joints = skeletonJoints();
  if (!joints || !app.handleJoints.has(k) || !app.positions) return null;
  return headInPose(joints, app.handleJoints.get(k), app.mesh && app.mesh.rest, app.positions);
}

/** The constraints JSON of the painted labels (empty handles are skipped).
 * A joint's handle is named after the joint and turns about its head
 * (`pivot`): a drag's rotation is about the joint, as an animator expects. */
export function constraintsJson() {
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
      const joints = skeletonJoints();
      const head = jointHandleHead(k);
      if (head) handles.push({ name: joints[app.handleJoints.get(k)].name, vertices: g, pivot: head });
      else handles.push({ name: `handle${k}`, vertices: g });
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
    discardSettingsRedo();
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
  app.handleJoints.clear();
  const joints = skeletonJoints() || [];
  const serverIndexOf = new Map();
  const n = app.labels.length;
  const inRange = (i) => Number.isInteger(i) && i >= 0 && i < n;
  if (c && Array.isArray(c.fixed)) for (const i of c.fixed) if (inRange(i)) app.labels[i] = FIXED;
  for (const [k, h] of ((c && c.handles) || []).entries()) {
    addHandle();
    serverIndexOf.set(k, k);
    // a handle named after a joint, with its pivot, is that joint's
    const j = joints.findIndex((jt) => jt.name === h.name);
    if (j >= 0 && h.pivot) app.handleJoints.set(k, j);
    if (Array.isArray(h.vertices)) for (const i of h.vertices) if (inRange(i)) app.labels[i] = k + 1;
  }
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

export function uploadPose() {
  vertexNormals(app.positions, app.mesh.triangles, app.normals);
  app.renderer.setPositions(app.positions, app.normals);
  app.needsDraw = true;
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
  if (send(msg)) {
    app.sent.set(seq, performance.now());
    app.dragged = true;
    discardSettingsRedo();
    emit('drag');
  }
}

/** A new edit after an undo across a settings change: the sessions of the
 * settings undone (the redo branch) can no longer be returned to, and are
 * closed on the server. Until then they are kept (and Redo returns to
 * them), for as long as the server keeps an idle session. */
export function discardSettingsRedo() {
  if (app.settingsRedo.length === 0) return;
  for (const { session } of app.settingsRedo.splice(0)) {
    app.api.json('DELETE', `/v1/sessions/${session.id}`, undefined, session.token).catch(() => {});
  }
  showUndoRedo();
}

/** The Undo and Redo buttons: the session's own history, then the
 * settings changes around it. */
export function showUndoRedo() {
  $('undo').disabled = !app.canUndo && app.settingsUndo.length === 0;
  $('redo').disabled = !app.canRedo && app.settingsRedo.length === 0;
}

/** An error or warning shown next to the control that caused it (`anchor`:
 * that control; its row gets the message below it), kept until dismissed
 * (×) or until the same control shows another or succeeds (`text` ''). */
export function controlMessage(anchor, text, kind = 'error') {
  const row = anchor.closest('.row, label.file, section > *') || anchor;
  const id = `${anchor.id}Msg`;
  let box = document.getElementById(id);
  if (!text) {
    if (box) box.remove();
    return;
  }
  if (!box) {
    box = document.createElement('div');
    box.id = id;
    box.setAttribute('role', kind === 'error' ? 'alert' : 'status');
    const span = document.createElement('span');
    const close = document.createElement('button');
    close.textContent = '×';
    close.setAttribute('aria-label', 'dismiss');
    close.onclick = () => box.remove();
    box.append(span, close);
    row.after(box);
  }
  box.className = `ctlMsg ${kind}`;
  box.firstChild.textContent = text;
}

/** The text of an error as the banners show it: `code: message`. */
export function errorText(e) {
  return e instanceof ApiError || (e && e.code) ? `${e.code}: ${e.message}` : String(e && e.message ? e.message : e);
}

export function needSession() {
  if (!app.session) throw new ApiError('no_session', 'generate or upload a mesh first');
  return app.session;
}

/** Width / height of the canvas. */
export function viewAspect() {
  const c = $('view');
  return c.clientHeight > 0 ? c.clientWidth / c.clientHeight : 1;
}

/** Frames the current pose: the camera fits its bounding box. */
export function frameView() {
  if (!app.positions) return;
  app.camera.fit(bbox(app.positions), viewAspect());
  app.needsDraw = true;
}

