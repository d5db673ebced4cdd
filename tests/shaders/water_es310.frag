#version 310 es
// A GLSL ES 3.10 material: compiled by glslang's ES profile; no desktop OpenGL runs it.
// @study constant GAIN 0.1 4.0
precision highp float;
in vec3 varyingVecEye;
out vec4 fragColor;
const float GAIN = 1.0;

void main()
{
    fragColor = vec4(GAIN * normalize(varyingVecEye), 1.0);
}
