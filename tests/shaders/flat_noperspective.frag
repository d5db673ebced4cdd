#version 330 core
// Reads flat_noperspective.vert's varyings with the same qualifiers.
// @study constant GAIN 0.1 4.0
// @study constant SKY 0.0 1.0
flat in vec3 vFlat;
noperspective in vec2 vScreen;
noperspective in float vDepthLinear;
in vec3 vToEye;
in vec2 vUV;
out vec4 fragColor;
uniform samplerCube reflectionTexture;
uniform sampler2D normalMap;
const float GAIN = 0.8;
const float SKY = 0.3;

void main() {
    vec3 n = normalize(texture(normalMap, vUV).xyz * 2.0 - 1.0);
    vec3 sky = texture(reflectionTexture, reflect(-normalize(vToEye), n)).rgb;
    vec3 c = GAIN * vec3(vFlat.x, vScreen.x * vDepthLinear, vScreen.y) + SKY * sky;
    fragColor = vec4(c, 1.0);
}
