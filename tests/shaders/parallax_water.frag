#version 330 core
// Parallax-occlusion water: a linear search along the refracted ray for the floor, a secant
// step between the last two samples, Beer-Lambert absorption per channel over the path.
// @study constant ABSORPTION 0.001 5.0
// @study constant BUMP 0.05 4.0
// @study constant STEP_LENGTH 0.02 1.0
uniform mat4 uTextureMatrix0;
in vec4 vTexCoord0;
in vec3 varyingVecWorldPosition;
in vec3 varyingVecEye;
out vec4 fragColor;
uniform sampler2D normalMap;
uniform sampler2D refractionTexture;
uniform sampler2D worldYComponent;

const vec3 ABSORPTION = vec3(0.3, 0.12, 0.08);
const float BUMP = 1.0;
const float STEP_LENGTH = 0.15;
const int MAX_STEPS = 48;

float ground(vec3 p)
{
    return texture(worldYComponent, (uTextureMatrix0 * vec4(p, 1.0)).xy).r;
}

void main(void)
{
    vec3 n = 2.0 * texture(normalMap, vTexCoord0.xy).xyz - 1.0;
    n = normalize(vec3(n.x * BUMP, n.y, n.z * BUMP));
    vec3 r = refract(-normalize(varyingVecEye), n, 0.75) * STEP_LENGTH;
    vec3 p = varyingVecWorldPosition;
    vec3 prev = p;
    float h = ground(p);
    float hprev = h;
    int i = 0;
    while (i < MAX_STEPS && h < p.y)
    {
        prev = p;
        hprev = h;
        p += r;
        h = ground(p);
        i++;
    }
    float a = (prev.y - hprev) / (prev.y - p.y + h - hprev);
    vec3 hit = mix(prev, p, clamp(a, 0.0, 1.0));
    vec3 colour = texture(refractionTexture, (uTextureMatrix0 * vec4(hit, 1.0)).xy).rgb;
    float d = length(hit - varyingVecWorldPosition);
    fragColor = vec4(colour * exp(-ABSORPTION * d), 1.0);
}
