#version 120
// A water vertex shader in the style of an engine that uploads its model, view and projection
// matrices apart and a mirror camera's texture matrix, written for the study's tests. Its names
// are its own and it carries no pragma: an experiment's fit.declare binds them.
uniform mat4 uModel;
uniform mat4 uView;
uniform mat4 uProjection;
uniform mat4 uMirrorTexMatrix;
uniform vec3 uEye;
uniform vec2 uRipple0;
uniform vec2 uRipple1;
uniform float uRippleTiling;

attribute vec3 inPosition;
attribute vec2 inTexCoord;

varying vec4 vMirror;
varying vec3 vToEye;
varying vec2 vRipple0;
varying vec2 vRipple1;

void main()
{
    vec4 world = uModel * vec4(inPosition, 1.0);
    vMirror = uMirrorTexMatrix * world;
    vToEye = uEye - world.xyz;
    vRipple0 = inTexCoord * uRippleTiling + uRipple0;
    vRipple1 = inTexCoord * uRippleTiling + uRipple1;
    gl_Position = uProjection * uView * world;
}
