#version 330 core
// The sky reflected as an engine looks its cube map up (written for the tests): the reflected
// view ray of the wavy surface, no y flip.
// @study constant GAIN 0.5 2.0
uniform samplerCube sky_cube;
uniform sampler2D normalMap;
in vec3 varyingVecEye;
in vec4 vTexCoord0;
out vec4 fragColor;

const float GAIN = 1.0;

void main(void)
{
    vec3 n = normalize(2.0 * texture(normalMap, vTexCoord0.xy).xzy - 1.0);
    vec3 r = reflect(-normalize(varyingVecEye), n.xzy);
    fragColor = vec4(GAIN * texture(sky_cube, r).rgb, 1.0);
}
