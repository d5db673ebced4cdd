#version 300 es
// A water vertex shader in the style of a WebGL 2 engine's (object-to-world and world-to-clip
// matrices, the eye in world space, two flowing texture coordinates), written for the study's
// tests. Its names are its own and it carries no pragma: an experiment's fit.declare binds them.
uniform mat4 u_objectToWorld;
uniform mat4 u_worldToClip;
uniform vec3 u_eyeWorld;
uniform vec2 u_flowA;
uniform vec2 u_flowB;

in vec3 a_pos;
in vec2 a_uv;

out vec3 v_world;
out vec3 v_toEye;
out vec2 v_uvA;
out vec2 v_uvB;

void main()
{
    vec4 world = u_objectToWorld * vec4(a_pos, 1.0);
    v_world = world.xyz;
    v_toEye = u_eyeWorld - world.xyz;
    v_uvA = a_uv + u_flowA;
    v_uvB = a_uv * 0.5 + u_flowB;
    gl_Position = u_worldToClip * world;
}
