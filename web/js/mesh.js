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
