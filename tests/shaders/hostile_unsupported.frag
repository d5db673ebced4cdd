#version 400 core
// A dither from the bit-reversed pixel column: an integer instruction (OpBitReverse) the
// SPIR-V executor does not implement.
// @study constant GAIN 0.1 4.0
in vec3 varyingVecWorldPosition;
out vec4 fragColor;
const float GAIN = 1.0;

void main(void)
{
    int k = bitfieldReverse(int(gl_FragCoord.x)) & 255;
    fragColor = vec4(GAIN * float(k) / 255.0, 0.5, 0.5, 1.0);
}
