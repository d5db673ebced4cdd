#version 330
// A GLSL 330 water whose material uniforms carry initializers the fit does not touch
// (Shininess, Tint), written for the study's tests: GLSL ES takes no uniform initializer.
// @study constant BUMP 0.0 2.0
// @study bind waveNormals normalMap
uniform sampler2D waveNormals;
uniform samplerCube reflectionTexture;
in vec4 vTexCoord0;
in vec3 varyingVecEye;
uniform float Shininess = 800.0;
uniform vec3 Tint = vec3(0.1, 0.2, 0.3);
const float BUMP = 1.0;
out vec4 fragColor;
void main() {
    vec3 n = normalize((2.0 * texture(waveNormals, vTexCoord0.xy).xzy - 1.0) * vec3(BUMP, 1.0, BUMP));
    vec3 e = normalize(varyingVecEye);
    vec3 r = reflect(-e, n);
    float s = pow(max(dot(r, normalize(vec3(0.0, 1.0, -1.0))), 0.0), Shininess);
    fragColor = vec4(Tint + texture(reflectionTexture, r * vec3(1.0, -1.0, 1.0)).rgb * 0.1 + s, 1.0);
}
