// The uniforms and stage interface of one_file_water.glsl, per stage (declared, some unread).
#ifdef COMPILEVS
#define varying out
in vec4 iPos;
in vec2 iTexCoord;
uniform mat4 cModel;
uniform mat4 cViewProj;
uniform vec3 cCameraPos;
uniform float cTiling;
uniform vec4 cUnusedVS;
#else
#define varying in
out vec4 fragData[1];
uniform vec3 cTint;
uniform float cShine;
uniform vec2 cBias;
uniform vec4 cUnusedPS;
uniform sampler2D sWaves;
uniform sampler2D sUnused;
#endif
