// The calibrated water in three.js: an ES module written by study/export/threejs into every
// calibration's threejs/ folder (a project template, copied as it is). In a three.js app:
//
//   import shipped from './calibration.js';
//   import { loadCalibration, loadWaterTextures, WaterInputs, createWater } from './water.js';
//   const calibration = await loadCalibration(shipped, new URL('./', import.meta.url));
//   const textures = await loadWaterTextures(calibration);
//   const inputs = new WaterInputs(renderer, calibration);
//   const water = createWater(calibration, textures, inputs);
//   inputs.update(scene, [water]);   // the pool and sky as seen by the shader (again when they change)
//   scene.add(water);
//   // each frame: water.setTime(seconds); renderer.render(scene, camera);
//
// Conventions (those of the study and its binding sheets): world units, +y up, the water plane
// at y = calibration.water.y; every colour linear RGB (render to a float target, or let three
// encode the canvas); the shader's matrices are three's own (WebGL clip space, z in [-w, w]).

import * as THREE from 'three';
import { EXRLoader } from 'three/addons/loaders/EXRLoader.js';

const FILTERS = { linear: THREE.LinearFilter, nearest: THREE.NearestFilter };
const WRAPS = { repeat: THREE.RepeatWrapping, clamp: THREE.ClampToEdgeWrapping };

// the bytes at url: fetch over http(s); XMLHttpRequest for a page opened from file://
// (Chromium's fetch refuses file: URLs; a browser started with --allow-file-access-from-files
// reads them through XMLHttpRequest)
function readBytes(url) {
  if (!url.startsWith('file:')) {
    return fetch(url).then((r) => {
      if (!r.ok) throw new Error(`HTTP ${r.status}`);
      return r.arrayBuffer();
    });
  }
  return new Promise((resolve, reject) => {
    const xhr = new XMLHttpRequest();
    xhr.open('GET', url);
    xhr.responseType = 'arraybuffer';
    xhr.onload = () => (xhr.response && xhr.response.byteLength ? resolve(xhr.response) : reject(new Error('empty or missing file')));
    xhr.onerror = () => reject(new Error('not readable (open the page through a local server, or start the browser with --allow-file-access-from-files)'));
    xhr.send();
  });
}

// reverse the rows of a (height, width, channels) float array in place
function flipRows(data, width, height, channels) {
  const row = width * channels;
  const tmp = new Float32Array(row);
  for (let y = 0; y < height >> 1; y++) {
    const a = y * row, b = (height - 1 - y) * row;
    tmp.set(data.subarray(a, a + row));
    data.copyWithin(a, b, b + row);
    data.set(tmp, b);
  }
}

function text(url, what) {
  return readBytes(url).then((b) => new TextDecoder().decode(b), (e) => {
    throw new Error(`could not load ${what} from ${url}: ${(e && e.message) || e}`);
  });
}

// The calibration as the export ships it, read from the files the binding sheet names and
// nothing else: the shaders from the GLSL ES files, and from shaders/textures/textures.json the
// values the fit used (the light, the waves' offsets and velocities, the top-down camera's
// extent and size, the normal map's tile) and the textures' files and sampler state.
// shipped: calibration.js's object (files: the URLs of those files, relative to base; the
// water's rectangle, the example's camera, a user's shader's names for the inputs).
export async function loadCalibration(shipped, base) {
  const url = (rel) => new URL(rel, base).href;
  const record = JSON.parse(await text(url(shipped.files.textures), 'textures.json'));
  const strip = (src) => src.replace(/^#version[^\n]*\n/, '');
  const [vert, frag] = await Promise.all([
    text(url(shipped.files.vert), 'the vertex shader'), text(url(shipped.files.frag), 'the fragment shader')]);
  const s = record.scene;
  const texture = (r) => ({ url: new URL(r.file, url(shipped.files.textures)).href, filter: r.filter, wrap: r.wrap });
  return {
    ...shipped,
    shaders: { vert: strip(vert), frag: strip(frag) },
    light: { position: s.lightpos, color: s.lightcolor },
    waves: { offsets: s.wave_offsets, velocities: s.wave_velocities },
    normalTile: record.normal_map.tile,
    topDown: { extent: s.top_down.extent, size: s.top_down.size, noGeometry: s.top_down.no_geometry },
    textures: {
      normalMap: texture(record.normal_map), fresnelLookup: texture(record.fresnel_lut),
      // the parallax's heights, where the shader reads them (PARALLAX_OFFSET)
      ...(record.height_map ? { heightMap: texture(record.height_map) } : {}),
    },
  };
}

// The textures the constants were fitted with (calibration.textures of loadCalibration: the
// normal map, the Fresnel LUT and the parallax's heights where shipped, float32 OpenEXR in
// shaders/textures/), read by three's EXRLoader, with the sampler state of textures.json.
export async function loadWaterTextures(calibration) {
  const out = {};
  for (const [name, spec] of Object.entries(calibration.textures)) {
    const url = spec.url;
    let parsed;
    try {
      parsed = new EXRLoader().setDataType(THREE.FloatType).parse(await readBytes(url));
    } catch (e) {
      throw new Error(`could not load the texture ${name} from ${url}: ${(e && e.message) || e}`);
    }
    // EXRLoader puts the file's last row at t = 0; the study's files have their first row there
    flipRows(parsed.data, parsed.width, parsed.height, 4);
    const tex = new THREE.DataTexture(parsed.data, parsed.width, parsed.height, THREE.RGBAFormat, THREE.FloatType);
    tex.minFilter = tex.magFilter = FILTERS[spec.filter];
    tex.wrapS = tex.wrapT = WRAPS[spec.wrap];
    tex.generateMipmaps = false;
    tex.colorSpace = THREE.NoColorSpace;
    tex.needsUpdate = true;
    out[name] = tex;
  }
  return out;
}

// the cube map faces in GL order: (direction the face looks along, up) such that the render's
// x and y are the face's s and t (the GL specification's table of sc, tc)
const SKY_FACES = [
  [[1, 0, 0], [0, -1, 0]], [[-1, 0, 0], [0, -1, 0]],
  [[0, 1, 0], [0, 0, 1]], [[0, -1, 0], [0, 0, -1]],
  [[0, 0, 1], [0, -1, 0]], [[0, 0, -1], [0, -1, 0]],
];

const HEIGHT_VERT = `
varying float vWorldY;
void main() {
  vec4 w = modelMatrix * vec4(position, 1.0);
  vWorldY = w.y;
  gl_Position = projectionMatrix * viewMatrix * w;
}`;
const HEIGHT_FRAG = `
varying float vWorldY;
void main() { gl_FragColor = vec4(vWorldY, 0.0, 0.0, 1.0); }`;

// The inputs the shader reads from the scene, built with three from the user's own scene:
// refractionTexture (the ground under the water seen from straight above: an orthographic
// top-down render, linear RGB), worldYComponent (the world y of that ground, R of a float
// target; calibration.topDown.noGeometry where nothing is below), the top-down camera's
// textureMatrix (world (x, y, z, 1) -> (s, t)), and skyTexture (the scene's background as a
// cube map of world directions in GL's convention, rendered with the face table of the GL
// specification: three's own CubeCamera turns each face's image by 180 degrees).
export class WaterInputs {
  constructor(renderer, calibration, { size = calibration.topDown.size, skySize = calibration.sky.size } = {}) {
    this.renderer = renderer;
    this.calibration = calibration;
    const [x0, z0, x1, z1] = calibration.topDown.extent;
    const w = x1 - x0, h = z1 - z0, cx = (x0 + x1) / 2, cz = (z0 + z1) / 2;
    // straight down, x to the right: (s, t) = (x - x0, z1 - z) / extent
    const cam = new THREE.OrthographicCamera(-w / 2, w / 2, h / 2, -h / 2, 0.01, 1000);
    cam.position.set(cx, 100, cz);
    cam.up.set(0, 0, -1);
    cam.lookAt(cx, 0, cz);
    cam.updateMatrixWorld(true);
    this.camera = cam;
    const bias = new THREE.Matrix4().set(0.5, 0, 0, 0.5, 0, 0.5, 0, 0.5, 0, 0, 0.5, 0.5, 0, 0, 0, 1);
    this.textureMatrix = bias.multiply(cam.projectionMatrix).multiply(cam.matrixWorldInverse);
    const target = (filter) => new THREE.WebGLRenderTarget(size, size, {
      type: THREE.FloatType, format: THREE.RGBAFormat, minFilter: filter, magFilter: filter,
      wrapS: THREE.ClampToEdgeWrapping, wrapT: THREE.ClampToEdgeWrapping,
      generateMipmaps: false, depthBuffer: true, colorSpace: THREE.NoColorSpace,
    });
    this.colorTarget = target(THREE.LinearFilter);
    this.heightTarget = target(THREE.NearestFilter);
    this.skyTarget = new THREE.WebGLCubeRenderTarget(skySize, {
      type: THREE.FloatType, generateMipmaps: false, minFilter: THREE.LinearFilter, magFilter: THREE.LinearFilter,
    });
    this.skyCameras = SKY_FACES.map(([look, up]) => {
      const c = new THREE.PerspectiveCamera(90, 1, 0.1, 1000);
      c.up.set(...up);
      c.lookAt(...look);
      return c;
    });
    this.heightMaterial = new THREE.ShaderMaterial({ vertexShader: HEIGHT_VERT, fragmentShader: HEIGHT_FRAG, side: THREE.DoubleSide });
  }

  get refractionTexture() { return this.colorTarget.texture; }
  get worldYComponent() { return this.heightTarget.texture; }
  get skyTexture() { return this.skyTarget.texture; }

  // Render the three inputs from scene, with the objects in hide (the water) left out.
  update(scene, hide = []) {
    const r = this.renderer;
    const saved = {
      target: r.getRenderTarget(), autoClear: r.autoClear, clear: r.getClearColor(new THREE.Color()),
      alpha: r.getClearAlpha(), background: scene.background, override: scene.overrideMaterial,
      visible: hide.map((o) => o.visible),
    };
    hide.forEach((o) => { o.visible = false; });
    try {
      r.autoClear = true;
      scene.background = null;
      r.setClearColor(new THREE.Color(0, 0, 0), 1);
      r.setRenderTarget(this.colorTarget);
      r.render(scene, this.camera);
      scene.overrideMaterial = this.heightMaterial;
      r.setClearColor(new THREE.Color(this.calibration.topDown.noGeometry, 0, 0), 1);
      r.setRenderTarget(this.heightTarget);
      r.render(scene, this.camera);
      scene.overrideMaterial = saved.override;
      // the sky alone: the scene's background seen from the water's centre
      const sky = new THREE.Scene();
      sky.background = saved.background;
      sky.backgroundIntensity = scene.backgroundIntensity;
      sky.backgroundRotation.copy(scene.backgroundRotation);
      this.skyCameras.forEach((c, face) => {
        c.updateMatrixWorld(true);
        r.setRenderTarget(this.skyTarget, face);
        r.render(sky, c);
      });
    } finally {
      scene.background = saved.background;
      scene.overrideMaterial = saved.override;
      hide.forEach((o, k) => { o.visible = saved.visible[k]; });
      r.setClearColor(saved.clear, saved.alpha);
      r.autoClear = saved.autoClear;
      r.setRenderTarget(saved.target);
    }
  }
}

// The water quad of calibration.water.rect at y = calibration.water.y, with the calibrated
// shader (a RawShaderMaterial: the exported GLSL ES 3.00 text, fitted constants in it) reading
// textures (loadWaterTextures) and inputs (a WaterInputs, or any object with the same four
// fields). The returned mesh has setTime(seconds) (the waves' clock: offset + velocity * t,
// texture units) and setConstants('fitted' | 'default') (the start constants: the export with
// #define lines; a user's shader carries its fitted constants only). Its per-camera uniforms are
// set in onBeforeRender.
export function createWater(calibration, textures, inputs) {
  const [x0, z0, x1, z1] = calibration.water.rect;
  const tile = calibration.normalTile;
  const corners = [[x0, z0], [x1, z0], [x0, z1], [x1, z1]];
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('aVertex', new THREE.Float32BufferAttribute(corners.flatMap(([x, z]) => [x, 0, z, 1]), 4));
  geometry.setAttribute('aMultiTexCoord0', new THREE.Float32BufferAttribute(corners.flatMap(([x, z]) => [x / tile, z / tile, 0, 1]), 4));
  geometry.setIndex([0, 2, 1, 1, 2, 3]);
  const v3 = (a) => new THREE.Vector3(a[0], a[1], a[2]);
  const uniforms = {
    WaterTransformationMatrix: { value: new THREE.Matrix4() },
    uModelViewProjectionMatrix: { value: new THREE.Matrix4() },
    uModelViewProjectionMatrixInverse: { value: new THREE.Matrix4() },
    uNormalMatrix: { value: new THREE.Matrix3() },
    uTextureMatrix0: { value: inputs.textureMatrix },
    viewpos: { value: new THREE.Vector3() },
    lightpos: { value: v3(calibration.light.position) },
    lightcolor: { value: v3(calibration.light.color) },
    normalMap: { value: textures.normalMap },
    fresnelLookup: { value: textures.fresnelLookup },
    ...(textures.heightMap ? { heightMap: { value: textures.heightMap } } : {}),
    refractionTexture: { value: inputs.refractionTexture },
    worldYComponent: { value: inputs.worldYComponent },
    reflectionTexture: { value: inputs.skyTexture },
  };
  calibration.waves.offsets.forEach((o, k) => { uniforms[`wave${k + 1}`] = { value: new THREE.Vector2(o[0], o[1]) }; });
  // a user's shader: its own names for the inputs above (the same uniform objects), and the
  // uniforms its material sets (fitted uniform constants, the declaration's values)
  for (const [name, input] of Object.entries(calibration.uniformNames || {})) uniforms[name] = uniforms[input];
  const VECTORS = { 2: THREE.Vector2, 3: THREE.Vector3, 4: THREE.Vector4 };
  for (const [name, v] of Object.entries(calibration.values || {})) {
    if (!Array.isArray(v)) uniforms[name] = { value: v };
    else if (v.length === 16) uniforms[name] = { value: new THREE.Matrix4().fromArray(v) };
    else uniforms[name] = { value: new VECTORS[v.length](...v) };
  }
  const material = (defines) => new THREE.RawShaderMaterial({
    name: `${calibration.shader} (calibrated)`,
    glslVersion: THREE.GLSL3,
    vertexShader: calibration.shaders.vert,
    fragmentShader: calibration.shaders.frag,
    uniforms,
    defines,
    side: THREE.DoubleSide,
  });
  const materials = { fitted: material({}) };
  if (calibration.startDefines) materials.default = material(calibration.startDefines);
  const mesh = new THREE.Mesh(geometry, materials.fitted);
  mesh.name = 'calibrated water';
  mesh.position.y = calibration.water.y;
  mesh.frustumCulled = false; // no 'position' attribute to bound
  mesh.uniforms = uniforms;
  mesh.setTime = (t) => {
    calibration.waves.offsets.forEach((o, k) => {
      const v = calibration.waves.velocities[k];
      uniforms[`wave${k + 1}`].value.set(o[0] + v[0] * t, o[1] + v[1] * t);
    });
  };
  mesh.setConstants = (which) => {
    if (!(which in materials)) throw new Error(`constants: one of ${Object.keys(materials).join(', ')}, not ${which}`);
    mesh.material = materials[which];
  };
  mesh.setInputs = (next) => {
    uniforms.uTextureMatrix0.value = next.textureMatrix;
    uniforms.refractionTexture.value = next.refractionTexture;
    uniforms.worldYComponent.value = next.worldYComponent;
    uniforms.reflectionTexture.value = next.skyTexture;
  };
  const mvp = new THREE.Matrix4();
  mesh.onBeforeRender = (renderer, scene, camera) => {
    uniforms.WaterTransformationMatrix.value.copy(mesh.matrixWorld);
    mvp.multiplyMatrices(camera.projectionMatrix, camera.matrixWorldInverse).multiply(mesh.matrixWorld);
    uniforms.uModelViewProjectionMatrix.value.copy(mvp);
    uniforms.uModelViewProjectionMatrixInverse.value.copy(mvp).invert();
    uniforms.uNormalMatrix.value.setFromMatrix4(camera.matrixWorldInverse);
    uniforms.viewpos.value.setFromMatrixPosition(camera.matrixWorld);
    mesh.material.uniformsNeedUpdate = true;
  };
  return mesh;
}
