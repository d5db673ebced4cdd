#version 330 core
// The normal map sampled with an implicit level of detail (mipmapped where the binding has
// mip levels) plus fwidth of the texture coordinate: what a derivative-based lookup needs
// from the pixel quads, after the study's water.vert or after a vertex shader of one's own.
// @study constant GAIN 0.0 2.0
in vec4 vTexCoord0;
uniform sampler2D normalMap;
out vec4 fragColor;
const float GAIN = 1.0;

void main() {
    vec2 w = fwidth(vTexCoord0.xy * 16.0);
    fragColor = vec4(GAIN * texture(normalMap, vTexCoord0.xy).rgb, 1.0) + vec4(w, 0.0, 0.0);
}
