#version 330 core
// The engine's textures an export ships (written for the tests): a DuDv map (jMonkeyEngine's
// name) distorting a lookup of the user's own normal-map image (three.js's name: trilinear,
// mipmapped), the sky cube map reflected, the clock scrolling the DuDv map.
// @study normal_map ../../experiments/files/water_normals.png
// @study constant GAIN 0.5 2.0
uniform sampler2D m_water_dudvmap;
uniform sampler2D normalSampler;
uniform samplerCube sky_cube;
uniform float time;
in vec3 varyingVecWorldPosition;
in vec3 varyingVecEye;
in vec4 vTexCoord0;
out vec4 fragColor;

const float GAIN = 1.0;

void main(void)
{
    vec2 dudv = texture(m_water_dudvmap, vTexCoord0.xy + vec2(0.02 * time, 0.0)).rg * 2.0 - 1.0;
    vec3 t = texture(normalSampler, varyingVecWorldPosition.xz * 0.5 + 0.05 * dudv).rgb * 2.0 - 1.0;
    vec3 n = normalize(vec3(0.3 * t.x, t.z, 0.3 * t.y));
    vec3 r = reflect(-normalize(varyingVecEye), n);
    fragColor = vec4(GAIN * (0.5 * texture(sky_cube, r).rgb + 0.25 * t + 0.25), 1.0);
}
