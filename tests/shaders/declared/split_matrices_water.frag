#version 120
// The fragment shader of split_matrices_water.vert: two ripple layers of a normal map, a
// mirror reflection distorted by them, a deep-water colour and a sun highlight. No pragma:
// an experiment's fit.declare names the constants to fit and binds the samplers.
uniform sampler2D uMirrorMap;
uniform sampler2D uRippleMap;
uniform vec3 uSunDir;

varying vec4 vMirror;
varying vec3 vToEye;
varying vec2 vRipple0;
varying vec2 vRipple1;

const float rippleStrength = 0.8;
const float mirrorDistortion = 0.03;
const vec3 deepColor = vec3(0.02, 0.10, 0.16);
const float glossPower = 300.0;
const float glossStrength = 1.5;

void main()
{
    vec3 a = texture2D(uRippleMap, vRipple0).rgb * 2.0 - 1.0;
    vec3 b = texture2D(uRippleMap, vRipple1).rgb * 2.0 - 1.0;
    vec3 n = normalize(vec3((a.x + b.x) * rippleStrength, a.y + b.y, (a.z + b.z) * rippleStrength));
    vec3 v = normalize(vToEye);
    vec2 uv = vMirror.xy / vMirror.w + n.xz * mirrorDistortion;
    vec3 mirror = texture2D(uMirrorMap, uv).rgb;
    float facing = 1.0 - max(dot(n, v), 0.0);
    float fresnel = 0.02 + 0.98 * pow(facing, 5.0);
    vec3 h = normalize(v + normalize(uSunDir));
    vec3 sun = vec3(glossStrength * pow(max(dot(n, h), 0.0), glossPower));
    gl_FragColor = vec4(mix(deepColor, mirror, fresnel) + sun, 1.0);
}
