// Sessions: generating or uploading a mesh and opening a session on it,
// joining one from a share link, a settings change as a new session on the
// same mesh (one undo step), and undo across those changes.

import { OrbitCamera } from './camera.js';
import { parseObj, edgeList, bbox, parseGlb, glbTexture, glbImage } from './mesh.js';
import { socketHandlers } from './socket.js';
import {
  app, guarded, notice, progress, setState, updateStats, clearHeld, send, recolor, uploadPose, viewAspect, addHandle, constraintsJson,
  showConstraints,
} from './app.js';
import {
  params, settingsSnapshot, restoreSettings, showPresetInfo, showStiffness,
} from './settings.js';

const $ = (id) => document.getElementById(id);

export function setMesh(obj) {
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
export async function generateShape(shape) {
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

export const generate = guarded(() => generateShape($('shape').value));

export const upload = guarded(async (ev) => {
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

export function resetPaint() {
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

/** Takes the panel's settings as the current ones (at start-up, once the
 * presets are loaded). */
export function rememberSettings() {
  lastSettings = settingsSnapshot();
}

export function settingsChanged() {
  const previous = lastSettings;
  lastSettings = settingsSnapshot();
  showPresetInfo();
  showStiffness();
  if (previous) changeSettings(previous);
}

/** Joins an existing session from a share link (#session=…&token=…). */
export async function join(id, token) {
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

