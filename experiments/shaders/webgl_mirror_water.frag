// A water fragment shader in the style of three.js's Water object (WebGL 1, GLSL ES 1.00),
// written for the study: the mirrored camera's image distorted by the waves, four layers of
// the water's own tangent-space normal-map image, a sun highlight and diffuse term, a
// water colour scattered towards the eye, Schlick's Fresnel between the two. It has no
// refraction: the scattered colour stands in for what lies under the water.
precision highp float;

// @study normal_map ../files/water_normals.png
// @study constant distortionScale 0.0 8.0
// @study constant normalScale 0.01 2.0
// @study normal n
// @study constant waterColor 0.0 1.0
// @study constant rf0 0.0 0.5
// @study constant specularStrength 0.0 4.0
uniform sampler2D mirrorSampler;
uniform sampler2D normalSampler;
uniform vec3 sunColor;
uniform vec3 sunDirection;
uniform vec3 eye;

varying vec4 mirrorCoord;
varying vec4 worldPosition;
varying vec4 layerUv01;
varying vec4 layerUv23;

const float distortionScale = 3.7;
const float normalScale = 1.5;
const vec3 waterColor = vec3(0.0, 0.12, 0.1);
const float rf0 = 0.3;
const float shininess = 100.0;
const float specularStrength = 2.0;

vec3 waveNormal() {
    vec3 sum = texture2D(normalSampler, layerUv01.xy).rgb + texture2D(normalSampler, layerUv01.zw).rgb
             + texture2D(normalSampler, layerUv23.xy).rgb + texture2D(normalSampler, layerUv23.zw).rgb;
    vec3 t = sum * 2.0 - 4.0;  // four tangent-space normals summed: (along x, along z, up)
    return normalize(t.xzy * vec3(normalScale, 1.0, normalScale));
}

void main() {
    vec3 n = waveNormal();
    vec3 toEye = eye - worldPosition.xyz;
    float dist = length(toEye);
    vec3 v = toEye / dist;

    vec3 h = normalize(sunDirection + v);
    float highlight = pow(max(dot(n, h), 0.0), shininess) * specularStrength;
    float diffuse = max(dot(sunDirection, n), 0.0) * 0.5;

    vec2 offset = n.xz * distortionScale / (dist + 1.0) * 0.1;
    vec3 mirrored = texture2D(mirrorSampler, mirrorCoord.xy / mirrorCoord.w + offset).rgb;

    float cosTheta = max(dot(v, n), 0.0);
    float reflectance = rf0 + (1.0 - rf0) * pow(1.0 - cosTheta, 5.0);
    vec3 below = sunColor * diffuse * 0.3 + cosTheta * waterColor;
    vec3 above = mirrored + sunColor * highlight;
    gl_FragColor = vec4(mix(below, above, reflectance), 1.0);
}
