// The skeleton of a skinned asset as an outliner: a "Skeleton" section of
// the side panel, shown when the open mesh's info (GET /v1/meshes/{id})
// lists a skeleton, with the joints as a tree (each under its parent).
//
// A click on a joint does what the section's choice says: "grab" makes the
// joint's region (with its children's, unless unticked) a handle named
// after the joint, selected for the gizmo, which sits at the joint's head
// and turns the handle about it (the handle's pivot); "pin" makes the
// region fixed. The regions are the server's (each joint's `region`: the
// vertices whose largest skin weight is the joint's), painted over what
// was there and applied at once. A joint that is already a handle is just
// selected.
//
// The section's exports fit the poses onto the rig (`as=skeleton`: the
// current pose; `as=skeleton-animation`: one keyframe per named pose), with
// each pose's corrective shape unless unticked, and show the fit's
// residual (the skinned poses without their correctives against the
// solved ones, as fractions of the rest diagonal) the server reports.

import {
  app, events, recolor, addHandle, applyConstraints, controlMessage, errorText, skeletonJoints,
} from './app.js';
import { FIXED } from './regions.js';
import { jointTree, regionOf } from './rig.js';

const $ = (id) => document.getElementById(id);

function panel() {
  const sec = document.createElement('details');
  sec.className = 'sec';
  sec.id = 'secRig';
  sec.open = true;
  sec.hidden = true;
  sec.innerHTML = `
    <summary>Skeleton</summary>
    <div id="rigError" class="muted" hidden></div>
    <div class="row" role="radiogroup" aria-label="what a click on a joint does">
      <span>Click a joint to</span>
      <label title="the joint's region becomes a handle: the gizmo sits at the joint's head and turns it about the joint"><input type="radio" name="rigAction" value="handle" checked> grab it</label>
      <label title="the joint's region becomes fixed"><input type="radio" name="rigAction" value="pin"> pin it</label>
      <label title="with the regions of the joints below it"><input id="rigChildren" type="checkbox" checked> with its children</label>
    </div>
    <ul id="rigTree" class="rigTree" role="tree" aria-label="skeleton"></ul>
    <div class="row">
      <button id="rigExport" title="the uploaded glTF with the current pose fitted onto its joints">Export skeleton</button>
      <button id="rigExportAnim" title="the uploaded glTF with one keyframe per named pose, fitted onto its joints">Export animation</button>
      <label title="each pose's corrective shape (a morph target): skeleton and corrective give the solved pose exactly"><input id="rigCorrective" type="checkbox" checked> corrective</label>
    </div>
    <div id="rigResidual" class="muted" role="status"></div>`;
  $('secMesh').after(sec);
}

/** What joint `k` is in the painted labels: 'handle' (every vertex of its
 * region in one handle), 'pinned' (every vertex fixed), or ''. */
function jointState(joint) {
  const r = joint.region || [];
  if (!app.labels || r.length === 0) return '';
  const first = app.labels[r[0]];
  if (first === 0 || !r.every((i) => app.labels[i] === first)) return '';
  return first === FIXED ? 'pinned' : `handle ${first - 1}`;
}

function row(joints, children, k, level) {
  const j = joints[k];
  const li = document.createElement('li');
  li.setAttribute('role', 'treeitem');
  li.setAttribute('aria-level', String(level));
  const b = document.createElement('button');
  b.className = 'joint';
  b.id = `joint-${k}`;
  b.dataset.joint = j.name;
  b.textContent = j.name;
  b.title = `${j.parent ? `parent ${j.parent}` : 'a root'}; ${j.vertices} vertices; head at ${j.head.map((x) => x.toFixed(3)).join(', ')}`;
  b.addEventListener('click', () => pick(k));
  const state = document.createElement('span');
  state.className = 'jointState';
  li.append(b, state);
  if (children[k].length) {
    const ul = document.createElement('ul');
    ul.setAttribute('role', 'group');
    ul.append(...children[k].map((c) => row(joints, children, c, level + 1)));
    li.append(ul);
  }
  return li;
}

/** The section for the open mesh: the tree, or why there is none. */
function show() {
  const a = app.meshInfo && app.meshInfo.asset;
  const joints = skeletonJoints();
  $('secRig').hidden = !joints && !(a && a.skin_error);
  $('rigError').hidden = !(a && a.skin_error);
  $('rigError').textContent = a && a.skin_error ? `the skin cannot be used as a rig: ${a.skin_error}` : '';
  $('rigResidual').textContent = '';
  app.rigFit = null;
  if (!joints) {
    $('rigTree').replaceChildren();
    return;
  }
  const { children, roots } = jointTree(joints);
  $('rigTree').replaceChildren(...roots.map((k) => row(joints, children, k, 1)));
  showStates();
}

/** Each joint's state beside its name. */
function showStates() {
  const joints = skeletonJoints();
  if (!joints) return;
  joints.forEach((j, k) => {
    const b = $(`joint-${k}`);
    if (!b) return;
    const s = jointState(j);
    b.nextSibling.textContent = s ? ` ${s}` : '';
    b.setAttribute('aria-pressed', String(s !== ''));
  });
}

/** A click on joint `k` (the module comment). */
function pick(k) {
  const joints = skeletonJoints();
  if (!joints || !app.labels) return;
  const action = document.querySelector('input[name="rigAction"]:checked').value;
  const region = regionOf(joints, k, $('rigChildren').checked);
  controlMessage($('rigTree'), '');
  if (region.length === 0) {
    controlMessage($('rigTree'), `${joints[k].name} has no vertices of its own (no vertex is weighted most to it): tick “with its children” or pick another joint`, 'warning');
    return;
  }
  if (action === 'handle') {
    // already this joint's handle, with these vertices: select it
    for (const [h, j] of app.handleJoints) {
      if (j === k && region.every((i) => app.labels[i] === h + 1)) {
        app.gizmo.handle = h;
        app.needsDraw = true;
        return;
      }
    }
    addHandle();
    const h = app.handles - 1;
    const option = [...$('target').options].find((o) => o.value === `h${h}`);
    if (option) option.textContent = `handle ${h} (${joints[k].name})`;
    for (const i of region) app.labels[i] = h + 1;
    app.handleJoints.set(h, k);
    app.gizmo.handle = h;
  } else {
    for (const i of region) app.labels[i] = FIXED;
  }
  app.dirtyLabels = true;
  recolor();
  applyConstraints();
}

/** Downloads the skeleton export (`animation`: as=skeleton-animation) and
 * shows the fit's residual. */
async function exportSkeleton(animation, button) {
  const s = app.session;
  try {
    if (!s) throw Object.assign(new Error('generate or upload a mesh first'), { code: 'no_session' });
    const how = animation ? 'skeleton-animation' : 'skeleton';
    const corrective = $('rigCorrective').checked ? '' : '&corrective=false';
    const res = await fetch(`/v1/sessions/${s.id}/export?format=glb&as=${how}${corrective}`, {
      headers: { Authorization: `Bearer ${s.token}` },
    });
    if (!res.ok) {
      const e = await res.json().catch(() => ({ code: `http_${res.status}`, message: res.statusText }));
      throw Object.assign(new Error(e.message), { code: e.code });
    }
    const h = (name) => Number(res.headers.get(name));
    app.rigFit = {
      max: h('x-dend-fit-residual-max'),
      mean: h('x-dend-fit-residual-mean'),
      poses: h('x-dend-fit-poses'),
      warning: res.headers.get('x-dend-warning') || '',
    };
    const f = app.rigFit;
    $('rigResidual').textContent = `fit residual (without the corrective): max ${f.max.toExponential(2)}, `
      + `mean ${f.mean.toExponential(2)} of the diagonal, over ${f.poses} pose${f.poses === 1 ? '' : 's'}`
      + (f.warning ? ` — ⚠ ${f.warning}` : '');
    const a = document.createElement('a');
    a.href = URL.createObjectURL(await res.blob());
    const base = (app.meshInfo && app.meshInfo.asset && app.meshInfo.asset.name) || 'dend';
    a.download = `${base}-${how}.glb`;
    a.click();
    setTimeout(() => URL.revokeObjectURL(a.href), 1000);
    controlMessage(button, '');
  } catch (e) {
    controlMessage(button, errorText(e));
  }
}

panel();
$('rigExport').addEventListener('click', () => exportSkeleton(false, $('rigExport')));
$('rigExportAnim').addEventListener('click', () => exportSkeleton(true, $('rigExportAnim')));
events.addEventListener('session', show);
events.addEventListener('labels', showStates);
