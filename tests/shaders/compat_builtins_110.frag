// Water in the style of an OpenGL 2.0 engine (GLSL 1.10: no #version line) that reads the
// compatibility built-ins: the normal-map coordinate gl_TexCoord[0], the eye-space normal by
// gl_NormalMatrix, the window depth by gl_ModelViewProjectionMatrix, the colour to
// gl_FragColor.
// @study constant TINT 0.0 1.0
// @study constant BUMP 0.05 2.0
uniform sampler2D normalMap;
uniform samplerCube reflectionTexture;
varying vec3 varyingVecWorldPosition;
varying vec3 varyingVecEye;
const vec3 TINT = vec3(0.1, 0.35, 0.4);
const float BUMP = 0.5;

void main()
{
    vec3 m = texture2D(normalMap, gl_TexCoord[0].xy).xyz * 2.0 - 1.0;
    vec3 n = normalize(vec3(BUMP * m.x, 1.0, BUMP * m.z));
    vec3 eyeNormal = gl_NormalMatrix * n;
    vec4 clip = gl_ModelViewProjectionMatrix * vec4(varyingVecWorldPosition, 1.0);
    float depth = 0.5 + 0.5 * clip.z / clip.w;
    vec3 e = normalize(varyingVecEye);
    vec3 sky = textureCube(reflectionTexture, reflect(-e, n) * vec3(1.0, -1.0, 1.0)).rgb;
    float f = 0.02 + 0.98 * pow(1.0 - clamp(abs(eyeNormal.z), 0.0, 1.0), 5.0);
    gl_FragColor = vec4(mix(TINT, sky, f) * (0.6 + 0.4 * depth), 1.0);
}
