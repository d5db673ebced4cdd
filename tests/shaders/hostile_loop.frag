#version 330 core
// A march whose exit test never fails for the pixels that look up the water (eye.y > 0):
// x only grows there.
// @study constant GAIN 0.1 4.0
in vec3 varyingVecEye;
out vec4 fragColor;
const float GAIN = 1.0;

void main(void)
{
    float x = varyingVecEye.y;
    while (x > 0.0)
        x += 1.0;
    fragColor = vec4(GAIN * abs(x), 0.0, 0.0, 1.0);
}
