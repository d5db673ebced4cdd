#version 330 core
// Engine-style uniforms written for the tests: the clock, the sun (three.js's Water names), the
// eye, the inverse view-projection (jMonkeyEngine), a DuDv map and the user's own normal map.
// @study constant GAIN 0.5 2.0
uniform float time;
uniform vec3 sunDirection;
uniform vec3 sunColor;
uniform vec3 eye;
uniform mat4 g_ViewProjectionMatrixInverse;
uniform sampler2D m_water_dudvmap;
uniform sampler2D normalSampler;
in vec3 varyingVecWorldPosition;
in vec4 vTexCoord0;
uniform vec2 screenSize;
out vec4 fragColor;

const float GAIN = 1.0;

void main(void)
{
    vec2 dudv = texture(m_water_dudvmap, vTexCoord0.xy + vec2(0.01 * time, 0.0)).rg * 2.0 - 1.0;
    vec3 n = texture(normalSampler, varyingVecWorldPosition.xz * 0.7 + dudv * 0.1).rgb;
    vec4 ndc = vec4(2.0 * gl_FragCoord.xy / screenSize - 1.0, 2.0 * gl_FragCoord.z - 1.0, 1.0);
    vec4 w = g_ViewProjectionMatrixInverse * ndc;
    float back = length(w.xyz / w.w - varyingVecWorldPosition);
    vec3 v = normalize(eye - varyingVecWorldPosition);
    float spec = pow(max(dot(reflect(-sunDirection, vec3(0.0, 1.0, 0.0)), v), 0.0), 8.0);
    fragColor = vec4(GAIN * (0.5 * n + spec * sunColor * 0.1) + vec3(back), 1.0);
}
