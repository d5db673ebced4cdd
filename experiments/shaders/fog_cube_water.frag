#version 300 es
// A water fragment shader in the style of Urho3D's water (GLSL ES 3.00 for WebGL 2, Urho3D's
// s/c names), written for the study: the screen-space refraction offset by the waves' noise
// (a DuDv map), fog over the water's thickness from the depth buffer, the sky's cube map
// reflected, a Fresnel power term; helpers from an #include, a #define switch set by the
// experiment (fit.defines).
precision highp float;

#include "water_fog.glsl"

// @study bind sNormalMap dudv_map
// @study bind sRefractMap refraction_sampler
// @study bind sDepthBuffer depth_sampler
// @study bind sEnvCubeMap sky_cube
// @study bind cNearClipPS camera_near
// @study bind cFarClipPS camera_far
// @study constant cNoiseStrength 0.0 0.5
// @study constant cFogDensity 0.0 4.0
// @study constant cFogColor 0.0 1.0
// @study constant cFresnelPower 0.5 10.0
// @study constant cReflectionGain 0.0 2.0
// @study normal normal
uniform sampler2D sNormalMap;
uniform sampler2D sRefractMap;
uniform sampler2D sDepthBuffer;
uniform samplerCube sEnvCubeMap;
uniform float cNearClipPS;
uniform float cFarClipPS;

in vec4 vScreenPos;
in vec4 vWaterUV;
in vec3 vEyeVec;
out vec4 fragColor;

const float cNoiseStrength = 0.02;
const float cFogDensity = 0.5;
const vec3 cFogColor = vec3(0.1, 0.3, 0.35);
const float cFresnelPower = 4.0;
const float cReflectionGain = 1.0;

void main()
{
    vec2 noise = (texture(sNormalMap, vWaterUV.xy).rg + texture(sNormalMap, vWaterUV.zw).rg - 1.0);
    vec3 normal = normalize(vec3(noise.x, 1.0, noise.y));  // RG - 0.5 = n.xz / (2 n.y)
    vec2 screenUV = vScreenPos.xy / vScreenPos.w * 0.5 + 0.5;
    vec2 refractUV = clamp(screenUV + noise * cNoiseStrength, 0.001, 0.999);

    float sceneDist = EyeDistance(texture(sDepthBuffer, refractUV).r, cNearClipPS, cFarClipPS);
    float waterDist = EyeDistance(gl_FragCoord.z, cNearClipPS, cFarClipPS);
    float fog = WaterFog(max(sceneDist - waterDist, 0.0), cFogDensity);
    vec3 refractColor = mix(texture(sRefractMap, refractUV).rgb, cFogColor, fog);

    vec3 eyeDir = normalize(vEyeVec);
    vec3 reflectColor = texture(sEnvCubeMap, reflect(-eyeDir, normal)).rgb * cReflectionGain;
    float fresnel = pow(1.0 - clamp(dot(eyeDir, normal), 0.0, 1.0), cFresnelPower);
    fragColor = vec4(mix(refractColor, reflectColor, fresnel), 1.0);
}
