// A user's shader in the water viewer: every uniform, texture and vertex attribute as the GL
// check (llvmpipe) bound them, read back from OpenGL by study/export/viewer/user.py and written
// into data.js as D.bound; bound here as they are, nothing recomputed. A project template,
// copied into every viewer/ beside viewer.js, which calls window.waterViewerBound once its
// programs are linked (fitted, default, mask) and then its draw() for each live frame.
(function () {
  "use strict";

  // (gl, D: window.WATER_VIEWER_DATA, env: {floats, FORMATS, checkError, W, H}, programs)
  // -> {draw(which, time, target, maskTarget)}: draws programs[which] into target.fbo and the
  // water's coverage into maskTarget.fbo
  window.waterViewerBound = function (gl, D, env, programs) {
    const { floats, FORMATS, checkError, W, H } = env;
    let bound = null; // {textures: [[unit, target, texture]], vaos: {program: {main, screen}}}
    const SETTERS = {
      float: "uniform1fv", vec2: "uniform2fv", vec3: "uniform3fv", vec4: "uniform4fv",
      int: "uniform1iv", ivec2: "uniform2iv", ivec3: "uniform3iv", ivec4: "uniform4iv",
      bool: "uniform1iv", bvec2: "uniform2iv", bvec3: "uniform3iv", bvec4: "uniform4iv",
      uint: "uniform1uiv", uvec2: "uniform2uiv", uvec3: "uniform3uiv", uvec4: "uniform4uiv",
      sampler2D: "uniform1iv", samplerCube: "uniform1iv",
      mat2: "uniformMatrix2fv", mat3: "uniformMatrix3fv", mat4: "uniformMatrix4fv",
    };
    function boundTexture(t) {
      const target = t.target === "cube" ? gl.TEXTURE_CUBE_MAP : gl.TEXTURE_2D;
      const tex = gl.createTexture(), [ifmt, fmt] = FORMATS[t.channels];
      gl.bindTexture(target, tex);
      gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
      const up = (to, k, w, h, b64) => gl.texImage2D(to, k, gl[ifmt], w, h, 0, gl[fmt], gl.FLOAT, floats(b64));
      if (t.target === "cube") t.faces.forEach((f, i) => up(gl.TEXTURE_CUBE_MAP_POSITIVE_X + i, 0, t.width, t.height, f));
      else t.levels.forEach((l, k) => up(gl.TEXTURE_2D, k, Math.max(1, t.width >> k), Math.max(1, t.height >> k), l));
      gl.texParameteri(target, gl.TEXTURE_MAX_LEVEL, t.target === "cube" ? 0 : t.levels.length - 1);
      gl.texParameteri(target, gl.TEXTURE_MIN_FILTER, gl[t.min_filter.toUpperCase()]);
      gl.texParameteri(target, gl.TEXTURE_MAG_FILTER, gl[t.mag_filter.toUpperCase()]);
      for (const p of [gl.TEXTURE_WRAP_S, gl.TEXTURE_WRAP_T, gl.TEXTURE_WRAP_R]) gl.texParameteri(target, p, gl[t.wrap.toUpperCase()]);
      return [t.unit, target, tex];
    }
    function boundVao(prog, attrs, indices, what) {
      const n = gl.getProgramParameter(prog, gl.ACTIVE_ATTRIBUTES);
      for (let k = 0; k < n; k++) {
        const name = gl.getActiveAttrib(prog, k).name;
        if (!attrs[name]) throw new Error(`${what} reads the vertex attribute ${name}, which the GL check does not bind`);
      }
      const vao = gl.createVertexArray();
      gl.bindVertexArray(vao);
      let count = 0;
      for (const [name, a] of Object.entries(attrs)) {
        const loc = gl.getAttribLocation(prog, name), data = floats(a.data);
        count = data.length / a.size;
        if (loc < 0) continue;
        gl.bindBuffer(gl.ARRAY_BUFFER, gl.createBuffer());
        gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
        gl.enableVertexAttribArray(loc);
        gl.vertexAttribPointer(loc, a.size, gl.FLOAT, false, 0, 0);
      }
      if (indices) {
        const idx = new Uint32Array(floats(indices).buffer);
        gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, gl.createBuffer());
        gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, idx, gl.STATIC_DRAW);
        count = idx.length;
      }
      gl.bindVertexArray(null);
      return { vao, count, indexed: !!indices };
    }
    function setup() {
      const G = D.bound.geometry;
      bound = { textures: D.bound.textures.map(boundTexture), vaos: {} };
      // a sampler the GL check's program does not read (see setBound): a black texel of its
      // type on a unit of its own, never one of the framebuffers drawn into
      const spare = 1 + Math.max(0, ...bound.textures.map((t) => t[0]));
      const black = (target, faces) => boundTexture({
        target, faces, levels: faces, unit: target === "cube" ? spare + 1 : spare, channels: 3,
        width: 1, height: 1, min_filter: "nearest", mag_filter: "nearest", wrap: "clamp_to_edge",
      });
      const texel = btoa(String.fromCharCode(...new Uint8Array(12)));
      bound.spare = { [gl.SAMPLER_2D]: black("2d", [texel]), [gl.SAMPLER_CUBE]: black("cube", Array(6).fill(texel)) };
      for (const [name, p] of Object.entries(programs)) {
        bound.vaos[name] = {
          main: boundVao(p, G.attributes, G.indices, name === "mask" ? "the water's coverage" : `the ${name} shader`),
          screen: G.screen && name !== "mask" ? boundVao(p, G.screen, null, `the ${name} shader`) : null,
        };
      }
    }
    function setBound(prog, list, time) {
      const byName = {};
      for (const u of list) byName[u.name] = u;
      const n = gl.getProgramParameter(prog, gl.ACTIVE_UNIFORMS);
      for (let k = 0; k < n; k++) {
        const info = gl.getActiveUniform(prog, k), name = info.name.replace(/\[0\]$/, "");
        const u = byName[name];
        if (!u && D.bound.inactive.includes(name)) {
          // read by no output of the pair (GL's linker dropped it; ANGLE keeps it): left at 0,
          // a sampler on its spare unit
          if (bound.spare[info.type]) gl.uniform1i(gl.getUniformLocation(prog, name), bound.spare[info.type][0]);
          continue;
        }
      if (!u) throw new Error(`the shader reads the uniform ${name}, which the GL check does not bind`);
        let v = u.value;
        const c = D.bound.clock[name]; // the clock: time in seconds, or a layer's offset
        if (c === "time") v = [v[0] + time];
        else if (c) {
          const vel = D.animation.velocities[+c.slice(4) - 1];
          v = [v[0] + time * vel[0], v[1] + time * vel[1]];
        }
        const f = SETTERS[u.type], loc = gl.getUniformLocation(prog, name);
        if (f.startsWith("uniformMatrix")) gl[f](loc, false, new Float32Array(v));
        else gl[f](loc, f.endsWith("uiv") ? new Uint32Array(v) : f.endsWith("iv") ? new Int32Array(v) : new Float32Array(v));
      }
    }
    function draw(which, time, target, maskTarget) {
      const G = D.bound.geometry, list = D.bound.uniforms[which];
      const draw = (v) => {
        gl.bindVertexArray(v.vao);
        if (v.indexed) gl.drawElements(gl.TRIANGLES, v.count, gl.UNSIGNED_INT, 0);
        else gl.drawArrays(gl.TRIANGLE_STRIP, 0, v.count);
      };
      // the water's coverage (the grid's, depth-tested; the quad's, into the stencil too)
      gl.bindFramebuffer(gl.FRAMEBUFFER, maskTarget.fbo);
      gl.viewport(0, 0, W, H);
      gl.clearColor(0, 0, 0, 0);
      gl.clearDepth(1);
      gl.clearStencil(0);
      gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT | gl.STENCIL_BUFFER_BIT);
      if (G.depth_test) {
        gl.enable(gl.DEPTH_TEST);
        gl.depthFunc(gl.LESS);
      } else {
        gl.enable(gl.STENCIL_TEST);
        gl.stencilFunc(gl.ALWAYS, 1, 0xff);
        gl.stencilOp(gl.KEEP, gl.KEEP, gl.REPLACE);
      }
      gl.useProgram(programs.mask);
      setBound(programs.mask, list, time);
      draw(bound.vaos.mask.main);
      // the shader: over the grid again, or over the screen's plane where the stencil is set
      gl.bindFramebuffer(gl.FRAMEBUFFER, target.fbo);
      gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
      gl.stencilFunc(gl.EQUAL, 1, 0xff);
      gl.stencilOp(gl.KEEP, gl.KEEP, gl.KEEP);
      gl.useProgram(programs[which]);
      setBound(programs[which], list, time);
      for (const [unit, target, tex] of [...bound.textures, ...Object.values(bound.spare)]) {
        gl.activeTexture(gl.TEXTURE0 + unit);
        gl.bindTexture(target, tex);
      }
      draw(bound.vaos[which].screen || bound.vaos[which].main);
      gl.disable(gl.DEPTH_TEST);
      gl.disable(gl.STENCIL_TEST);
      gl.bindVertexArray(null);
      checkError("drawing the water");
    }

    setup();
    return { draw };
  };
})();
