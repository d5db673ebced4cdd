#version 120
// A water fragment shader in the style of jMonkeyEngine's simple water (GLSL 1.20, its
// m_water_* samplers), written for the study: a planar reflection and the refraction render
// target, both distorted by a DuDv map; the depth buffer, linearised with the camera's near
// and far planes, gives the water's thickness along the view, which fades the refraction
// towards the water colour; the water's own normal map lights a sun highlight; a Fresnel
// power term mixes the two. Its constants are material uniforms, as the engine holds them.

// @study normal_map ../files/water_normals.png
// @study bind m_near camera_near
// @study bind m_far camera_far
// @study constant m_distortionScale 0.0 0.2 0.05
// @study constant m_waterDepth 0.1 20.0 2.0
// @study constant m_waterColor 0.0 1.0 0.0078,0.3176,0.5
// @study constant m_fresnelPower 1.0 10.0 2.0
// @study constant m_shininess 10.0 2000.0 300.0
// @study normal n
uniform sampler2D m_water_reflection;
uniform sampler2D m_water_refraction;
uniform sampler2D m_water_dudvmap;
uniform sampler2D m_water_depthmap;
uniform sampler2D m_water_normalmap;
uniform vec3 sunDirection;
uniform vec3 sunColor;
uniform float m_near;
uniform float m_far;
uniform float m_distortionScale;
uniform float m_waterDepth;
uniform vec3 m_waterColor;
uniform float m_fresnelPower;
uniform float m_shininess;

varying vec4 viewCoords;
varying vec4 reflectionCoords;
varying vec2 waveUv0;
varying vec2 waveUv1;
varying vec3 toEye;

float eyeDistance(float d)
{
    return 2.0 * m_near * m_far / (m_far + m_near - (2.0 * d - 1.0) * (m_far - m_near));
}

void main()
{
    vec2 dudv = texture2D(m_water_dudvmap, waveUv0).rg + texture2D(m_water_dudvmap, waveUv1).rg;
    vec2 distortion = (dudv - 1.0) * m_distortionScale;

    vec2 screen = viewCoords.xy / viewCoords.w * 0.5 + 0.5;
    vec2 refractUv = clamp(screen + distortion, 0.001, 0.999);
    float thickness = max(eyeDistance(texture2D(m_water_depthmap, refractUv).r)
                          - eyeDistance(gl_FragCoord.z), 0.0);
    float fade = clamp(thickness / m_waterDepth, 0.0, 1.0);
    vec3 refraction = mix(texture2D(m_water_refraction, refractUv).rgb, m_waterColor, fade);

    vec2 reflectUv = reflectionCoords.xy / reflectionCoords.w + distortion;
    vec3 reflection = texture2D(m_water_reflection, reflectUv).rgb;

    vec3 t = (texture2D(m_water_normalmap, waveUv0).rgb + texture2D(m_water_normalmap, waveUv1).rgb) - 1.0;
    vec3 n = normalize(t.xzy * vec3(0.25, 1.0, 0.25));
    vec3 v = normalize(toEye);
    float fresnel = pow(1.0 - clamp(dot(v, n), 0.0, 1.0), m_fresnelPower);
    float highlight = pow(max(dot(reflect(-sunDirection, n), v), 0.0), m_shininess);

    gl_FragColor = vec4(mix(refraction, reflection, fresnel) + sunColor * highlight, 1.0);
}
