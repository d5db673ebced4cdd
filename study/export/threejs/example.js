// The pool of the calibration in three.js, and its water drawn by water.js (a project
// template, copied into every calibration's threejs/ folder by study/export/threejs). The
// study's images come from ../viewer/data.js (window.WATER_VIEWER_DATA). For the project's
// tests: waterThree.renderFloat({inputs: 'scene' | 'study', time, constants}) draws the water
// alone into a float target and returns it, as the viewer's renderFloat does.
import * as THREE from 'three';
import shipped from './calibration.js';
import { loadCalibration, loadWaterTextures, WaterInputs, createWater } from './water.js';

const api = window.waterThree;
const D = window.WATER_VIEWER_DATA;
// the calibration as loadCalibration reads it from the shipped files (set first in main)
let calibration;

function floats(b64) {
  const bin = atob(b64);
  const bytes = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
  return new Float32Array(bytes.buffer);
}
function floatsToB64(arr) {
  const bytes = new Uint8Array(arr.buffer, arr.byteOffset, arr.byteLength);
  let s = '';
  for (let i = 0; i < bytes.length; i += 0x8000) s += String.fromCharCode.apply(null, bytes.subarray(i, i + 0x8000));
  return btoa(s);
}
// n texels of c channels -> RGBA (alpha 1)
function rgba(src, c, n) {
  const out = new Float32Array(n * 4);
  for (let i = 0; i < n; i++) {
    for (let k = 0; k < 4; k++) out[i * 4 + k] = k < c ? src[i * c + k] : (k === 3 ? 1 : 0);
  }
  return out;
}
function dataTexture(data, w, h, filter) {
  const t = new THREE.DataTexture(data, w, h, THREE.RGBAFormat, THREE.FloatType);
  t.minFilter = t.magFilter = filter;
  t.wrapS = t.wrapT = THREE.ClampToEdgeWrapping;
  t.generateMipmaps = false;
  t.colorSpace = THREE.NoColorSpace;
  t.needsUpdate = true;
  return t;
}
// six (size x size x 3) faces -> a CubeTexture of float RGBA faces; mirror: three's convention
// for a cube map it did not render (it looks up (-x, y, z)): the +X and -X faces swapped and
// every face's columns reversed
function cubeTexture(entry, mirror) {
  const n = entry.size, all = floats(entry.data), faces = [];
  for (let f = 0; f < 6; f++) {
    const src = mirror ? [1, 0, 2, 3, 4, 5][f] : f;
    const face = rgba(all.subarray(src * n * n * 3, (src + 1) * n * n * 3), 3, n * n);
    if (mirror) {
      for (let y = 0; y < n; y++) {
        for (let x = 0; x < n >> 1; x++) {
          for (let k = 0; k < 4; k++) {
            const a = (y * n + x) * 4 + k, b = (y * n + n - 1 - x) * 4 + k;
            const tmp = face[a]; face[a] = face[b]; face[b] = tmp;
          }
        }
      }
    }
    faces.push(dataTexture(face, n, n, THREE.LinearFilter));
  }
  const cube = new THREE.CubeTexture(faces);
  cube.format = THREE.RGBAFormat;
  cube.type = THREE.FloatType;
  cube.minFilter = cube.magFilter = THREE.LinearFilter;
  cube.generateMipmaps = false;
  cube.colorSpace = THREE.NoColorSpace;
  cube.needsUpdate = true;
  return cube;
}

// the study's own inputs (the images the viewer and the GL check use), as water.js takes them
function studyInputs() {
  const t = D.textures, c = t.refractionTexture, y = t.worldYComponent;
  return {
    refractionTexture: dataTexture(rgba(floats(c.data), c.channels, c.width * c.height), c.width, c.height, THREE.LinearFilter),
    worldYComponent: dataTexture(rgba(floats(y.data), y.channels, y.width * y.height), y.width, y.height, THREE.NearestFilter),
    skyTexture: cubeTexture(t.reflectionTexture, false),
    textureMatrix: new THREE.Matrix4().fromArray(D.inputs.tex_matrix0),
  };
}

// The pool as a three.js scene: a height field through the texel centres of the study's
// top-down world height (one more ring of vertices at the edge), unlit, with the lit
// top-down colour as vertex colours; the sky as three holds a cube map.
function poolScene() {
  const y = D.textures.worldYComponent, c = D.textures.refractionTexture;
  const hs = floats(y.data), cs = floats(c.data);
  const S = y.width, T = y.height;
  const [x0, z0, x1, z1] = calibration.topDown.extent;
  const pos = [], col = [], index = [];
  const clamp = (v, n) => Math.min(Math.max(v, 0), n - 1);
  for (let t = -1; t <= T; t++) {
    for (let s = -1; s <= S; s++) {
      const i = clamp(t, T) * S + clamp(s, S);
      pos.push(x0 + ((s + 0.5) / S) * (x1 - x0), hs[i], z0 + ((t + 0.5) / T) * (z1 - z0));
      for (let k = 0; k < 3; k++) col.push(cs[i * c.channels + k]);
    }
  }
  const row = S + 2;
  for (let t = 0; t < T + 1; t++) {
    for (let s = 0; s < S + 1; s++) {
      const a = t * row + s;
      index.push(a, a + row, a + 1, a + 1, a + row, a + row + 1);
    }
  }
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.Float32BufferAttribute(pos, 3));
  geometry.setAttribute('color', new THREE.Float32BufferAttribute(col, 3));
  geometry.setIndex(index);
  const pool = new THREE.Mesh(geometry, new THREE.MeshBasicMaterial({ vertexColors: true, side: THREE.DoubleSide }));
  pool.name = 'pool';
  const scene = new THREE.Scene();
  scene.add(pool);
  scene.background = cubeTexture(D.textures.reflectionTexture, true);
  return { scene, pool };
}

// The water plane drawn as the quad whose corners are the screen's corners (null when a corner
// ray misses the plane): its vertices sit on the pixel grid, so SwiftShader's snapping of
// vertices to 1/16 pixel moves no varying (the viewer draws it so too); the coverage comes from
// the water's own rectangle.
function screenPlane(camera) {
  const tile = calibration.normalTile, y0 = calibration.water.y, pos = [], tex = [];
  for (const [x, y] of [[-1, -1], [1, -1], [-1, 1], [1, 1]]) {
    const a = new THREE.Vector3(x, y, -1).unproject(camera), b = new THREE.Vector3(x, y, 1).unproject(camera);
    if (!(a.y > y0 && b.y < y0)) return null;
    const p = a.lerp(b, (a.y - y0) / (a.y - b.y));
    pos.push(p.x, 0, p.z, 1);
    tex.push(p.x / tile, p.z / tile, 0, 1);
  }
  const g = new THREE.BufferGeometry();
  g.setAttribute('aVertex', new THREE.Float32BufferAttribute(pos, 4));
  g.setAttribute('aMultiTexCoord0', new THREE.Float32BufferAttribute(tex, 4));
  g.setIndex([0, 2, 1, 1, 2, 3]);
  return g;
}

function floatTarget(w, h) {
  return new THREE.WebGLRenderTarget(w, h, {
    type: THREE.FloatType, format: THREE.RGBAFormat, minFilter: THREE.NearestFilter,
    magFilter: THREE.NearestFilter, generateMipmaps: false, colorSpace: THREE.NoColorSpace,
  });
}

async function main() {
  if (!D) throw new Error('../viewer/data.js did not load: the page shows the pool from the viewer\'s data (write it with `study viewer`)');
  calibration = await loadCalibration(shipped, new URL('./', import.meta.url));
  const [W, H] = calibration.resolution;
  const canvas = document.getElementById('view');
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: false });
  renderer.setPixelRatio(1);
  renderer.setSize(W, H, false);
  const gl = renderer.getContext();
  for (const ext of ['EXT_color_buffer_float', 'OES_texture_float_linear']) {
    if (!gl.getExtension(ext)) throw new Error(`WebGL 2 lacks ${ext}: the water's float textures need it`);
  }
  // three logs a shader WebGL rejects and draws nothing; the page names it
  const shaderErrors = [];
  renderer.debug.onShaderError = (gl, program, vs, fs) => {
    const log = [vs, fs].map((sh) => gl.getShaderInfoLog(sh)).filter(Boolean).join('\n');
    shaderErrors.push(`WebGL could not compile or link the water's shader:\n${log || gl.getProgramInfoLog(program)}`);
  };
  const textures = await loadWaterTextures(calibration);
  const { scene, pool } = poolScene();
  const inputs = new WaterInputs(renderer, calibration);
  const water = createWater(calibration, textures, inputs);
  inputs.update(scene, [water]);
  scene.add(water);
  const study = studyInputs();
  const cam = calibration.camera;
  const camera = new THREE.PerspectiveCamera(cam.fovY, W / H, cam.near, cam.far);
  camera.position.set(...cam.position);
  camera.lookAt(...cam.target);
  camera.updateMatrixWorld(true);

  // the water alone, into float targets: its colour and its coverage
  const colorTarget = floatTarget(W, H), maskTarget = floatTarget(W, H);
  const maskMaterial = new THREE.RawShaderMaterial({
    glslVersion: THREE.GLSL3, vertexShader: calibration.shaders.vert,
    fragmentShader: 'precision highp float;\nout vec4 coverage;\nvoid main() { coverage = vec4(1.0); }',
    uniforms: water.uniforms, side: THREE.DoubleSide,
  });
  const mask = new THREE.Mesh(water.geometry, maskMaterial);
  mask.frustumCulled = false;
  mask.onBeforeRender = (...a) => { water.onBeforeRender(...a); maskMaterial.uniformsNeedUpdate = true; };
  const waterOnly = new THREE.Scene();
  const quad = water.geometry, plane = screenPlane(camera);
  // opts: inputs 'scene' (the ones WaterInputs built) | 'study' (the study's images); time
  // (seconds); constants 'fitted' | 'default'; screenPlane (true: the colour drawn on the
  // screen's quad, see screenPlane)
  api.renderFloat = (opts = {}) => {
    const which = opts.inputs || 'scene';
    if (opts.screenPlane && !plane) throw new Error('the study camera sees the horizon: no screen plane');
    water.geometry = opts.screenPlane ? plane : quad;
    water.setInputs(which === 'study' ? study : inputs);
    water.setConstants(opts.constants || 'fitted');
    water.setTime(opts.time || 0);
    const out = { width: W, height: H };
    for (const [key, mesh, target] of [['rgba', water, colorTarget], ['mask', mask, maskTarget]]) {
      const parent = mesh.parent;
      waterOnly.add(mesh);
      renderer.setRenderTarget(target);
      renderer.setClearColor(0x000000, 0);
      renderer.clear();
      renderer.render(waterOnly, camera);
      waterOnly.remove(mesh);
      if (parent) parent.add(mesh);
      const buf = new Float32Array(W * H * 4);
      renderer.readRenderTargetPixels(target, 0, 0, W, H, buf);
      out[key] = floatsToB64(buf);
    }
    renderer.setRenderTarget(null);
    water.setInputs(inputs);
    water.geometry = quad;
    return out;
  };
  // the inputs water.js built from the scene, read back: the top-down colour and height (rows
  // in the target's order, t = 0 first) and the six sky faces (GL order)
  api.builtInputs = () => {
    const read = (target, w, h, face) => {
      const buf = new Float32Array(w * h * 4);
      renderer.readRenderTargetPixels(target, 0, 0, w, h, buf, face);
      return floatsToB64(buf);
    };
    const n = inputs.colorTarget.width, k = inputs.skyTarget.width;
    return {
      size: n, skySize: k, textureMatrix: Array.from(inputs.textureMatrix.elements),
      color: read(inputs.colorTarget, n, n), height: read(inputs.heightTarget, n, n),
      sky: [0, 1, 2, 3, 4, 5].map((f) => read(inputs.skyTarget, k, k, f)),
    };
  };
  document.getElementById('what').textContent = `${calibration.shader} calibrated on ${calibration.experiment} `
    + `(three.js ${THREE.REVISION}; the module was written for ${calibration.threeVersion}).`;
  const still = new URLSearchParams(location.search).has('still');
  const t0 = performance.now();
  const frame = () => {
    water.setTime(still ? 0 : (performance.now() - t0) / 1000);
    renderer.setRenderTarget(null);
    renderer.render(scene, camera);
    if (!still) requestAnimationFrame(frame);
  };
  frame();
  if (calibration.startDefines) {
    water.setConstants('default');
    renderer.compile(scene, camera);
    water.setConstants('fitted');
  }
  if (shaderErrors.length) throw new Error(shaderErrors.join('\n'));
  api.pool = pool;
  api.water = water;
  api.ready = true;
}

main().catch((e) => api.fail(e)).finally(() => api.done());
