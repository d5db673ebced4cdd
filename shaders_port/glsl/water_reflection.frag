#version 120
// Reflection and refraction pixel shader of Lipp, "Physically correct perturbed
// planar refractions & reflections in real time" (seed 000, section 3):
// the refraction part of water_refraction.frag, then raycast local reflections.
// Fixes against the documented text are listed in shaders_port/README.md.

// ---- BEGIN TUNABLE CONSTANTS (written by `study export`) ----
//travelLength==ATTENUATION_DISTANCE => fully attenuated to waterColor
const float ATTENUATION_DISTANCE = 7.5;
//raycast steps per unit of depth at a grazing (R.y=0) and a steep (R.y=-1) refraction ray
const float STEPS_GRAZING = 10.0;
const float STEPS_STEEP = 3.0;
//maximum number of raycast steps
const int LOOP_CAP = 40;
//reflection raycast steps per unit at a steep (R.y=1) and a grazing (R.y=0) reflection ray
const float REFL_STEPS_STEEP = 0.5;
const float REFL_STEPS_GRAZING = 4.0;
//maximum number of reflection raycast steps
const int REFL_LOOP_CAP = 60;
//end the reflection ray above this height (maximum height of the reflected scene)
const float REFL_HEIGHT_CUT = 0.8;
//specular strength and Phong exponent
const float SPECULAR_STRENGTH = 2.0;
const float SPECULAR_EXPONENT = 256.0;
//variant BEER_ATTENUATION: absorption coefficients per unit of travelLength (red, green, blue)
const float ABSORPTION_R = 0.13333334;
const float ABSORPTION_G = 0.13333334;
const float ABSORPTION_B = 0.13333334;
//variant GGX_SPECULAR: GGX roughness (alpha) of the specular lobe
const float SPECULAR_ROUGHNESS = 0.2;
//variant SUN_DISC_SPECULAR: the sun's disc, its angular radius at half brightness (degrees), the
//softness of its edge (0 hard, 1 a cone from its centre to twice the radius) and its radiance
const float SUN_DISC_RADIUS = 0.27;
const float SUN_DISC_SOFTNESS = 0.05;
const float SUN_DISC_RADIANCE = 1.0;
//variants BINARY_REFINE / SECANT_REFINE: refinement steps after the linear search
const int REFINE_STEPS = 3;
//multiplier to enhance normal-perturbation. 0=max perturbation 1=normal perturbation
uniform float BumptexMult = 1.0;
//refractioncoefficient = c_air/c_water
uniform float refrCoeff = 0.7501876;
//watercolor, for modulation of refracted color
uniform vec4 waterColor = vec4(0.05, 0.25, 0.3, 1.0);
//color for modulation of reflected light
uniform vec4 reflectColor = vec4(1.0, 1.0, 1.0, 1.0);
// ---- END TUNABLE CONSTANTS ----

//Refraction Texture, Rendered from Top
uniform sampler2D refractionTexture;
//Reflection Texture, Cubemap containing skybox
uniform samplerCube reflectionTexture;
//Normal pertubation map, defined in water-plane
uniform sampler2D normalMap;
//Y-components of geometry under the water, rendered from top
uniform sampler2D worldYComponent;
//Fresnel Lookup Texture, lookup from cos(theta) -> Transm. Coeff, Refr. Coeff
uniform sampler2D fresnelLookup;
//Y-components of geometry above the water, rendered from bottom
uniform sampler2D worldYComponentReflection;
//Reflection rendered orthogonal and perpendicular to water surface
uniform sampler2D reflectionBottom;

//color of specular highlight
uniform vec3 lightcolor;

//vectors set up by the vertex shader
//World space position of point on the water-plane
varying vec3 varyingVecWorldPosition;
//vector from varyingVecWorldPosition to worldspace Camera Position
varying vec3 varyingVecEye;
//vector from varyingVecWorldPosition to worldspace Light Position
varying vec3 varyingVecLight;

#ifdef SLOPE_NORMALS
//variant: the layers blended as slopes (partial-derivative blending, Barre-Brisebois and Hill
//2012): the normal of the layers' mean height, not the mean of their normals.
//A layer's slope (dh/dx, dh/dz) from its texel; texels tipped past 87 degrees are held there
vec2 layerSlope(vec3 texel)
{
    vec3 n = 2.0 * texel - 1.0;
    return -n.xz / max(n.y, 0.05);
}
#endif

#ifdef LEAN_NORMALS
//variant: LEAN mapping (Olano and Baker 2010): slopeMoments holds each texel's slope
//(dh/dx, dh/dz) and its squares (sx, sz, sx*sx, sz*sz), mipmapped and read trilinearly: a
//lookup's means over the pixel's footprint. The per-axis variance of the slopes the pixel does
//not resolve
uniform sampler2D slopeMoments;
float unresolvedVariance(vec4 moments)
{
    return 0.5 * (max(moments.z - moments.x * moments.x, 0.0)
        + max(moments.w - moments.y * moments.y, 0.0));
}
//radians squared to degrees squared
const float DEG2_PER_RAD2 = 3282.8064;
#endif

#ifdef PARALLAX_OFFSET
//variant: parallax offset mapping (Kaneko et al. 2001): heightMap holds the heights of the
//normal map's waves over the water plane, in tile lengths (texture-coordinate units)
uniform sampler2D heightMap;
#endif

void main (void)
{
    // ---- [1] Eye and light vectors ----
    //Get vectors to eye&light
    //Renormalize interpolated varying vectors
    vec3 vEye=normalize(varyingVecEye);
    vec3 vLight = normalize(varyingVecLight);

    // ---- [2] Normal map: average four layers, bump scaling ----
#ifdef PARALLAX_OFFSET
    //variant: the eye ray meets the waves at their height over the water plane's point: the
    //layers are read where it does, shifted along the view by the layers' mean height (one step)
#if defined(ONE_NORMAL_LAYER)
    float waveHeight = texture2D(heightMap, gl_TexCoord[0].xy).r;
#elif defined(TWO_NORMAL_LAYERS)
    float waveHeight = 0.5 * (texture2D(heightMap, gl_TexCoord[0].xy).r
        + texture2D(heightMap, gl_TexCoord[1].xy).r);
#else
    float waveHeight = 0.25 * (texture2D(heightMap, gl_TexCoord[0].xy).r
        + texture2D(heightMap, gl_TexCoord[1].xy).r
        + texture2D(heightMap, gl_TexCoord[2].xy).r
        + texture2D(heightMap, gl_TexCoord[3].xy).r);
#endif
    vec2 parallaxShift = waveHeight / max(vEye.y, 0.05) * vEye.xz;
#else
    vec2 parallaxShift = vec2(0.0);
#endif
#if defined(LEAN_NORMALS)
    //variant: the layers' mean slope over the pixel's footprint (the normal of their mean
    //height there) and the variance of the mean slope the pixel does not resolve
    vec4 vMomentsA = texture2D(slopeMoments, gl_TexCoord[0].xy);
#if defined(ONE_NORMAL_LAYER)
    vec2 meanSlope = vMomentsA.xy;
    float slopeVariance = unresolvedVariance(vMomentsA);
#elif defined(TWO_NORMAL_LAYERS)
    vec4 vMomentsB = texture2D(slopeMoments, gl_TexCoord[1].xy);
    vec2 meanSlope = 0.5 * (vMomentsA.xy + vMomentsB.xy);
    float slopeVariance = 0.25 * (unresolvedVariance(vMomentsA) + unresolvedVariance(vMomentsB));
#else
    vec4 vMomentsB = texture2D(slopeMoments, gl_TexCoord[1].xy);
    vec4 vMomentsC = texture2D(slopeMoments, gl_TexCoord[2].xy);
    vec4 vMomentsD = texture2D(slopeMoments, gl_TexCoord[3].xy);
    vec2 meanSlope = 0.25 * (vMomentsA.xy + vMomentsB.xy + vMomentsC.xy + vMomentsD.xy);
    float slopeVariance = 0.0625 * (unresolvedVariance(vMomentsA) + unresolvedVariance(vMomentsB)
        + unresolvedVariance(vMomentsC) + unresolvedVariance(vMomentsD));
#endif
    vec3 vBumpTex = normalize(vec3(-meanSlope.x, 1.0, -meanSlope.y));
#elif defined(ONE_NORMAL_LAYER)
    //variant: one layer only, transform from [0,1] to [-1,1]
    vec3 vBumpTexA = vec3(texture2D(normalMap, gl_TexCoord[0].xy + parallaxShift));
    vec3 vBumpTex = normalize( 2.0 * vBumpTexA - 1.0);
#elif defined(TWO_NORMAL_LAYERS)
    //variant: average the first two layers, transform from [0,1] to [-1,1]
    vec3 vBumpTexA = vec3(texture2D(normalMap, gl_TexCoord[0].xy + parallaxShift));
    vec3 vBumpTexB = vec3(texture2D(normalMap, gl_TexCoord[1].xy + parallaxShift));
#ifdef SLOPE_NORMALS
    vec2 meanSlope = 0.5 * (layerSlope(vBumpTexA) + layerSlope(vBumpTexB));
    vec3 vBumpTex = normalize(vec3(-meanSlope.x, 1.0, -meanSlope.y));
#else
    vec3 vBumpTex = normalize( 2.0 * (vBumpTexA+vBumpTexB) - 2.0);
#endif
#else
    //Sample normalmap at different locations
    vec3 vBumpTexA = vec3(texture2D(normalMap, gl_TexCoord[0].xy + parallaxShift));
    vec3 vBumpTexB = vec3(texture2D(normalMap, gl_TexCoord[1].xy + parallaxShift));
    vec3 vBumpTexC = vec3(texture2D(normalMap, gl_TexCoord[2].xy + parallaxShift));
    vec3 vBumpTexD = vec3(texture2D(normalMap, gl_TexCoord[3].xy + parallaxShift));

#ifdef SLOPE_NORMALS
    //variant: the mean of the layers' slopes, the normal of their mean height
    vec2 meanSlope = 0.25 * (layerSlope(vBumpTexA) + layerSlope(vBumpTexB)
        + layerSlope(vBumpTexC) + layerSlope(vBumpTexD));
    vec3 vBumpTex = normalize(vec3(-meanSlope.x, 1.0, -meanSlope.y));
#else
    //Average Bump Layers, transform from [0,1] to [-1,1]
    vec3 vBumpTex = normalize( 2.0 *
        (vBumpTexA+vBumpTexB+vBumpTexC+vBumpTexD) - 4.0);
#endif
#endif

    //Increase bumps: decrease y-component, then renormalize
    //This results in larger xz-components
    vec3 vBumpTexMore = normalize( vBumpTex*vec3(1.0,BumptexMult,1.0));

    // ---- [3] Refraction vector and step schedule ----
    //Calc correct refraction vector
    vec3 R = normalize(refract(-vEye, vBumpTexMore, refrCoeff));

    //Calculate ideal stepsize: If R.y = 0 the reflection ray is at an grazing angle => use maximum steps=10
    //at R.y=1: use minimum steps=3
    float numsteps = mix(STEPS_GRAZING,STEPS_STEEP,-R.y); //Linear Interpolate based on -R.y

    float stepsize= 1.0 / numsteps;
    //Scale Refraction vector with stepsize
    R*=stepsize;

    // ---- [4] Raycast the ground ----
    float depth, olddepth;

    //Start with approximation at vertex-world-position
    vec3 current_position = vec3(varyingVecWorldPosition);
    vec3 current_position_old=current_position;
    olddepth=0;

    //Fetch the depth of the water at the starting-position
    vec4 depthtex = texture2D(worldYComponent, ( gl_TextureMatrix[0]*vec4(current_position,1)).xy);
    depth = depthtex.r;

    for (int i=0; i<LOOP_CAP;i++)
    {
        //Save old position on ray
        current_position_old=current_position;
        //step further on ray
        current_position +=R;
        //save old depth
        olddepth=depth;

        //Fetch ground-depth for current position on ray
        depthtex = texture2D(worldYComponent, ( gl_TextureMatrix[0]*vec4(current_position,1)).xy);
        depth = depthtex.r;

        //Assume water plane is parallel to xz-plane
        //-> a comparison of world-space y can be used for water depth comp.
        if (depth> current_position.y )
        {
            break;
        }
    }

    // ---- [5] Interpolate the crossing ----
#if defined(BINARY_REFINE) || defined(SECANT_REFINE)
    //variants: shrink the bracket [current_position_old, current_position] REFINE_STEPS times,
    //at its middle (relief mapping) or at its secant crossing (parallax occlusion mapping)
    for (int j=0; j<REFINE_STEPS; j++)
    {
#if defined(BINARY_REFINE)
        vec3 middle_position = 0.5*(current_position_old+current_position);
#else
        vec3 middle_position = mix(current_position_old,current_position,
            (current_position_old.y-olddepth) / (current_position_old.y-current_position.y+depth-olddepth));
#endif
        float middle_depth = texture2D(worldYComponent, ( gl_TextureMatrix[0]*vec4(middle_position,1)).xy).r;
        if (middle_depth> middle_position.y)
        {
            current_position=middle_position;
            depth=middle_depth;
        }
        else
        {
            current_position_old=middle_position;
            olddepth=middle_depth;
        }
    }
#endif
    float cpoy=current_position_old.y;
    float cpy = current_position.y;

    current_position=mix(current_position_old,current_position,(cpoy-olddepth) / (cpoy-cpy+depth-olddepth));

    //Fetch Interpolated Refracted Position
    vec4 vRefraction = texture2D(refractionTexture, ( gl_TextureMatrix[0]*vec4(current_position,1)).xy);

    // ---- [6] Attenuation ----
    //Calculate distance Ray traveled through water
    float travelLength = length(current_position-varyingVecWorldPosition);
#ifdef BEER_ATTENUATION
    //variant: Beer-Lambert transmittance per colour channel, towards waterColor
    vec3 transmittance = exp(-vec3(ABSORPTION_R,ABSORPTION_G,ABSORPTION_B)*travelLength);
    vRefraction=mix(waterColor, vRefraction, vec4(transmittance,1.0));
#else
    //travelLength==7.5 => 1, travelLength=0 => 0
    travelLength = clamp( travelLength/ATTENUATION_DISTANCE, 0,1);
    //Calc new attenuated vRefraction
    vRefraction=mix(vRefraction, waterColor, travelLength);
#endif
#ifdef WALL_FACES
    //variant: the ray crossed into geometry that rises above the water plane (a pool wall),
    //so it hit that geometry's vertical face under the water, which the top-down textures do
    //not hold (they show its top): shade the face as water seen to full attenuation
    if (depth > varyingVecWorldPosition.y)
    {
        vRefraction = waterColor;
    }
#endif

    // ---- [7] Reflection ----
#ifndef NOREFLECTION
    //Calculate reflection vector
    R = normalize(reflect(-vEye, vBumpTexMore));
    //clamp y to 0.0001, else reflection vector would go into water
    R.y = max(R.y,0.001);
    R=normalize(R);
#endif

    //Calculate ideal stepsize: If 1-R.y = 1 the reflection ray is at an grazing angle
    numsteps = mix(REFL_STEPS_STEEP,REFL_STEPS_GRAZING,1-R.y);
    stepsize= 1.0 / numsteps;
    //scale Reflection ray with stepsize
    R*=stepsize;

    //Trace Ray!

    //Start at vertex position
    current_position = varyingVecWorldPosition;
    current_position_old=current_position;
    olddepth=0;
    depthtex = texture2D(worldYComponentReflection, (gl_TextureMatrix[1]*vec4(current_position,1)).xy);
    depth = depthtex.r;

    bool noHit=true;

    for (int i=0; i<REFL_LOOP_CAP;i++)
    {
        current_position_old=current_position;
        //Step further
        current_position +=R;
        //calculate texcoords for current position
        //Assume Water.y = 0
        vec2 texcoord= (gl_TextureMatrix[1]*vec4(current_position,1)).xy;

        //Outside of reflection texture? -> no hit!
        if ((texcoord.x<0)|| (texcoord.x>1)||
            (texcoord.y<0)|| (texcoord.y>1))
        {
            break;
        }

        //Fetch depth
        depthtex = texture2D(worldYComponentReflection, texcoord);
        olddepth=depth;
        depth = depthtex.r;

        //If we are below the reflection surface, we have a hit
        if (depth> current_position.y)
        {
            noHit=false;
            break;
        }

        //end if too high over water surface
        if (current_position.y>REFL_HEIGHT_CUT)
        {
            break;
        }
    }
    vec4 vReflection;

    if (!noHit)
    {
        //Interpolate, one step of zero-approximation
        float cpoy= current_position_old.y;
        float cpy = current_position.y;
        current_position=mix(current_position_old,current_position,
            (cpoy-olddepth) / (cpoy-cpy+depth-olddepth) );
        vReflection=texture2D(reflectionBottom, (gl_TextureMatrix[1]*vec4(current_position,1)).xy)*reflectColor;
    }
    else
    {
        //No hit with reflection surface -> just fetch color from cubemap
        //otherwise fetch color from reflection-texture
        vReflection = textureCube(reflectionTexture, normalize(R)*vec3(1,-1,1) )*reflectColor;
    }

    // ---- [8] Specular highlight ----
    //Calculate specular reflection

#if defined(GGX_SPECULAR)
    //variant: GGX microfacet lobe with Smith masking (Fresnel: the combine below)
    vec3 vHalf = normalize(vLight+vEye);
    float NdotH = clamp(dot(vBumpTex, vHalf),0,1);
    float NdotL = clamp(dot(vBumpTex, vLight),0,1);
    float NdotE = clamp(dot(vBumpTex, vEye),0,1);
    float alpha2 = SPECULAR_ROUGHNESS*SPECULAR_ROUGHNESS;
#ifdef LEAN_NORMALS
    //variant: the lobe widened by the unresolved slopes (Beckmann's alpha^2 = 2 variance)
    alpha2 += 2.0*slopeVariance;
#endif
    float ggxDenominator = NdotH*NdotH*(alpha2-1.0)+1.0;
    float ggxD = alpha2 / (3.14159265*ggxDenominator*ggxDenominator);
    float smithVis = 1.0 / ((NdotL+sqrt(alpha2+(1.0-alpha2)*NdotL*NdotL))
                          * (NdotE+sqrt(alpha2+(1.0-alpha2)*NdotE*NdotE)));
    vec4 specular = vec4(ggxD*smithVis*NdotL*lightcolor,1);
    vReflection+=specular*SPECULAR_STRENGTH;
#elif defined(SUN_DISC_SPECULAR)
    //variant: the sun's disc seen in the mirror of the normal, soft-edged (no lobe)
    vec3 rLight = dot(2*vBumpTex,vLight)*vBumpTex-vLight;
#ifdef LEAN_NORMALS
    //variant: the disc widened by the unresolved slopes: a normal tilted by slope s turns the
    //mirrored sun by 2 s radians; the disc of the same second moment, its radiance spread over it
    float wideRadius = sqrt(SUN_DISC_RADIUS*SUN_DISC_RADIUS + 16.0*DEG2_PER_RAD2*slopeVariance);
    float outerCos = cos(radians(wideRadius*(1.0+SUN_DISC_SOFTNESS)));
    float innerCos = cos(radians(wideRadius*(1.0-SUN_DISC_SOFTNESS)));
    vec4 specular = vec4(smoothstep(outerCos, innerCos, dot(rLight, vEye))*lightcolor,1);
    vReflection+=specular*(SUN_DISC_RADIANCE*(SUN_DISC_RADIUS*SUN_DISC_RADIUS)
        /(wideRadius*wideRadius));
#else
    float outerCos = cos(radians(SUN_DISC_RADIUS*(1.0+SUN_DISC_SOFTNESS)));
    float innerCos = cos(radians(SUN_DISC_RADIUS*(1.0-SUN_DISC_SOFTNESS)));
    vec4 specular = vec4(smoothstep(outerCos, innerCos, dot(rLight, vEye))*lightcolor,1);
    vReflection+=specular*SUN_DISC_RADIANCE;
#endif
#elif !defined(NO_SPECULAR)
    //Calculate specular Reflection vector
    vec3 rLight = dot(2*vBumpTex,vLight)*vBumpTex-vLight;
    //evaluate phong specular reflection model, modulate with lightcolor
#ifdef LEAN_NORMALS
    //variant: the lobe widened by the unresolved slopes (cos^n has the per-axis variance 1/n,
    //the mirrored light spreads by 4 variance), its energy kept
    float widen = 1.0 + 4.0*slopeVariance*SPECULAR_EXPONENT;
    vec4 specular = vec4(pow(clamp(dot(rLight, vEye),0,1),SPECULAR_EXPONENT/widen)*lightcolor,1);
    vReflection+=specular*(SPECULAR_STRENGTH/widen);
#else
    vec4 specular = vec4(pow(clamp(dot(rLight, vEye),0,1),SPECULAR_EXPONENT)*lightcolor,1);
    //multiply with specular strength (2)
    vReflection+=specular*SPECULAR_STRENGTH;
#endif
#endif

    // ---- [9] Fresnel combine ----
    //Fresnel
    float NdotV = clamp( dot(vEye, vBumpTex),0,1);

    //Lookup exact Fresnel Coefficients.
    vec4 FresnelCoeffs = texture2D(fresnelLookup, vec2(NdotV, 0.5)) ;

    gl_FragColor = vReflection*FresnelCoeffs.g+vRefraction*FresnelCoeffs.r;
}
