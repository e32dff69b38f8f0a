// Mesh helpers: parse the server's OBJ export (the triangles), per-frame
// vertex normals, unique edges for the wireframe, bounding box.

/** Parses `v x y z` / `f a b c` lines (1-based, `a/b/c` forms allowed;
 * polygons are fanned). Returns {positions: Float32Array, triangles: Uint32Array}. */
export function parseObj(text) {
  const pos = [];
  const tri = [];
  for (const line of text.split('\n')) {
    const t = line.trim().split(/\s+/);
    if (t[0] === 'v') {
      pos.push(+t[1], +t[2], +t[3]);
    } else if (t[0] === 'f') {
      const n = pos.length / 3;
      const idx = t.slice(1).map((s) => {
        const k = parseInt(s.split('/')[0], 10);
        return k < 0 ? n + k : k - 1;
      });
      for (let i = 1; i + 1 < idx.length; i++) tri.push(idx[0], idx[i], idx[i + 1]);
    }
  }
  return { positions: new Float32Array(pos), triangles: new Uint32Array(tri) };
}

/** Area-weighted vertex normals of `positions` (xyz f32) into `out`. */
export function vertexNormals(positions, triangles, out) {
  out.fill(0);
  const p = positions;
  for (let t = 0; t < triangles.length; t += 3) {
    const a = 3 * triangles[t], b = 3 * triangles[t + 1], c = 3 * triangles[t + 2];
    const ux = p[b] - p[a], uy = p[b + 1] - p[a + 1], uz = p[b + 2] - p[a + 2];
    const vx = p[c] - p[a], vy = p[c + 1] - p[a + 1], vz = p[c + 2] - p[a + 2];
    const nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
    for (const i of [a, b, c]) {
      out[i] += nx;
      out[i + 1] += ny;
      out[i + 2] += nz;
    }
  }
  for (let i = 0; i < out.length; i += 3) {
    const l = Math.hypot(out[i], out[i + 1], out[i + 2]) || 1;
    out[i] /= l;
    out[i + 1] /= l;
    out[i + 2] /= l;
  }
  return out;
}

/** Unique undirected edges as a flat index list (for gl.LINES). */
export function edgeList(triangles) {
  const seen = new Set();
  const out = [];
  for (let t = 0; t < triangles.length; t += 3) {
    for (let k = 0; k < 3; k++) {
      const a = triangles[t + k], b = triangles[t + ((k + 1) % 3)];
      const key = a < b ? a * 4294967296 + b : b * 4294967296 + a;
      if (!seen.has(key)) {
        seen.add(key);
        out.push(a, b);
      }
    }
  }
  return new Uint32Array(out);
}

export function bbox(positions) {
  const lo = [Infinity, Infinity, Infinity];
  const hi = [-Infinity, -Infinity, -Infinity];
  for (let i = 0; i < positions.length; i += 3) {
    for (let k = 0; k < 3; k++) {
      lo[k] = Math.min(lo[k], positions[i + k]);
      hi[k] = Math.max(hi[k], positions[i + k]);
    }
  }
  return [lo, hi];
}

/** OBJ text of a pose (for download when the server export is not wanted). */
export function toObj(positions, triangles) {
  const lines = [];
  for (let i = 0; i < positions.length; i += 3) {
    lines.push(`v ${positions[i]} ${positions[i + 1]} ${positions[i + 2]}`);
  }
  for (let t = 0; t < triangles.length; t += 3) {
    lines.push(`f ${triangles[t] + 1} ${triangles[t + 1] + 1} ${triangles[t + 2] + 1}`);
  }
  return lines.join('\n') + '\n';
}

// ---------- the glTF's own UVs and base-colour texture ----------
// An uploaded glTF/GLB keeps its own vertex layout on the server (seam
// copies split, UVs, materials, images); the session's export in GLB
// (`GET …/export?format=glb`) writes it back with the pose. The editor
// draws the welded vertices (the OBJ export), so each welded triangle gets
// the UVs of the file triangle over the same welded vertices: a file
// vertex is matched to the welded vertex at its position (world space:
// node matrices applied, none for skinned meshes, as the server places
// them), and each corner takes its own file vertex's UV, so the two sides
// of a UV seam keep theirs.

const GLB_MAGIC = 0x46546c67, CHUNK_JSON = 0x4e4f534a, CHUNK_BIN = 0x004e4942;

/** The JSON and BIN chunks of a GLB: {json, bin: Uint8Array}. */
export function parseGlb(buffer) {
  const dv = new DataView(buffer);
  if (buffer.byteLength < 20 || dv.getUint32(0, true) !== GLB_MAGIC) throw new Error('not a GLB file');
  let json = null, bin = new Uint8Array(0);
  for (let o = 12; o + 8 <= buffer.byteLength;) {
    const len = dv.getUint32(o, true), type = dv.getUint32(o + 4, true);
    const data = new Uint8Array(buffer, o + 8, Math.min(len, buffer.byteLength - o - 8));
    if (type === CHUNK_JSON) json = JSON.parse(new TextDecoder().decode(data));
    else if (type === CHUNK_BIN && bin.length === 0) bin = data;
    o += 8 + len + ((4 - (len % 4)) % 4);
  }
  if (!json) throw new Error('GLB without a JSON chunk');
  return { json, bin };
}

const COMPONENTS = { 5120: Int8Array, 5121: Uint8Array, 5122: Int16Array, 5123: Uint16Array, 5125: Uint32Array, 5126: Float32Array };
const WIDTH = { SCALAR: 1, VEC2: 2, VEC3: 3, VEC4: 4 };

/** An accessor's values as a flat Float64Array (`normalized` integers
 * scaled to [0, 1] or [-1, 1]), honouring the view's byteStride. */
function readAccessor({ json, bin }, index) {
  const a = json.accessors[index];
  const T = COMPONENTS[a.componentType];
  const width = WIDTH[a.type];
  const out = new Float64Array(a.count * width);
  if (!T || !width || a.bufferView === undefined) return out;
  const view = json.bufferViews[a.bufferView];
  const start = bin.byteOffset + (view.byteOffset || 0) + (a.byteOffset || 0);
  const stride = view.byteStride || T.BYTES_PER_ELEMENT * width;
  const dv = new DataView(bin.buffer);
  const get = {
    5120: (o) => dv.getInt8(o), 5121: (o) => dv.getUint8(o), 5122: (o) => dv.getInt16(o, true),
    5123: (o) => dv.getUint16(o, true), 5125: (o) => dv.getUint32(o, true), 5126: (o) => dv.getFloat32(o, true),
  }[a.componentType];
  const scale = a.normalized && T !== Float32Array ? 2 ** (8 * T.BYTES_PER_ELEMENT - (T.name.startsWith('Int') ? 1 : 0)) - 1 : 1;
  for (let i = 0; i < a.count; i++) {
    for (let k = 0; k < width; k++) {
      const v = get(start + i * stride + k * T.BYTES_PER_ELEMENT);
      out[i * width + k] = scale === 1 ? v : Math.max(v / scale, -1);
    }
  }
  return out;
}

/** A node's local matrix (column-major 4×4): `matrix`, else T·R·S. */
function nodeMatrix(n) {
  if (n.matrix) return n.matrix.slice();
  const [tx, ty, tz] = n.translation || [0, 0, 0];
  const [x, y, z, w] = n.rotation || [0, 0, 0, 1];
  const [sx, sy, sz] = n.scale || [1, 1, 1];
  return [
    (1 - 2 * (y * y + z * z)) * sx, 2 * (x * y + z * w) * sx, 2 * (x * z - y * w) * sx, 0,
    2 * (x * y - z * w) * sy, (1 - 2 * (x * x + z * z)) * sy, 2 * (y * z + x * w) * sy, 0,
    2 * (x * z + y * w) * sz, 2 * (y * z - x * w) * sz, (1 - 2 * (x * x + y * y)) * sz, 0,
    tx, ty, tz, 1,
  ];
}

function mulMat(a, b) {
  const o = new Array(16).fill(0);
  for (let c = 0; c < 4; c++) for (let r = 0; r < 4; r++) for (let k = 0; k < 4; k++) o[4 * c + r] += a[4 * k + r] * b[4 * c + k];
  return o;
}

/** Every mesh-carrying node of the scene with the matrix that places it
 * (the server's rule: the default scene, else the first, else every
 * root; skinned meshes in mesh space). */
function placedMeshes(json) {
  const nodes = json.nodes || [];
  const scenes = json.scenes || [];
  let roots = (scenes[json.scene ?? 0] || scenes[0] || {}).nodes;
  if (!roots) {
    const child = new Set(nodes.flatMap((n) => n.children || []));
    roots = nodes.map((_, i) => i).filter((i) => !child.has(i));
  }
  const id = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1];
  const out = [];
  const stack = roots.map((i) => [i, id]);
  const seen = new Set();
  while (stack.length) {
    const [i, parent] = stack.pop();
    if (seen.has(i) || !nodes[i]) continue;
    seen.add(i);
    const world = mulMat(parent, nodeMatrix(nodes[i]));
    for (const c of nodes[i].children || []) stack.push([c, world]);
    if (nodes[i].mesh !== undefined) out.push({ mesh: nodes[i].mesh, world: nodes[i].skin !== undefined ? id : world });
  }
  return out;
}

/** Nearest of `positions` (xyz) to each query point within `tol`, through
 * a grid of cell `tol`: an index, or -1. */
function matcher(positions, tol) {
  const cell = (x) => Math.floor(x / tol);
  const grid = new Map();
  const key = (a, b, c) => `${a},${b},${c}`;
  for (let i = 0; i < positions.length / 3; i++) {
    const k = key(cell(positions[3 * i]), cell(positions[3 * i + 1]), cell(positions[3 * i + 2]));
    if (!grid.has(k)) grid.set(k, []);
    grid.get(k).push(i);
  }
  return (x, y, z) => {
    let best = -1, bd = tol * tol;
    const [cx, cy, cz] = [cell(x), cell(y), cell(z)];
    for (let a = cx - 1; a <= cx + 1; a++) for (let b = cy - 1; b <= cy + 1; b++) for (let c = cz - 1; c <= cz + 1; c++) {
      for (const i of grid.get(key(a, b, c)) || []) {
        const d = (positions[3 * i] - x) ** 2 + (positions[3 * i + 1] - y) ** 2 + (positions[3 * i + 2] - z) ** 2;
        if (d <= bd) { bd = d; best = i; }
      }
    }
    return best;
  };
}

/** The base-colour texture of the GLB `glb` ({json, bin}) laid on the
 * welded mesh (`positions`, `triangles` of the OBJ export of the same
 * pose): the texture most triangles use (through TEXCOORD_0), its
 * material's baseColorFactor, its sampler and image, and per welded
 * triangle corner its UV (`uv`, vec2 per corner) with `textured` (1 per
 * triangle that has them). Null when no triangle has a texture. */
export function glbTexture(glb, positions, triangles) {
  const { json } = glb;
  const materials = json.materials || [];
  const texOf = (m) => {
    const t = materials[m] && materials[m].pbrMetallicRoughness && materials[m].pbrMetallicRoughness.baseColorTexture;
    return t && (t.texCoord || 0) === 0 ? t.index : undefined;
  };
  const [lo, hi] = bbox(positions);
  const tol = 1e-5 * Math.max(Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]), 1e-9);
  const nearest = matcher(positions, tol);
  // file triangles by their welded vertex set: corner welded ids and UVs
  const byFace = new Map();
  const uses = new Map(); // texture index → [triangles, material]
  const faceKey = (a, b, c) => [a, b, c].sort((x, y) => x - y).join(',');
  for (const { mesh, world } of placedMeshes(json)) {
    for (const prim of ((json.meshes || [])[mesh] || {}).primitives || []) {
      const tex = texOf(prim.material);
      const at = prim.attributes || {};
      if ((prim.mode ?? 4) !== 4 || tex === undefined || at.POSITION === undefined || at.TEXCOORD_0 === undefined) continue;
      const p = readAccessor(glb, at.POSITION), uv = readAccessor(glb, at.TEXCOORD_0);
      const weld = new Int32Array(p.length / 3);
      for (let i = 0; i < weld.length; i++) {
        const [x, y, z] = [p[3 * i], p[3 * i + 1], p[3 * i + 2]];
        weld[i] = nearest(
          world[0] * x + world[4] * y + world[8] * z + world[12],
          world[1] * x + world[5] * y + world[9] * z + world[13],
          world[2] * x + world[6] * y + world[10] * z + world[14]);
      }
      const idx = prim.indices !== undefined ? readAccessor(glb, prim.indices) : weld.map((_, i) => i);
      const u = uses.get(tex) || [0, prim.material];
      for (let t = 0; t + 2 < idx.length; t += 3) {
        const w = [weld[idx[t]], weld[idx[t + 1]], weld[idx[t + 2]]];
        if (w.includes(-1)) continue;
        const k = faceKey(...w);
        if (!byFace.has(k)) byFace.set(k, { tex, w, uv: [0, 1, 2].map((j) => [uv[2 * idx[t + j]], uv[2 * idx[t + j] + 1]]) });
        u[0]++;
      }
      uses.set(tex, u);
    }
  }
  if (uses.size === 0) return null;
  const [texture, [, material]] = [...uses.entries()].sort((a, b) => b[1][0] - a[1][0])[0];
  const faces = triangles.length / 3;
  const out = { uv: new Float32Array(2 * triangles.length), textured: new Uint8Array(faces) };
  for (let f = 0; f < faces; f++) {
    const t = [triangles[3 * f], triangles[3 * f + 1], triangles[3 * f + 2]];
    const file = byFace.get(faceKey(...t));
    if (!file || file.tex !== texture) continue;
    out.textured[f] = 1;
    for (let k = 0; k < 3; k++) out.uv.set(file.uv[file.w.indexOf(t[k])], 2 * (3 * f + k));
  }
  const tx = json.textures[texture] || {};
  const pbr = materials[material].pbrMetallicRoughness;
  return {
    ...out,
    image: (json.images || [])[tx.source],
    sampler: (json.samplers || [])[tx.sampler] || {},
    factor: pbr.baseColorFactor || [1, 1, 1, 1],
  };
}

/** The image of `glbTexture`'s answer as an ImageBitmap (a bufferView in
 * the BIN chunk, or a data URI). */
export async function glbImage(glb, image) {
  let blob;
  if (image.bufferView !== undefined) {
    const v = glb.json.bufferViews[image.bufferView];
    blob = new Blob([glb.bin.subarray(v.byteOffset || 0, (v.byteOffset || 0) + v.byteLength)], { type: image.mimeType || 'image/png' });
  } else if (image.uri && image.uri.startsWith('data:')) {
    blob = await (await fetch(image.uri)).blob();
  } else {
    throw new Error('the texture image is neither in the file nor a data URI');
  }
  return createImageBitmap(blob, { imageOrientation: 'none', premultiplyAlpha: 'none', colorSpaceConversion: 'none' });
}
