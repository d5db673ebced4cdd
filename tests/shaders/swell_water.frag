#version 330 core
// Shades swell_water.vert's surface: its normal perturbed by the normal map, the sky reflected
// with Schlick's Fresnel over a height-tinted body colour and the vertex shader's glint.
// @study constant BUMP 0.0 2.0
// @study constant SHINE 0.0 1.0 0.6
in vec3 worldPos;
in vec3 waveNormal;
in vec2 texCoord;
in vec3 toEye;
in float glint;
out vec4 fragColor;
uniform samplerCube reflectionTexture;
uniform sampler2D normalMap;
uniform float SHINE;
const float BUMP = 0.5;
const vec3 DEEP = vec3(0.05, 0.25, 0.3);

void main() {
    vec3 m = texture(normalMap, texCoord).xyz * 2.0 - 1.0;
    vec3 n = normalize(waveNormal + BUMP * vec3(m.x, 0.0, m.z));
    vec3 v = normalize(toEye);
    float f = 0.02 + 0.98 * pow(1.0 - max(dot(n, v), 0.0), 5.0);
    vec3 sky = texture(reflectionTexture, reflect(-v, n)).rgb;
    vec3 body = DEEP * (1.0 + worldPos.y) + vec3(0.1 * SHINE * glint);
    fragColor = vec4(mix(body, sky, f), 1.0);
}
