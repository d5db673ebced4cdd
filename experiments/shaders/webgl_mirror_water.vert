// A water vertex shader in the style of three.js's Water object (WebGL 1, GLSL ES 1.00),
// written for the study: the mirrored camera's projective coordinate, the world position and
// four scrolled coordinates of the water's normal-map image, packed two to a varying.
precision highp float;

// @study bind layerOffset0 wave1
// @study bind layerOffset1 wave2
// @study bind layerOffset2 wave3
// @study bind layerOffset3 wave4
attribute vec3 position;
attribute vec2 uv;
uniform mat4 modelMatrix;
uniform mat4 viewMatrix;
uniform mat4 projectionMatrix;
uniform mat4 textureMatrix;
uniform float time;
uniform vec2 layerOffset0;
uniform vec2 layerOffset1;
uniform vec2 layerOffset2;
uniform vec2 layerOffset3;

varying vec4 mirrorCoord;
varying vec4 worldPosition;
varying vec4 layerUv01;
varying vec4 layerUv23;

void main() {
    worldPosition = modelMatrix * vec4(position, 1.0);
    mirrorCoord = textureMatrix * worldPosition;
    vec2 drift = vec2(time * 0.013, time * -0.009);
    layerUv01 = vec4(uv + layerOffset0 + drift, uv + layerOffset1 - drift);
    layerUv23 = vec4(uv + layerOffset2 + drift.yx, uv + layerOffset3 - drift.yx);
    gl_Position = projectionMatrix * viewMatrix * worldPosition;
}
