#version 330 core
// A planar-reflection water: the mirrored camera's image at the pixel, shifted by the wave
// normals in screen space, over the tinted floor straight below (no refraction).
// @study constant DISTORT 0.0 0.2
// @study constant REFLECTIVITY 0.0 1.0
// @study constant TINT 0.0 1.0
// @study bind mirrorImage reflection_sampler
// @study bind waves normalMap
uniform mat4 uTextureMatrix0;
uniform vec2 screenSize;
in vec4 vTexCoord0;
in vec3 varyingVecWorldPosition;
out vec4 fragColor;
uniform sampler2D mirrorImage;
uniform sampler2D waves;
uniform sampler2D refractionTexture;

const float DISTORT = 0.05;
const float REFLECTIVITY = 0.3;
const vec3 TINT = vec3(0.6, 0.8, 0.85);

void main(void)
{
    vec3 n = 2.0 * texture(waves, vTexCoord0.xy).xyz - 1.0;
    vec2 screen = gl_FragCoord.xy / screenSize + DISTORT * n.xz;
    vec3 mirror = texture(mirrorImage, screen).rgb;
    vec2 st = (uTextureMatrix0 * vec4(varyingVecWorldPosition, 1.0)).xy;
    vec3 ground = texture(refractionTexture, st).rgb;
    fragColor = vec4(mix(TINT * ground, mirror, REFLECTIVITY), 1.0);
}
