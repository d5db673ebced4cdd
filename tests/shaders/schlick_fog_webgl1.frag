// Schlick-Fresnel water in the style of a WebGL 1 material (GLSL ES 1.00: no #version,
// precision statements, varyings, texture2D/textureCube, gl_FragColor). The fitted constants
// are uniforms the material sets: their start values are declared here.
// @study constant FOG_DENSITY 0.01 4.0 0.35
// @study constant FOG_COLOR 0.0 1.0 0.05,0.2,0.25
// @study constant BUMP 0.05 4.0 1.0
// @study bind waveNormals normalMap
#ifdef GL_ES
precision highp float;
#endif
uniform mat4 uTextureMatrix0;
varying vec4 vTexCoord0;
varying vec4 vTexCoord1;
varying vec3 varyingVecWorldPosition;
varying vec3 varyingVecEye;
uniform sampler2D waveNormals;
uniform sampler2D refractionTexture;
uniform sampler2D worldYComponent;
uniform samplerCube reflectionTexture;
uniform float FOG_DENSITY;
uniform vec3 FOG_COLOR;
uniform float BUMP;
const float F0 = 0.02;

vec3 layer(vec4 uv)
{
    return 2.0 * texture2D(waveNormals, uv.xy).xyz - 1.0;
}

void main()
{
    vec3 n = normalize(layer(vTexCoord0) + layer(vTexCoord1));
    n = normalize(vec3(n.x * BUMP, n.y, n.z * BUMP));
    vec3 e = normalize(varyingVecEye);
    vec3 r = refract(-e, n, 0.75);
    vec2 st = (uTextureMatrix0 * vec4(varyingVecWorldPosition, 1.0)).xy;
    float floorY = texture2D(worldYComponent, st).r;
    float t = floorY / min(r.y, -0.05);
    vec3 hit = varyingVecWorldPosition + t * r;
    vec3 ground = texture2D(refractionTexture, (uTextureMatrix0 * vec4(hit, 1.0)).xy).rgb;
    vec3 water = mix(FOG_COLOR, ground, exp(-FOG_DENSITY * t));
    vec3 sky = textureCube(reflectionTexture, reflect(-e, n) * vec3(1.0, -1.0, 1.0)).rgb;
    float c = clamp(dot(n, e), 0.0, 1.0);
    float fresnel = F0 + (1.0 - F0) * pow(1.0 - c, 5.0);
    gl_FragColor = vec4(mix(water, sky, fresnel), 1.0);
}
