// Pointer interaction on the canvas: orbit/pan/zoom, brush, box and lasso
// painting (visible vertices only unless "through": zbuffer.js), the
// handle gizmo (gizmo.js), and handle dragging (translate in the view
// plane; Alt in depth; Shift rotates about the handle's centroid). Touch:
// one finger acts as the left mouse button (orbit, paint, drag), two
// fingers pan (their midpoint), pinch-zoom (their distance) and twist (the
// angle between them turns the view about the vertical).

import { Renderer } from './renderer.js';
import { project, brush, box, lasso, pick, adjacency, fillRegion } from './select.js';
import { Occlusion } from './zbuffer.js';
import { sub, dot, add, scale } from './camera.js';
import { paint, strokeEnded, sendDrag, send, serverHandle, heldByOther, showHeld } from './app.js';

const $ = (id) => document.getElementById(id);

function tool() {
  return document.querySelector('input[name=tool]:checked').value;
}

export function attachInteraction(app, canvas) {
  let drag = null; // current gesture

  const size = () => [canvas.clientWidth, canvas.clientHeight];
  const screen = () => {
    const [w, h] = size();
    return project(app.positions, Renderer.mvp(app.camera, w / h), w, h);
  };
  app.occlusion = new Occlusion();
  /** The visibility predicate of the selection tools: the z-buffer test,
   * or none ("through": every vertex under the tool). */
  const visible = () => {
    if ($('throughSel').checked) return null;
    const [w, h] = size();
    return app.occlusion.get(app.positions, app.mesh.triangles, app.camera, w, h);
  };

  /** Centroid of a UI handle's vertices in the current pose. */
  const centroid = (k) => {
    let c = [0, 0, 0];
    let n = 0;
    app.labels.forEach((l, i) => {
      if (l === k + 1) {
        c = add(c, [app.positions[3 * i], app.positions[3 * i + 1], app.positions[3 * i + 2]]);
        n++;
      }
    });
    return scale(c, 1 / Math.max(1, n));
  };

  /** Screen position of a world point. */
  const toScreen = (p) => {
    const [w, h] = size();
    const s = project(new Float32Array(p), Renderer.mvp(app.camera, w / h), w, h);
    return [s[0], s[1]];
  };

  canvas.addEventListener('contextmenu', (e) => e.preventDefault());

  const touches = new Map(); // pointerId → [x, y] of the fingers down
  let pinch = null; // {mid, dist, angle} of the last two-finger move

  const twoFingers = () => {
    const [a, b] = [...touches.values()];
    return {
      mid: [(a[0] + b[0]) / 2, (a[1] + b[1]) / 2],
      dist: Math.max(1, Math.hypot(b[0] - a[0], b[1] - a[1])),
      angle: Math.atan2(b[1] - a[1], b[0] - a[0]),
    };
  };

  /** A second finger ends the one-finger gesture: a handle drag is
   * released (its moves so far stay), a box or lasso is dropped. */
  const cancelGesture = () => {
    if (!drag) return;
    if (drag.kind === 'handle' || drag.kind === 'gizmo') endHandleDrag(drag);
    if (drag.kind === 'brush') strokeEnded();
    $('boxRect').hidden = true;
    $('lasso').hidden = true;
    drag = null;
  };

  const endHandleDrag = (d) => {
    send({ type: 'release', handle: serverHandle(d.k) });
    if (d.kind === 'gizmo') app.gizmo.end();
    app.needsDraw = true;
  };

  canvas.addEventListener('pointerdown', (e) => {
    canvas.focus();
    canvas.setPointerCapture(e.pointerId);
    const x = e.offsetX, y = e.offsetY;
    if (e.pointerType === 'touch') {
      touches.set(e.pointerId, [x, y]);
      if (touches.size >= 2) {
        cancelGesture();
        pinch = touches.size === 2 ? twoFingers() : pinch;
        return;
      }
    }
    const t = tool();
    const panning = e.button === 2 || e.button === 1 || e.ctrlKey;
    if (!app.positions || panning) {
      drag = { kind: 'pan', x, y };
      return;
    }
    if (t === 'brush') {
      drag = { kind: 'brush', erase: e.altKey };
      paint(brush(screen(), x, y, +$('brushRadius').value, visible()), e.altKey);
      return;
    }
    if (t === 'box') {
      drag = { kind: 'box', x0: x, y0: y, erase: e.altKey };
      return;
    }
    if (t === 'lasso') {
      drag = { kind: 'lasso', points: [[x, y]], erase: e.altKey };
      return;
    }
    if (t === 'fill') {
      // the nearest visible vertex under the cursor seeds a bucket fill of
      // its label's connected region (Alt: erase that region)
      const seed = pick(screen(), x, y, 14, visible());
      if (seed >= 0) {
        if (!app.adjacency || app.adjacency.mesh !== app.mesh) {
          app.adjacency = { mesh: app.mesh, ...adjacency(app.mesh.edges, app.labels.length) };
        }
        paint(fillRegion(app.adjacency, app.labels, seed), e.altKey);
        strokeEnded();
      }
      return;
    }
    const part = app.gizmo.hit(x, y);
    // a handle another client holds: its status (once), and the press orbits
    const held = (k) => {
      if (!heldByOther(k)) return false;
      showHeld(serverHandle(k), app.held.get(serverHandle(k)));
      return true;
    };
    if (part && !part.center && !held(app.gizmo.handle)) {
      const k = app.gizmo.handle;
      drag = { kind: 'gizmo', k, g: app.gizmo.start(part, x, y) };
      send({ type: 'grab', handle: serverHandle(k) });
      app.needsDraw = true;
      return;
    }
    // the gizmo's centre moves its handle in the view plane, as a press on
    // the handle itself does
    const v = part && part.center ? -1 : pick(screen(), x, y, 14, (i) => app.labels[i] > 0);
    if ((v >= 0 || (part && part.center)) && !held(v >= 0 ? app.labels[v] - 1 : app.gizmo.handle)) {
      const k = v >= 0 ? app.labels[v] - 1 : app.gizmo.handle;
      app.gizmo.handle = k; // a picked handle gets the gizmo
      app.needsDraw = true;
      const c = centroid(k);
      const { fwd } = app.camera.basis();
      const depth = Math.max(1e-9, dot(sub(c, app.camera.eye()), fwd));
      const unit = (2 * depth * Math.tan(app.camera.fovy / 2)) / size()[1];
      drag = { kind: 'handle', k, x, y, unit, center: toScreen(c), angle: null };
      send({ type: 'grab', handle: serverHandle(k) });
      return;
    }
    drag = { kind: 'orbit', x, y };
  });

  /** The brush's circle follows the pointer while the brush tool is on. */
  const brushCircle = (x, y) => {
    const c = $('brushCircle');
    const on = tool() === 'brush' && x !== null;
    c.hidden = !on;
    if (!on) return;
    const r = +$('brushRadius').value;
    Object.assign(c.style, { left: `${x - r}px`, top: `${y - r}px`, width: `${2 * r}px`, height: `${2 * r}px` });
  };
  canvas.addEventListener('pointerleave', () => brushCircle(null, null));

  canvas.addEventListener('pointermove', (e) => {
    const x = e.offsetX, y = e.offsetY;
    if (e.pointerType === 'touch' && touches.has(e.pointerId)) {
      touches.set(e.pointerId, [x, y]);
      if (pinch && touches.size === 2) {
        const now = twoFingers();
        app.camera.pan(now.mid[0] - pinch.mid[0], now.mid[1] - pinch.mid[1], size()[1]);
        app.camera.zoom(pinch.dist / now.dist); // fingers apart: closer
        app.camera.yaw -= ((now.angle - pinch.angle + 3 * Math.PI) % (2 * Math.PI)) - Math.PI;
        pinch = now;
        app.needsDraw = true;
        return;
      }
      if (pinch) return;
    } else {
      brushCircle(x, y);
    }
    if (!drag) return;
    if (drag.kind === 'orbit' || drag.kind === 'pan') {
      if (drag.kind === 'orbit') app.camera.orbit(x - drag.x, y - drag.y);
      else app.camera.pan(x - drag.x, y - drag.y, size()[1]);
      drag.x = x;
      drag.y = y;
      app.needsDraw = true;
    } else if (drag.kind === 'brush') {
      paint(brush(screen(), x, y, +$('brushRadius').value, visible()), drag.erase);
    } else if (drag.kind === 'box') {
      const r = $('boxRect');
      r.hidden = false;
      Object.assign(r.style, {
        left: `${Math.min(x, drag.x0)}px`, top: `${Math.min(y, drag.y0)}px`,
        width: `${Math.abs(x - drag.x0)}px`, height: `${Math.abs(y - drag.y0)}px`,
      });
      drag.x1 = x;
      drag.y1 = y;
    } else if (drag.kind === 'lasso') {
      const last = drag.points[drag.points.length - 1];
      if (Math.hypot(x - last[0], y - last[1]) >= 2) drag.points.push([x, y]);
      const l = $('lasso');
      l.hidden = false;
      l.firstElementChild.setAttribute('points', drag.points.map((p) => p.join(',')).join(' '));
    } else if (drag.kind === 'gizmo') {
      const delta = app.gizmo.move(drag.g, x, y);
      if (delta && delta.translate) sendDrag(drag.k, delta.translate, null);
      else if (delta) sendDrag(drag.k, [0, 0, 0], { axis: delta.axis, degrees: delta.degrees });
    } else if (drag.kind === 'handle') {
      handleMove(drag, x, y, e.shiftKey, e.altKey);
    }
  });

  function handleMove(d, x, y, rotating, inDepth) {
    const { right, up, fwd } = app.camera.basis();
    if (rotating) {
      const axisName = $('rotAxis').value;
      let degrees;
      let axis;
      if (axisName === 'view') {
        // Angle swept around the handle's centroid on screen; clockwise on
        // screen (y down) is a right-handed turn about the into-screen axis.
        const a = Math.atan2(y - d.center[1], x - d.center[0]);
        degrees = d.angle === null ? 0 : ((a - d.angle + 3 * Math.PI) % (2 * Math.PI) - Math.PI) * (180 / Math.PI);
        d.angle = a;
        axis = fwd;
      } else {
        degrees = (x - d.x) * 0.5;
        axis = { x: [1, 0, 0], y: [0, 1, 0], z: [0, 0, 1] }[axisName];
      }
      d.x = x;
      d.y = y;
      if (degrees !== 0) sendDrag(d.k, [0, 0, 0], { axis, degrees });
      return;
    }
    d.angle = null;
    const dx = x - d.x, dy = y - d.y;
    d.x = x;
    d.y = y;
    if (inDepth) {
      // Alt: vertical motion moves the handle along the view direction
      // (up on screen = away from the viewer)
      sendDrag(d.k, scale(fwd, -dy * d.unit), null);
      return;
    }
    const t = add(scale(right, dx * d.unit), scale(up, -dy * d.unit));
    d.center = [d.center[0] + dx, d.center[1] + dy];
    sendDrag(d.k, t, null);
  }

  const pointerUp = (e) => {
    if (e.pointerType === 'touch') {
      touches.delete(e.pointerId);
      if (pinch) {
        // the gesture ends with the last finger: no orbit jump in between
        if (touches.size === 0) pinch = null;
        else if (touches.size === 2) pinch = twoFingers();
        return;
      }
    }
    if (!drag) return;
    const d = drag;
    drag = null;
    if (canvas.hasPointerCapture(e.pointerId)) canvas.releasePointerCapture(e.pointerId);
    if (d.kind === 'box') {
      $('boxRect').hidden = true;
      if (d.x1 !== undefined) paint(box(screen(), d.x0, d.y0, d.x1, d.y1, visible()), d.erase);
      strokeEnded();
    } else if (d.kind === 'lasso') {
      $('lasso').hidden = true;
      paint(lasso(screen(), d.points, visible()), d.erase);
      strokeEnded();
    } else if (d.kind === 'brush') {
      strokeEnded();
    } else if (d.kind === 'handle' || d.kind === 'gizmo') {
      endHandleDrag(d);
    }
  };
  canvas.addEventListener('pointerup', pointerUp);
  canvas.addEventListener('pointercancel', (e) => {
    // the browser took the pointer: nothing is painted, a drag is released
    if (e.pointerType === 'touch') touches.delete(e.pointerId);
    if (touches.size === 0) pinch = null;
    cancelGesture();
  });

  canvas.addEventListener('wheel', (e) => {
    e.preventDefault();
    app.camera.zoom(Math.exp(e.deltaY * 0.001));
    app.needsDraw = true;
  }, { passive: false });
}
