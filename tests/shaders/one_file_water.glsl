#version 150
// A water pair in one file for both stages, as Urho3D compiles its shaders: the stage chosen by
// COMPILEVS / COMPILEPS, VS() and PS() each made main() by a define, the uniforms in an
// included file, matrices uploaded row-major (`p * cViewProj`), uniforms the engine sets
// (`value` pragmas) and the colour written to an output array, as Urho3D's GL3 path does.
// @study constant cTint 0.0 1.0 0.6,0.8,0.9
// @study constant cShine 0.0 4.0 1.0
// @study value cTiling 0.5
// @study value cBias 0.25,0.5
// @study bind sWaves normalMap
#include "include/one_file_uniforms.glsl"
varying vec4 vClip;
varying vec2 vUv;
varying vec3 vEye;

#ifdef COMPILEVS
void VS()
{
    vec3 world = (iPos * cModel).xyz;
    gl_Position = vec4(world, 1.0) * cViewProj;
    vClip = gl_Position;
    vUv = iTexCoord * cTiling;
    vEye = cCameraPos - world;
}
#endif

#ifdef COMPILEPS
void PS()
{
    vec3 n = normalize(texture(sWaves, vUv).rgb * 2.0 - 1.0);
    float f = pow(1.0 - clamp(dot(normalize(vEye), n), 0.0, 1.0), 5.0);
    vec2 s = vClip.xy / vClip.w * 0.5 + cBias;
    fragData[0] = vec4(cTint * (1.0 - f) + cShine * f * vec3(s, 1.0), 1.0);
}
#endif
