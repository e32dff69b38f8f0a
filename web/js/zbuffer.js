// Occlusion for the selection tools: a CPU z-buffer of the current pose at
// the canvas' CSS-pixel resolution. Every triangle is rasterised with the
// camera's projection (pixel centres, perspective-correct depth as the
// eye-space distance along the view axis); a vertex is visible when its
// own depth is no more than a small tolerance behind the nearest surface
// at its pixel (or at one of its four neighbours, which keeps silhouette
// vertices whose pixel centre the surface just misses).

/** Eye-space depth (distance in front of the eye) of every vertex and its
 * CSS-pixel position: Float32Array [x, y, depth] per vertex (depth ≤ 0 =
 * behind the eye). `view` and `proj` are the camera's column-major
 * matrices. */
export function projectDepth(positions, view, proj, width, height) {
  const n = positions.length / 3;
  const out = new Float32Array(3 * n);
  const v = view, p = proj;
  for (let i = 0; i < n; i++) {
    const x = positions[3 * i], y = positions[3 * i + 1], z = positions[3 * i + 2];
    const ex = v[0] * x + v[4] * y + v[8] * z + v[12];
    const ey = v[1] * x + v[5] * y + v[9] * z + v[13];
    const ez = v[2] * x + v[6] * y + v[10] * z + v[14];
    const cx = p[0] * ex + p[4] * ey + p[8] * ez + p[12];
    const cy = p[1] * ex + p[5] * ey + p[9] * ez + p[13];
    const cw = p[3] * ex + p[7] * ey + p[11] * ez + p[15];
    out[3 * i] = (cx / cw * 0.5 + 0.5) * width;
    out[3 * i + 1] = (1 - (cy / cw * 0.5 + 0.5)) * height;
    out[3 * i + 2] = -ez;
  }
  return out;
}

/** The nearest eye-space depth per pixel (Infinity where nothing is
 * drawn), rasterising `triangles` over the projected vertices `sd`
 * (projectDepth's output). Depth is interpolated as 1/z across the screen
 * (perspective-correct). Triangles touching the eye plane are skipped. */
export function rasterise(sd, triangles, width, height) {
  const w = Math.max(1, Math.round(width)), h = Math.max(1, Math.round(height));
  const zb = new Float32Array(w * h).fill(Infinity);
  for (let t = 0; t < triangles.length; t += 3) {
    const a = 3 * triangles[t], b = 3 * triangles[t + 1], c = 3 * triangles[t + 2];
    const za = sd[a + 2], zbv = sd[b + 2], zc = sd[c + 2];
    if (!(za > 0 && zbv > 0 && zc > 0)) continue;
    const ax = sd[a], ay = sd[a + 1], bx = sd[b], by = sd[b + 1], cx = sd[c], cy = sd[c + 1];
    const area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax);
    if (!(Math.abs(area) > 1e-12)) continue;
    const x0 = Math.max(0, Math.ceil(Math.min(ax, bx, cx) - 0.5));
    const x1 = Math.min(w - 1, Math.floor(Math.max(ax, bx, cx) - 0.5));
    const y0 = Math.max(0, Math.ceil(Math.min(ay, by, cy) - 0.5));
    const y1 = Math.min(h - 1, Math.floor(Math.max(ay, by, cy) - 0.5));
    if (x0 > x1 || y0 > y1) continue;
    const ia = 1 / za, ib = 1 / zbv, ic = 1 / zc;
    const inv = 1 / area;
    for (let y = y0; y <= y1; y++) {
      const py = y + 0.5;
      for (let x = x0; x <= x1; x++) {
        const px = x + 0.5;
        // barycentric weights (same sign as the area inside)
        const wa = ((bx - px) * (cy - py) - (by - py) * (cx - px)) * inv;
        const wb = ((cx - px) * (ay - py) - (cy - py) * (ax - px)) * inv;
        const wc = 1 - wa - wb;
        if (wa < 0 || wb < 0 || wc < 0) continue;
        const d = 1 / (wa * ia + wb * ib + wc * ic);
        const k = y * w + x;
        if (d < zb[k]) zb[k] = d;
      }
    }
  }
  return { zb, w, h };
}

/** A visibility predicate `(i) => bool` over the vertices of `sd` given
 * the z-buffer `buf`: vertex i is visible when its depth d exceeds the
 * surface's at its pixel (or a 4-neighbour) by at most `tol + slope · d`
 * (mesh units; `slope · d` is a pixel's footprint at depth d, for slanted
 * surfaces). Vertices off screen or behind the eye are not visible. */
export function visibleFrom(sd, buf, tol, slope = 0) {
  const { zb, w, h } = buf;
  return (i) => {
    const d = sd[3 * i + 2];
    if (!(d > 0)) return false;
    const x = Math.floor(sd[3 * i]), y = Math.floor(sd[3 * i + 1]);
    if (x < 0 || y < 0 || x >= w || y >= h) return false;
    const lim = d - tol - slope * d;
    const k = y * w + x;
    if (zb[k] >= lim) return true;
    if (x > 0 && zb[k - 1] >= lim) return true;
    if (x + 1 < w && zb[k + 1] >= lim) return true;
    if (y > 0 && zb[k - w] >= lim) return true;
    if (y + 1 < h && zb[k + w] >= lim) return true;
    return false;
  };
}

/** Caches the z-buffer of one pose seen by one camera at one canvas size,
 * rebuilt when any of them changes. `get(positions, triangles, camera,
 * width, height)` returns the visibility predicate; the depth tolerance
 * is 1 % of the mesh's bounding radius plus two pixels' footprint at the
 * vertex' depth. */
export class Occlusion {
  constructor() {
    this.key = null;
    this.pred = null;
    this.builds = 0; // rebuilt only when the pose, camera or size changed
  }

  get(positions, triangles, camera, width, height) {
    const view = camera.view();
    const proj = camera.proj(width / height);
    const key = [width, height, ...view, ...proj].join(',');
    if (this.pred && this.positions === positions && this.triangles === triangles && this.key === key) return this.pred;
    const sd = projectDepth(positions, view, proj, width, height);
    const buf = rasterise(sd, triangles, width, height);
    const pxPerUnit = height / (2 * Math.tan(camera.fovy / 2)); // at depth 1
    this.pred = visibleFrom(sd, buf, 0.01 * camera.radius, 2 / pxPerUnit);
    Object.assign(this, { key, positions, triangles, zbuffer: buf });
    this.builds++;
    return this.pred;
  }
}
