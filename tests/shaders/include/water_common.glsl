// shared by the test shaders: a wave layer's normal and Schlick's Fresnel term
uniform sampler2D waveNormals;
const float F0 = 0.02;

vec3 layer(vec4 uv)
{
    return 2.0 * texture2D(waveNormals, uv.xy).xyz - 1.0;
}

float schlick(float c)
{
    return F0 + (1.0 - F0) * pow(1.0 - c, 5.0);
}
