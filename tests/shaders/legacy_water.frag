#version 120
// Reads legacy_water.vert's varyings in GLSL 1.20: gl_TexCoord[0] for the normal map, the
// eye-space position and normal for a Fresnel term, the world position for a tint.
// @study constant BUMP 0.0 2.0
// @study constant TINT 0.0 1.0
uniform sampler2D normalMap;
varying vec3 vWorldPos;
varying vec3 vEyeNormal;
varying vec3 vEyePos;
const float BUMP = 0.5;
const vec3 TINT = vec3(0.1, 0.35, 0.4);

void main()
{
    vec3 m = texture2D(normalMap, gl_TexCoord[0].xy).xyz * 2.0 - 1.0;
    vec3 n = normalize(vEyeNormal + BUMP * vec3(m.x, 0.0, m.z));
    vec3 v = normalize(-vEyePos);
    float f = 0.02 + 0.98 * pow(1.0 - max(dot(n, v), 0.0), 5.0);
    gl_FragColor = vec4(mix(TINT, vec3(0.8, 0.9, 1.0), f) + 0.01 * vWorldPos.x, 1.0);
}
