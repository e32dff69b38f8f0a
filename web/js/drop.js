// Files to upload, picked or dropped on the view: one mesh file as it is,
// or a .gltf with the files its buffers and images name (`uri`), which the
// server does not read from anywhere: they are embedded in the JSON as
// data: URIs first, so the upload is one self-contained file.

import { ApiError } from './api.js';

/** The formats the server reads (`POST /v1/meshes?format=`). */
export const MESH_EXTENSIONS = ['obj', 'off', 'ply', 'stl', 'glb', 'gltf'];

const ext = (name) => name.split('.').pop().toLowerCase();

function dataUri(bytes, mime) {
  let s = '';
  const chunk = 0x8000;
  for (let i = 0; i < bytes.length; i += chunk) s += String.fromCharCode(...bytes.subarray(i, i + chunk));
  return `data:${mime};base64,${btoa(s)}`;
}

const MIME = { png: 'image/png', jpg: 'image/jpeg', jpeg: 'image/jpeg', webp: 'image/webp', ktx2: 'image/ktx2' };

/** A .gltf whose external `uri`s name other dropped `files` (by file
 * name, percent-decoded, any folder part ignored), with those embedded. A
 * `uri` no file matches is an error that names it. */
async function embedGltf(gltf, files) {
  let json;
  try {
    json = JSON.parse(await gltf.text());
  } catch (e) {
    throw new ApiError('invalid_gltf', `${gltf.name} is not JSON: ${e.message}`);
  }
  const byName = new Map(files.map((f) => [f.name, f]));
  const missing = [];
  const embed = async (item, mime) => {
    if (!item || typeof item.uri !== 'string' || item.uri.startsWith('data:')) return;
    let name = item.uri;
    try {
      name = decodeURIComponent(name);
    } catch (e) { /* keep it as written */ }
    const f = byName.get(name.split('/').pop());
    if (!f) {
      missing.push(item.uri);
      return;
    }
    item.uri = dataUri(new Uint8Array(await f.arrayBuffer()), mime(f.name));
  };
  for (const b of json.buffers || []) await embed(b, () => 'application/octet-stream');
  for (const im of json.images || []) await embed(im, (n) => im.mimeType || MIME[ext(n)] || 'application/octet-stream');
  if (missing.length) {
    throw new ApiError('missing_files', `${gltf.name} needs ${missing.join(', ')}: pick or drop them together with it`);
  }
  return new File([JSON.stringify(json)], gltf.name, { type: 'model/gltf+json' });
}

/** The one file to upload for `files`: the mesh file among them (a .gltf
 * with the others embedded). */
export async function uploadBody(files) {
  const list = [...files];
  const meshes = list.filter((f) => MESH_EXTENSIONS.includes(ext(f.name)));
  if (meshes.length === 0) {
    throw new ApiError('unsupported_format', `${list.map((f) => f.name).join(', ')}: not a mesh file (${MESH_EXTENSIONS.join(', ')})`);
  }
  if (meshes.length > 1) {
    throw new ApiError('one_mesh', `${meshes.map((f) => f.name).join(', ')}: one mesh at a time`);
  }
  const [mesh] = meshes;
  return ext(mesh.name) === 'gltf' ? embedGltf(mesh, list) : mesh;
}

/** Uploads what is dropped on `target` (`onFiles(files)`), with a drop
 * zone shown (`zone`) while files are dragged over it. */
export function attachDrop(target, zone, onFiles) {
  let depth = 0;
  const hasFiles = (e) => e.dataTransfer && [...e.dataTransfer.types].includes('Files');
  target.addEventListener('dragenter', (e) => {
    if (!hasFiles(e)) return;
    e.preventDefault();
    depth++;
    zone.hidden = false;
  });
  target.addEventListener('dragover', (e) => {
    if (!hasFiles(e)) return;
    e.preventDefault();
    e.dataTransfer.dropEffect = 'copy';
  });
  target.addEventListener('dragleave', () => {
    depth = Math.max(0, depth - 1);
    if (depth === 0) zone.hidden = true;
  });
  target.addEventListener('drop', (e) => {
    if (!hasFiles(e)) return;
    e.preventDefault();
    depth = 0;
    zone.hidden = true;
    onFiles([...e.dataTransfer.files]);
  });
}
