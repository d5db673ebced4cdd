#version 330 core
// A vertex shader in Urho3D's names and matrix order (Uniforms.vert, Transform.vert: `p * M`)
// that feeds the varyings of experiments/shaders/my_water.frag: two scrolled normal-map
// coordinates, the world position and the vector to the eye.
in vec4 iPos;
in vec2 iTexCoord;
uniform mat4 cModel;
uniform mat4 cViewProj;
uniform vec3 cCameraPos;
uniform vec2 wave1;
uniform vec2 wave2;
out vec4 vTexCoord0;
out vec4 vTexCoord1;
out vec3 varyingVecWorldPosition;
out vec3 varyingVecEye;

void main() {
    vec4 world = iPos * cModel;  // Urho3D uploads its matrices row-major: p * M
    varyingVecWorldPosition = world.xyz;
    varyingVecEye = cCameraPos - world.xyz;
    vTexCoord0 = vec4(iTexCoord + wave1, 0.0, 1.0);
    vTexCoord1 = vec4(iTexCoord + wave2, 0.0, 1.0);
    gl_Position = world * cViewProj;
}
