#version 300 es
// The fragment shader of es_cube_water.vert: two normal-map layers, the sky from a cube map
// by the reflected ray, a Schlick Fresnel term over a water colour. No pragma: an
// experiment's fit.declare names the constants to fit and binds the samplers.
precision highp float;

uniform sampler2D u_waves;
uniform samplerCube u_sky;

in vec3 v_world;
in vec3 v_toEye;
in vec2 v_uvA;
in vec2 v_uvB;

out vec4 fragColor;

const float waveScale = 1.0;
const float f0 = 0.02;
const vec3 waterTint = vec3(0.03, 0.12, 0.15);

void main()
{
    vec3 a = texture(u_waves, v_uvA).rgb * 2.0 - 1.0;
    vec3 b = texture(u_waves, v_uvB).rgb * 2.0 - 1.0;
    vec3 n = normalize(vec3((a.x + b.x) * waveScale, a.y + b.y, (a.z + b.z) * waveScale));
    vec3 v = normalize(v_toEye);
    vec3 r = reflect(-v, n);
    vec3 sky = texture(u_sky, r).rgb;
    float c = 1.0 - max(dot(n, v), 0.0);
    float fresnel = f0 + (1.0 - f0) * c * c * c * c * c;
    fragColor = vec4(mix(waterTint, sky, fresnel), 1.0);
}
