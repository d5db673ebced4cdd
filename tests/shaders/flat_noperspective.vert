#version 330 core
// A vertex shader in Babylon.js's names: a `flat` varying (one value per triangle, from its
// provoking vertex) and two `noperspective` ones (interpolated linearly on the screen).
in vec3 position;
in vec2 uv;
uniform mat4 world;
uniform mat4 viewProjection;
uniform vec4 vEyePosition;
flat out vec3 vFlat;
noperspective out vec2 vScreen;
noperspective out float vDepthLinear;
out vec3 vToEye;
out vec2 vUV;

void main() {
    vec4 p = world * vec4(position, 1.0);
    vFlat = vec3(fract(p.x * 1.37 + 0.21), fract(p.z * 0.73 + 0.4), 0.5 + 0.25 * sin(p.x * p.z));
    gl_Position = viewProjection * p;
    vScreen = gl_Position.xy / gl_Position.w * 0.5 + 0.5;
    vDepthLinear = 0.25 * p.z + 0.5;
    vToEye = vEyePosition.xyz - p.xyz;
    vUV = uv;
}
