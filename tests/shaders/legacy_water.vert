#version 120
// A GLSL 1.20 vertex shader with the compatibility names an older engine's water uses:
// ftransform(), gl_Vertex, gl_MultiTexCoord0, gl_Normal, gl_ModelViewMatrix,
// gl_NormalMatrix and gl_TexCoord[0] as an output.
uniform vec2 wave1;
varying vec3 vWorldPos;
varying vec3 vEyeNormal;
varying vec3 vEyePos;

void main()
{
    gl_Position = ftransform();
    vWorldPos = gl_Vertex.xyz;
    vEyePos = (gl_ModelViewMatrix * gl_Vertex).xyz;
    vEyeNormal = gl_NormalMatrix * gl_Normal;
    gl_TexCoord[0] = vec4(gl_MultiTexCoord0.xy + wave1, 0.0, 1.0);
}
