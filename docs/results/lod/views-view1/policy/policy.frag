#version 330 core
// A level-of-detail policy of 2 bands by distance (study.export.policy_shader); band k's names carry the prefix b<k>_.
uniform mat4 uModelViewProjectionMatrixInverse;
uniform vec2 screenSize;
uniform vec3 viewpos;
in vec3 varyingVecEye;
uniform mat4 uModelViewProjectionMatrix;
uniform mat3 uNormalMatrix;
uniform mat4 uTextureMatrix0;
in vec4 vTexCoord0;
in vec4 vTexCoord1;
in vec4 vTexCoord2;
in vec4 vTexCoord3;
out vec4 fragColor;
uniform sampler2D refractionTexture;
uniform samplerCube reflectionTexture;
uniform sampler2D normalMap;
uniform sampler2D worldYComponent;
uniform sampler2D fresnelLookup;
uniform vec3 lightcolor;
uniform samplerCube boxReflectionTexture;
uniform vec3 boxMin;
uniform vec3 boxMax;
uniform vec3 boxCapturePosition;
in vec3 varyingVecWorldPosition;
in vec3 varyingVecLight;
vec4 policyColour;
// ---- band 0: water_refraction_box_beer (2.5, 0.75, 10) ----
const float b0_ATTENUATION_DISTANCE = 7.5;
const float b0_STEPS_GRAZING = 2.5;
const float b0_STEPS_STEEP = 0.75;
const int b0_LOOP_CAP = 10;
const float b0_SPECULAR_STRENGTH = 2.0;
const float b0_SPECULAR_EXPONENT = 256.0;
const float b0_ABSORPTION_R = 0.3291517;
const float b0_ABSORPTION_G = 0.08815943;
const float b0_ABSORPTION_B = 0.080293864;
const float b0_SPECULAR_ROUGHNESS = 0.2;
const float b0_SUN_DISC_RADIUS = 5.0;
const float b0_SUN_DISC_SOFTNESS = 0.05;
const float b0_SUN_DISC_RADIANCE = 8.0;
const int b0_REFINE_STEPS = 3;
const float b0_REFLECT_DISTORTION = 0.1;
const float b0_BumptexMult = 0.9886966;
const float b0_refrCoeff = 0.7501876;
const vec4 b0_waterColor = vec4(0.0034716341, 0.020825295, 0.14187878, 1.0);
const vec4 b0_reflectColor = vec4(1.0, 1.0, 1.0, 1.0);
void b0_main(void)
{



    vec3 vEye = normalize(varyingVecEye);
    vec3 vLight = normalize(varyingVecLight);


















    vec3 vBumpTexA = vec3(texture(normalMap, vTexCoord0 . xy));
    vec3 vBumpTexB = vec3(texture(normalMap, vTexCoord1 . xy));
    vec3 vBumpTexC = vec3(texture(normalMap, vTexCoord2 . xy));
    vec3 vBumpTexD = vec3(texture(normalMap, vTexCoord3 . xy));








    vec3 vBumpTex = normalize(2.0 *
        (vBumpTexA + vBumpTexB + vBumpTexC + vBumpTexD)- 4.0);





    vec3 vBumpTexMore = normalize(vBumpTex * vec3(1.0, b0_BumptexMult, 1.0));



    vec3 R = normalize(refract(- vEye, vBumpTexMore, b0_refrCoeff));



    float numsteps = mix(b0_STEPS_GRAZING, b0_STEPS_STEEP, - R . y);

    float stepsize = 1.0 / numsteps;

    R *= stepsize;


    float depth, olddepth;


    vec3 current_position = vec3(varyingVecWorldPosition);
    vec3 current_position_old = current_position;
    olddepth = 0;


    vec4 depthtex = texture(worldYComponent,(uTextureMatrix0 * vec4(current_position, 1)). xy);
    depth = depthtex . r;

    for(int i = 0;i < b0_LOOP_CAP;i ++)
    {

        current_position_old = current_position;

        current_position += R;

        olddepth = depth;


        depthtex = texture(worldYComponent,(uTextureMatrix0 * vec4(current_position, 1)). xy);
        depth = depthtex . r;



        if(depth > current_position . y)
        {
            break;
        }
    }


























    float cpoy = current_position_old . y;
    float cpy = current_position . y;

    current_position = mix(current_position_old, current_position,(cpoy - olddepth)/(cpoy - cpy + depth - olddepth));


    vec4 vRefraction = texture(refractionTexture,(uTextureMatrix0 * vec4(current_position, 1)). xy);



    float travelLength = length(current_position - varyingVecWorldPosition);


    vec3 transmittance = exp(- vec3(b0_ABSORPTION_R, b0_ABSORPTION_G, b0_ABSORPTION_B)* travelLength);
    vRefraction = mix(b0_waterColor, vRefraction, vec4(transmittance, 1.0));


































    R = normalize(reflect(- vEye, vBumpTexMore));

    R . y = max(R . y, 0.001);




    vec3 boxPlane = mix(boxMin, boxMax, step(0.0, R));
    vec3 boxT = abs(boxPlane - varyingVecWorldPosition)/ max(abs(R), vec3(1e-6));
    vec3 boxHit = varyingVecWorldPosition + min(boxT . x, boxT . z)* R;
    vec3 boxLookup = boxHit . y < boxMax . y ? boxHit - boxCapturePosition : R;
    vec4 vReflection = texture(boxReflectionTexture, normalize(boxLookup)* vec3(1, - 1, 1))* b0_reflectColor;











































































    vec3 rLight = dot(2 * vBumpTex, vLight)* vBumpTex - vLight;

    vec4 specular = vec4(pow(clamp(dot(rLight, vEye), 0, 1), b0_SPECULAR_EXPONENT)* lightcolor, 1);

    vReflection += specular * b0_SPECULAR_STRENGTH;




    float NdotV = clamp(dot(vEye, vBumpTex), 0, 1);


    vec4 FresnelCoeffs = texture(fresnelLookup, vec2(NdotV, 0.5));

    policyColour = vReflection * FresnelCoeffs . g + vRefraction * FresnelCoeffs . r;





}

// ---- band 1: water_refraction_box_walls (10, 3, 40) ----
const float b1_ATTENUATION_DISTANCE = 6.826335;
const float b1_STEPS_GRAZING = 10.0;
const float b1_STEPS_STEEP = 3.0;
const int b1_LOOP_CAP = 40;
const float b1_SPECULAR_STRENGTH = 2.0;
const float b1_SPECULAR_EXPONENT = 256.0;
const float b1_ABSORPTION_R = 0.13333334;
const float b1_ABSORPTION_G = 0.13333334;
const float b1_ABSORPTION_B = 0.13333334;
const float b1_SPECULAR_ROUGHNESS = 0.2;
const float b1_SUN_DISC_RADIUS = 5.0;
const float b1_SUN_DISC_SOFTNESS = 0.05;
const float b1_SUN_DISC_RADIANCE = 8.0;
const int b1_REFINE_STEPS = 3;
const float b1_REFLECT_DISTORTION = 0.1;
const float b1_BumptexMult = 0.9949732;
const float b1_refrCoeff = 0.7501876;
const vec4 b1_waterColor = vec4(0.0, 0.15143354, 0.32395887, 1.0);
const vec4 b1_reflectColor = vec4(1.0, 1.0, 1.0, 1.0);
void b1_main(void)
{



    vec3 vEye = normalize(varyingVecEye);
    vec3 vLight = normalize(varyingVecLight);


















    vec3 vBumpTexA = vec3(texture(normalMap, vTexCoord0 . xy));
    vec3 vBumpTexB = vec3(texture(normalMap, vTexCoord1 . xy));
    vec3 vBumpTexC = vec3(texture(normalMap, vTexCoord2 . xy));
    vec3 vBumpTexD = vec3(texture(normalMap, vTexCoord3 . xy));








    vec3 vBumpTex = normalize(2.0 *
        (vBumpTexA + vBumpTexB + vBumpTexC + vBumpTexD)- 4.0);





    vec3 vBumpTexMore = normalize(vBumpTex * vec3(1.0, b1_BumptexMult, 1.0));



    vec3 R = normalize(refract(- vEye, vBumpTexMore, b1_refrCoeff));



    float numsteps = mix(b1_STEPS_GRAZING, b1_STEPS_STEEP, - R . y);

    float stepsize = 1.0 / numsteps;

    R *= stepsize;


    float depth, olddepth;


    vec3 current_position = vec3(varyingVecWorldPosition);
    vec3 current_position_old = current_position;
    olddepth = 0;


    vec4 depthtex = texture(worldYComponent,(uTextureMatrix0 * vec4(current_position, 1)). xy);
    depth = depthtex . r;

    for(int i = 0;i < b1_LOOP_CAP;i ++)
    {

        current_position_old = current_position;

        current_position += R;

        olddepth = depth;


        depthtex = texture(worldYComponent,(uTextureMatrix0 * vec4(current_position, 1)). xy);
        depth = depthtex . r;



        if(depth > current_position . y)
        {
            break;
        }
    }


























    float cpoy = current_position_old . y;
    float cpy = current_position . y;

    current_position = mix(current_position_old, current_position,(cpoy - olddepth)/(cpoy - cpy + depth - olddepth));


    vec4 vRefraction = texture(refractionTexture,(uTextureMatrix0 * vec4(current_position, 1)). xy);



    float travelLength = length(current_position - varyingVecWorldPosition);






    travelLength = clamp(travelLength / b1_ATTENUATION_DISTANCE, 0, 1);

    vRefraction = mix(vRefraction, b1_waterColor, travelLength);





    if(depth > varyingVecWorldPosition . y)
    {
        vRefraction = b1_waterColor;
    }




















    R = normalize(reflect(- vEye, vBumpTexMore));

    R . y = max(R . y, 0.001);




    vec3 boxPlane = mix(boxMin, boxMax, step(0.0, R));
    vec3 boxT = abs(boxPlane - varyingVecWorldPosition)/ max(abs(R), vec3(1e-6));
    vec3 boxHit = varyingVecWorldPosition + min(boxT . x, boxT . z)* R;
    vec3 boxLookup = boxHit . y < boxMax . y ? boxHit - boxCapturePosition : R;
    vec4 vReflection = texture(boxReflectionTexture, normalize(boxLookup)* vec3(1, - 1, 1))* b1_reflectColor;











































































    vec3 rLight = dot(2 * vBumpTex, vLight)* vBumpTex - vLight;

    vec4 specular = vec4(pow(clamp(dot(rLight, vEye), 0, 1), b1_SPECULAR_EXPONENT)* lightcolor, 1);

    vReflection += specular * b1_SPECULAR_STRENGTH;




    float NdotV = clamp(dot(vEye, vBumpTex), 0, 1);


    vec4 FresnelCoeffs = texture(fresnelLookup, vec2(NdotV, 0.5));

    policyColour = vReflection * FresnelCoeffs . g + vRefraction * FresnelCoeffs . r;





}

// ---- the policy ----
const float POLICY_BOUND_0 = 8.834735925224427;
const float POLICY_MARGIN = 0.0005;
float policyMeasure()
{
    return length(varyingVecEye);
}
void main(void)
{
    float lm = log(policyMeasure());
    float t0 = smoothstep(-POLICY_MARGIN, POLICY_MARGIN, lm - log(POLICY_BOUND_0));
    vec4 acc = vec4(0.0);
    float w;
    w = 1.0 - t0;
    if (w > 0.0) { b0_main(); acc += w * policyColour; }
    w = t0;
    if (w > 0.0) { b1_main(); acc += w * policyColour; }
    fragColor = acc;
}
