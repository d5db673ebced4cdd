#version 120
// A water vertex shader in the style of a Z-up engine's (Cube 2 / Tesseract: GLSL 1.20 with
// the compatibility built-ins), written for the study: the water lies on z = 0 and +z is up
// (`// @study up z` in zup_water.frag). The mirrored camera's projective coordinate, the clip
// position for the refraction, the vector to the camera, two scrolled normal-map coordinates
// in gl_TexCoord.

// @study bind camera cameraPosition
// @study bind reflectmatrix reflection_texture_matrix
// @study bind millis time
// @study bind waterscroll0 wave2
// @study bind waterscroll1 wave4
uniform vec3 camera;
uniform mat4 reflectmatrix;
uniform float millis;
uniform vec2 waterscroll0;
uniform vec2 waterscroll1;

varying vec3 camdir;
varying vec4 reflpos;
varying vec4 refrpos;

void main(void)
{
    gl_Position = ftransform();
    reflpos = reflectmatrix * gl_Vertex;
    refrpos = gl_Position;
    camdir = camera - gl_Vertex.xyz;
    vec2 drift = vec2(0.011, 0.007) * millis;
    gl_TexCoord[0] = vec4(gl_MultiTexCoord0.xy + waterscroll0 + drift, 0.0, 1.0);
    gl_TexCoord[1] = vec4(gl_MultiTexCoord0.xy + waterscroll1 - drift, 0.0, 1.0);
}
