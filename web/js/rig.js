// Rig arithmetic of the editor, on plain arrays (no editor state): the
// joints of a skeleton listing (GET /v1/meshes/{id}: name, parent, head,
// region) as a tree, a joint's region with its descendants', and where a
// joint's head is in the current pose.
//
// A joint's head moves with its region: the region's rigid motion from the
// rest positions to the pose (least squares, Horn's closed form with unit
// quaternions) carries the rest head. A handle moves its region rigidly, so
// for a joint that is a handle this is exact; for a free region it is the
// motion that fits it best.

/** The joints' children (indices) and the roots, in listing order. */
export function jointTree(joints) {
  const index = new Map(joints.map((j, k) => [j.name, k]));
  const children = joints.map(() => []);
  const roots = [];
  joints.forEach((j, k) => {
    const p = j.parent === undefined || j.parent === null ? undefined : index.get(j.parent);
    if (p === undefined || p === k) roots.push(k);
    else children[p].push(k);
  });
  return { children, roots };
}

/** Joint `k` and, with `withChildren`, every descendant (indices). */
export function jointsUnder(joints, k, withChildren) {
  if (!withChildren) return [k];
  const { children } = jointTree(joints);
  const out = [];
  const stack = [k];
  const seen = new Set();
  while (stack.length) {
    const j = stack.pop();
    if (seen.has(j)) continue; // a listing with a cycle (the server refuses one)
    seen.add(j);
    out.push(j);
    stack.push(...children[j]);
  }
  return out;
}

/** The welded vertices of joint `k`'s region, with its descendants'. */
export function regionOf(joints, k, withChildren) {
  const out = [];
  for (const j of jointsUnder(joints, k, withChildren)) out.push(...(joints[j].region || []));
  return out;
}

/** Eigenvector of the largest eigenvalue of a symmetric 4 × 4 matrix
 * (row-major array of 16), by cyclic Jacobi rotations. */
function topEigenvector(a) {
  const m = a.slice();
  const v = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1];
  for (let sweep = 0; sweep < 50; sweep++) {
    let off = 0;
    for (let p = 0; p < 4; p++) for (let q = p + 1; q < 4; q++) off += m[4 * p + q] ** 2;
    if (off < 1e-30) break;
    for (let p = 0; p < 4; p++) {
      for (let q = p + 1; q < 4; q++) {
        const apq = m[4 * p + q];
        if (Math.abs(apq) < 1e-300) continue;
        const theta = (m[4 * q + q] - m[4 * p + p]) / (2 * apq);
        const t = Math.sign(theta || 1) / (Math.abs(theta) + Math.sqrt(theta * theta + 1));
        const c = 1 / Math.sqrt(t * t + 1);
        const s = t * c;
        for (let k = 0; k < 4; k++) {
          const [mkp, mkq] = [m[4 * k + p], m[4 * k + q]];
          m[4 * k + p] = c * mkp - s * mkq;
          m[4 * k + q] = s * mkp + c * mkq;
        }
        for (let k = 0; k < 4; k++) {
          const [mpk, mqk] = [m[4 * p + k], m[4 * q + k]];
          m[4 * p + k] = c * mpk - s * mqk;
          m[4 * q + k] = s * mpk + c * mqk;
        }
        for (let k = 0; k < 4; k++) {
          const [vkp, vkq] = [v[4 * k + p], v[4 * k + q]];
          v[4 * k + p] = c * vkp - s * vkq;
          v[4 * k + q] = s * vkp + c * vkq;
        }
      }
    }
  }
  let best = 0;
  for (let k = 1; k < 4; k++) if (m[5 * k] > m[5 * best]) best = k;
  return [v[best], v[4 + best], v[8 + best], v[12 + best]];
}

/** The rigid motion {rotation (row-major 3 × 3), from, to} that best maps
 * the vertices `idx` of `rest` onto `pose` (flat xyz arrays): `p ↦ to +
 * R (p − from)`, `from` and `to` the two centroids. Null without vertices. */
export function rigidFit(rest, pose, idx) {
  if (!idx.length) return null;
  const from = [0, 0, 0];
  const to = [0, 0, 0];
  for (const i of idx) {
    for (let k = 0; k < 3; k++) {
      from[k] += rest[3 * i + k];
      to[k] += pose[3 * i + k];
    }
  }
  for (let k = 0; k < 3; k++) {
    from[k] /= idx.length;
    to[k] /= idx.length;
  }
  // S = Σ (a − ā)(b − b̄)ᵀ
  const s = new Array(9).fill(0);
  for (const i of idx) {
    for (let r = 0; r < 3; r++) {
      const a = rest[3 * i + r] - from[r];
      for (let c = 0; c < 3; c++) s[3 * r + c] += a * (pose[3 * i + c] - to[c]);
    }
  }
  const [xx, xy, xz, yx, yy, yz, zx, zy, zz] = s;
  const n = [
    xx + yy + zz, yz - zy, zx - xz, xy - yx,
    yz - zy, xx - yy - zz, xy + yx, zx + xz,
    zx - xz, xy + yx, -xx + yy - zz, yz + zy,
    xy - yx, zx + xz, yz + zy, -xx - yy + zz,
  ];
  const [w, x, y, z] = topEigenvector(n);
  const rotation = [
    w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y),
    2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x),
    2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z,
  ];
  return { rotation, from, to };
}

/** `fit` (rigidFit's) applied to the point `p`. */
export function applyFit(fit, p) {
  const d = [p[0] - fit.from[0], p[1] - fit.from[1], p[2] - fit.from[2]];
  const r = fit.rotation;
  return [0, 1, 2].map((k) => fit.to[k] + r[3 * k] * d[0] + r[3 * k + 1] * d[1] + r[3 * k + 2] * d[2]);
}

/** Where joint `k`'s head is in `pose`: its rest head carried by the
 * rigid motion of its region (with its descendants' when its own region is
 * too small to fix a rotation: fewer than 3 vertices); the rest head when
 * the rest positions are unknown or no vertex moves with it. */
export function headInPose(joints, k, rest, pose) {
  const head = joints[k].head;
  if (!rest || !pose) return head.slice();
  let idx = joints[k].region || [];
  if (idx.length < 3) idx = regionOf(joints, k, true);
  const fit = rigidFit(rest, pose, idx);
  return fit ? applyFit(fit, head) : head.slice();
}
