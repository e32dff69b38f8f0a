// The three.js binding in Node (three's math and geometry need no DOM): a
// socket's frames copied into a BufferGeometry in place, coarse frames
// flagged, and pointer motion on a handle turned into drags in the mesh's
// own units.

import { test } from 'node:test';
import assert from 'node:assert/strict';

let THREE = null;
let binding = null;
try {
  THREE = await import('three');
  binding = await import('../src/three/index.js');
} catch (e) {
  // three is a dev dependency (npm ci); CI installs it
  if (process.env.CI === 'true') throw e;
}
const needThree = THREE ? {} : { skip: 'three is not installed here (npm ci in clients/js)' };

/** A socket stand-in: frames pushed by the test, messages recorded. */
function fakeSocket() {
  const fns = [];
  return {
    latest: null,
    sent: [],
    seq: 0,
    on(type, fn) { if (type === 'frame') fns.push(fn); return () => fns.splice(fns.indexOf(fn), 1); },
    push(frame) { this.latest = frame; fns.forEach((f) => f(frame)); },
    drag(handle, delta) { this.sent.push({ type: 'drag', handle, ...delta }); return ++this.seq; },
    grab(handle) { this.sent.push({ type: 'grab', handle }); return true; },
    release(handle) { this.sent.push({ type: 'release', handle }); return true; },
  };
}

const square = { positions: [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], triangles: [[0, 1, 2], [0, 2, 3]] };

test('frames are copied into the geometry in place, normals too; coarse frames flagged', needThree, () => {
  const g = binding.geometryFromMesh(square.positions, square.triangles);
  const pos = g.getAttribute('position');
  const nor = g.getAttribute('normal');
  const array = pos.array;
  const s = fakeSocket();
  const follow = new binding.SessionGeometry(s, g);
  const seen = [];
  follow.addEventListener('dendframe', (e) => seen.push(e.coarse));
  // the square folded about its diagonal 0-2: vertex 3 lifted to z = 1
  const folded = new Float32Array([0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 1]);
  s.push({ positions: folded, level: 1 });
  assert.equal(g.getAttribute('position').array, array, 'the same array, not a new one');
  assert.equal(g.getAttribute('normal'), nor, 'the same normal attribute');
  assert.deepEqual(Array.from(array), Array.from(folded));
  const n3 = new THREE.Vector3().fromBufferAttribute(nor, 3);
  const want = new THREE.Vector3(0, 1, 1).cross(new THREE.Vector3(1, 1, 0)).normalize().negate();
  assert.ok(n3.distanceTo(want) < 1e-6 || n3.distanceTo(want.negate()) < 1e-6, `vertex 3's normal is the folded face's (${n3.toArray()})`);
  assert.ok(follow.coarse);
  assert.equal(g.userData.dendLevel, 1);
  s.push({ positions: new Float32Array(12), level: 0 });
  assert.ok(!follow.coarse);
  assert.deepEqual(seen, [true, false]);
  assert.ok(pos.version >= 2, 'marked for upload');
  s.push({ positions: new Float32Array(9), level: 0 });
  assert.equal(follow.mismatches, 1, 'a frame of another vertex count is not applied');
  assert.equal(follow.updates, 2);
  follow.dispose();
  s.push({ positions: folded, level: 0 });
  assert.equal(follow.updates, 2);
});

test('a press on a handle grabs it, motion sends drags in the mesh units, release lets go', needThree, () => {
  const g = binding.geometryFromMesh(square.positions, square.triangles);
  const object = new THREE.Mesh(g, new THREE.MeshBasicMaterial());
  // the mesh placed at x = 10 and scaled by 2: drags are in its own units
  object.position.set(10, 0, 0);
  object.scale.setScalar(2);
  object.updateMatrixWorld(true);
  const camera = new THREE.PerspectiveCamera(60, 1, 0.1, 100);
  camera.position.set(11, 1, 5);
  camera.lookAt(11, 1, 0);
  camera.updateMatrixWorld(true);
  const listeners = {};
  const dom = {
    style: {},
    addEventListener: (t, f) => { listeners[t] = f; },
    removeEventListener: (t) => { delete listeners[t]; },
    getBoundingClientRect: () => ({ left: 0, top: 0, width: 400, height: 400 }),
  };
  const s = fakeSocket();
  const handleOf = binding.handleIndexOf(4, [{ vertices: [2] }]);
  const drag = new binding.HandleDragControls(s, object, camera, dom, { handleOf });
  const screen = (x, y) => {
    const p = new THREE.Vector3(x, y, 0).applyMatrix4(object.matrixWorld).project(camera);
    return { clientX: ((p.x + 1) / 2) * 400, clientY: ((1 - p.y) / 2) * 400 };
  };
  const ev = (xy) => ({ ...xy, button: 0, pointerId: 1, preventDefault() {}, stopPropagation() {} });
  // a press far from the handle's vertex does nothing
  listeners.pointerdown(ev(screen(0.1, 0.1)));
  assert.deepEqual(s.sent, []);
  listeners.pointerdown(ev(screen(0.95, 0.9)));
  assert.deepEqual(s.sent, [{ type: 'grab', handle: 0 }]);
  listeners.pointermove(ev(screen(0.95, 1.4)));
  listeners.pointermove(ev(screen(0.75, 1.4)));
  listeners.pointerup(ev(screen(0.75, 1.4)));
  const drags = s.sent.filter((m) => m.type === 'drag');
  assert.equal(drags.length, 2);
  const total = drags.reduce((a, d) => a.map((x, k) => x + d.translate[k]), [0, 0, 0]);
  assert.ok(Math.abs(total[0] + 0.2) < 1e-9 && Math.abs(total[1] - 0.5) < 1e-9 && Math.abs(total[2]) < 1e-9, `moved (-0.2, 0.5, 0) in mesh units: ${total}`);
  assert.deepEqual(s.sent.at(-1), { type: 'release', handle: 0 });
  drag.dispose();
  assert.deepEqual(Object.keys(listeners), []);
});
