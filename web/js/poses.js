// Named poses in the editor: a "Named poses" section of the side panel to
// save the settled pose under a name, restore (an undo step), rename or
// delete one, and download the uploaded glTF with the poses as morph
// targets. A restore reaches the view as the frame every client of the
// session gets.
//
// A name in use is never overwritten silently: the server refuses a save
// under an existing name (`pose_exists`) unless asked to replace it, and
// the editor asks first. Errors stay next to the control that caused them
// until dismissed; the morph-target export is offered only for a mesh
// uploaded as glTF/GLB (the reason is the disabled button's tooltip).

import { app, events, controlMessage, errorText, discardSettingsRedo } from './app.js';

const $ = (id) => document.getElementById(id);

async function call(method, tail, body) {
  const s = app.session;
  if (!s) throw Object.assign(new Error('generate or upload a mesh first'), { code: 'no_session' });
  const res = await fetch(`/v1/sessions/${s.id}${tail}`, {
    method,
    headers: { authorization: `Bearer ${s.token}`, ...(body ? { 'content-type': 'application/json' } : {}) },
    body: body ? JSON.stringify(body) : undefined,
  });
  if (!res.ok) {
    const e = await res.json().catch(() => ({ code: 'http_error', message: res.statusText }));
    throw Object.assign(new Error(e.message), { code: e.code, status: res.status });
  }
  return res;
}

const enc = (name) => encodeURIComponent(name);

/** The names listed last (the save asks before replacing one of them). */
let names = [];

function panel() {
  const sec = document.createElement('details');
  sec.className = 'sec';
  sec.id = 'posesPanel';
  sec.open = true;
  sec.innerHTML = `
    <summary>Named poses</summary>
    <div class="row">
      <input id="poseName" placeholder="pose name" aria-label="pose name">
      <button id="poseSave" title="save the settled pose under this name">Save pose</button>
      <button id="poseMorph" title="the uploaded glTF with one morph target per named pose">Export morph targets</button>
    </div>
    <div id="poseConfirm" class="confirm" role="alertdialog" hidden>
      <span id="poseConfirmText"></span>
      <button id="poseReplace">Replace</button>
      <button id="poseKeep">Cancel</button>
    </div>
    <ul id="poseList" class="muted"></ul>`;
  $('secPose').after(sec);
}

/** An error of `control`, kept beside it until dismissed ('' clears it). */
function failed(control) {
  return (e) => controlMessage(control, e ? errorText(e) : '');
}

async function refresh() {
  const list = $('poseList');
  if (!app.session) {
    list.replaceChildren();
    names = [];
    return;
  }
  let poses;
  try {
    ({ poses } = await (await call('GET', '/poses')).json());
  } catch (e) {
    // the list is polled: a failed read leaves the last one shown
    return;
  }
  names = poses.map((p) => p.name);
  list.replaceChildren(...poses.map((p) => {
    const li = document.createElement('li');
    li.textContent = `${p.name} `;
    const button = (label, act) => {
      const b = document.createElement('button');
      b.textContent = label;
      b.id = `pose${label}-${p.index}`;
      b.addEventListener('click', () => act().then(() => { controlMessage($('poseList'), ''); refresh(); }, failed($('poseList'))));
      li.append(b);
    };
    button('Restore', async () => {
      await call('POST', `/poses/${enc(p.name)}/restore`);
      discardSettingsRedo();
    });
    button('Rename', async () => {
      const to = prompt('new name', p.name);
      if (to && to !== p.name) await call('PATCH', `/poses/${enc(p.name)}`, { name: to });
    });
    button('Delete', () => call('DELETE', `/poses/${enc(p.name)}`));
    return li;
  }));
}

/** Saves the pose under the typed name; a name in use is replaced only
 * once the user confirms. */
async function save(replace) {
  const name = $('poseName').value.trim();
  $('poseConfirm').hidden = true;
  if (!replace && names.includes(name)) {
    askReplace(name);
    return;
  }
  try {
    await call('POST', '/poses', replace ? { name, replace: true } : { name });
    controlMessage($('poseSave'), '');
  } catch (e) {
    // a pose of that name saved meanwhile (another tab): ask too
    if (e.code === 'pose_exists' && !replace) askReplace(name);
    else failed($('poseSave'))(e);
  }
  await refresh();
}

function askReplace(name) {
  $('poseConfirmText').textContent = `A pose named “${name}” exists. Replace it with this pose?`;
  $('poseConfirm').hidden = false;
  $('poseReplace').focus();
}

async function exportMorphTargets() {
  const res = await call('GET', '/export?format=glb&as=morph-targets&animation=1');
  const a = document.createElement('a');
  a.href = URL.createObjectURL(await res.blob());
  a.download = 'poses.glb';
  a.click();
  setTimeout(() => URL.revokeObjectURL(a.href), 1000);
}

/** The morph-target export needs the glTF asset of an upload. */
function showMorphAvailability() {
  const b = $('poseMorph');
  const a = app.meshInfo && app.meshInfo.asset;
  const gltf = !!a && (a.format === 'glb' || a.format === 'gltf');
  b.disabled = !gltf;
  b.title = gltf
    ? 'the uploaded glTF with one morph target per named pose'
    : 'only for a mesh uploaded as glTF or GLB: its file gets one morph target per named pose';
}

panel();
$('poseSave').addEventListener('click', () => save(false));
$('poseName').addEventListener('keydown', (e) => { if (e.key === 'Enter') save(false); });
$('poseReplace').addEventListener('click', () => save(true));
$('poseKeep').addEventListener('click', () => { $('poseConfirm').hidden = true; });
$('poseMorph').addEventListener('click', () => exportMorphTargets().then(() => failed($('poseMorph'))(null), failed($('poseMorph'))));
events.addEventListener('session', () => {
  $('poseConfirm').hidden = true;
  showMorphAvailability();
  refresh();
});
showMorphAvailability();
// other clients of the session save and rename too
setInterval(() => { if (!document.hidden) refresh(); }, 3000);
refresh();
