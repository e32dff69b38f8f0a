// The three.js binding of dend-client (`dend-client/three`): a session's
// pose followed into a BufferGeometry in place, and a DragControls-like
// helper that turns pointer motion on a handle into `drag` messages.
// three.js is a peer dependency: this module imports it as `three`.

import { BufferAttribute, BufferGeometry, EventDispatcher, Plane, Raycaster, Vector2, Vector3 } from 'three';

/** A BufferGeometry of a mesh: `positions` (flat or `[[x,y,z]…]`),
 * `triangles` (flat or `[[a,b,c]…]`), with vertex normals. */
export function geometryFromMesh(positions, triangles) {
  const flat = (a) => (a.length && typeof a[0] === 'object' ? a.flat() : Array.from(a));
  const p = new Float32Array(flat(positions));
  const t = flat(triangles);
  const g = new BufferGeometry();
  g.setAttribute('position', new BufferAttribute(p, 3));
  g.setIndex(new BufferAttribute(p.length / 3 > 65535 ? new Uint32Array(t) : new Uint16Array(t), 1));
  g.computeVertexNormals();
  g.computeBoundingSphere();
  return g;
}

/** Follows a {@link SessionSocket} into `geometry`: each frame's positions
 * are copied into the geometry's `position` attribute in place (no
 * reallocation), and with `normals` (true) its vertex normals are
 * recomputed into the existing `normal` attribute. `coarse` flags a
 * coarse preview frame (level 1); the geometry's `userData.dendLevel`
 * holds the level, and it dispatches a `dendframe` event `{frame, coarse}`
 * after every update. A frame whose vertex count is not the geometry's is
 * not applied (`mismatches` counts them). */
export class SessionGeometry extends EventDispatcher {
  constructor(socket, geometry, { normals = true } = {}) {
    super();
    this.socket = socket;
    this.geometry = geometry;
    this.normals = normals;
    this.coarse = false;
    this.frame = null;
    this.updates = 0;
    this.mismatches = 0;
    this.off = socket.on('frame', (f) => this.apply(f));
    if (socket.latest) this.apply(socket.latest);
  }

  /** Copies `frame`'s positions into the geometry. */
  apply(frame) {
    const pos = this.geometry.getAttribute('position');
    if (!pos || !frame.positions || pos.array.length !== frame.positions.length) {
      this.mismatches++;
      return false;
    }
    pos.array.set(frame.positions);
    pos.needsUpdate = true;
    if (this.normals) {
      // reuses the normal attribute when there is one
      this.geometry.computeVertexNormals();
    }
    this.geometry.computeBoundingSphere();
    this.frame = frame;
    this.coarse = frame.level === 1;
    this.geometry.userData.dendLevel = frame.level;
    this.updates++;
    this.dispatchEvent({ type: 'dendframe', frame, coarse: this.coarse });
    return true;
  }

  /** Stops following the socket. */
  dispose() {
    this.off();
  }
}

/** Which handle a vertex belongs to: from a constraint set's `handles`
 * given as index lists (`[{name, vertices: [i…]}…]`), an array of
 * vertex → handle index (-1 for none). */
export function handleIndexOf(vertexCount, handles) {
  const of = new Int32Array(vertexCount).fill(-1);
  handles.forEach((h, k) => {
    if (!Array.isArray(h.vertices)) throw new TypeError(`handle ${k}: vertices must be an index list here`);
    for (const v of h.vertices) of[v] = k;
  });
  return of;
}

/** Drags a session's handles with the pointer, like three's DragControls:
 * a press on a vertex of a handle (the picked triangle's nearest vertex)
 * grabs it, motion moves it in the plane facing the camera through the
 * picked point, and each move sends the `drag` of its translation (in the
 * mesh object's own units) over the socket; release lets go. Options:
 * `handleOf` (vertex → handle index or name, -1/null/undefined for none: an
 * array or a function). Events: `dragstart` `{handle, point}`, `drag`
 * `{handle, translate, seq}`, `dragend` `{handle}`, `hoveron`/`hoveroff`. */
export class HandleDragControls extends EventDispatcher {
  constructor(socket, object, camera, domElement, { handleOf } = {}) {
    super();
    this.socket = socket;
    this.object = object;
    this.camera = camera;
    this.domElement = domElement;
    this.handleOf = typeof handleOf === 'function' ? handleOf : (v) => (handleOf ? handleOf[v] : undefined);
    this.enabled = true;
    this.active = null;
    this.hovered = null;
    this.raycaster = new Raycaster();
    this.plane = new Plane();
    this.last = new Vector3();
    this.pointer = new Vector2();
    this.down = (e) => this.onDown(e);
    this.move = (e) => this.onMove(e);
    this.up = (e) => this.onUp(e);
    domElement.addEventListener('pointerdown', this.down);
    domElement.addEventListener('pointermove', this.move);
    domElement.addEventListener('pointerup', this.up);
    domElement.addEventListener('pointercancel', this.up);
    domElement.style.touchAction = 'none';
  }

  ray(e) {
    const r = this.domElement.getBoundingClientRect();
    this.pointer.set(((e.clientX - r.left) / r.width) * 2 - 1, -((e.clientY - r.top) / r.height) * 2 + 1);
    this.raycaster.setFromCamera(this.pointer, this.camera);
    return this.raycaster;
  }

  /** The handle under the pointer: `{handle, vertex, point}` or null. */
  pick(e) {
    const hit = this.ray(e).intersectObject(this.object, false)[0];
    if (!hit || !hit.face) return null;
    const pos = this.object.geometry.getAttribute('position');
    const local = this.object.worldToLocal(hit.point.clone());
    let best = -1;
    let bestD = Infinity;
    for (const v of [hit.face.a, hit.face.b, hit.face.c]) {
      const d = local.distanceToSquared(new Vector3().fromBufferAttribute(pos, v));
      if (d < bestD) { bestD = d; best = v; }
    }
    const handle = this.handleOf(best);
    if (handle === undefined || handle === null || handle === -1) return null;
    return { handle, vertex: best, point: hit.point.clone() };
  }

  onDown(e) {
    if (!this.enabled || e.button !== 0) return;
    const p = this.pick(e);
    if (!p) return;
    e.preventDefault();
    e.stopPropagation();
    this.domElement.setPointerCapture?.(e.pointerId);
    const normal = this.camera.getWorldDirection(new Vector3()).negate();
    this.plane.setFromNormalAndCoplanarPoint(normal, p.point);
    this.last.copy(this.object.worldToLocal(p.point.clone()));
    this.active = p.handle;
    this.socket.grab(p.handle);
    this.dispatchEvent({ type: 'dragstart', handle: p.handle, point: p.point });
  }

  onMove(e) {
    if (!this.enabled) return;
    if (this.active === null) {
      const p = this.pick(e);
      const h = p ? p.handle : null;
      if (h !== this.hovered) {
        if (this.hovered !== null) this.dispatchEvent({ type: 'hoveroff', handle: this.hovered });
        if (h !== null) this.dispatchEvent({ type: 'hoveron', handle: h });
        this.hovered = h;
      }
      return;
    }
    const at = this.ray(e).ray.intersectPlane(this.plane, new Vector3());
    if (!at) return;
    const local = this.object.worldToLocal(at);
    const d = local.clone().sub(this.last);
    if (d.lengthSq() === 0) return;
    this.last.copy(local);
    const translate = [d.x, d.y, d.z];
    const seq = this.socket.drag(this.active, { translate });
    this.dispatchEvent({ type: 'drag', handle: this.active, translate, seq });
  }

  onUp(e) {
    if (this.active === null) return;
    this.domElement.releasePointerCapture?.(e.pointerId);
    const handle = this.active;
    this.active = null;
    this.socket.release(handle);
    this.dispatchEvent({ type: 'dragend', handle });
  }

  /** Removes the listeners. */
  dispose() {
    this.domElement.removeEventListener('pointerdown', this.down);
    this.domElement.removeEventListener('pointermove', this.move);
    this.domElement.removeEventListener('pointerup', this.up);
    this.domElement.removeEventListener('pointercancel', this.up);
  }
}
