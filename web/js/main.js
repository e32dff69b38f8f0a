// The editor's entry point: wires the panel's controls, the canvas
// interaction, the gizmo and the keys to the shared state (app.js) and the
// session actions (session.js), runs the draw loop and opens the first
// session. `window.dend` exposes a read-only view of the state for the
// browser tests.

import { ApiError } from './api.js';
import { Renderer } from './renderer.js';
import { attachInteraction } from './interact.js';
import { Gizmo, wireNumeric, gizmoLabel } from './gizmo.js';
import { attachKeys } from './keys.js';
import { project } from './select.js';
import { FREE } from './regions.js';
import {
  app, guarded, showError, recolor, growShrink, addHandle, applyConstraints, showConstraints, needSession,
  refreshCurvature, sendDrag, discardSettingsRedo, controlMessage, errorText,
} from './app.js';
import { showAdvanced, currentPreset, showStiffness, loadPresets } from './settings.js';
import {
  generate, upload, uploadFiles, undo, redo, settingsChanged, generateShape, join, rememberSettings,
} from './session.js';
import { attachGuide } from './guide.js';
import { attachDrop } from './drop.js';
// the Named poses and Skeleton sections (they follow the shared state's events)
import './poses.js';
import './outliner.js';

const $ = (id) => document.getElementById(id);

// ---------- pose buttons ----------

async function download(name, blob) {
  const a = document.createElement('a');
  a.href = URL.createObjectURL(blob);
  a.download = name;
  a.click();
  setTimeout(() => URL.revokeObjectURL(a.href), 1000);
}

$('errorClose').onclick = () => { $('error').hidden = true; };
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
$('redo').onclick = redo;
$('reset').onclick = guarded(async () => {
  const s = needSession();
  await app.api.reset(s.id, s.token);
  discardSettingsRedo();
});
/** The pose as a file; what the format leaves out of the asset (the
 * server's `Dend-Warnings`) shows next to the button until dismissed. */
$('export').onclick = async () => {
  const button = $('export');
  try {
    const s = needSession();
    const f = $('exportFormat').value;
    const res = await fetch(`/v1/sessions/${s.id}/export?format=${encodeURIComponent(f)}`, {
      headers: { Authorization: `Bearer ${s.token}` },
    });
    if (!res.ok) {
      const e = await res.json().catch(() => ({ code: `http_${res.status}`, message: res.statusText }));
      throw new ApiError(e.code, e.message);
    }
    let warnings = [];
    try {
      warnings = JSON.parse(res.headers.get('dend-warnings') || '[]');
    } catch (e) { /* a header that does not parse: no warning to show */ }
    app.exportWarnings = warnings.map((w) => w.code);
    controlMessage(button, warnings.map((w) => `⚠ ${w.message}`).join('\n'), 'warning');
    await download(`dend-${s.id.slice(0, 8)}.${f}`, await res.blob());
  } catch (e) {
    controlMessage(button, errorText(e));
  }
};
/** The iteration budget ran out before the pose converged: "Keep
 * refining" sends an identity drag (the targets stay where they are), on
 * which the server runs another budget of iterations from this pose; or
 * undo the step. */
$('refine').onclick = () => {
  const applied = app.applied ? [...app.applied.serverIndexOf.keys()] : [];
  const k = applied.includes(app.gizmo.handle) ? app.gizmo.handle : applied[0];
  if (k === undefined) {
    showError({ code: 'no_handle', message: 'no applied handle to refine with' });
    return;
  }
  sendDrag(k, [0, 0, 0]);
};
$('capUndo').onclick = undo;
$('share').onclick = guarded(async () => {
  needSession();
  $('shareLink').select();
  if (navigator.clipboard) await navigator.clipboard.writeText($('shareLink').value).catch(() => {});
});
$('wireframe').onchange = (e) => { app.renderer.wireframe = e.target.checked; app.needsDraw = true; };
$('energy').onchange = (e) => { $('combinedRow').hidden = e.target.value !== 'combined'; };
$('hard').onchange = (e) => { $('lambda1').disabled = e.target.checked; };
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
  attachGuide();
  // a mesh file dropped anywhere on the view is uploaded
  attachDrop($('view').parentElement, $('dropZone'), uploadFiles);
  new ResizeObserver(() => { app.needsDraw = true; }).observe($('view'));
  requestAnimationFrame(loop);
  const h = new URLSearchParams(location.hash.slice(1));
  (async () => {
    await loadPresets();
    rememberSettings();
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
