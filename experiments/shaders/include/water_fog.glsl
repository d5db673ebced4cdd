// Helpers shared by the Urho3D-style water (experiments/shaders/fog_cube_water.frag), included
// as an engine's shader library is: the eye distance of a depth-buffer value, the fog of a
// path through the water.

float EyeDistance(float depth, float nearClip, float farClip)
{
    return 2.0 * nearClip * farClip / (farClip + nearClip - (2.0 * depth - 1.0) * (farClip - nearClip));
}

float WaterFog(float thickness, float density)
{
#ifdef FOG_EXPONENTIAL
    return 1.0 - exp(-thickness * density);
#else
    return clamp(thickness * density, 0.0, 1.0);
#endif
}
