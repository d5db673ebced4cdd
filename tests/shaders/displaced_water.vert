#version 330 core
// A vertex shader in jMonkeyEngine's names that displaces the grid vertically (two sine
// waves): the coverage and depth are those of the displaced surface.
in vec3 inPosition;
in vec2 inTexCoord;
in vec3 inNormal;
uniform mat4 g_WorldMatrix;
uniform mat4 g_WorldViewProjectionMatrix;
uniform vec3 g_CameraPosition;
uniform vec2 wave1;
out vec3 worldPos;
out vec3 waveNormal;
out vec2 texCoord;
out vec3 toEye;
const float AMPLITUDE = 0.35;

void main() {
    vec3 p = inPosition;
    float h = AMPLITUDE * sin(2.1 * p.x + 0.4) * cos(1.7 * p.z);
    float dx = AMPLITUDE * 2.1 * cos(2.1 * p.x + 0.4) * cos(1.7 * p.z);
    float dz = -AMPLITUDE * 1.7 * sin(2.1 * p.x + 0.4) * sin(1.7 * p.z);
    vec4 displaced = vec4(p.x, p.y + h, p.z, 1.0);
    worldPos = (g_WorldMatrix * displaced).xyz;
    waveNormal = normalize(inNormal - vec3(dx, 0.0, dz));
    texCoord = inTexCoord + wave1;
    toEye = g_CameraPosition - worldPos;
    gl_Position = g_WorldViewProjectionMatrix * displaced;
}
