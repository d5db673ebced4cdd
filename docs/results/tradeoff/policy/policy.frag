#version 330 core
// A level-of-detail policy of 5 bands by distance (study.export.policy_shader); band k's names carry the prefix b<k>_.
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
uniform sampler2D heightMap;
uniform samplerCube boxReflectionTexture;
uniform vec3 boxMin;
uniform vec3 boxMax;
uniform vec3 boxCapturePosition;
vec4 policyColour;
// ---- band 0: water_refraction_beer_disc_walls_slopes (2.5, 0.75, 10) ----
const float b0_ATTENUATION_DISTANCE = 7.5;
const float b0_STEPS_GRAZING = 2.5;
const float b0_STEPS_STEEP = 0.75;
const int b0_LOOP_CAP = 10;
const float b0_SPECULAR_STRENGTH = 2.0;
const float b0_SPECULAR_EXPONENT = 256.0;
const float b0_ABSORPTION_R = 0.263941;
const float b0_ABSORPTION_G = 0.08396034;
const float b0_ABSORPTION_B = 0.06973038;
const float b0_SPECULAR_ROUGHNESS = 0.2;
const float b0_SUN_DISC_RADIUS = 5.0;
const float b0_SUN_DISC_SOFTNESS = 0.05;
const float b0_SUN_DISC_RADIANCE = 8.0;
const int b0_REFINE_STEPS = 3;
const float b0_REFLECT_DISTORTION = 0.1;
const float b0_BumptexMult = 0.98839724;
const float b0_refrCoeff = 0.7501876;
const vec4 b0_waterColor = vec4(0.0, 0.060772114, 0.1613289, 1.0);
const vec4 b0_reflectColor = vec4(1.0, 1.0, 1.0, 1.0);
vec2 b0_layerSlope(vec3 texel)
{
    vec3 n = 2.0 * texel - 1.0;
    return - n . xz / max(n . y, 0.05);
}
void b0_main(void)
{



    vec3 vEye = normalize(varyingVecEye);
    vec3 vLight = normalize(varyingVecLight);


















    vec2 parallaxShift = vec2(0.0);





































    vec3 vBumpTexA = vec3(texture(normalMap, vTexCoord0 . xy + parallaxShift));
    vec3 vBumpTexB = vec3(texture(normalMap, vTexCoord1 . xy + parallaxShift));
    vec3 vBumpTexC = vec3(texture(normalMap, vTexCoord2 . xy + parallaxShift));
    vec3 vBumpTexD = vec3(texture(normalMap, vTexCoord3 . xy + parallaxShift));



    vec2 meanSlope = 0.25 *(b0_layerSlope(vBumpTexA)+ b0_layerSlope(vBumpTexB)
        + b0_layerSlope(vBumpTexC)+ b0_layerSlope(vBumpTexD));
    vec3 vBumpTex = normalize(vec3(- meanSlope . x, 1.0, - meanSlope . y));









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










    if(depth > varyingVecWorldPosition . y)
    {
        vRefraction = b0_waterColor;
    }




















    R = normalize(reflect(- vEye, vBumpTexMore));

    R . y = max(R . y, 0.001);























































    vec4 vReflection = texture(reflectionTexture, normalize(R)* vec3(1, - 1, 1))* b0_reflectColor;

























    vec3 rLight = dot(2 * vBumpTex, vLight)* vBumpTex - vLight;










    float outerCos = cos(radians(b0_SUN_DISC_RADIUS *(1.0 + b0_SUN_DISC_SOFTNESS)));
    float innerCos = cos(radians(b0_SUN_DISC_RADIUS *(1.0 - b0_SUN_DISC_SOFTNESS)));
    vec4 specular = vec4(smoothstep(outerCos, innerCos, dot(rLight, vEye))* lightcolor, 1);
    vReflection += specular * b0_SUN_DISC_RADIANCE;




















    float NdotV = clamp(dot(vEye, vBumpTex), 0, 1);


    vec4 FresnelCoeffs = texture(fresnelLookup, vec2(NdotV, 0.5));

    policyColour = vReflection * FresnelCoeffs . g + vRefraction * FresnelCoeffs . r;





}

// ---- band 1: water_refraction_beer_disc_walls_parallax (5, 1.5, 20) ----
const float b1_ATTENUATION_DISTANCE = 7.5;
const float b1_STEPS_GRAZING = 5.0;
const float b1_STEPS_STEEP = 1.5;
const int b1_LOOP_CAP = 20;
const float b1_SPECULAR_STRENGTH = 2.0;
const float b1_SPECULAR_EXPONENT = 256.0;
const float b1_ABSORPTION_R = 0.24425063;
const float b1_ABSORPTION_G = 0.06889099;
const float b1_ABSORPTION_B = 0.05920277;
const float b1_SPECULAR_ROUGHNESS = 0.2;
const float b1_SUN_DISC_RADIUS = 5.0;
const float b1_SUN_DISC_SOFTNESS = 0.05;
const float b1_SUN_DISC_RADIANCE = 8.0;
const int b1_REFINE_STEPS = 3;
const float b1_REFLECT_DISTORTION = 0.1;
const float b1_BumptexMult = 1.0040624;
const float b1_refrCoeff = 0.7501876;
const vec4 b1_waterColor = vec4(0.0, 0.043466732, 0.14216082, 1.0);
const vec4 b1_reflectColor = vec4(1.0, 1.0, 1.0, 1.0);
void b1_main(void)
{



    vec3 vEye = normalize(varyingVecEye);
    vec3 vLight = normalize(varyingVecLight);











    float waveHeight = 0.25 *(texture(heightMap, vTexCoord0 . xy). r
        + texture(heightMap, vTexCoord1 . xy). r
        + texture(heightMap, vTexCoord2 . xy). r
        + texture(heightMap, vTexCoord3 . xy). r);

    vec2 parallaxShift = waveHeight / max(vEye . y, 0.05)* vEye . xz;







































    vec3 vBumpTexA = vec3(texture(normalMap, vTexCoord0 . xy + parallaxShift));
    vec3 vBumpTexB = vec3(texture(normalMap, vTexCoord1 . xy + parallaxShift));
    vec3 vBumpTexC = vec3(texture(normalMap, vTexCoord2 . xy + parallaxShift));
    vec3 vBumpTexD = vec3(texture(normalMap, vTexCoord3 . xy + parallaxShift));








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


    vec3 transmittance = exp(- vec3(b1_ABSORPTION_R, b1_ABSORPTION_G, b1_ABSORPTION_B)* travelLength);
    vRefraction = mix(b1_waterColor, vRefraction, vec4(transmittance, 1.0));










    if(depth > varyingVecWorldPosition . y)
    {
        vRefraction = b1_waterColor;
    }




















    R = normalize(reflect(- vEye, vBumpTexMore));

    R . y = max(R . y, 0.001);























































    vec4 vReflection = texture(reflectionTexture, normalize(R)* vec3(1, - 1, 1))* b1_reflectColor;

























    vec3 rLight = dot(2 * vBumpTex, vLight)* vBumpTex - vLight;










    float outerCos = cos(radians(b1_SUN_DISC_RADIUS *(1.0 + b1_SUN_DISC_SOFTNESS)));
    float innerCos = cos(radians(b1_SUN_DISC_RADIUS *(1.0 - b1_SUN_DISC_SOFTNESS)));
    vec4 specular = vec4(smoothstep(outerCos, innerCos, dot(rLight, vEye))* lightcolor, 1);
    vReflection += specular * b1_SUN_DISC_RADIANCE;




















    float NdotV = clamp(dot(vEye, vBumpTex), 0, 1);


    vec4 FresnelCoeffs = texture(fresnelLookup, vec2(NdotV, 0.5));

    policyColour = vReflection * FresnelCoeffs . g + vRefraction * FresnelCoeffs . r;





}

// ---- band 2: water_refraction_beer_disc_walls_slopes (2.5, 0.75, 10) ----
const float b2_ATTENUATION_DISTANCE = 7.5;
const float b2_STEPS_GRAZING = 2.5;
const float b2_STEPS_STEEP = 0.75;
const int b2_LOOP_CAP = 10;
const float b2_SPECULAR_STRENGTH = 2.0;
const float b2_SPECULAR_EXPONENT = 256.0;
const float b2_ABSORPTION_R = 0.263941;
const float b2_ABSORPTION_G = 0.08396034;
const float b2_ABSORPTION_B = 0.06973038;
const float b2_SPECULAR_ROUGHNESS = 0.2;
const float b2_SUN_DISC_RADIUS = 5.0;
const float b2_SUN_DISC_SOFTNESS = 0.05;
const float b2_SUN_DISC_RADIANCE = 8.0;
const int b2_REFINE_STEPS = 3;
const float b2_REFLECT_DISTORTION = 0.1;
const float b2_BumptexMult = 0.98839724;
const float b2_refrCoeff = 0.7501876;
const vec4 b2_waterColor = vec4(0.0, 0.060772114, 0.1613289, 1.0);
const vec4 b2_reflectColor = vec4(1.0, 1.0, 1.0, 1.0);
vec2 b2_layerSlope(vec3 texel)
{
    vec3 n = 2.0 * texel - 1.0;
    return - n . xz / max(n . y, 0.05);
}
void b2_main(void)
{



    vec3 vEye = normalize(varyingVecEye);
    vec3 vLight = normalize(varyingVecLight);


















    vec2 parallaxShift = vec2(0.0);





































    vec3 vBumpTexA = vec3(texture(normalMap, vTexCoord0 . xy + parallaxShift));
    vec3 vBumpTexB = vec3(texture(normalMap, vTexCoord1 . xy + parallaxShift));
    vec3 vBumpTexC = vec3(texture(normalMap, vTexCoord2 . xy + parallaxShift));
    vec3 vBumpTexD = vec3(texture(normalMap, vTexCoord3 . xy + parallaxShift));



    vec2 meanSlope = 0.25 *(b2_layerSlope(vBumpTexA)+ b2_layerSlope(vBumpTexB)
        + b2_layerSlope(vBumpTexC)+ b2_layerSlope(vBumpTexD));
    vec3 vBumpTex = normalize(vec3(- meanSlope . x, 1.0, - meanSlope . y));









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


























    float cpoy = current_position_old . y;
    float cpy = current_position . y;

    current_position = mix(current_position_old, current_position,(cpoy - olddepth)/(cpoy - cpy + depth - olddepth));


    vec4 vRefraction = texture(refractionTexture,(uTextureMatrix0 * vec4(current_position, 1)). xy);



    float travelLength = length(current_position - varyingVecWorldPosition);


    vec3 transmittance = exp(- vec3(b2_ABSORPTION_R, b2_ABSORPTION_G, b2_ABSORPTION_B)* travelLength);
    vRefraction = mix(b2_waterColor, vRefraction, vec4(transmittance, 1.0));










    if(depth > varyingVecWorldPosition . y)
    {
        vRefraction = b2_waterColor;
    }




















    R = normalize(reflect(- vEye, vBumpTexMore));

    R . y = max(R . y, 0.001);























































    vec4 vReflection = texture(reflectionTexture, normalize(R)* vec3(1, - 1, 1))* b2_reflectColor;

























    vec3 rLight = dot(2 * vBumpTex, vLight)* vBumpTex - vLight;










    float outerCos = cos(radians(b2_SUN_DISC_RADIUS *(1.0 + b2_SUN_DISC_SOFTNESS)));
    float innerCos = cos(radians(b2_SUN_DISC_RADIUS *(1.0 - b2_SUN_DISC_SOFTNESS)));
    vec4 specular = vec4(smoothstep(outerCos, innerCos, dot(rLight, vEye))* lightcolor, 1);
    vReflection += specular * b2_SUN_DISC_RADIANCE;




















    float NdotV = clamp(dot(vEye, vBumpTex), 0, 1);


    vec4 FresnelCoeffs = texture(fresnelLookup, vec2(NdotV, 0.5));

    policyColour = vReflection * FresnelCoeffs . g + vRefraction * FresnelCoeffs . r;





}

// ---- band 3: water_refraction_box_beer_disc_walls (2.5, 0.75, 10) ----
const float b3_ATTENUATION_DISTANCE = 7.5;
const float b3_STEPS_GRAZING = 2.5;
const float b3_STEPS_STEEP = 0.75;
const int b3_LOOP_CAP = 10;
const float b3_SPECULAR_STRENGTH = 2.0;
const float b3_SPECULAR_EXPONENT = 256.0;
const float b3_ABSORPTION_R = 0.29199016;
const float b3_ABSORPTION_G = 0.105950974;
const float b3_ABSORPTION_B = 0.096320346;
const float b3_SPECULAR_ROUGHNESS = 0.2;
const float b3_SUN_DISC_RADIUS = 5.0;
const float b3_SUN_DISC_SOFTNESS = 0.05;
const float b3_SUN_DISC_RADIANCE = 8.0;
const int b3_REFINE_STEPS = 3;
const float b3_REFLECT_DISTORTION = 0.1;
const float b3_BumptexMult = 1.0064104;
const float b3_refrCoeff = 0.7501876;
const vec4 b3_waterColor = vec4(0.011067333, 0.11872768, 0.25176466, 1.0);
const vec4 b3_reflectColor = vec4(1.0, 1.0, 1.0, 1.0);
void b3_main(void)
{



    vec3 vEye = normalize(varyingVecEye);
    vec3 vLight = normalize(varyingVecLight);


















    vec2 parallaxShift = vec2(0.0);





































    vec3 vBumpTexA = vec3(texture(normalMap, vTexCoord0 . xy + parallaxShift));
    vec3 vBumpTexB = vec3(texture(normalMap, vTexCoord1 . xy + parallaxShift));
    vec3 vBumpTexC = vec3(texture(normalMap, vTexCoord2 . xy + parallaxShift));
    vec3 vBumpTexD = vec3(texture(normalMap, vTexCoord3 . xy + parallaxShift));








    vec3 vBumpTex = normalize(2.0 *
        (vBumpTexA + vBumpTexB + vBumpTexC + vBumpTexD)- 4.0);





    vec3 vBumpTexMore = normalize(vBumpTex * vec3(1.0, b3_BumptexMult, 1.0));



    vec3 R = normalize(refract(- vEye, vBumpTexMore, b3_refrCoeff));



    float numsteps = mix(b3_STEPS_GRAZING, b3_STEPS_STEEP, - R . y);

    float stepsize = 1.0 / numsteps;

    R *= stepsize;


    float depth, olddepth;


    vec3 current_position = vec3(varyingVecWorldPosition);
    vec3 current_position_old = current_position;
    olddepth = 0;


    vec4 depthtex = texture(worldYComponent,(uTextureMatrix0 * vec4(current_position, 1)). xy);
    depth = depthtex . r;

    for(int i = 0;i < b3_LOOP_CAP;i ++)
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


    vec3 transmittance = exp(- vec3(b3_ABSORPTION_R, b3_ABSORPTION_G, b3_ABSORPTION_B)* travelLength);
    vRefraction = mix(b3_waterColor, vRefraction, vec4(transmittance, 1.0));










    if(depth > varyingVecWorldPosition . y)
    {
        vRefraction = b3_waterColor;
    }




















    R = normalize(reflect(- vEye, vBumpTexMore));

    R . y = max(R . y, 0.001);




    vec3 boxPlane = mix(boxMin, boxMax, step(0.0, R));
    vec3 boxT = abs(boxPlane - varyingVecWorldPosition)/ max(abs(R), vec3(1e-6));
    vec3 boxHit = varyingVecWorldPosition + min(boxT . x, boxT . z)* R;
    vec3 boxLookup = boxHit . y < boxMax . y ? boxHit - boxCapturePosition : R;
    vec4 vReflection = texture(boxReflectionTexture, normalize(boxLookup)* vec3(1, - 1, 1))* b3_reflectColor;








































































    vec3 rLight = dot(2 * vBumpTex, vLight)* vBumpTex - vLight;










    float outerCos = cos(radians(b3_SUN_DISC_RADIUS *(1.0 + b3_SUN_DISC_SOFTNESS)));
    float innerCos = cos(radians(b3_SUN_DISC_RADIUS *(1.0 - b3_SUN_DISC_SOFTNESS)));
    vec4 specular = vec4(smoothstep(outerCos, innerCos, dot(rLight, vEye))* lightcolor, 1);
    vReflection += specular * b3_SUN_DISC_RADIANCE;




















    float NdotV = clamp(dot(vEye, vBumpTex), 0, 1);


    vec4 FresnelCoeffs = texture(fresnelLookup, vec2(NdotV, 0.5));

    policyColour = vReflection * FresnelCoeffs . g + vRefraction * FresnelCoeffs . r;





}

// ---- band 4: water_refraction_box_beer_disc_walls (5, 1.5, 20) ----
const float b4_ATTENUATION_DISTANCE = 7.5;
const float b4_STEPS_GRAZING = 5.0;
const float b4_STEPS_STEEP = 1.5;
const int b4_LOOP_CAP = 20;
const float b4_SPECULAR_STRENGTH = 2.0;
const float b4_SPECULAR_EXPONENT = 256.0;
const float b4_ABSORPTION_R = 0.27812767;
const float b4_ABSORPTION_G = 0.10063275;
const float b4_ABSORPTION_B = 0.08921758;
const float b4_SPECULAR_ROUGHNESS = 0.2;
const float b4_SUN_DISC_RADIUS = 5.0;
const float b4_SUN_DISC_SOFTNESS = 0.05;
const float b4_SUN_DISC_RADIANCE = 8.0;
const int b4_REFINE_STEPS = 3;
const float b4_REFLECT_DISTORTION = 0.1;
const float b4_BumptexMult = 1.0044234;
const float b4_refrCoeff = 0.7501876;
const vec4 b4_waterColor = vec4(0.0068868212, 0.10838335, 0.23391381, 1.0);
const vec4 b4_reflectColor = vec4(1.0, 1.0, 1.0, 1.0);
void b4_main(void)
{



    vec3 vEye = normalize(varyingVecEye);
    vec3 vLight = normalize(varyingVecLight);


















    vec2 parallaxShift = vec2(0.0);





































    vec3 vBumpTexA = vec3(texture(normalMap, vTexCoord0 . xy + parallaxShift));
    vec3 vBumpTexB = vec3(texture(normalMap, vTexCoord1 . xy + parallaxShift));
    vec3 vBumpTexC = vec3(texture(normalMap, vTexCoord2 . xy + parallaxShift));
    vec3 vBumpTexD = vec3(texture(normalMap, vTexCoord3 . xy + parallaxShift));








    vec3 vBumpTex = normalize(2.0 *
        (vBumpTexA + vBumpTexB + vBumpTexC + vBumpTexD)- 4.0);





    vec3 vBumpTexMore = normalize(vBumpTex * vec3(1.0, b4_BumptexMult, 1.0));



    vec3 R = normalize(refract(- vEye, vBumpTexMore, b4_refrCoeff));



    float numsteps = mix(b4_STEPS_GRAZING, b4_STEPS_STEEP, - R . y);

    float stepsize = 1.0 / numsteps;

    R *= stepsize;


    float depth, olddepth;


    vec3 current_position = vec3(varyingVecWorldPosition);
    vec3 current_position_old = current_position;
    olddepth = 0;


    vec4 depthtex = texture(worldYComponent,(uTextureMatrix0 * vec4(current_position, 1)). xy);
    depth = depthtex . r;

    for(int i = 0;i < b4_LOOP_CAP;i ++)
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


    vec3 transmittance = exp(- vec3(b4_ABSORPTION_R, b4_ABSORPTION_G, b4_ABSORPTION_B)* travelLength);
    vRefraction = mix(b4_waterColor, vRefraction, vec4(transmittance, 1.0));










    if(depth > varyingVecWorldPosition . y)
    {
        vRefraction = b4_waterColor;
    }




















    R = normalize(reflect(- vEye, vBumpTexMore));

    R . y = max(R . y, 0.001);




    vec3 boxPlane = mix(boxMin, boxMax, step(0.0, R));
    vec3 boxT = abs(boxPlane - varyingVecWorldPosition)/ max(abs(R), vec3(1e-6));
    vec3 boxHit = varyingVecWorldPosition + min(boxT . x, boxT . z)* R;
    vec3 boxLookup = boxHit . y < boxMax . y ? boxHit - boxCapturePosition : R;
    vec4 vReflection = texture(boxReflectionTexture, normalize(boxLookup)* vec3(1, - 1, 1))* b4_reflectColor;








































































    vec3 rLight = dot(2 * vBumpTex, vLight)* vBumpTex - vLight;










    float outerCos = cos(radians(b4_SUN_DISC_RADIUS *(1.0 + b4_SUN_DISC_SOFTNESS)));
    float innerCos = cos(radians(b4_SUN_DISC_RADIUS *(1.0 - b4_SUN_DISC_SOFTNESS)));
    vec4 specular = vec4(smoothstep(outerCos, innerCos, dot(rLight, vEye))* lightcolor, 1);
    vReflection += specular * b4_SUN_DISC_RADIANCE;




















    float NdotV = clamp(dot(vEye, vBumpTex), 0, 1);


    vec4 FresnelCoeffs = texture(fresnelLookup, vec2(NdotV, 0.5));

    policyColour = vReflection * FresnelCoeffs . g + vRefraction * FresnelCoeffs . r;





}

// ---- the policy ----
const float POLICY_BOUND_0 = 5.532722070518892;
const float POLICY_BOUND_1 = 6.00681253955393;
const float POLICY_BOUND_2 = 8.254304351606809;
const float POLICY_BOUND_3 = 9.464718099663447;
const float POLICY_MARGIN = 0.00036996442637705153;
float policyMeasure()
{
    return length(varyingVecEye);
}
void main(void)
{
    float lm = log(policyMeasure());
    float t0 = smoothstep(-POLICY_MARGIN, POLICY_MARGIN, lm - log(POLICY_BOUND_0));
    float t1 = smoothstep(-POLICY_MARGIN, POLICY_MARGIN, lm - log(POLICY_BOUND_1));
    float t2 = smoothstep(-POLICY_MARGIN, POLICY_MARGIN, lm - log(POLICY_BOUND_2));
    float t3 = smoothstep(-POLICY_MARGIN, POLICY_MARGIN, lm - log(POLICY_BOUND_3));
    vec4 acc = vec4(0.0);
    float w;
    w = 1.0 - t0;
    if (w > 0.0) { b0_main(); acc += w * policyColour; }
    w = t0 - t1;
    if (w > 0.0) { b1_main(); acc += w * policyColour; }
    w = t1 - t2;
    if (w > 0.0) { b2_main(); acc += w * policyColour; }
    w = t2 - t3;
    if (w > 0.0) { b3_main(); acc += w * policyColour; }
    w = t3;
    if (w > 0.0) { b4_main(); acc += w * policyColour; }
    fragColor = acc;
}
