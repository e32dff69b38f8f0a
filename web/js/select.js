// Screen-space selection of vertices: projection with the current camera,
// brush (circle), box and lasso (freehand polygon), each optionally
// restricted by a visibility predicate (zbuffer.js: only vertices the
// camera sees, so a brush paints the visible side only).

/** Projects vertex xyz (f32) through column-major `mvp` to CSS pixels.
 * Returns Float32Array [x, y, depth] per vertex (depth > 1 = clipped). */
export function project(positions, mvp, width, height) {
  const n = positions.length / 3;
  const out = new Float32Array(3 * n);
  const m = mvp;
  for (let i = 0; i < n; i++) {
    const x = positions[3 * i], y = positions[3 * i + 1], z = positions[3 * i + 2];
    const cx = m[0] * x + m[4] * y + m[8] * z + m[12];
    const cy = m[1] * x + m[5] * y + m[9] * z + m[13];
    const cz = m[2] * x + m[6] * y + m[10] * z + m[14];
    const cw = m[3] * x + m[7] * y + m[11] * z + m[15];
    out[3 * i] = (cx / cw * 0.5 + 0.5) * width;
    out[3 * i + 1] = (1 - (cy / cw * 0.5 + 0.5)) * height;
    out[3 * i + 2] = cw > 0 ? cz / cw : 2;
  }
  return out;
}

/** Vertices within `radius` px of (x, y). */
export function brush(screen, x, y, radius, visible) {
  const out = [];
  const r2 = radius * radius;
  for (let i = 0; i < screen.length / 3; i++) {
    const dx = screen[3 * i] - x, dy = screen[3 * i + 1] - y;
    if (screen[3 * i + 2] <= 1 && dx * dx + dy * dy <= r2 && (!visible || visible(i))) out.push(i);
  }
  return out;
}

/** Vertices inside the screen rectangle spanned by two corners. */
export function box(screen, x0, y0, x1, y1, visible) {
  const [ax, bx] = [Math.min(x0, x1), Math.max(x0, x1)];
  const [ay, by] = [Math.min(y0, y1), Math.max(y0, y1)];
  const out = [];
  for (let i = 0; i < screen.length / 3; i++) {
    const sx = screen[3 * i], sy = screen[3 * i + 1];
    if (screen[3 * i + 2] <= 1 && sx >= ax && sx <= bx && sy >= ay && sy <= by && (!visible || visible(i))) {
      out.push(i);
    }
  }
  return out;
}

/** Whether (x, y) is inside the closed polygon `poly` ([[x, y], ...]),
 * by the even-odd rule (a self-crossing lasso selects what it encloses an
 * odd number of times, as drawing programs do). */
export function insidePolygon(poly, x, y) {
  let inside = false;
  for (let i = 0, j = poly.length - 1; i < poly.length; j = i++) {
    const [xi, yi] = poly[i];
    const [xj, yj] = poly[j];
    if ((yi > y) !== (yj > y) && x < ((xj - xi) * (y - yi)) / (yj - yi) + xi) inside = !inside;
  }
  return inside;
}

/** Vertices inside the lasso polygon `poly` (screen px, at least 3 points). */
export function lasso(screen, poly, visible) {
  if (poly.length < 3) return [];
  let [ax, ay, bx, by] = [Infinity, Infinity, -Infinity, -Infinity];
  for (const [x, y] of poly) {
    [ax, ay, bx, by] = [Math.min(ax, x), Math.min(ay, y), Math.max(bx, x), Math.max(by, y)];
  }
  const out = [];
  for (let i = 0; i < screen.length / 3; i++) {
    const sx = screen[3 * i], sy = screen[3 * i + 1];
    if (screen[3 * i + 2] > 1 || sx < ax || sx > bx || sy < ay || sy > by) continue;
    if (insidePolygon(poly, sx, sy) && (!visible || visible(i))) out.push(i);
  }
  return out;
}

/** The nearest vertex to (x, y) within `radius` px among those `accept`ed,
 * preferring the one closest to the eye among near ties. */
export function pick(screen, x, y, radius, accept) {
  let best = -1;
  let bestScore = Infinity;
  for (let i = 0; i < screen.length / 3; i++) {
    if (screen[3 * i + 2] > 1 || (accept && !accept(i))) continue;
    const d = Math.hypot(screen[3 * i] - x, screen[3 * i + 1] - y);
    if (d > radius) continue;
    const score = d + 40 * screen[3 * i + 2];
    if (score < bestScore) {
      bestScore = score;
      best = i;
    }
  }
  return best;
}

/** Vertex adjacency (CSR: `start`, `next`) from a flat edge list
 * `[a, b, a, b, ...]` over `n` vertices. */
export function adjacency(edges, n) {
  const start = new Uint32Array(n + 1);
  for (let k = 0; k < edges.length; k++) start[edges[k] + 1]++;
  for (let i = 0; i < n; i++) start[i + 1] += start[i];
  const fill = start.slice(0, n);
  const next = new Uint32Array(edges.length);
  for (let k = 0; k < edges.length; k += 2) {
    const [a, b] = [edges[k], edges[k + 1]];
    next[fill[a]++] = b;
    next[fill[b]++] = a;
  }
  return { start, next };
}

/** The vertices reachable from `seed` over edges through vertices whose
 * label equals the seed's (a bucket fill: a region painted around a limb
 * bounds the fill of the part beyond it; on an unpainted mesh it is the
 * seed's connected component). */
export function fillRegion(adj, labels, seed) {
  const want = labels[seed];
  const seen = new Uint8Array(labels.length);
  const out = [seed];
  seen[seed] = 1;
  for (let q = 0; q < out.length; q++) {
    const v = out[q];
    for (let k = adj.start[v]; k < adj.start[v + 1]; k++) {
      const w = adj.next[k];
      if (!seen[w] && labels[w] === want) {
        seen[w] = 1;
        out.push(w);
      }
    }
  }
  return out;
}
