#version 330 core
// Engine-style screen-space water written for the tests: the mirrored camera's image through
// three.js's projective textureMatrix, Babylon.js's refraction sampler at the pixel, and
// jMonkeyEngine's depth map linearised with three.js's cameraNear / cameraFar (and with
// jMonkeyEngine's m_FrustumNearFar, the same planes as one vec2).
// @study constant GAIN 0.5 2.0
uniform mat4 textureMatrix;
uniform sampler2D mirrorSampler;
uniform sampler2D refractionSampler;
uniform sampler2D m_water_depthmap;
uniform float cameraNear;
uniform float cameraFar;
uniform vec2 m_FrustumNearFar;
uniform vec2 screenSize;
in vec3 varyingVecWorldPosition;
out vec4 fragColor;

const float GAIN = 1.0;

void main(void)
{
    vec4 proj = textureMatrix * vec4(varyingVecWorldPosition, 1.0);
    vec3 mirror = textureProj(mirrorSampler, proj).rgb;
    vec2 screen = gl_FragCoord.xy / screenSize;
    vec3 below = texture(refractionSampler, screen).rgb;
    float d = texture(m_water_depthmap, screen).r;
    float z = 2.0 * cameraNear * cameraFar / (cameraFar + cameraNear - (2.0 * d - 1.0) * (cameraFar - cameraNear));
    float zj = 2.0 * m_FrustumNearFar.x / (m_FrustumNearFar.y + m_FrustumNearFar.x - d * (m_FrustumNearFar.y - m_FrustumNearFar.x));
    fragColor = vec4(GAIN * mix(below, mirror, 0.5), 1.0) + vec4(0.0, 0.5 * zj, 0.05 * z, 0.0);
}
