// A generated textured skinned asset for the morph-target tests, written
// here so the browser test needs no Rust tool: a GLB tube along z (radius
// 0.5, z in [0, 3], 16 segments around, 12 along) with a UV seam (its
// first column repeated at u = 1, same positions), a top cap in a second
// primitive (its own hard-edged vertices on the tube's top ring and a centre
// vertex), NORMAL, TEXCOORD_0, a 2 × 2 PNG base-colour texture, and a
// two-joint skin (root at the origin, a child joint at z = 1.5; weights
// linear in z). File vertices: 13 × 17 (tube) + 17 (cap) = 238; the server
// welds the seam and the cap ring, leaving 13 × 16 + 1 = 209.

import { deflateSync } from 'node:zlib';

export const TUBE = { radius: 0.5, length: 3, around: 16, along: 12 };

function crc32(buf) {
  let c = ~0;
  for (const b of buf) {
    c ^= b;
    for (let k = 0; k < 8; k++) c = (c >>> 1) ^ (0xedb88320 & -(c & 1));
  }
  return ~c >>> 0;
}

/** The default texture: a red and cream checker (row-major texels, the
 * first row at v = 0). */
export const CHECKER = [[230, 60, 40], [250, 240, 220], [250, 240, 220], [230, 60, 40]];

/** A 2 × 2 RGB PNG of four texels (row-major, RGB). */
export function checkerPng(texels = CHECKER) {
  const chunk = (type, data) => {
    const len = Buffer.alloc(4);
    len.writeUInt32BE(data.length);
    const td = Buffer.concat([Buffer.from(type, 'latin1'), data]);
    const crc = Buffer.alloc(4);
    crc.writeUInt32BE(crc32(td));
    return Buffer.concat([len, td, crc]);
  };
  const ihdr = Buffer.alloc(13);
  ihdr.writeUInt32BE(2, 0);
  ihdr.writeUInt32BE(2, 4);
  ihdr[8] = 8; // bit depth
  ihdr[9] = 2; // RGB
  const rows = Buffer.from([0, ...texels[0], ...texels[1], 0, ...texels[2], ...texels[3]]);
  return Buffer.concat([
    Buffer.from([0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a]),
    chunk('IHDR', ihdr), chunk('IDAT', deflateSync(rows)), chunk('IEND', Buffer.alloc(0)),
  ]);
}

/** The tube's two primitives as plain arrays (file layout). */
function primitives() {
  const { radius, length, around, along } = TUBE;
  const weightsAt = (z) => { const w = z / length; return [1 - w, w, 0, 0]; };
  // a joint of zero weight is written as joint 0 (the validator's rule)
  const jointsAt = (z) => [0, z > 0 ? 1 : 0, 0, 0];
  const tube = { pos: [], nrm: [], uv: [], joints: [], weights: [], idx: [] };
  for (let r = 0; r <= along; r++) {
    const z = (length * r) / along;
    for (let c = 0; c <= around; c++) {
      const t = (2 * Math.PI * (c % around)) / around;
      const [x, y] = [Math.fround(radius * Math.cos(t)), Math.fround(radius * Math.sin(t))];
      tube.pos.push(x, y, z);
      tube.nrm.push(Math.cos(t), Math.sin(t), 0);
      tube.uv.push(c / around, 1 - r / along);
      tube.joints.push(...jointsAt(z));
      tube.weights.push(...weightsAt(z));
    }
  }
  const at = (r, c) => r * (around + 1) + c;
  for (let r = 0; r < along; r++) {
    for (let c = 0; c < around; c++) {
      tube.idx.push(at(r, c), at(r, c + 1), at(r + 1, c + 1), at(r, c), at(r + 1, c + 1), at(r + 1, c));
    }
  }
  // the cap: the top ring again (same positions as the tube's) and a centre
  const cap = { pos: [], nrm: [], uv: [], joints: [], weights: [], idx: [] };
  for (let c = 0; c < around; c++) {
    const k = at(along, c);
    cap.pos.push(tube.pos[3 * k], tube.pos[3 * k + 1], length);
    const t = (2 * Math.PI * c) / around;
    cap.uv.push(0.5 + 0.5 * Math.cos(t), 0.5 + 0.5 * Math.sin(t));
  }
  cap.pos.push(0, 0, length);
  cap.uv.push(0.5, 0.5);
  for (let c = 0; c <= around; c++) {
    cap.nrm.push(0, 0, 1);
    cap.joints.push(...jointsAt(length));
    cap.weights.push(...weightsAt(length));
  }
  for (let c = 0; c < around; c++) cap.idx.push(around, c, (c + 1) % around);
  return [tube, cap];
}

/** The GLB bytes; `texels`: the 2 × 2 texture's colours (default CHECKER);
 * `place`: a transform of the tube's node (`translation`, `rotation`,
 * `scale`), which then has no skin (a skinned mesh ignores its node's
 * transform) and no JOINTS_0/WEIGHTS_0. */
export function skinnedTubeGlb(texels = CHECKER, place = null) {
  const chunks = [];
  let offset = 0;
  const views = [];
  const accessors = [];
  const addView = (buf, target) => {
    const pad = (4 - (offset % 4)) % 4;
    if (pad) { chunks.push(Buffer.alloc(pad)); offset += pad; }
    views.push({ buffer: 0, byteOffset: offset, byteLength: buf.length, ...(target ? { target } : {}) });
    chunks.push(buf);
    offset += buf.length;
    return views.length - 1;
  };
  const addAccessor = (array, componentType, type, target, withBounds) => {
    const width = { SCALAR: 1, VEC2: 2, VEC3: 3, VEC4: 4, MAT4: 16 }[type];
    const bytes = Buffer.from(array.buffer, array.byteOffset, array.byteLength);
    const a = { bufferView: addView(bytes, target), componentType, count: array.length / width, type };
    if (withBounds) {
      a.min = Array(width).fill(Infinity);
      a.max = Array(width).fill(-Infinity);
      array.forEach((v, i) => {
        a.min[i % width] = Math.min(a.min[i % width], v);
        a.max[i % width] = Math.max(a.max[i % width], v);
      });
    }
    accessors.push(a);
    return accessors.length - 1;
  };
  const FLOAT = 5126, USHORT = 5123, UBYTE = 5121, VERTEX = 34962, INDEX = 34963;
  const prims = primitives().map((p) => ({
    attributes: {
      POSITION: addAccessor(new Float32Array(p.pos), FLOAT, 'VEC3', VERTEX, true),
      NORMAL: addAccessor(new Float32Array(p.nrm), FLOAT, 'VEC3', VERTEX),
      TEXCOORD_0: addAccessor(new Float32Array(p.uv), FLOAT, 'VEC2', VERTEX),
      ...(place ? {} : {
        JOINTS_0: addAccessor(new Uint8Array(p.joints), UBYTE, 'VEC4', VERTEX),
        WEIGHTS_0: addAccessor(new Float32Array(p.weights), FLOAT, 'VEC4', VERTEX),
      }),
    },
    indices: addAccessor(new Uint16Array(p.idx), USHORT, 'SCALAR', INDEX),
    material: 0,
  }));
  // column-major inverse bind matrices: the joints' world transforms are
  // translations by 0 and by 1.5 along z
  const ibm = new Float32Array(32);
  for (const j of [0, 1]) for (const d of [0, 5, 10, 15]) ibm[16 * j + d] = 1;
  ibm[16 + 14] = -1.5;
  const inverseBindMatrices = addAccessor(ibm, FLOAT, 'MAT4');
  const image = addView(checkerPng(texels));
  const json = {
    asset: { version: '2.0', generator: 'dend web/tests/skinned_tube.mjs' },
    scene: 0,
    scenes: [{ nodes: [0, 1] }],
    nodes: [
      place ? { name: 'tube', mesh: 0, ...place } : { name: 'tube', mesh: 0, skin: 0 },
      { name: 'root', children: [2] },
      { name: 'upper', translation: [0, 0, 1.5] },
    ],
    meshes: [{ name: 'tube', primitives: prims }],
    skins: [{ joints: [1, 2], inverseBindMatrices, skeleton: 1 }],
    materials: [{ name: 'checker', pbrMetallicRoughness: { baseColorTexture: { index: 0 }, metallicFactor: 0 } }],
    textures: [{ source: 0, sampler: 0 }],
    images: [{ bufferView: image, mimeType: 'image/png' }],
    samplers: [{ magFilter: 9728, minFilter: 9728 }],
    accessors,
    bufferViews: views,
    buffers: [{ byteLength: 0 }],
  };
  let bin = Buffer.concat(chunks);
  bin = Buffer.concat([bin, Buffer.alloc((4 - (bin.length % 4)) % 4)]);
  json.buffers[0].byteLength = bin.length;
  let js = Buffer.from(JSON.stringify(json), 'utf8');
  js = Buffer.concat([js, Buffer.alloc((4 - (js.length % 4)) % 4, 0x20)]);
  const header = Buffer.alloc(12);
  header.writeUInt32LE(0x46546c67, 0);
  header.writeUInt32LE(2, 4);
  header.writeUInt32LE(12 + 8 + js.length + 8 + bin.length, 8);
  const ch = (len, type) => { const b = Buffer.alloc(8); b.writeUInt32LE(len, 0); b.writeUInt32LE(type, 4); return b; };
  return Buffer.concat([header, ch(js.length, 0x4e4f534a), js, ch(bin.length, 0x004e4942), bin]);
}
