#version 120
// A water vertex shader in the style of jMonkeyEngine's simple water (GLSL 1.20, its
// g_/m_ names), written for the study: the clip position for the screen-space refraction and
// depth lookups, the mirrored camera's projective coordinate, two scrolled coordinates of
// the DuDv and normal maps, the vector to the eye.

// @study bind m_reflectionMatrix reflection_texture_matrix
// @study bind m_waveOffset0 wave1
// @study bind m_waveOffset1 wave2
attribute vec4 inPosition;
attribute vec2 inTexCoord;
uniform mat4 g_WorldViewProjectionMatrix;
uniform mat4 g_WorldMatrix;
uniform vec3 g_CameraPosition;
uniform mat4 m_reflectionMatrix;
uniform float m_time;
uniform vec2 m_waveOffset0;
uniform vec2 m_waveOffset1;

varying vec4 viewCoords;
varying vec4 reflectionCoords;
varying vec2 waveUv0;
varying vec2 waveUv1;
varying vec3 toEye;

void main()
{
    vec4 world = g_WorldMatrix * inPosition;
    viewCoords = g_WorldViewProjectionMatrix * inPosition;
    reflectionCoords = m_reflectionMatrix * world;
    waveUv0 = inTexCoord + m_waveOffset0 + vec2(0.02, 0.01) * m_time;
    waveUv1 = inTexCoord + m_waveOffset1 - vec2(0.01, 0.02) * m_time;
    toEye = g_CameraPosition - world.xyz;
    gl_Position = viewCoords;
}
