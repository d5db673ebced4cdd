#import "include/chunk_prefix.glsllib"
// A GLSL ES 1.00 vertex shader in three.js's style: its host's declarations in an imported
// file (jMonkeyEngine's `#import`), a chunk included as `#include <name>`, and the mirrored
// camera's projective texture matrix read by its engine name (three.js's Water reads it here).
uniform mat4 textureMatrix;
varying vec4 mirrorCoord;
varying vec3 worldPosition;
#include <include/chunk_empty>
void main() {
    vec4 world = modelMatrix * vec4(position, 1.0);
    worldPosition = world.xyz;
    mirrorCoord = textureMatrix * world;
    gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0);
}
