#version 330 core
// A level-of-detail policy of 3 bands by distance (study.export.policy_shader); band k's names carry the prefix b<k>_.
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
in vec3 varyingVecWorldPosition;
in vec3 varyingVecLight;
vec4 policyColour;
// ---- band 0: water_refraction_beer_binary (2.5, 0.75, 10) ----
const float b0_ATTENUATION_DISTANCE = 7.5;
const float b0_STEPS_GRAZING = 2.5;
const float b0_STEPS_STEEP = 0.75;
const int b0_LOOP_CAP = 10;
const float b0_SPECULAR_STRENGTH = 7.7807813;
const float b0_SPECULAR_EXPONENT = 485.4007;
const float b0_ABSORPTION_R = 0.29104644;
const float b0_ABSORPTION_G = 0.06333032;
const float b0_ABSORPTION_B = 0.0436965;
const float b0_SPECULAR_ROUGHNESS = 0.2;
const float b0_SUN_DISC_RADIUS = 5.0;
const float b0_SUN_DISC_SOFTNESS = 0.05;
const float b0_SUN_DISC_RADIANCE = 8.0;
const int b0_REFINE_STEPS = 3;
const float b0_REFLECT_DISTORTION = 0.1;
const float b0_BumptexMult = 1.0028899;
const float b0_refrCoeff = 0.7501876;
const vec4 b0_waterColor = vec4(0.0037862635, 0.0, 0.0, 1.0);
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





    for(int j = 0;j < b0_REFINE_STEPS;j ++)
    {

        vec3 middle_position = 0.5 *(current_position_old + current_position);




        float middle_depth = texture(worldYComponent,(uTextureMatrix0 * vec4(middle_position, 1)). xy). r;
        if(middle_depth > middle_position . y)
        {
            current_position = middle_position;
            depth = middle_depth;
        }
        else
        {
            current_position_old = middle_position;
            olddepth = middle_depth;
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























































    vec4 vReflection = texture(reflectionTexture, normalize(R)* vec3(1, - 1, 1))* b0_reflectColor;




























    vec3 rLight = dot(2 * vBumpTex, vLight)* vBumpTex - vLight;

    vec4 specular = vec4(pow(clamp(dot(rLight, vEye), 0, 1), b0_SPECULAR_EXPONENT)* lightcolor, 1);

    vReflection += specular * b0_SPECULAR_STRENGTH;




    float NdotV = clamp(dot(vEye, vBumpTex), 0, 1);


    vec4 FresnelCoeffs = texture(fresnelLookup, vec2(NdotV, 0.5));

    policyColour = vReflection * FresnelCoeffs . g + vRefraction * FresnelCoeffs . r;





}

// ---- band 1: water_refraction_beer_binary (5, 1.5, 20) ----
const float b1_ATTENUATION_DISTANCE = 7.5;
const float b1_STEPS_GRAZING = 5.0;
const float b1_STEPS_STEEP = 1.5;
const int b1_LOOP_CAP = 20;
const float b1_SPECULAR_STRENGTH = 7.8552117;
const float b1_SPECULAR_EXPONENT = 483.10867;
const float b1_ABSORPTION_R = 0.2939893;
const float b1_ABSORPTION_G = 0.062536806;
const float b1_ABSORPTION_B = 0.042746857;
const float b1_SPECULAR_ROUGHNESS = 0.2;
const float b1_SUN_DISC_RADIUS = 5.0;
const float b1_SUN_DISC_SOFTNESS = 0.05;
const float b1_SUN_DISC_RADIANCE = 8.0;
const int b1_REFINE_STEPS = 3;
const float b1_REFLECT_DISTORTION = 0.1;
const float b1_BumptexMult = 0.99759215;
const float b1_refrCoeff = 0.7501876;
const vec4 b1_waterColor = vec4(0.005010882, 0.0, 0.0, 1.0);
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





    for(int j = 0;j < b1_REFINE_STEPS;j ++)
    {

        vec3 middle_position = 0.5 *(current_position_old + current_position);




        float middle_depth = texture(worldYComponent,(uTextureMatrix0 * vec4(middle_position, 1)). xy). r;
        if(middle_depth > middle_position . y)
        {
            current_position = middle_position;
            depth = middle_depth;
        }
        else
        {
            current_position_old = middle_position;
            olddepth = middle_depth;
        }
    }

    float cpoy = current_position_old . y;
    float cpy = current_position . y;

    current_position = mix(current_position_old, current_position,(cpoy - olddepth)/(cpoy - cpy + depth - olddepth));


    vec4 vRefraction = texture(refractionTexture,(uTextureMatrix0 * vec4(current_position, 1)). xy);



    float travelLength = length(current_position - varyingVecWorldPosition);


    vec3 transmittance = exp(- vec3(b1_ABSORPTION_R, b1_ABSORPTION_G, b1_ABSORPTION_B)* travelLength);
    vRefraction = mix(b1_waterColor, vRefraction, vec4(transmittance, 1.0));


































    R = normalize(reflect(- vEye, vBumpTexMore));

    R . y = max(R . y, 0.001);























































    vec4 vReflection = texture(reflectionTexture, normalize(R)* vec3(1, - 1, 1))* b1_reflectColor;




























    vec3 rLight = dot(2 * vBumpTex, vLight)* vBumpTex - vLight;

    vec4 specular = vec4(pow(clamp(dot(rLight, vEye), 0, 1), b1_SPECULAR_EXPONENT)* lightcolor, 1);

    vReflection += specular * b1_SPECULAR_STRENGTH;




    float NdotV = clamp(dot(vEye, vBumpTex), 0, 1);


    vec4 FresnelCoeffs = texture(fresnelLookup, vec2(NdotV, 0.5));

    policyColour = vReflection * FresnelCoeffs . g + vRefraction * FresnelCoeffs . r;





}

// ---- band 2: water_refraction_beer_binary (2.5, 0.75, 10) ----
const float b2_ATTENUATION_DISTANCE = 7.5;
const float b2_STEPS_GRAZING = 2.5;
const float b2_STEPS_STEEP = 0.75;
const int b2_LOOP_CAP = 10;
const float b2_SPECULAR_STRENGTH = 7.7807813;
const float b2_SPECULAR_EXPONENT = 485.4007;
const float b2_ABSORPTION_R = 0.29104644;
const float b2_ABSORPTION_G = 0.06333032;
const float b2_ABSORPTION_B = 0.0436965;
const float b2_SPECULAR_ROUGHNESS = 0.2;
const float b2_SUN_DISC_RADIUS = 5.0;
const float b2_SUN_DISC_SOFTNESS = 0.05;
const float b2_SUN_DISC_RADIANCE = 8.0;
const int b2_REFINE_STEPS = 3;
const float b2_REFLECT_DISTORTION = 0.1;
const float b2_BumptexMult = 1.0028899;
const float b2_refrCoeff = 0.7501876;
const vec4 b2_waterColor = vec4(0.0037862635, 0.0, 0.0, 1.0);
const vec4 b2_reflectColor = vec4(1.0, 1.0, 1.0, 1.0);
void b2_main(void)
{



    vec3 vEye = normalize(varyingVecEye);
    vec3 vLight = normalize(varyingVecLight);


















    vec3 vBumpTexA = vec3(texture(normalMap, vTexCoord0 . xy));
    vec3 vBumpTexB = vec3(texture(normalMap, vTexCoord1 . xy));
    vec3 vBumpTexC = vec3(texture(normalMap, vTexCoord2 . xy));
    vec3 vBumpTexD = vec3(texture(normalMap, vTexCoord3 . xy));








    vec3 vBumpTex = normalize(2.0 *
        (vBumpTexA + vBumpTexB + vBumpTexC + vBumpTexD)- 4.0);





    vec3 vBumpTexMore = normalize(vBumpTex * vec3(1.0, b2_BumptexMult, 1.0));



    vec3 R = normalize(refract(- vEye, vBumpTexMore, b2_refrCoeff));



    float numsteps = mix(b2_STEPS_GRAZING, b2_STEPS_STEEP, - R . y);

    float stepsize = 1.0 / numsteps;

    R *= stepsize;


    float depth, olddepth;


    vec3 current_position = vec3(varyingVecWorldPosition);
    vec3 current_position_old = current_position;
    olddepth = 0;


    vec4 depthtex = texture(worldYComponent,(uTextureMatrix0 * vec4(current_position, 1)). xy);
    depth = depthtex . r;

    for(int i = 0;i < b2_LOOP_CAP;i ++)
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





    for(int j = 0;j < b2_REFINE_STEPS;j ++)
    {

        vec3 middle_position = 0.5 *(current_position_old + current_position);




        float middle_depth = texture(worldYComponent,(uTextureMatrix0 * vec4(middle_position, 1)). xy). r;
        if(middle_depth > middle_position . y)
        {
            current_position = middle_position;
            depth = middle_depth;
        }
        else
        {
            current_position_old = middle_position;
            olddepth = middle_depth;
        }
    }

    float cpoy = current_position_old . y;
    float cpy = current_position . y;

    current_position = mix(current_position_old, current_position,(cpoy - olddepth)/(cpoy - cpy + depth - olddepth));


    vec4 vRefraction = texture(refractionTexture,(uTextureMatrix0 * vec4(current_position, 1)). xy);



    float travelLength = length(current_position - varyingVecWorldPosition);


    vec3 transmittance = exp(- vec3(b2_ABSORPTION_R, b2_ABSORPTION_G, b2_ABSORPTION_B)* travelLength);
    vRefraction = mix(b2_waterColor, vRefraction, vec4(transmittance, 1.0));


































    R = normalize(reflect(- vEye, vBumpTexMore));

    R . y = max(R . y, 0.001);























































    vec4 vReflection = texture(reflectionTexture, normalize(R)* vec3(1, - 1, 1))* b2_reflectColor;




























    vec3 rLight = dot(2 * vBumpTex, vLight)* vBumpTex - vLight;

    vec4 specular = vec4(pow(clamp(dot(rLight, vEye), 0, 1), b2_SPECULAR_EXPONENT)* lightcolor, 1);

    vReflection += specular * b2_SPECULAR_STRENGTH;




    float NdotV = clamp(dot(vEye, vBumpTex), 0, 1);


    vec4 FresnelCoeffs = texture(fresnelLookup, vec2(NdotV, 0.5));

    policyColour = vReflection * FresnelCoeffs . g + vRefraction * FresnelCoeffs . r;





}

// ---- the policy ----
const float POLICY_BOUND_0 = 6.179456996439422;
const float POLICY_BOUND_1 = 6.322418441972927;
const float POLICY_MARGIN = 0.00010292128593710559;
float policyMeasure()
{
    return length(varyingVecEye);
}
void main(void)
{
    float lm = log(policyMeasure());
    float t0 = smoothstep(-POLICY_MARGIN, POLICY_MARGIN, lm - log(POLICY_BOUND_0));
    float t1 = smoothstep(-POLICY_MARGIN, POLICY_MARGIN, lm - log(POLICY_BOUND_1));
    vec4 acc = vec4(0.0);
    float w;
    w = 1.0 - t0;
    if (w > 0.0) { b0_main(); acc += w * policyColour; }
    w = t0 - t1;
    if (w > 0.0) { b1_main(); acc += w * policyColour; }
    w = t1;
    if (w > 0.0) { b2_main(); acc += w * policyColour; }
    fragColor = acc;
}
