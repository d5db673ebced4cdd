// The calibrated water in WebGL 2: the exported GLSL ES 3.00 shaders run on the calibration's
// own inputs (window.WATER_VIEWER_DATA, written by data.js beside this file). No framework, no
// build step; written by study/export/viewer (a project template, copied into every viewer/).
//
// Float data throughout: textures are RGB32F / RG32F / R32F (linear filtering of float textures
// needs OES_texture_float_linear), the shader draws into an RGBA32F framebuffer (needs
// EXT_color_buffer_float), which is shown on the canvas through an sRGB encoding (clipped to
// [0, 1]) and read back as floats by waterViewer.renderFloat.
(function () {
  "use strict";

  const errors = [];
  const api = { ready: false, errors: errors };
  window.waterViewer = api;

  function fail(msg) {
    errors.push(String(msg));
    const box = document.getElementById("errors");
    if (box) {
      box.hidden = false;
      const p = document.createElement("pre");
      p.textContent = String(msg);
      box.appendChild(p);
    }
  }
  window.addEventListener("error", (e) => fail("script error: " + e.message));

  // ---- data ------------------------------------------------------------------------------
  function floats(b64) {
    const bin = atob(b64);
    const bytes = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
    return new Float32Array(bytes.buffer);
  }
  function floatsToB64(arr) {
    const bytes = new Uint8Array(arr.buffer, arr.byteOffset, arr.byteLength);
    let s = "";
    const chunk = 0x8000;
    for (let i = 0; i < bytes.length; i += chunk) {
      s += String.fromCharCode.apply(null, bytes.subarray(i, i + chunk));
    }
    return btoa(s);
  }

  // ---- small matrix helpers (column-major Float32Array(16), as WebGL takes them) ---------
  function sub(a, b) { return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]; }
  function cross(a, b) {
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  }
  function norm(a) { const l = Math.hypot(a[0], a[1], a[2]); return [a[0] / l, a[1] / l, a[2] / l]; }
  function dot(a, b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

  // gluPerspective(fov_y) * gluLookAt(eye, target, up), as shaders_port.inputs.perspective_view_proj
  function viewProj(eye, target, up, fovY, aspect, near, far) {
    const f = norm(sub(target, eye));
    const s = norm(cross(f, up));
    const u = cross(s, f);
    const rows = [s, u, [-f[0], -f[1], -f[2]]];
    const t = rows.map((r) => -dot(r, eye));
    const g = 1 / Math.tan((fovY * Math.PI) / 360);
    const A = (far + near) / (near - far), B = (2 * far * near) / (near - far);
    // P @ V, row-major, then stored column-major
    const pv = [
      [(g / aspect) * s[0], (g / aspect) * s[1], (g / aspect) * s[2], (g / aspect) * t[0]],
      [g * u[0], g * u[1], g * u[2], g * t[1]],
      [A * rows[2][0], A * rows[2][1], A * rows[2][2], A * t[2] + B],
      [f[0], f[1], f[2], -t[2]],
    ];
    const m = new Float32Array(16);
    for (let r = 0; r < 4; r++) for (let c = 0; c < 4; c++) m[c * 4 + r] = pv[r][c];
    const nm = new Float32Array(9); // gl_NormalMatrix: the view's rotation, column-major
    for (let r = 0; r < 3; r++) for (let c = 0; c < 3; c++) nm[c * 3 + r] = rows[r][c];
    return { viewProj: m, normal: nm };
  }
  function invert4(m) {
    const inv = new Float64Array(16);
    const a = Array.from(m);
    inv[0] = a[5] * a[10] * a[15] - a[5] * a[11] * a[14] - a[9] * a[6] * a[15] + a[9] * a[7] * a[14] + a[13] * a[6] * a[11] - a[13] * a[7] * a[10];
    inv[4] = -a[4] * a[10] * a[15] + a[4] * a[11] * a[14] + a[8] * a[6] * a[15] - a[8] * a[7] * a[14] - a[12] * a[6] * a[11] + a[12] * a[7] * a[10];
    inv[8] = a[4] * a[9] * a[15] - a[4] * a[11] * a[13] - a[8] * a[5] * a[15] + a[8] * a[7] * a[13] + a[12] * a[5] * a[11] - a[12] * a[7] * a[9];
    inv[12] = -a[4] * a[9] * a[14] + a[4] * a[10] * a[13] + a[8] * a[5] * a[14] - a[8] * a[6] * a[13] - a[12] * a[5] * a[10] + a[12] * a[6] * a[9];
    inv[1] = -a[1] * a[10] * a[15] + a[1] * a[11] * a[14] + a[9] * a[2] * a[15] - a[9] * a[3] * a[14] - a[13] * a[2] * a[11] + a[13] * a[3] * a[10];
    inv[5] = a[0] * a[10] * a[15] - a[0] * a[11] * a[14] - a[8] * a[2] * a[15] + a[8] * a[3] * a[14] + a[12] * a[2] * a[11] - a[12] * a[3] * a[10];
    inv[9] = -a[0] * a[9] * a[15] + a[0] * a[11] * a[13] + a[8] * a[1] * a[15] - a[8] * a[3] * a[13] - a[12] * a[1] * a[11] + a[12] * a[3] * a[9];
    inv[13] = a[0] * a[9] * a[14] - a[0] * a[10] * a[13] - a[8] * a[1] * a[14] + a[8] * a[2] * a[13] + a[12] * a[1] * a[10] - a[12] * a[2] * a[9];
    inv[2] = a[1] * a[6] * a[15] - a[1] * a[7] * a[14] - a[5] * a[2] * a[15] + a[5] * a[3] * a[14] + a[13] * a[2] * a[7] - a[13] * a[3] * a[6];
    inv[6] = -a[0] * a[6] * a[15] + a[0] * a[7] * a[14] + a[4] * a[2] * a[15] - a[4] * a[3] * a[14] - a[12] * a[2] * a[7] + a[12] * a[3] * a[6];
    inv[10] = a[0] * a[5] * a[15] - a[0] * a[7] * a[13] - a[4] * a[1] * a[15] + a[4] * a[3] * a[13] + a[12] * a[1] * a[7] - a[12] * a[3] * a[5];
    inv[14] = -a[0] * a[5] * a[14] + a[0] * a[6] * a[13] + a[4] * a[1] * a[14] - a[4] * a[2] * a[13] - a[12] * a[1] * a[6] + a[12] * a[2] * a[5];
    inv[3] = -a[1] * a[6] * a[11] + a[1] * a[7] * a[10] + a[5] * a[2] * a[11] - a[5] * a[3] * a[10] - a[9] * a[2] * a[7] + a[9] * a[3] * a[6];
    inv[7] = a[0] * a[6] * a[11] - a[0] * a[7] * a[10] - a[4] * a[2] * a[11] + a[4] * a[3] * a[10] + a[8] * a[2] * a[7] - a[8] * a[3] * a[6];
    inv[11] = -a[0] * a[5] * a[11] + a[0] * a[7] * a[9] + a[4] * a[1] * a[11] - a[4] * a[3] * a[9] - a[8] * a[1] * a[7] + a[8] * a[3] * a[5];
    inv[15] = a[0] * a[5] * a[10] - a[0] * a[6] * a[9] - a[4] * a[1] * a[10] + a[4] * a[2] * a[9] + a[8] * a[1] * a[6] - a[8] * a[2] * a[5];
    const det = a[0] * inv[0] + a[1] * inv[4] + a[2] * inv[8] + a[3] * inv[12];
    return Float32Array.from(inv, (v) => v / det);
  }

  // ---- WebGL ------------------------------------------------------------------------------
  const D = window.WATER_VIEWER_DATA;
  const canvas = document.getElementById("view");
  let gl = null;
  const W = D ? D.width : 1, H = D ? D.height : 1;

  function compile(type, source, what) {
    const sh = gl.createShader(type);
    gl.shaderSource(sh, source);
    gl.compileShader(sh);
    if (!gl.getShaderParameter(sh, gl.COMPILE_STATUS)) {
      throw new Error(`WebGL could not compile ${what}:\n${gl.getShaderInfoLog(sh)}`);
    }
    return sh;
  }
  function link(vs, fs, what) {
    const p = gl.createProgram();
    gl.attachShader(p, compile(gl.VERTEX_SHADER, vs, what + " (vertex shader)"));
    gl.attachShader(p, compile(gl.FRAGMENT_SHADER, fs, what + " (fragment shader)"));
    gl.linkProgram(p);
    if (!gl.getProgramParameter(p, gl.LINK_STATUS)) {
      throw new Error(`WebGL could not link ${what}:\n${gl.getProgramInfoLog(p)}`);
    }
    return p;
  }

  const FORMATS = { 1: ["R32F", "RED"], 2: ["RG32F", "RG"], 3: ["RGB32F", "RGB"], 4: ["RGBA32F", "RGBA"] };
  function texture2d(t, filter, repeat) {
    const tex = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, tex);
    const [ifmt, fmt] = FORMATS[t.channels];
    gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl[ifmt], t.width, t.height, 0, gl[fmt], gl.FLOAT, floats(t.data));
    // "trilinear": the mip levels given (box-filtered halvings, as the GL check's), uploaded as they are
    let w = t.width, h = t.height;
    (t.levels || []).forEach((lv, k) => {
      w = Math.max(1, w >> 1); h = Math.max(1, h >> 1);
      gl.texImage2D(gl.TEXTURE_2D, k + 1, gl[ifmt], w, h, 0, gl[fmt], gl.FLOAT, floats(lv));
    });
    const f = filter === "nearest" ? gl.NEAREST : gl.LINEAR;
    const wrap = repeat ? gl.REPEAT : gl.CLAMP_TO_EDGE;
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, filter === "trilinear" ? gl.LINEAR_MIPMAP_LINEAR : f);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, f);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, wrap);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, wrap);
    return tex;
  }
  function textureCube(t) {
    const tex = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_CUBE_MAP, tex);
    gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
    const all = floats(t.data), n = t.size * t.size * 3;
    for (let i = 0; i < 6; i++) {
      gl.texImage2D(gl.TEXTURE_CUBE_MAP_POSITIVE_X + i, 0, gl.RGB32F, t.size, t.size, 0, gl.RGB,
        gl.FLOAT, all.subarray(i * n, (i + 1) * n));
    }
    for (const p of [gl.TEXTURE_MIN_FILTER, gl.TEXTURE_MAG_FILTER]) gl.texParameteri(gl.TEXTURE_CUBE_MAP, p, gl.LINEAR);
    for (const p of [gl.TEXTURE_WRAP_S, gl.TEXTURE_WRAP_T, gl.TEXTURE_WRAP_R]) {
      gl.texParameteri(gl.TEXTURE_CUBE_MAP, p, gl.CLAMP_TO_EDGE);
    }
    return tex;
  }
  // an RGBA32F colour texture and a stencil (the water's coverage, shared by both targets)
  let stencil = null;
  function floatTarget(w, h) {
    const tex = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, tex);
    gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGBA32F, w, h);
    for (const p of [gl.TEXTURE_MIN_FILTER, gl.TEXTURE_MAG_FILTER]) gl.texParameteri(gl.TEXTURE_2D, p, gl.NEAREST);
    if (!stencil) {
      stencil = gl.createRenderbuffer();
      gl.bindRenderbuffer(gl.RENDERBUFFER, stencil);
      gl.renderbufferStorage(gl.RENDERBUFFER, gl.DEPTH24_STENCIL8, w, h);
    }
    const fbo = gl.createFramebuffer();
    gl.bindFramebuffer(gl.FRAMEBUFFER, fbo);
    gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, tex, 0);
    gl.framebufferRenderbuffer(gl.FRAMEBUFFER, gl.DEPTH_STENCIL_ATTACHMENT, gl.RENDERBUFFER, stencil);
    const status = gl.checkFramebufferStatus(gl.FRAMEBUFFER);
    if (status !== gl.FRAMEBUFFER_COMPLETE) {
      throw new Error("WebGL cannot render into an RGBA32F framebuffer (status 0x" + status.toString(16) + ")");
    }
    return { tex, fbo };
  }

  // the study's sampler names -> (texture unit, key of D.textures)
  const SAMPLERS = {
    refractionTexture: 0, worldYComponent: 1, normalMap: 2, reflectionTexture: 3, fresnelLookup: 4,
    worldYComponentReflection: 5, reflectionBottom: 6, sceneColor: 7, sceneDepth: 8, reflection_sampler: 9,
    boxReflectionTexture: 10, slopeMoments: 11, heightMap: 12,
  };
  // the samplers that read a cube map
  const CUBES = new Set(["reflectionTexture", "boxReflectionTexture"]);
  const MASK_FRAG = "#version 300 es\nprecision highp float;\nout vec4 c;\nvoid main() { c = vec4(1.0); }\n";
  const SHOW_VERT = "#version 300 es\nout vec2 uv;\nvoid main() {\n" +
    "  vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));\n" +
    "  uv = p; gl_Position = vec4(2.0 * p - 1.0, 0.0, 1.0);\n}\n";
  // two images side by side at a wipe position, each over a background where the product of
  // its two masks is 0, shown sRGB-encoded (linear values clipped to [0, 1])
  const SHOW_FRAG = `#version 300 es
precision highp float;
uniform sampler2D left, right, leftBack, rightBack, leftMaskA, leftMaskB, rightMaskA, rightMaskB;
uniform float split;
in vec2 uv;
out vec4 color;
vec3 srgb(vec3 x) {
  x = clamp(x, 0.0, 1.0);
  return mix(12.92 * x, 1.055 * pow(x, vec3(1.0 / 2.4)) - 0.055, step(vec3(0.0031308), x));
}
void main() {
  bool isLeft = uv.x < split;
  vec3 c = isLeft ? texture(left, uv).rgb : texture(right, uv).rgb;
  vec3 b = isLeft ? texture(leftBack, uv).rgb : texture(rightBack, uv).rgb;
  float m = isLeft ? texture(leftMaskA, uv).r * texture(leftMaskB, uv).r
                   : texture(rightMaskA, uv).r * texture(rightMaskB, uv).r;
  vec3 rgb = mix(b, c, m);
  if (abs(uv.x - split) < 0.004 && split > 0.0 && split < 1.0) rgb = vec3(1.0, 0.85, 0.2);
  color = vec4(srgb(rgb), 1.0);
}`;

  const state = {
    time: 0, playing: false, speed: 1, yaw: 0, pitch: null, distance: 1,
    left: "live_fitted", right: "reference", split: 0.5, last: null,
  };
  let programs, vao, quad, quadBuffer, textures, targets, maskTarget, showProg, images, black, white;
  let bound = null; // a user's shader: bound as the GL check bound it (bound.js)

  function uniformValues(cam, time) {
    const I = D.inputs, waves = [];
    for (let i = 0; i < 4; i++) {
      waves.push([
        I.waves[i][0] + time * D.animation.velocities[i][0],
        I.waves[i][1] + time * D.animation.velocities[i][1],
      ]);
    }
    const v = {
      WaterTransformationMatrix: ["m4", new Float32Array([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1])],
      uModelViewProjectionMatrix: ["m4", cam.viewProj],
      uModelViewProjectionMatrixInverse: ["m4", cam.inverse],
      uNormalMatrix: ["m3", cam.normal],
      uTextureMatrix0: ["m4", new Float32Array(I.tex_matrix0)],
      uTextureMatrix1: ["m4", new Float32Array(I.tex_matrix1)],
      viewpos: ["v3", new Float32Array(cam.eye)],
      lightpos: ["v3", new Float32Array(I.lightpos)],
      lightcolor: ["v3", new Float32Array(I.lightcolor)],
      screenSize: ["v2", new Float32Array([W, H])],
    };
    if (I.reflection_view_proj) v.o2v_projection_reflection = ["m4", new Float32Array(I.reflection_view_proj)];
    if (I.box_min) {
      v.boxMin = ["v3", new Float32Array(I.box_min)];
      v.boxMax = ["v3", new Float32Array(I.box_max)];
      v.boxCapturePosition = ["v3", new Float32Array(I.box_capture)];
    }
    for (let i = 0; i < 4; i++) v["wave" + (i + 1)] = ["v2", new Float32Array(waves[i])];
    return v;
  }

  function setUniforms(prog, vals) {
    const n = gl.getProgramParameter(prog, gl.ACTIVE_UNIFORMS);
    for (let k = 0; k < n; k++) {
      const info = gl.getActiveUniform(prog, k);
      const name = info.name.replace(/\[0\]$/, "");
      const study = (D.bindings && D.bindings[name]) || name;
      const loc = gl.getUniformLocation(prog, info.name);
      if (study in SAMPLERS) continue; // bound in bindTextures
      const val = vals[study];
      if (!val) throw new Error(`the shader reads the uniform ${name}, which the viewer has no value for`);
      const [kind, x] = val;
      if (kind === "m4") gl.uniformMatrix4fv(loc, false, x);
      else if (kind === "m3") gl.uniformMatrix3fv(loc, false, x);
      else if (kind === "v3") gl.uniform3fv(loc, x);
      else if (kind === "v2") gl.uniform2fv(loc, x);
    }
  }
  function bindTextures(prog) {
    const n = gl.getProgramParameter(prog, gl.ACTIVE_UNIFORMS);
    for (let k = 0; k < n; k++) {
      const name = gl.getActiveUniform(prog, k).name;
      const study = (D.bindings && D.bindings[name]) || name;
      if (!(study in SAMPLERS)) continue;
      const tex = textures[study];
      if (!tex) {
        throw new Error(`the shader reads the texture ${name}` + (study !== name ? ` (${study})` : "") +
          ", which the viewer's data does not hold: write the viewer again with `study viewer OUT`");
      }
      const unit = SAMPLERS[study];
      gl.activeTexture(gl.TEXTURE0 + unit);
      gl.bindTexture(CUBES.has(study) ? gl.TEXTURE_CUBE_MAP : gl.TEXTURE_2D, tex);
      gl.uniform1i(gl.getUniformLocation(prog, name), unit);
    }
  }

  function camera() {
    const C = D.camera;
    if (!C.orbit || (state.yaw === 0 && state.pitch === null && state.distance === 1)) {
      const vp = new Float32Array(D.inputs.view_proj);
      return { study: true, eye: D.inputs.viewpos, viewProj: vp, inverse: invert4(vp), normal: new Float32Array(D.inputs.normal_matrix) };
    }
    const off = sub(C.position, C.target);
    const r = Math.hypot(off[0], off[1], off[2]) * state.distance;
    const yaw0 = Math.atan2(off[0], off[2]);
    const pitch0 = Math.asin(off[1] / Math.hypot(off[0], off[1], off[2]));
    const yaw = yaw0 + (state.yaw * Math.PI) / 180;
    const pitch = state.pitch === null ? pitch0 : (state.pitch * Math.PI) / 180;
    const eye = [
      C.target[0] + r * Math.cos(pitch) * Math.sin(yaw),
      C.target[1] + r * Math.sin(pitch),
      C.target[2] + r * Math.cos(pitch) * Math.cos(yaw),
    ];
    const m = viewProj(eye, C.target, [0, 1, 0], C.fov_y, W / H, C.near, C.far);
    return { study: false, eye, viewProj: m.viewProj, inverse: invert4(m.viewProj), normal: m.normal };
  }

  // The water plane y = 0 drawn as the quad whose corners are the screen's corners (when all
  // four corner rays meet the plane in front of the camera): its vertices then sit exactly on
  // the pixel grid, so a rasterizer that snaps vertices to a coarse sub-pixel grid (SwiftShader:
  // 1/16 pixel, an error of ~0.02 pixel in every varying) interpolates the varyings exactly as
  // at the pixel centres. The water rectangle itself is cut out by the stencil, drawn first.
  function screenPlane(cam) {
    const inv = cam.inverse, tile = D.inputs.normal_tile, out = [];
    const un = (x, y, z) => {
      const v = [0, 1, 2, 3].map((r) => inv[r] * x + inv[4 + r] * y + inv[8 + r] * z + inv[12 + r]);
      return [v[0] / v[3], v[1] / v[3], v[2] / v[3]];
    };
    for (const [x, y] of [[-1, -1], [1, -1], [-1, 1], [1, 1]]) {
      const a = un(x, y, -1), b = un(x, y, 1);
      if (!(a[1] > 0 && b[1] < 0)) return null; // the ray leaves the screen above the horizon
      const t = a[1] / (a[1] - b[1]);
      const X = a[0] + t * (b[0] - a[0]), Z = a[2] + t * (b[2] - a[2]);
      out.push(X, 0, Z, X / tile, Z / tile);
    }
    return new Float32Array(out);
  }

  function drawWater(which, time, cam) {
    if (bound) return bound.draw(which, time, targets[which], maskTarget);
    const vals = uniformValues(cam, time);
    const plane = screenPlane(cam);
    // the water's coverage: into the mask target's colour and stencil
    gl.bindFramebuffer(gl.FRAMEBUFFER, maskTarget.fbo);
    gl.viewport(0, 0, W, H);
    gl.clearColor(0, 0, 0, 0);
    gl.clearStencil(0);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.STENCIL_BUFFER_BIT);
    gl.enable(gl.STENCIL_TEST);
    gl.stencilFunc(gl.ALWAYS, 1, 0xff);
    gl.stencilOp(gl.KEEP, gl.KEEP, gl.REPLACE);
    gl.useProgram(programs.mask);
    setUniforms(programs.mask, vals);
    gl.bindVertexArray(vao);
    gl.bindBuffer(gl.ARRAY_BUFFER, quadBuffer);
    gl.bufferData(gl.ARRAY_BUFFER, quad, gl.DYNAMIC_DRAW);
    gl.drawArrays(gl.TRIANGLE_STRIP, 0, 4);
    // the shader where the stencil is set
    gl.bindFramebuffer(gl.FRAMEBUFFER, targets[which].fbo);
    gl.clear(gl.COLOR_BUFFER_BIT);
    gl.stencilFunc(gl.EQUAL, 1, 0xff);
    gl.stencilOp(gl.KEEP, gl.KEEP, gl.KEEP);
    const prog = programs[which];
    gl.useProgram(prog);
    setUniforms(prog, vals);
    bindTextures(prog);
    if (plane) gl.bufferData(gl.ARRAY_BUFFER, plane, gl.DYNAMIC_DRAW);
    gl.drawArrays(gl.TRIANGLE_STRIP, 0, 4);
    gl.disable(gl.STENCIL_TEST);
    checkError("drawing the water");
  }
  function checkError(what) {
    const e = gl.getError();
    if (e !== gl.NO_ERROR) throw new Error(`WebGL error 0x${e.toString(16)} while ${what}`);
  }

  function readFloats(fbo) {
    gl.bindFramebuffer(gl.FRAMEBUFFER, fbo);
    const px = new Float32Array(W * H * 4);
    gl.readPixels(0, 0, W, H, gl.RGBA, gl.FLOAT, px);
    checkError("reading the framebuffer back");
    return px;
  }

  // what each view shows: a live render (its program) or one of the run's images; at the
  // study's camera, water the reference sees (not behind a wall) over the reference
  function source(view, cam) {
    const ref = images.reference || black;
    if (view === "live_fitted" || view === "live_default") {
      const study = cam.study;
      return { tex: targets[view.slice(5)].tex, maskA: maskTarget.tex, maskB: study ? images.scored : white,
               back: study ? ref : black, live: view.slice(5) };
    }
    if (view === "reference") return { tex: ref, maskA: white, maskB: white, back: black };
    return { tex: images[view] || black, maskA: images.scored, maskB: white, back: ref };
  }

  function frame() {
    const cam = camera();
    const L = source(state.left, cam), R = source(state.right, cam);
    // each live side drawn once (the coverage is the same for both)
    if (L.live) drawWater(L.live, state.time, cam);
    if (R.live && R.live !== L.live) drawWater(R.live, state.time, cam);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    gl.viewport(0, 0, canvas.width, canvas.height);
    gl.useProgram(showProg);
    const bind = (name, unit, tex) => {
      gl.activeTexture(gl.TEXTURE0 + unit);
      gl.bindTexture(gl.TEXTURE_2D, tex);
      gl.uniform1i(gl.getUniformLocation(showProg, name), unit);
    };
    bind("left", 0, L.tex); bind("right", 1, R.tex);
    bind("leftBack", 2, L.back); bind("rightBack", 3, R.back);
    bind("leftMaskA", 4, L.maskA); bind("leftMaskB", 5, L.maskB);
    bind("rightMaskA", 6, R.maskA); bind("rightMaskB", 7, R.maskB);
    gl.uniform1f(gl.getUniformLocation(showProg, "split"), state.split);
    gl.bindVertexArray(null);
    gl.drawArrays(gl.TRIANGLES, 0, 3);
    checkError("showing the frame");
  }

  function setup() {
    if (!D) throw new Error("data.js did not load: keep index.html, data.js and viewer.js together in one folder");
    canvas.width = W;
    canvas.height = H;
    gl = canvas.getContext("webgl2", { antialias: false, preserveDrawingBuffer: true });
    if (!gl) throw new Error("this browser gives no WebGL 2 context");
    for (const ext of ["EXT_color_buffer_float", "OES_texture_float_linear"]) {
      if (!gl.getExtension(ext)) throw new Error(`WebGL 2 here lacks ${ext}, which the float data needs`);
    }
    programs = {
      fitted: link(D.shaders.vert, D.shaders.frag, "the fitted shader"),
      default: link(D.shaders.vert, D.shaders.frag_default, "the shader at its original constants"),
      mask: link(D.shaders.vert, MASK_FRAG, "the water's coverage"),
    };
    showProg = link(SHOW_VERT, SHOW_FRAG, "the display pass");
    textures = {};
    for (const [name, t] of Object.entries(D.textures)) {
      textures[name] = CUBES.has(name) ? textureCube(t) : texture2d(t, t.filter, t.repeat);
    }
    images = {};
    for (const [name, t] of Object.entries(D.images)) images[name] = texture2d(t, "nearest", false);
    const one = (v) => texture2d({ width: 1, height: 1, channels: 3, data: floatsToB64(new Float32Array([v, v, v])) }, "nearest", false);
    black = one(0);
    white = one(1);
    if (D.bound) {
      if (!window.waterViewerBound) throw new Error("bound.js did not load: keep it beside index.html");
      bound = window.waterViewerBound(gl, D, { floats, FORMATS, checkError, W, H }, programs);
    }
    vao = gl.createVertexArray();
    gl.bindVertexArray(vao);
    quad = new Float32Array(D.inputs.quad);
    quadBuffer = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, quadBuffer);
    gl.bufferData(gl.ARRAY_BUFFER, quad, gl.DYNAMIC_DRAW);
    for (const p of Object.values(programs)) {
      for (const [name, size, offset] of [["aVertex", 3, 0], ["aMultiTexCoord0", 2, 12]]) {
        const loc = gl.getAttribLocation(p, name);
        if (loc >= 0) {
          gl.enableVertexAttribArray(loc);
          gl.vertexAttribPointer(loc, size, gl.FLOAT, false, 20, offset);
        }
      }
    }
    // one float target per live shader: both can be on screen at once
    targets = { fitted: floatTarget(W, H), default: floatTarget(W, H) };
    maskTarget = floatTarget(W, H);
    checkError("setting up");
  }

  // ---- the page's API (the tests and the benchmark drive it) -----------------------------
  // renderFloat({time, constants: 'fitted'|'default', yaw, pitch, distance}): the shader's
  // RGBA float32 framebuffer, W*H*4 values, rows bottom to top (GL order), base64; its mask too.
  api.renderFloat = function (opts) {
    opts = opts || {};
    const saved = [state.yaw, state.pitch, state.distance];
    state.yaw = opts.yaw || 0;
    state.pitch = opts.pitch === undefined ? null : opts.pitch;
    state.distance = opts.distance || 1;
    try {
      const which = opts.constants || "fitted";
      drawWater(which, opts.time || 0, camera());
      return { width: W, height: H, rgba: floatsToB64(readFloats(targets[which].fbo)), mask: floatsToB64(readFloats(maskTarget.fbo)) };
    } finally {
      [state.yaw, state.pitch, state.distance] = saved;
    }
  };
  // timeFrames(n): milliseconds of each of n frames (draw, then a one-pixel read-back to wait
  // for the renderer), after one warm-up frame
  api.timeFrames = function (n) {
    const px = new Float32Array(4), out = [];
    const one = () => {
      drawWater("fitted", state.time, camera());
      gl.bindFramebuffer(gl.FRAMEBUFFER, targets.fitted.fbo);
      gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.FLOAT, px);
    };
    one();
    for (let i = 0; i < n; i++) {
      const t0 = performance.now();
      one();
      out.push(performance.now() - t0);
    }
    return out;
  };
  api.state = state;
  api.width = W;
  api.height = H;
  api.redraw = () => frame();

  // ---- the controls --------------------------------------------------------------------------
  function controls() {
    const $ = (id) => document.getElementById(id);
    const redraw = () => { try { frame(); } catch (e) { fail(e.message); stop(); } };
    if (!D.images.reference) state.right = "live_default";
    for (const side of ["left", "right"]) {
      $(side).value = state[side];
      $(side).addEventListener("change", () => { state[side] = $(side).value; redraw(); });
    }
    $("split").addEventListener("input", () => { state.split = +$("split").value / 100; redraw(); });
    $("time").addEventListener("input", () => {
      state.time = +$("time").value;
      $("clock").textContent = state.time.toFixed(2) + " s";
      redraw();
    });
    $("speed").addEventListener("change", () => { state.speed = +$("speed").value; });
    $("play").addEventListener("click", () => { state.playing ? stop() : play(); });
    if (D.camera.orbit) {
      $("yaw").addEventListener("input", () => { state.yaw = +$("yaw").value; redraw(); });
      $("pitch").addEventListener("input", () => { state.pitch = +$("pitch").value; redraw(); });
      $("distance").addEventListener("input", () => { state.distance = +$("distance").value / 100; redraw(); });
      $("study-camera").addEventListener("click", () => {
        state.yaw = 0; state.pitch = null; state.distance = 1;
        $("yaw").value = 0; $("distance").value = 100; $("pitch").value = D.camera.pitch_deg;
        redraw();
      });
      let drag = null;
      canvas.addEventListener("pointerdown", (e) => { drag = [e.clientX, e.clientY, state.yaw, state.pitch === null ? D.camera.pitch_deg : state.pitch]; });
      window.addEventListener("pointerup", () => { drag = null; });
      canvas.addEventListener("pointermove", (e) => {
        if (!drag) return;
        state.yaw = Math.round(drag[2] - (e.clientX - drag[0]) * 0.5);
        state.pitch = Math.max(3, Math.min(89, drag[3] + (e.clientY - drag[1]) * 0.3));
        $("yaw").value = state.yaw; $("pitch").value = state.pitch;
        redraw();
      });
    } else {
      for (const id of ["yaw", "pitch", "distance", "study-camera"]) $(id).disabled = true;
    }
    let last = null;
    function tick(now) {
      if (!state.playing) return;
      if (last !== null) state.time += ((now - last) / 1000) * state.speed;
      last = now;
      if (state.time > +$("time").max) state.time = 0;
      $("time").value = state.time;
      $("clock").textContent = state.time.toFixed(2) + " s";
      redraw();
      requestAnimationFrame(tick);
    }
    function play() { state.playing = true; last = null; $("play").textContent = "pause"; requestAnimationFrame(tick); }
    function stop() { state.playing = false; $("play").textContent = "play"; }
    redraw();
  }

  try {
    const t0 = performance.now();
    setup();
    frame();
    api.setup_ms = performance.now() - t0;
    controls();
    api.ready = true;
  } catch (e) {
    fail(e.message || String(e));
  }
})();
