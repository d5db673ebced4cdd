#version 330 core
// Reads displaced_water.vert's varyings with screen-space derivatives: the faceted normal of
// the displaced triangles (the cross product of dFdx and dFdy of the world position), a
// line pattern antialiased with fwidth of the texture coordinate, and fwidth of the depth.
// @study constant FACET 0.0 1.0
// @study constant LINES 0.0 1.0
in vec3 worldPos;
in vec3 waveNormal;
in vec2 texCoord;
in vec3 toEye;
out vec4 fragColor;
uniform samplerCube reflectionTexture;
const float FACET = 0.6;
const float LINES = 0.5;

void main() {
    vec3 facet = normalize(cross(dFdx(worldPos), dFdy(worldPos)));
    facet *= sign(facet.y + 1e-6);
    vec3 n = normalize(mix(waveNormal, facet, FACET));
    vec3 v = normalize(toEye);
    float f = 0.02 + 0.98 * pow(1.0 - max(dot(n, v), 0.0), 5.0);
    vec3 sky = texture(reflectionTexture, reflect(-v, n)).rgb;
    vec2 w = fwidth(texCoord * 8.0);
    vec2 g = abs(fract(texCoord * 8.0 - 0.5) - 0.5) / max(w, vec2(1e-4));
    float line = 1.0 - min(min(g.x, g.y), 1.0);
    float dz = fwidth(gl_FragCoord.z) * 20.0;
    vec3 col = mix(vec3(0.05, 0.25, 0.3), sky, f) + LINES * line * vec3(0.2) + vec3(dz, 0.0, 0.0);
    fragColor = vec4(col, 1.0);
}
