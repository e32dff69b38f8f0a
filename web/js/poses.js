// Named poses in the editor: a "Named poses" section of the side panel to
// save the settled pose under a name, restore (an undo step), rename or
// delete one, and download the uploaded glTF with the poses as morph
// targets. A module of its own: it reads the open session from the page's
// `#session=…&token=…` (set by app.js) and talks to the HTTP API only; a
// restore reaches the view as the frame every client of the session gets.

const $ = (id) => document.getElementById(id);

function session() {
  const h = new URLSearchParams(location.hash.slice(1));
  const id = h.get('session');
  const token = h.get('token');
  return id && token ? { id, token } : null;
}

async function call(method, tail, body) {
  const s = session();
  if (!s) throw new Error('no session: generate or upload a mesh first');
  const res = await fetch(`/v1/sessions/${s.id}${tail}`, {
    method,
    headers: { authorization: `Bearer ${s.token}`, ...(body ? { 'content-type': 'application/json' } : {}) },
    body: body ? JSON.stringify(body) : undefined,
  });
  if (!res.ok) {
    const e = await res.json().catch(() => ({ code: 'http_error', message: res.statusText }));
    throw new Error(`${e.code}: ${e.message}`);
  }
  return res;
}

const enc = (name) => encodeURIComponent(name);

function panel() {
  const sec = document.createElement('section');
  sec.id = 'posesPanel';
  sec.innerHTML = `
    <h2>Named poses</h2>
    <div class="row">
      <input id="poseName" placeholder="pose name" aria-label="pose name">
      <button id="poseSave" title="save the settled pose under this name">Save pose</button>
      <button id="poseMorph" title="the uploaded glTF with one morph target per named pose">Export morph targets</button>
    </div>
    <ul id="poseList" class="muted"></ul>
    <div id="poseError" role="alert" class="muted" hidden></div>`;
  const help = document.querySelector('#panel .help');
  $('panel').insertBefore(sec, help);
}

function shown(e) {
  const el = $('poseError');
  el.hidden = !e;
  el.textContent = e ? String(e.message || e) : '';
}

async function refresh() {
  const list = $('poseList');
  if (!session()) {
    list.replaceChildren();
    return;
  }
  try {
    const { poses } = await (await call('GET', '/poses')).json();
    list.replaceChildren(...poses.map((p) => {
      const li = document.createElement('li');
      li.textContent = `${p.name} `;
      const button = (label, act) => {
        const b = document.createElement('button');
        b.textContent = label;
        b.addEventListener('click', () => act().then(refresh, shown));
        li.append(b);
      };
      button('Restore', () => call('POST', `/poses/${enc(p.name)}/restore`));
      button('Rename', async () => {
        const to = prompt('new name', p.name);
        if (to && to !== p.name) await call('PATCH', `/poses/${enc(p.name)}`, { name: to });
      });
      button('Delete', () => call('DELETE', `/poses/${enc(p.name)}`));
      return li;
    }));
    shown(null);
  } catch (e) {
    shown(e);
  }
}

async function exportMorphTargets() {
  const res = await call('GET', '/export?format=glb&as=morph-targets&animation=1');
  const a = document.createElement('a');
  a.href = URL.createObjectURL(await res.blob());
  a.download = 'poses.glb';
  a.click();
  URL.revokeObjectURL(a.href);
}

panel();
$('poseSave').addEventListener('click', () => {
  const name = $('poseName').value.trim();
  call('POST', '/poses', { name }).then(refresh, shown);
});
$('poseMorph').addEventListener('click', () => exportMorphTargets().then(() => shown(null), shown));
window.addEventListener('hashchange', refresh);
// other clients of the session save and rename too
setInterval(() => { if (!document.hidden) refresh(); }, 3000);
refresh();
