// Sessions: generating or uploading a mesh and opening a session on it,
// joining one from a share link, a settings change as a new session on the
// same mesh (one undo step), and undo and redo across those changes.
//
// Undo at the start of a session's own history goes back to the session
// before the last settings change; the session left is kept, and Redo
// returns to it (its own history intact). A new edit after such an undo (a
// drag, applied constraints, a reset, a restored pose, another settings
// change) discards that redo branch and closes its sessions on the server
// (`discardSettingsRedo`, app.js); until then they live as long as the
// server keeps an idle session.

import { OrbitCamera } from './camera.js';
import { parseObj, edgeList, bbox, parseGlb, glbTexture, glbImage } from './mesh.js';
import { socketHandlers } from './socket.js';
import {
  app, guarded, notice, progress, setState, updateStats, clearHeld, send, recolor, uploadPose, viewAspect, constraintsJson,
  showConstraints, emit, showUndoRedo, discardSettingsRedo, controlMessage, errorText,
} from './app.js';
import { uploadBody } from './drop.js';
import {
  params, settingsSnapshot, restoreSettings, showPresetInfo, showStiffness,
} from './settings.js';

const $ = (id) => document.getElementById(id);

export function setMesh(obj) {
  app.mesh = { triangles: obj.triangles, edges: edgeList(obj.triangles) };
  app.dragged = false;
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
  app.canRedo = false;
  showUndoRedo();
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
  emit('session');
}

// socket.js shows the session's own history on the Undo and Redo buttons;
// the settings steps around it are this module's, so its state events pass
// through here too (the handlers object is the one every connect and
// reconnect uses)
const onEvent = socketHandlers.event;
socketHandlers.event = (e) => {
  onEvent(e);
  if (e.type === 'state') {
    app.canRedo = !!e.can_redo;
    showUndoRedo();
  }
};

/** The warnings of the mesh's info (an extent or coordinates no real
 * asset has), next to the upload control until dismissed. */
function showMeshWarnings(info) {
  const list = (info && info.warnings) || [];
  controlMessage($('upload'), list.map((w) => `⚠ ${w.message}`).join('\n'), 'warning');
}

async function startSession(meshId, info) {
  app.meshInfo = info || null;
  showMeshWarnings(info);
  progress('computing the mesh operators…');
  const s = await app.api.createSession(meshId, params()).finally(() => progress(''));
  // The triangles come from the OBJ export of the rest pose (the API has no
  // route for the mesh itself); then the socket, whose frames need them.
  const obj = parseObj(await app.api.exportObj(s.id, s.token));
  setMesh(obj);
  // a new session is at rest: its positions are the rest a joint's head
  // is carried from (rig.js)
  app.mesh.rest = Float32Array.from(obj.positions);
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
  forgetSettingsSteps();
  await startSession(m.id, m);
  resetPaint();
  if (m.constraints) {
    const r = await app.api.setConstraints(app.session.id, app.session.token, m.constraints, app.constraintsRevision);
    showConstraints({ constraints: m.constraints, constraints_revision: r.constraints_revision });
    app.gizmo.handle = 0;
    app.needsDraw = true;
  }
}

export const generate = guarded(() => generateShape($('shape').value));

/** Another mesh: the settings steps of the last one are not undo steps of
 * this one (the redo branch's sessions are closed). */
function forgetSettingsSteps() {
  app.settingsUndo = [];
  discardSettingsRedo();
}

/** Uploads `files` (picked or dropped: one mesh file, or a .gltf with
 * the buffers and images it names) and opens a session on the mesh. An
 * error (a file the server cannot read, a missing side file) shows beside
 * the upload control until dismissed; the open session stays. */
export async function uploadFiles(files) {
  if (!files || files.length === 0) return;
  $('error').hidden = true;
  controlMessage($('upload'), '');
  try {
    await uploadMesh(await uploadBody(files));
  } catch (e) {
    controlMessage($('upload'), errorText(e));
  }
}

async function uploadMesh(body) {
  const before = app.state;
  setState('uploading');
  progress(`uploading and parsing ${body.name} (${(body.size / 1e6).toFixed(1)} MB)…`);
  let m;
  try {
    m = await app.api.upload(body);
  } catch (e) {
    setState(before);
    throw e;
  } finally {
    progress('');
  }
  forgetSettingsSteps();
  await startSession(m.id, m);
  resetPaint();
}

export const upload = (ev) => {
  const files = [...ev.target.files];
  ev.target.value = ''; // the same file can be picked again
  return uploadFiles(files);
};

/** Labels cleared for a new mesh: no regions and no handle yet ("+ handle"
 * makes handle 0). */
export function resetPaint() {
  app.handles = 0;
  app.handleJoints.clear();
  app.applied = null;
  app.constraintsRevision = 0;
  app.dirtyLabels = false;
  for (const o of [...$('target').options]) if (o.value.startsWith('h')) o.remove();
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
    discardSettingsRedo(); // a new branch
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

/** Moves from the open session to `to` ({session, settings}), the open
 * one going onto `back` with the settings it had. */
async function switchSession(to, back) {
  const info = await app.api.session(to.session.id, to.session.token);
  back.push({ session: app.session, settings: lastSettings });
  restoreSettings(to.settings);
  lastSettings = to.settings;
  await openSession(to.session.id, to.session.token, to.session.meshId);
  showConstraints(info);
  setState(info.state);
}

/** Undo: the session's own history first; at its start, the last
 * settings change (back to the session and settings before it; the
 * session left is the redo step). */
export const undo = guarded(async () => {
  if (app.canUndo || app.settingsUndo.length === 0) {
    send({ type: 'undo' });
    return;
  }
  await switchSession(app.settingsUndo.pop(), app.settingsRedo);
});

/** Redo: the session's own history first; at its end, the settings
 * change undone last (forward to its session, as it was left). */
export const redo = guarded(async () => {
  if (app.canRedo || app.settingsRedo.length === 0) {
    send({ type: 'redo' });
    return;
  }
  const next = app.settingsRedo.pop();
  try {
    await switchSession(next, app.settingsUndo);
  } catch (e) {
    // its session is gone (the server's idle timeout): no redo there
    discardSettingsRedo();
    throw e;
  }
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
  app.meshInfo = await app.api.json('GET', `/v1/meshes/${info.mesh_id}`).catch(() => null);
  showMeshWarnings(app.meshInfo);
  const obj = parseObj(await app.api.exportObj(id, token));
  setMesh(obj);
  // a rig's joint heads are carried from the rest (rig.js): a joined
  // session may be posed, so its rest comes from the server
  if (app.meshInfo && app.meshInfo.asset && app.meshInfo.asset.skeleton) {
    const res = await fetch(`/v1/sessions/${encodeURIComponent(id)}/export?format=obj&pose=rest`, {
      headers: { Authorization: `Bearer ${token}` },
    });
    if (res.ok) app.mesh.rest = Float32Array.from(parseObj(await res.text()).positions);
  }
  resetPaint();
  showConstraints(info);
  // a set with handles: the first one gets the gizmo
  if (app.labels.some((l) => l > 0)) app.gizmo.handle = 0;
  setState(info.state);
  await openSession(id, token, info.mesh_id);
  await showTexture({ id, token }, app.meshInfo, obj);
}

