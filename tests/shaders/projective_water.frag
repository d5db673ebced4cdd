#version 330 core
// Reads the varyings of projective_water.vert: a projective lookup of the floor, two normal
// layers, the sky reflected with Schlick's Fresnel, a screen-space term.
// @study constant BUMP 0.0 2.0
// @study constant TINT 0.0 1.0
in vec4 vProj;
in vec4 vScreen;
in vec3 vWorldPos;
in vec2 vUv0;
in vec2 vUv1;
in vec3 vToEye;
out vec4 fragColor;
uniform sampler2D refractionTexture;
uniform sampler2D normalMap;
uniform samplerCube reflectionTexture;
const float BUMP = 0.6;
const vec3 TINT = vec3(0.4, 0.7, 0.8);

void main() {
    vec3 n1 = texture(normalMap, vUv0).xyz * 2.0 - 1.0;
    vec3 n2 = texture(normalMap, vUv1).xyz * 2.0 - 1.0;
    vec3 n = normalize(vec3(0.0, 1.0, 0.0) + BUMP * vec3(n1.x + n2.x, 0.0, n1.z + n2.z));
    vec3 v = normalize(vToEye);
    vec2 st = vProj.xy / vProj.w + 0.05 * n.xz;
    vec3 floorColor = texture(refractionTexture, st).rgb;
    vec3 sky = texture(reflectionTexture, reflect(-v, n)).rgb;
    float f = 0.02 + 0.98 * pow(1.0 - max(dot(n, v), 0.0), 5.0);
    vec2 screen = vScreen.xy / vScreen.w * 0.5 + 0.5;
    vec3 col = mix(floorColor * TINT, sky, f) * (0.9 + 0.1 * screen.x) + 0.01 * vWorldPos.x;
    fragColor = vec4(col, 1.0);
}
