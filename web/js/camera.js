// Orbit camera (yaw/pitch/distance around a target, +y up) and the few
// column-major 4×4 matrix helpers the renderer needs.

export function sub(a, b) { return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]; }
export function add(a, b) { return [a[0] + b[0], a[1] + b[1], a[2] + b[2]]; }
export function scale(a, s) { return [a[0] * s, a[1] * s, a[2] * s]; }
export function dot(a, b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
export function cross(a, b) {
  return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
}
export function normalize(a) {
  const l = Math.hypot(a[0], a[1], a[2]) || 1;
  return [a[0] / l, a[1] / l, a[2] / l];
}

/** Column-major product a·b of two 4×4 matrices. */
export function mul4(a, b) {
  const o = new Float32Array(16);
  for (let c = 0; c < 4; c++) {
    for (let r = 0; r < 4; r++) {
      let s = 0;
      for (let k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k];
      o[c * 4 + r] = s;
    }
  }
  return o;
}

export function perspective(fovy, aspect, near, far) {
  const f = 1 / Math.tan(fovy / 2);
  const o = new Float32Array(16);
  o[0] = f / aspect;
  o[5] = f;
  o[10] = (far + near) / (near - far);
  o[11] = -1;
  o[14] = (2 * far * near) / (near - far);
  return o;
}

export function lookAt(eye, target, up) {
  const z = normalize(sub(eye, target));
  const x = normalize(cross(up, z));
  const y = cross(z, x);
  return new Float32Array([
    x[0], y[0], z[0], 0,
    x[1], y[1], z[1], 0,
    x[2], y[2], z[2], 0,
    -dot(x, eye), -dot(y, eye), -dot(z, eye), 1,
  ]);
}

export class OrbitCamera {
  constructor() {
    this.target = [0, 0, 0];
    this.yaw = 1.1;
    this.pitch = 0.35;
    this.distance = 5;
    this.radius = 1;
    this.fovy = (40 * Math.PI) / 180;
  }

  /** Frames a bounding box [min, max]. */
  /** Frames the bounding sphere of `bbox` in a view of width/height
   * `aspect` (on a portrait screen the horizontal field of view is the
   * narrower one). */
  fit(bbox, aspect = 1) {
    const [lo, hi] = bbox;
    this.target = scale(add(lo, hi), 0.5);
    this.radius = Math.max(1e-9, 0.5 * Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]));
    const half = Math.min(this.fovy / 2, Math.atan(Math.tan(this.fovy / 2) * Math.max(aspect, 1e-3)));
    this.distance = (this.radius / Math.sin(half)) * 1.05;
  }

  eye() {
    const cp = Math.cos(this.pitch);
    const d = [cp * Math.sin(this.yaw), Math.sin(this.pitch), cp * Math.cos(this.yaw)];
    return add(this.target, scale(d, this.distance));
  }

  /** Unit vectors of the screen axes in world space: right, up, and the
   * direction from the eye into the screen. */
  basis() {
    const fwd = normalize(sub(this.target, this.eye()));
    const right = normalize(cross(fwd, [0, 1, 0]));
    const up = cross(right, fwd);
    return { right, up, fwd };
  }

  view() { return lookAt(this.eye(), this.target, [0, 1, 0]); }

  proj(aspect) {
    const near = Math.max(this.distance - 2 * this.radius, this.distance * 0.01);
    return perspective(this.fovy, aspect, near, this.distance + 2 * this.radius);
  }

  orbit(dx, dy) {
    this.yaw -= dx * 0.008;
    this.pitch = Math.max(-1.55, Math.min(1.55, this.pitch + dy * 0.008));
  }

  /** World units per screen pixel at the target's depth. */
  unitsPerPixel(heightPx) {
    return (2 * this.distance * Math.tan(this.fovy / 2)) / heightPx;
  }

  pan(dx, dy, heightPx) {
    const { right, up } = this.basis();
    const u = this.unitsPerPixel(heightPx);
    this.target = add(this.target, add(scale(right, -dx * u), scale(up, dy * u)));
  }

  zoom(factor) {
    this.distance = Math.max(this.radius * 0.05, Math.min(this.radius * 50, this.distance * factor));
  }
}
