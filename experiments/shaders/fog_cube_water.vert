#version 300 es
// A water vertex shader in the style of Urho3D's water (GLSL ES 3.00 for WebGL 2, Urho3D's
// i/c names), written for the study: the clip position for screen-space lookups, two
// scrolled noise coordinates, the vector to the eye. Urho3D uploads its matrices row-major and
// multiplies a row vector on the left, as here.
precision highp float;

// @study bind cElapsedTime time
// @study bind cNoiseOffset0 wave1
// @study bind cNoiseOffset1 wave3
in vec4 iPos;
in vec2 iTexCoord;
uniform mat4 cModel;
uniform mat4 cViewProj;
uniform vec3 cCameraPos;
uniform float cElapsedTime;
uniform vec2 cNoiseOffset0;
uniform vec2 cNoiseOffset1;

out vec4 vScreenPos;
out vec4 vWaterUV;
out vec3 vEyeVec;

void main()
{
    vec4 worldPos = iPos * cModel;
    vec2 speed = vec2(0.05, 0.03) * cElapsedTime;
    vWaterUV = vec4(iTexCoord + cNoiseOffset0 + speed, iTexCoord + cNoiseOffset1 - speed.yx);
    vEyeVec = cCameraPos - worldPos.xyz;
    gl_Position = worldPos * cViewProj;
    vScreenPos = gl_Position;
}
