#version 330 core
// The square root of a value that is negative on part of the water: NaN there.
// @study constant GAIN 0.1 4.0
in vec3 varyingVecWorldPosition;
out vec4 fragColor;
const float GAIN = 1.0;

void main(void)
{
    float s = sqrt(varyingVecWorldPosition.x);
    fragColor = vec4(GAIN * s, 0.5, 0.5, 1.0);
}
