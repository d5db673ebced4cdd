#version 330 core
// A Z-up engine's shader written for the tests: the water plane is z = 0, the sun and the eye
// above it have z > 0, the texture matrix takes Z-up world points.
// @study constant GAIN 0.5 2.0
// @study up z
uniform vec3 sunDirection;
uniform vec3 cameraPosition;
uniform mat4 uTextureMatrix0;
uniform sampler2D refractionTexture;
in vec3 varyingVecWorldPosition;
in vec3 varyingVecEye;
out vec4 fragColor;

const float GAIN = 1.0;

void main(void)
{
    vec3 p = varyingVecWorldPosition;
    vec3 ground = texture(refractionTexture, (uTextureMatrix0 * vec4(p, 1.0)).xy).rgb;
    float above = step(0.0, sunDirection.z) * step(0.0, cameraPosition.z);
    float eyeCheck = length(cameraPosition - p - varyingVecEye);
    fragColor = vec4(GAIN * ground * above + vec3(abs(p.z) + eyeCheck), 1.0);
}
