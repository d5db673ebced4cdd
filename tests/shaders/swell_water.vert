#version 330 core
// A vertex shader in jMonkeyEngine's names whose constants shape the image: the swell's height
// (the vertices displaced), the normal map's tiling (a uniform without initializer, as an
// engine's material sets it) and offset (a vec2), and a glint strength shared with the fragment
// shader (a uniform of both stages, which GL links into one; declared in the fragment shader).
// @study constant AMPLITUDE 0.0 1.0
// @study constant uTiling 0.25 4.0 1.5
// @study constant SCROLL -0.5 0.5
in vec3 inPosition;
in vec2 inTexCoord;
in vec3 inNormal;
uniform mat4 g_WorldMatrix;
uniform mat4 g_WorldViewProjectionMatrix;
uniform vec3 g_CameraPosition;
uniform vec2 wave1;
uniform float uTiling;
uniform float SHINE;
out vec3 worldPos;
out vec3 waveNormal;
out vec2 texCoord;
out vec3 toEye;
out float glint;
const float AMPLITUDE = 0.3;
const vec2 SCROLL = vec2(0.1, -0.05);

void main() {
    vec3 p = inPosition;
    float s = sin(2.1 * p.x + 0.4) * cos(1.7 * p.z);
    float dx = AMPLITUDE * 2.1 * cos(2.1 * p.x + 0.4) * cos(1.7 * p.z);
    float dz = -AMPLITUDE * 1.7 * sin(2.1 * p.x + 0.4) * sin(1.7 * p.z);
    vec4 displaced = vec4(p.x, p.y + AMPLITUDE * s, p.z, 1.0);
    worldPos = (g_WorldMatrix * displaced).xyz;
    waveNormal = normalize(inNormal - vec3(dx, 0.0, dz));
    texCoord = inTexCoord * uTiling + wave1 + SCROLL;
    toEye = g_CameraPosition - worldPos;
    glint = SHINE * (0.5 + 0.5 * s);
    gl_Position = g_WorldViewProjectionMatrix * displaced;
}
