// The handle gizmo: for the selected handle, three arrows along the world
// axes (x red, y green, z blue) and three rotation rings about them, drawn
// at the handle's centroid (a joint's handle: at the joint's head, its
// pivot) on a 2D overlay above the WebGL canvas (always
// on top, a constant size on screen). Dragging an arrow translates the
// handle along its axis; dragging a ring rotates it about that axis
// through the centroid (the drag protocol's rotation is about the handle's
// current pivot, its centroid). The numeric entry of the panel sends a
// translation and a rotation as one drag between a grab and a release: one
// undo step.
//
// Hit test (the order a press is resolved in): the centre disc moves the
// handle in the view plane (as a press on the handle itself does); then
// the arrows; then the rings, only on their visible arcs (the half nearer
// the eye) and only when a ring is not seen nearly edge-on: an edge-on
// ring projects to a line through the centre, and used to take presses
// meant for the handle (a ~0° rotation instead of a move). The back arcs
// and edge-on rings are drawn faint.

import { add, scale, sub, dot } from './camera.js';
import { Renderer } from './renderer.js';
import { project } from './select.js';
import { send, sendDrag, serverHandle, showError, jointHandleHead } from './app.js';

const AXES = [[1, 0, 0], [0, 1, 0], [0, 0, 1]];
const COLORS = ['#d22', '#2a2', '#25d'];
const ARROW_PX = 90; // arrow length on screen
const RING = 0.7; // ring radius as a fraction of the arrow length
const CENTER_PX = 12; // radius of the centre disc that moves the handle
const EDGE_ON = 0.25; // |cos| between a ring's axis and the view below which it is edge-on

export class Gizmo {
  constructor(app, overlay) {
    this.app = app;
    this.overlay = overlay;
    this.handle = null; // UI handle index, or null
    this.geom = null; // screen geometry of the last draw (hit tests, test)
  }

  /** Where UI handle `k`'s gizmo sits in the current pose: a joint's
   * handle at the joint's head, any other at its vertices' centroid; null
   * when it has no vertex. */
  centroid(k) {
    const { labels, positions } = this.app;
    if (!labels || k === null) return null;
    const head = jointHandleHead(k);
    if (head && labels.includes(k + 1)) return head;
    const c = [0, 0, 0];
    let n = 0;
    for (let i = 0; i < labels.length; i++) {
      if (labels[i] === k + 1) {
        c[0] += positions[3 * i];
        c[1] += positions[3 * i + 1];
        c[2] += positions[3 * i + 2];
        n++;
      }
    }
    return n ? scale(c, 1 / n) : null;
  }

  toScreen(points) {
    const c = this.overlay;
    const [w, h] = [c.clientWidth, c.clientHeight];
    const s = project(new Float32Array(points.flat()), Renderer.mvp(this.app.camera, w / h), w, h);
    return points.map((_, i) => [s[3 * i], s[3 * i + 1], s[3 * i + 2]]);
  }

  /** Screen geometry: centre, arrow tips, ring polylines; null when no
   * handle is selected or it has no vertex. */
  geometry() {
    const c = this.centroid(this.handle);
    if (!c) return null;
    const cam = this.app.camera;
    const depth = Math.max(1e-9, dot(sub(c, cam.eye()), cam.basis().fwd));
    const len = (ARROW_PX * 2 * depth * Math.tan(cam.fovy / 2)) / Math.max(1, this.overlay.clientHeight);
    const pts = [c, ...AXES.map((a) => add(c, scale(a, len)))];
    const rings = AXES.map((a, k) => {
      const [u, v] = [AXES[(k + 1) % 3], AXES[(k + 2) % 3]];
      return Array.from({ length: 49 }, (_, j) => {
        const t = (2 * Math.PI * j) / 48;
        return add(c, add(scale(u, RING * len * Math.cos(t)), scale(v, RING * len * Math.sin(t))));
      });
    });
    const s = this.toScreen([...pts, ...rings.flat()]);
    if (s[0][2] > 1) return null; // behind the eye
    const { fwd } = cam.basis();
    return {
      world: c,
      length: len,
      center: s[0].slice(0, 2),
      tips: s.slice(1, 4).map((p) => p.slice(0, 2)),
      rings: rings.map((_, k) => s.slice(4 + 49 * k, 4 + 49 * (k + 1)).map((p) => p.slice(0, 2))),
      // per ring point: on the half nearer the eye
      front: rings.map((r) => r.map((p) => dot(sub(p, c), fwd) <= 1e-9 * len)),
      edgeOn: AXES.map((a) => Math.abs(dot(a, fwd)) < EDGE_ON),
    };
  }

  draw() {
    const c = this.overlay;
    const dpr = window.devicePixelRatio || 1;
    const [w, h] = [Math.round(c.clientWidth * dpr), Math.round(c.clientHeight * dpr)];
    if (c.width !== w || c.height !== h) [c.width, c.height] = [w, h];
    const g = c.getContext('2d');
    g.setTransform(dpr, 0, 0, dpr, 0, 0);
    g.clearRect(0, 0, c.clientWidth, c.clientHeight);
    this.geom = this.geometry();
    const geo = this.geom;
    if (!geo) return;
    g.lineWidth = 2;
    geo.rings.forEach((ring, k) => {
      g.strokeStyle = COLORS[k];
      // the visible arcs (those a press can take) strong, the rest faint
      for (const front of [false, true]) {
        const on = front && !geo.edgeOn[k];
        g.globalAlpha = this.active && this.active.ring === k ? 1 : on ? 0.65 : 0.18;
        g.beginPath();
        for (let j = 0; j + 1 < ring.length; j++) {
          if (geo.front[k][j] !== front && geo.front[k][j + 1] !== front) continue;
          g.moveTo(ring[j][0], ring[j][1]);
          g.lineTo(ring[j + 1][0], ring[j + 1][1]);
        }
        g.stroke();
      }
    });
    g.globalAlpha = 1;
    const [cx, cy] = geo.center;
    geo.tips.forEach(([x, y], k) => {
      g.strokeStyle = g.fillStyle = COLORS[k];
      g.lineWidth = this.active && this.active.axis === k ? 4 : 3;
      g.beginPath();
      g.moveTo(cx, cy);
      g.lineTo(x, y);
      g.stroke();
      const a = Math.atan2(y - cy, x - cx);
      g.beginPath();
      g.moveTo(x + 6 * Math.cos(a), y + 6 * Math.sin(a));
      g.lineTo(x + 8 * Math.cos(a + 2.5), y + 8 * Math.sin(a + 2.5));
      g.lineTo(x + 8 * Math.cos(a - 2.5), y + 8 * Math.sin(a - 2.5));
      g.fill();
      g.font = '11px system-ui, sans-serif';
      g.fillText('xyz'[k], x + 12 * Math.cos(a) - 3, y + 12 * Math.sin(a) + 4);
    });
    // the centre disc: press here to move the handle in the view plane
    g.fillStyle = 'rgba(255,255,255,0.55)';
    g.strokeStyle = '#222';
    g.lineWidth = 1.5;
    g.beginPath();
    g.arc(cx, cy, CENTER_PX - 4, 0, 2 * Math.PI);
    g.fill();
    g.stroke();
    g.fillStyle = '#222';
    g.beginPath();
    g.arc(cx, cy, 2.5, 0, 2 * Math.PI);
    g.fill();
  }

  /** What is under the pointer: {center: true} (the centre disc),
   * {axis: k} (an arrow), {ring: k} (a visible arc of a ring not seen
   * edge-on), or null. */
  hit(x, y) {
    const geo = this.geom;
    if (!geo) return null;
    const [cx, cy] = geo.center;
    if (Math.hypot(x - cx, y - cy) <= CENTER_PX) return { center: true };
    let best = null;
    let bestD = 7;
    geo.tips.forEach(([tx, ty], k) => {
      const d = segmentDistance(x, y, cx, cy, tx + 6 * Math.sign(tx - cx), ty + 6 * Math.sign(ty - cy));
      // the arrow's first pixels overlap the other arrows: skip the centre
      if (d < bestD && Math.hypot(x - cx, y - cy) > 8 && Math.hypot(tx - cx, ty - cy) > 6) {
        bestD = d;
        best = { axis: k };
      }
    });
    if (best) return best;
    bestD = 6;
    geo.rings.forEach((ring, k) => {
      if (geo.edgeOn[k]) return;
      for (let j = 0; j + 1 < ring.length; j++) {
        if (!geo.front[k][j] || !geo.front[k][j + 1]) continue;
        const d = segmentDistance(x, y, ring[j][0], ring[j][1], ring[j + 1][0], ring[j + 1][1]);
        if (d < bestD) {
          bestD = d;
          best = { ring: k };
        }
      }
    });
    return best;
  }

  /** A drag of the part `part` (hit's result) starting at (x, y). */
  start(part, x, y) {
    const geo = this.geom;
    this.active = part;
    const d = { part, x0: x, y0: y, center: geo.center, sent: 0 };
    if (part.axis !== undefined) {
      // world units per pixel along the arrow's screen direction
      const [tx, ty] = geo.tips[part.axis];
      d.dir = [tx - geo.center[0], ty - geo.center[1]];
      d.len = geo.length;
    } else {
      d.world = geo.world;
      d.theta = this.ringAngle(part.ring, geo.world, x, y);
      d.angle = Math.atan2(y - geo.center[1], x - geo.center[0]);
      const f = dot(AXES[part.ring], this.app.camera.basis().fwd);
      // clockwise on screen (y down) is a right-handed turn about the
      // into-screen axis: the ring's axis pointing away turns with it
      d.sign = f >= 0 ? 1 : -1;
    }
    return d;
  }

  /** The angle about axis k, in the ring's plane through `c`, of the point
   * under the pointer (the view ray through (x, y) meets the plane), from
   * the ring's first axis towards its second; null when the plane is seen
   * nearly edge-on. */
  ringAngle(k, c, x, y) {
    const cam = this.app.camera;
    const [w, h] = [this.overlay.clientWidth, this.overlay.clientHeight];
    const { right, up, fwd } = cam.basis();
    const t = Math.tan(cam.fovy / 2);
    const dir = add(fwd, add(scale(right, ((2 * x) / w - 1) * t * (w / h)), scale(up, (1 - (2 * y) / h) * t)));
    const a = AXES[k];
    const eye = cam.eye();
    const den = dot(dir, a);
    if (Math.abs(den) < 0.15 * Math.hypot(...dir)) return null;
    const p = sub(add(eye, scale(dir, dot(sub(c, eye), a) / den)), c);
    return Math.atan2(dot(p, AXES[(k + 2) % 3]), dot(p, AXES[(k + 1) % 3]));
  }

  /** The delta of the drag `d` for the pointer at (x, y): {translate} or
   * {axis, degrees}; null when nothing changes. */
  move(d, x, y) {
    if (d.part.axis !== undefined) {
      const l2 = dot([...d.dir, 0], [...d.dir, 0]);
      if (l2 < 1) return null; // the arrow points at the eye
      const total = (((x - d.x0) * d.dir[0] + (y - d.y0) * d.dir[1]) / l2) * d.len;
      const step = total - d.sent;
      d.sent = total;
      return step === 0 ? null : { translate: scale(AXES[d.part.axis], step) };
    }
    const wrap = (r) => ((r + 3 * Math.PI) % (2 * Math.PI)) - Math.PI;
    const a = Math.atan2(y - d.center[1], x - d.center[0]);
    const theta = this.ringAngle(d.part.ring, d.world, x, y);
    let degrees;
    if (theta !== null && d.theta !== null) {
      // the ring's point under the pointer follows it
      degrees = wrap(theta - d.theta) * (180 / Math.PI);
    } else {
      // seen edge-on: the angle swept around the centre on screen
      degrees = d.sign * wrap(a - d.angle) * (180 / Math.PI);
    }
    d.angle = a;
    d.theta = theta;
    return degrees === 0 ? null : { axis: AXES[d.part.ring], degrees };
  }

  end() {
    this.active = null;
  }
}

function segmentDistance(x, y, ax, ay, bx, by) {
  const [ux, uy] = [bx - ax, by - ay];
  const l2 = ux * ux + uy * uy;
  const t = l2 > 0 ? Math.max(0, Math.min(1, ((x - ax) * ux + (y - ay) * uy) / l2)) : 0;
  return Math.hypot(x - ax - t * ux, y - ay - t * uy);
}

/** The panel's numeric entry: dx, dy, dz and an angle about an axis,
 * applied to the gizmo's handle as one grabbed drag (one undo step). */
export function wireNumeric(app) {
  const $ = (id) => document.getElementById(id);
  $('numApply').onclick = () => {
    const k = app.gizmo.handle;
    if (k === null || !app.gizmo.centroid(k)) {
      showError({ code: 'no_handle', message: 'select a painted handle first (pick it in the view or choose it as the paint target)' });
      return;
    }
    const t = ['numDx', 'numDy', 'numDz'].map((id) => Number($(id).value) || 0);
    const deg = Number($('numDeg').value) || 0;
    if (t.every((v) => v === 0) && deg === 0) return;
    const h = serverHandle(k);
    send({ type: 'grab', handle: h });
    sendDrag(k, t, deg ? { axis: AXES['xyz'.indexOf($('numAxis').value)], degrees: deg } : null);
    send({ type: 'release', handle: h });
  };
}

/** "handle k" in the panel when the gizmo shows one. */
export function gizmoLabel(app) {
  const k = app.gizmo.handle;
  return k === null || !app.gizmo.centroid(k) ? 'no handle selected' : `handle ${k}`;
}
