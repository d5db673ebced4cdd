#version 120
// Schlick-Fresnel water in the style of an OpenGL 2.1 engine (GLSL 1.20): varyings, the
// compatibility texture coordinates gl_TexCoord[0..1], texture2D/textureCube, gl_FragData[0],
// uniform initializers; the helper comes from an #include file and the fog switch from a
// #define the experiment sets.
// @study constant FOG_DENSITY 0.01 4.0
// @study constant FOG_COLOR 0.0 1.0
// @study constant BUMP 0.05 4.0
// @study bind waveNormals normalMap
#extension GL_GOOGLE_include_directive : enable
#include "water_common.glsl"
uniform mat4 uTextureMatrix0;
varying vec3 varyingVecWorldPosition;
varying vec3 varyingVecEye;
uniform sampler2D refractionTexture;
uniform sampler2D worldYComponent;
uniform samplerCube reflectionTexture;

uniform float FOG_DENSITY = 0.35;
uniform vec3 FOG_COLOR = vec3(0.05, 0.2, 0.25);
const float BUMP = 1.0;

void main()
{
    vec3 n = normalize(layer(gl_TexCoord[0]) + layer(gl_TexCoord[1]));
    n = normalize(vec3(n.x * BUMP, n.y, n.z * BUMP));
    vec3 e = normalize(varyingVecEye);
    vec3 r = refract(-e, n, 0.75);
    vec2 st = (uTextureMatrix0 * vec4(varyingVecWorldPosition, 1.0)).xy;
    float floorY = texture2D(worldYComponent, st).r;
    float t = floorY / min(r.y, -0.05);
    vec3 hit = varyingVecWorldPosition + t * r;
    vec3 ground = texture2D(refractionTexture, (uTextureMatrix0 * vec4(hit, 1.0)).xy).rgb;
#if WATER_FOG
    vec3 water = mix(FOG_COLOR, ground, exp(-FOG_DENSITY * t));
#else
    vec3 water = ground;
#endif
    vec3 sky = textureCube(reflectionTexture, reflect(-e, n) * vec3(1.0, -1.0, 1.0)).rgb;
    gl_FragData[0] = vec4(mix(water, sky, schlick(clamp(dot(n, e), 0.0, 1.0))), 1.0);
}
