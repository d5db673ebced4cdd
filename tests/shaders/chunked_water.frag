precision highp float;
// The fragment shader of chunked_water.vert: the mirrored image at the projective coordinate,
// a chunk included as `#include <name>` giving a function, an engine-set uniform (`value`).
// @study constant tint 0.0 1.0 0.2,0.5,0.6
// @study value alpha 1.0
uniform sampler2D mirrorSampler;
uniform vec3 tint;
uniform float alpha;
varying vec4 mirrorCoord;
varying vec3 worldPosition;
#include <include/chunk_shadowmask>
void main() {
    vec3 mirrored = texture2D(mirrorSampler, mirrorCoord.xy / mirrorCoord.w).rgb;
    gl_FragColor = vec4(mix(tint, mirrored, 0.5) * getShadowMask(), alpha);
}
