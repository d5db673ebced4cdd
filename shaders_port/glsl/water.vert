#version 120
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
varying vec3 varyingVecEye;
varying vec3 varyingVecLight;
varying vec3 varyingVecWorldPosition;

//Water plane transformations. water plane must lie parallel to xz plane
//after transformations, else the depth comparisons are not correct.
uniform mat4 WaterTransformationMatrix;

void main(void)
{
    //Output worldpos to pixel shader
    varyingVecWorldPosition = vec3(WaterTransformationMatrix*gl_Vertex);
    //get vector to worldspace view position, output to pixel shader
    varyingVecEye= viewpos - varyingVecWorldPosition.xyz;
    //get vector to worldspace light position, output to pixel shader
    varyingVecLight= lightpos - varyingVecWorldPosition.xyz;

    //Texture coordinates for Normalmap lookup
    gl_TexCoord[0] = vec4(gl_MultiTexCoord0.xy + wave1,0,1);
    gl_TexCoord[1] = vec4(gl_MultiTexCoord0.xy + wave2,0,1);
    gl_TexCoord[2] = vec4(gl_MultiTexCoord0.xy + wave3,0,1);
    gl_TexCoord[3] = vec4(gl_MultiTexCoord0.xy + wave4,0,1);

    //transform vertex coords
    vec4 vpos = gl_ModelViewProjectionMatrix * gl_Vertex;
    gl_Position = vpos;
}
