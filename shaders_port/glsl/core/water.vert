#version 330 core
// core-profile names replacing GLSL 1.20 built-ins (see shaders_port/README.md)
in vec4 aVertex;
in vec4 aMultiTexCoord0;
uniform mat4 uModelViewProjectionMatrix;
out vec4 vTexCoord0;
out vec4 vTexCoord1;
out vec4 vTexCoord2;
out vec4 vTexCoord3;
// Vertex shader "water.vert" of Lipp, "Physically correct perturbed planar
// refractions & reflections in real time" (seed 000, section 2).
// Fixes against the documented text are listed in shaders_port/README.md.

//translation vectors for normalmap texturecoordinates
uniform vec2 wave1;
uniform vec2 wave2;
uniform vec2 wave3;
uniform vec2 wave4;

//worldspace camera position
uniform vec3 viewpos;
//worldspace light position
uniform vec3 lightpos;

//vectors to be transferred to the pixel shader
out vec3 varyingVecEye;
out vec3 varyingVecLight;
out vec3 varyingVecWorldPosition;

//Water plane transformations. water plane must lie parallel to xz plane
//after transformations, else the depth comparisons are not correct.
uniform mat4 WaterTransformationMatrix;

void main(void)
{
    //Output worldpos to pixel shader
    varyingVecWorldPosition = vec3(WaterTransformationMatrix*aVertex);
    //get vector to worldspace view position, output to pixel shader
    varyingVecEye= viewpos - varyingVecWorldPosition.xyz;
    //get vector to worldspace light position, output to pixel shader
    varyingVecLight= lightpos - varyingVecWorldPosition.xyz;

    //Texture coordinates for Normalmap lookup
    vTexCoord0 = vec4(aMultiTexCoord0.xy + wave1,0,1);
    vTexCoord1 = vec4(aMultiTexCoord0.xy + wave2,0,1);
    vTexCoord2 = vec4(aMultiTexCoord0.xy + wave3,0,1);
    vTexCoord3 = vec4(aMultiTexCoord0.xy + wave4,0,1);

    //transform vertex coords
    vec4 vpos = uModelViewProjectionMatrix * aVertex;
    gl_Position = vpos;
}
