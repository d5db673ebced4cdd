#version 120
// A water fragment shader in the style of a Z-up engine's minimal reflective, refractive
// water (Cube 2 / Tesseract: GLSL 1.20, samplers tex0..tex2), written for the study: the
// world is Z-up. Two layers of the study's normal map (encoded with g along the study's up,
// so a Z-up normal is (r, -b, g)), a distorted planar reflection and refraction, a tint, a
// Fresnel term with a floor.

// @study up z
// @study bind tex0 reflection_sampler
// @study bind tex1 refraction_sampler
// @study bind tex2 normalMap
// @study constant bumpscale 0.0 2.0
// @study constant distortion 0.0 0.1
// @study constant watercolor 0.0 1.5
// @study constant fresnelfloor 0.0 1.0
// @study normal n
uniform sampler2D tex0;
uniform sampler2D tex1;
uniform sampler2D tex2;

varying vec3 camdir;
varying vec4 reflpos;
varying vec4 refrpos;

const float bumpscale = 1.0;
const float distortion = 0.02;
const vec3 watercolor = vec3(0.6, 0.8, 0.8);
const float fresnelfloor = 0.25;

void main(void)
{
    vec3 a = texture2D(tex2, gl_TexCoord[0].xy).rgb * 2.0 - 1.0;
    vec3 b = texture2D(tex2, gl_TexCoord[1].xy).rgb * 2.0 - 1.0;
    vec3 bump = a + b;
    vec3 n = normalize(vec3(bump.x * bumpscale, -bump.z * bumpscale, bump.y));

    vec3 v = normalize(camdir);
    vec2 dxy = n.xy * distortion;
    vec3 reflected = texture2D(tex0, reflpos.xy / reflpos.w + dxy).rgb;
    vec2 screen = refrpos.xy / refrpos.w * 0.5 + 0.5;
    vec3 refracted = texture2D(tex1, clamp(screen + dxy, 0.001, 0.999)).rgb * watercolor;

    float facing = clamp(1.0 - dot(v, n), 0.0, 1.0);
    float fresnel = fresnelfloor + (1.0 - fresnelfloor) * facing * facing * facing * facing;
    gl_FragColor = vec4(mix(refracted, reflected, fresnel), 1.0);
}
