// A small WebGL2 renderer: one indexed triangle mesh with per-vertex
// colours, normals recomputed by the caller every frame, a headlight with
// two-sided shading, and an optional wireframe overlay (gl.LINES).

import { mul4 } from './camera.js';

const VS = `#version 300 es
layout(location=0) in vec3 aPos;
layout(location=1) in vec3 aNormal;
layout(location=2) in vec3 aColor;
uniform mat4 uView, uProj;
out vec3 vN; out vec3 vC; out vec3 vP;
void main() {
  vec4 p = uView * vec4(aPos, 1.0);
  vP = p.xyz;
  vN = mat3(uView) * aNormal;
  vC = aColor;
  gl_Position = uProj * p;
}`;

const FS = `#version 300 es
precision highp float;
in vec3 vN; in vec3 vC; in vec3 vP;
uniform int uLines;
out vec4 o;
void main() {
  if (uLines == 1) { o = vec4(0.08, 0.08, 0.1, 1.0); return; }
  vec3 n = normalize(vN);
  vec3 v = normalize(-vP);
  if (dot(n, v) < 0.0) n = -n;
  vec3 l = normalize(v + vec3(0.3, 0.5, 0.0));
  float d = max(dot(n, l), 0.0);
  float s = pow(max(dot(n, normalize(l + v)), 0.0), 40.0);
  vec3 c = vC * (0.25 + 0.75 * d) + vec3(0.25) * s;
  o = vec4(pow(c, vec3(1.0 / 2.2)), 1.0);
}`;

function compile(gl, type, src) {
  const s = gl.createShader(type);
  gl.shaderSource(s, src);
  gl.compileShader(s);
  if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
  return s;
}

export class Renderer {
  constructor(canvas) {
    this.canvas = canvas;
    const gl = canvas.getContext('webgl2', { antialias: true, preserveDrawingBuffer: true });
    if (!gl) throw new Error('WebGL2 is not available in this browser');
    this.gl = gl;
    const prog = gl.createProgram();
    gl.attachShader(prog, compile(gl, gl.VERTEX_SHADER, VS));
    gl.attachShader(prog, compile(gl, gl.FRAGMENT_SHADER, FS));
    gl.linkProgram(prog);
    if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(prog));
    this.prog = prog;
    this.u = {
      view: gl.getUniformLocation(prog, 'uView'),
      proj: gl.getUniformLocation(prog, 'uProj'),
      lines: gl.getUniformLocation(prog, 'uLines'),
    };
    this.vao = gl.createVertexArray();
    gl.bindVertexArray(this.vao);
    this.buf = [0, 1, 2].map((loc) => {
      const b = gl.createBuffer();
      gl.bindBuffer(gl.ARRAY_BUFFER, b);
      gl.enableVertexAttribArray(loc);
      gl.vertexAttribPointer(loc, 3, gl.FLOAT, false, 0, 0);
      return b;
    });
    this.tri = gl.createBuffer();
    this.lines = gl.createBuffer();
    this.counts = { tri: 0, lines: 0 };
    this.wireframe = false;
  }

  /** New topology: triangle and edge index buffers. */
  setTopology(triangles, edges) {
    const gl = this.gl;
    gl.bindVertexArray(this.vao);
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, this.tri);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, triangles, gl.STATIC_DRAW);
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, this.lines);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, edges, gl.STATIC_DRAW);
    this.counts = { tri: triangles.length, lines: edges.length };
  }

  setPositions(p, n) {
    const gl = this.gl;
    gl.bindBuffer(gl.ARRAY_BUFFER, this.buf[0]);
    gl.bufferData(gl.ARRAY_BUFFER, p, gl.DYNAMIC_DRAW);
    gl.bindBuffer(gl.ARRAY_BUFFER, this.buf[1]);
    gl.bufferData(gl.ARRAY_BUFFER, n, gl.DYNAMIC_DRAW);
  }

  setColors(c) {
    const gl = this.gl;
    gl.bindBuffer(gl.ARRAY_BUFFER, this.buf[2]);
    gl.bufferData(gl.ARRAY_BUFFER, c, gl.DYNAMIC_DRAW);
  }

  /** Resizes the drawing buffer to the canvas' CSS size; returns aspect. */
  resize() {
    const c = this.canvas;
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(c.clientWidth * dpr));
    const h = Math.max(1, Math.round(c.clientHeight * dpr));
    if (c.width !== w || c.height !== h) {
      c.width = w;
      c.height = h;
    }
    return w / h;
  }

  draw(camera) {
    const gl = this.gl;
    const aspect = this.resize();
    gl.viewport(0, 0, this.canvas.width, this.canvas.height);
    gl.clearColor(0.93, 0.94, 0.96, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    if (!this.counts.tri) return;
    gl.enable(gl.DEPTH_TEST);
    gl.useProgram(this.prog);
    gl.uniformMatrix4fv(this.u.view, false, camera.view());
    gl.uniformMatrix4fv(this.u.proj, false, camera.proj(aspect));
    gl.bindVertexArray(this.vao);
    gl.enable(gl.POLYGON_OFFSET_FILL);
    gl.polygonOffset(1, 1);
    gl.uniform1i(this.u.lines, 0);
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, this.tri);
    gl.drawElements(gl.TRIANGLES, this.counts.tri, gl.UNSIGNED_INT, 0);
    gl.disable(gl.POLYGON_OFFSET_FILL);
    if (this.wireframe) {
      gl.uniform1i(this.u.lines, 1);
      gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, this.lines);
      gl.drawElements(gl.LINES, this.counts.lines, gl.UNSIGNED_INT, 0);
    }
  }

  /** Model-view-projection of the last draw's camera (for picking). */
  static mvp(camera, aspect) {
    return mul4(camera.proj(aspect), camera.view());
  }
}
