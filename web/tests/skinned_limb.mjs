// A generated rigged limb for the rig tests, written here so the browser
// test needs no Rust tool (the same layout as the Rust crate's
// `dend::rig::sample::limb`, written independently): a capped tube along +y
// (radius 0.3, `around` vertices per ring, `ringsPerBone` rings per bone, a
// pole closing each end) skinned to a chain `bone0` → `bone1` → … →
// `end` under an `Armature` node (no mesh, not a joint), each bone 1 long
// along +y. A vertex at height y belongs to bone ⌊y⌋, blended with the next
// bone by a smoothstep over `blend` either side of each inner joint (at
// most two influences, summing to one). The `end` joint has no weight. The
// bind pose is the rest pose.

export const LIMB = { bones: 3, ringsPerBone: 8, around: 12, blend: 0.25, radius: 0.3 };

const smoothstep = (t) => {
  const u = Math.min(1, Math.max(0, t));
  return u * u * (3 - 2 * u);
};

/** Up to two [joint, weight] pairs of a vertex at height `y`. */
export function limbWeights(y, o = LIMB) {
  const k = Math.min(o.bones - 1, Math.max(0, Math.floor(y)));
  const h = o.blend;
  if (h > 0 && k > 0 && y - k < h) {
    const t = smoothstep((y - k + h) / (2 * h));
    return [[k - 1, 1 - t], [k, t]];
  }
  if (h > 0 && k + 1 < o.bones && k + 1 - y < h) {
    const t = smoothstep((y - (k + 1) + h) / (2 * h));
    return [[k, 1 - t], [k + 1, t]];
  }
  return [[k, 1], [k, 0]];
}

/** The limb as GLB bytes (a Buffer). */
export function skinnedLimbGlb(o = LIMB) {
  const rings = o.bones * o.ringsPerBone + 1;
  const length = o.bones;
  const pos = [], nrm = [], ys = [];
  for (let r = 0; r < rings; r++) {
    const y = (length * r) / (rings - 1);
    for (let c = 0; c < o.around; c++) {
      const a = (2 * Math.PI * c) / o.around;
      pos.push([o.radius * Math.cos(a), y, o.radius * Math.sin(a)]);
      nrm.push([Math.cos(a), 0, Math.sin(a)]);
      ys.push(y);
    }
  }
  const bottom = pos.length;
  pos.push([0, -o.radius, 0]);
  nrm.push([0, -1, 0]);
  ys.push(-o.radius);
  const top = pos.length;
  pos.push([0, length + o.radius, 0]);
  nrm.push([0, 1, 0]);
  ys.push(length + o.radius);
  const at = (r, c) => r * o.around + (c % o.around);
  const idx = [];
  for (let r = 0; r + 1 < rings; r++) {
    for (let c = 0; c < o.around; c++) {
      // counter-clockwise seen from outside
      idx.push(at(r, c), at(r + 1, c), at(r + 1, c + 1), at(r, c), at(r + 1, c + 1), at(r, c + 1));
    }
  }
  for (let c = 0; c < o.around; c++) {
    idx.push(bottom, at(0, c), at(0, c + 1), top, at(rings - 1, c + 1), at(rings - 1, c));
  }
  const joints = o.bones + 1;
  const chunks = [];
  let offset = 0;
  const views = [];
  const view = (buf, target) => {
    views.push({ buffer: 0, byteOffset: offset, byteLength: buf.length, ...(target ? { target } : {}) });
    chunks.push(buf);
    offset += buf.length;
    return views.length - 1;
  };
  const f32 = (xs) => Buffer.from(new Float32Array(xs).buffer);
  const vPos = view(f32(pos.flat()), 34962);
  const vNrm = view(f32(nrm.flat()), 34962);
  const jw = ys.map((y) => limbWeights(y, o));
  // a slot of zero weight names joint 0 (the validator warns of any other)
  const vJoints = view(Buffer.from(new Uint16Array(jw.flatMap((w) => [w[0][0], w[1][1] > 0 ? w[1][0] : 0, 0, 0])).buffer), 34962);
  const vWeights = view(f32(jw.flatMap((w) => [w[0][1], w[1][1], 0, 0])), 34962);
  const vIdx = view(Buffer.from(new Uint32Array(idx).buffer), 34963);
  // inverse bind matrices (column-major): the joints' rest globals are
  // translations to (0, j, 0)
  const ibm = [];
  for (let j = 0; j < joints; j++) ibm.push(1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, -j, 0, 1);
  const vIbm = view(f32(ibm), undefined);
  const lo = [0, 1, 2].map((k) => Math.min(...pos.map((p) => Math.fround(p[k]))));
  const hi = [0, 1, 2].map((k) => Math.max(...pos.map((p) => Math.fround(p[k]))));
  const nodes = [{ name: 'limb', mesh: 0, skin: 0 }, { name: 'Armature', children: [2] }];
  for (let j = 0; j < joints; j++) {
    const node = { name: j === o.bones ? 'end' : `bone${j}` };
    if (j > 0) node.translation = [0, 1, 0];
    if (j + 1 < joints) node.children = [j + 3];
    nodes.push(node);
  }
  const count = pos.length;
  const bin = Buffer.concat(chunks);
  const doc = {
    asset: { version: '2.0', generator: 'dend web test limb' },
    scene: 0,
    scenes: [{ name: 'limb', nodes: [0, 1] }],
    nodes,
    skins: [{ joints: [...Array(joints).keys()].map((j) => j + 2), inverseBindMatrices: 5, skeleton: 1 }],
    meshes: [{ name: 'limb', primitives: [{ attributes: { POSITION: 0, NORMAL: 1, JOINTS_0: 2, WEIGHTS_0: 3 }, indices: 4, mode: 4 }] }],
    accessors: [
      { bufferView: vPos, componentType: 5126, count, type: 'VEC3', min: lo, max: hi },
      { bufferView: vNrm, componentType: 5126, count, type: 'VEC3' },
      { bufferView: vJoints, componentType: 5123, count, type: 'VEC4' },
      { bufferView: vWeights, componentType: 5126, count, type: 'VEC4' },
      { bufferView: vIdx, componentType: 5125, count: idx.length, type: 'SCALAR' },
      { bufferView: vIbm, componentType: 5126, count: joints, type: 'MAT4' },
    ],
    bufferViews: views,
    buffers: [{ byteLength: bin.length }],
  };
  let json = Buffer.from(JSON.stringify(doc));
  json = Buffer.concat([json, Buffer.alloc((4 - (json.length % 4)) % 4, 0x20)]);
  const binPad = Buffer.concat([bin, Buffer.alloc((4 - (bin.length % 4)) % 4)]);
  const header = Buffer.alloc(12);
  header.writeUInt32LE(0x46546c67, 0);
  header.writeUInt32LE(2, 4);
  header.writeUInt32LE(12 + 8 + json.length + 8 + binPad.length, 8);
  const chunk = (type, data) => {
    const h = Buffer.alloc(8);
    h.writeUInt32LE(data.length, 0);
    h.writeUInt32LE(type, 4);
    return Buffer.concat([h, data]);
  };
  return Buffer.concat([header, chunk(0x4e4f534a, json), chunk(0x004e4942, binPad)]);
}
