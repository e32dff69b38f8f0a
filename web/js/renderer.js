// A small WebGL2 renderer: one triangle mesh drawn per corner (each
// triangle its own three vertices, so a colour can belong to a face: the
// painted regions have crisp borders, and a face whose vertices disagree
// is hatched), smooth normals recomputed by the caller every frame, a
// headlight with two-sided shading, and an optional wireframe overlay
// (gl.LINES over the shared vertices). A glTF's base-colour texture, when
// set (`setTexture`), is drawn under the colours: per corner its UV and a
// tint, the share of the flat colour mixed over the texture (0 on a free
// face, so the asset looks like itself; a painted region stays visible).

import { mul4 } from './camera.js';

const VS = `#version 300 es
layout(location=0) in vec3 aPos;
layout(location=1) in vec3 aNormal;
layout(location=2) in vec3 aColor;
layout(location=3) in float aHatch;
layout(location=4) in vec2 aUV;
layout(location=5) in float aTint;
uniform mat4 uView, uProj;
out vec3 vN; out vec3 vC; out vec3 vP; flat out float vHatch;
out vec2 vUV; flat out float vTint;
void main() {
  vec4 p = uView * vec4(aPos, 1.0);
  vP = p.xyz;
  vN = mat3(uView) * aNormal;
  vC = aColor;
  vHatch = aHatch;
  vUV = aUV;
  vTint = aTint;
  gl_Position = uProj * p;
}`;

const FS = `#version 300 es
precision highp float;
in vec3 vN; in vec3 vC; in vec3 vP; flat in float vHatch;
in vec2 vUV; flat in float vTint;
uniform int uLines, uTextured;
uniform sampler2D uTex;
uniform vec4 uFactor;
out vec4 o;
void main() {
  if (uLines == 1) { o = vec4(0.08, 0.08, 0.1, 1.0); return; }
  // mixed faces: dark diagonal stripes over their colour, 3 px of 6
  if (vHatch > 0.5 && mod(gl_FragCoord.x + gl_FragCoord.y, 6.0) < 3.0) { o = vec4(0.12, 0.1, 0.1, 1.0); return; }
  vec3 n = normalize(vN);
  vec3 v = normalize(-vP);
  if (dot(n, v) < 0.0) n = -n;
  vec3 l = normalize(v + vec3(0.3, 0.5, 0.0));
  float d = max(dot(n, l), 0.0);
  float s = pow(max(dot(n, normalize(l + v)), 0.0), 40.0);
  vec3 base = vC;
  // the texture is sRGB: sampled linear, like the colours
  if (uTextured == 1) base = mix(texture(uTex, vUV).rgb * uFactor.rgb, vC, vTint);
  vec3 c = base * (0.25 + 0.75 * d) + vec3(0.25) * s;
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
      textured: gl.getUniformLocation(prog, 'uTextured'),
      tex: gl.getUniformLocation(prog, 'uTex'),
      factor: gl.getUniformLocation(prog, 'uFactor'),
    };
    // triangles: per-corner position, normal, colour (vec3), hatch flag,
    // texture UV and tint
    this.vao = gl.createVertexArray();
    gl.bindVertexArray(this.vao);
    this.buf = [3, 3, 3, 1, 2, 1].map((size, loc) => {
      const b = gl.createBuffer();
      gl.bindBuffer(gl.ARRAY_BUFFER, b);
      gl.enableVertexAttribArray(loc);
      gl.vertexAttribPointer(loc, size, gl.FLOAT, false, 0, 0);
      return b;
    });
    // wireframe: the shared vertices, indexed by the edge list
    this.lineVao = gl.createVertexArray();
    gl.bindVertexArray(this.lineVao);
    this.linePos = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, this.linePos);
    gl.enableVertexAttribArray(0);
    gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
    for (const loc of [1, 2, 3, 4, 5]) gl.disableVertexAttribArray(loc);
    this.lines = gl.createBuffer();
    this.counts = { tri: 0, lines: 0 };
    this.triangles = new Uint32Array(0);
    this.wireframe = false;
    this.texture = null; // {tex: WebGLTexture, factor, textured: per triangle}
    this.faceTint = null; // per triangle: the flat colour's share over the texture
  }

  /** New topology: the triangles (corners to expand) and the edge list. */
  setTopology(triangles, edges) {
    const gl = this.gl;
    this.triangles = triangles;
    const c = triangles.length;
    this.corner = {
      pos: new Float32Array(3 * c), nrm: new Float32Array(3 * c), col: new Float32Array(3 * c), hatch: new Float32Array(c), tint: new Float32Array(c),
    };
    this.upload(this.buf[4], new Float32Array(2 * c));
    this.clearTexture();
    gl.bindVertexArray(this.lineVao);
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, this.lines);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, edges, gl.STATIC_DRAW);
    gl.bindVertexArray(null);
    this.counts = { tri: c, lines: edges.length };
  }

  /** Copies per-vertex vec3 `v` to the corners of every triangle. */
  expand(v, out) {
    const t = this.triangles;
    for (let k = 0; k < t.length; k++) {
      const i = 3 * t[k];
      out[3 * k] = v[i];
      out[3 * k + 1] = v[i + 1];
      out[3 * k + 2] = v[i + 2];
    }
    return out;
  }

  upload(slot, data) {
    const gl = this.gl;
    gl.bindBuffer(gl.ARRAY_BUFFER, slot);
    gl.bufferData(gl.ARRAY_BUFFER, data, gl.DYNAMIC_DRAW);
  }

  setPositions(p, n) {
    this.upload(this.buf[0], this.expand(p, this.corner.pos));
    this.upload(this.buf[1], this.expand(n, this.corner.nrm));
    this.upload(this.linePos, p);
  }

  /** Per-vertex colours (a colour map), blended across each face. */
  setColors(c) {
    this.upload(this.buf[2], this.expand(c, this.corner.col));
    this.corner.hatch.fill(0);
    this.upload(this.buf[3], this.corner.hatch);
    this.faceHatch = null;
    // a colour map is shown as is, without the texture
    this.faceTint = null;
    this.uploadTint();
  }

  /** Per-face colours (`rgb` vec3 per triangle) and hatch flags (1 per
   * triangle to stripe): every face one flat colour; over a texture, each
   * face's `tint` (0: the texture alone, 1: the flat colour alone). */
  setFaceColors(rgb, hatch, tint = null) {
    const { col, hatch: h } = this.corner;
    for (let f = 0; f < hatch.length; f++) {
      for (let k = 0; k < 3; k++) {
        const j = 3 * f + k;
        col[3 * j] = rgb[3 * f];
        col[3 * j + 1] = rgb[3 * f + 1];
        col[3 * j + 2] = rgb[3 * f + 2];
        h[j] = hatch[f];
      }
    }
    this.upload(this.buf[2], col);
    this.upload(this.buf[3], h);
    this.faceHatch = hatch;
    this.faceTint = tint;
    this.uploadTint();
  }

  /** Per-corner tints: the face's, on a textured face; else 1 (flat). */
  uploadTint() {
    const t = this.corner.tint;
    const tex = this.texture;
    for (let f = 0; f < t.length / 3; f++) {
      const v = tex && this.faceTint && tex.textured[f] ? this.faceTint[f] : 1;
      t[3 * f] = t[3 * f + 1] = t[3 * f + 2] = v;
    }
    this.upload(this.buf[5], t);
  }

  /** A base-colour texture over the triangles: `image` (ImageBitmap, sRGB),
   * the glTF `sampler`, the material's `factor` (RGBA), `uv` (vec2 per
   * corner) and `textured` (1 per triangle that has UVs). */
  setTexture(image, sampler, factor, uv, textured) {
    const gl = this.gl;
    this.clearTexture();
    const tex = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, tex);
    gl.pixelStorei(gl.UNPACK_FLIP_Y_WEBGL, false);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.SRGB8_ALPHA8, gl.RGBA, gl.UNSIGNED_BYTE, image);
    const min = sampler.minFilter || gl.LINEAR_MIPMAP_LINEAR;
    if (min !== gl.NEAREST && min !== gl.LINEAR) gl.generateMipmap(gl.TEXTURE_2D);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, min);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, sampler.magFilter || gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, sampler.wrapS || gl.REPEAT);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, sampler.wrapT || gl.REPEAT);
    this.texture = { tex, factor, textured };
    this.upload(this.buf[4], uv);
    this.uploadTint();
  }

  /** Back to flat colours only. */
  clearTexture() {
    if (this.texture) this.gl.deleteTexture(this.texture.tex);
    this.texture = null;
    if (this.corner) this.uploadTint();
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
    gl.uniform1i(this.u.textured, this.texture ? 1 : 0);
    if (this.texture) {
      gl.activeTexture(gl.TEXTURE0);
      gl.bindTexture(gl.TEXTURE_2D, this.texture.tex);
      gl.uniform1i(this.u.tex, 0);
      gl.uniform4fv(this.u.factor, this.texture.factor);
    }
    gl.drawArrays(gl.TRIANGLES, 0, this.counts.tri);
    gl.disable(gl.POLYGON_OFFSET_FILL);
    if (this.wireframe) {
      gl.uniform1i(this.u.lines, 1);
      gl.bindVertexArray(this.lineVao);
      gl.vertexAttrib3f(1, 0, 0, 1);
      gl.vertexAttrib3f(2, 0, 0, 0);
      gl.vertexAttrib1f(3, 0);
      gl.vertexAttrib2f(4, 0, 0);
      gl.vertexAttrib1f(5, 1);
      gl.drawElements(gl.LINES, this.counts.lines, gl.UNSIGNED_INT, 0);
    }
    gl.bindVertexArray(null);
  }

  /** Model-view-projection of the last draw's camera (for picking). */
  static mvp(camera, aspect) {
    return mul4(camera.proj(aspect), camera.view());
  }
}
