#version 330 core
// A water vertex shader in three.js's names (ShaderMaterial built-ins, GLSL 330 `in`):
// a projective texture coordinate, the world position, two scrolled texture coordinates,
// the vector to the eye and the clip position for a screen-space coordinate.
in vec3 position;
in vec2 uv;
uniform mat4 modelMatrix;
uniform mat4 viewMatrix;
uniform mat4 projectionMatrix;
uniform vec3 cameraPosition;
uniform mat4 uTextureMatrix0;
uniform vec2 wave1;
uniform vec2 wave2;
out vec4 vProj;
out vec4 vScreen;
out vec3 vWorldPos;
out vec2 vUv0;
out vec2 vUv1;
out vec3 vToEye;

void main() {
    vec4 world = modelMatrix * vec4(position, 1.0);
    vWorldPos = world.xyz;
    vProj = uTextureMatrix0 * world;
    vUv0 = uv + wave1;
    vUv1 = uv * 0.7 + wave2;
    vToEye = cameraPosition - world.xyz;
    gl_Position = projectionMatrix * viewMatrix * world;
    vScreen = gl_Position;
}
