#version 330 core
#define SLOPE_NORMALS
#define WALL_FACES
#define SUN_DISC_SPECULAR
#define BEER_ATTENUATION
// core-profile names replacing GLSL 1.20 built-ins (see shaders_port/README.md)
uniform mat4 uModelViewProjectionMatrix;
uniform mat4 uModelViewProjectionMatrixInverse;
uniform mat3 uNormalMatrix;
uniform mat4 uTextureMatrix0;
in vec4 vTexCoord0;
in vec4 vTexCoord1;
in vec4 vTexCoord2;
in vec4 vTexCoord3;
out vec4 fragColor;
// Refraction pixel shader of Lipp, "Physically correct perturbed planar
// refractions & reflections in real time" (seed 000, section 2).
// Compile with NOREFLECTION defined for the refraction-only variant, with PLANAR_REFLECTION
// for the reflection of seed 004's mirrored camera offset by the wave normal (seed 002), with
// BOX_REFLECTION for a box-projected (local) cube map of the pool (Lagarde and Zanuttini), with
// SSR_REFLECTION for a screen-space reflection over the camera's depth buffer (engines' SSR).
// Fixes against the documented text are listed in shaders_port/README.md.

// ---- BEGIN TUNABLE CONSTANTS (written by `study export`) ----
//travelLength==ATTENUATION_DISTANCE => fully attenuated to waterColor
const float ATTENUATION_DISTANCE = 7.5;
//raycast steps per unit of depth at a grazing (R.y=0) and a steep (R.y=-1) refraction ray
const float STEPS_GRAZING = 2.5;
const float STEPS_STEEP = 0.75;
//maximum number of raycast steps
const int LOOP_CAP = 10;
//specular strength and Phong exponent
const float SPECULAR_STRENGTH = 2.0;
const float SPECULAR_EXPONENT = 256.0;
//variant BEER_ATTENUATION: absorption coefficients per unit of travelLength (red, green, blue)
const float ABSORPTION_R = 0.263941;
const float ABSORPTION_G = 0.08396034;
const float ABSORPTION_B = 0.06973038;
//variant GGX_SPECULAR: GGX roughness (alpha) of the specular lobe
const float SPECULAR_ROUGHNESS = 0.2;
//variant SUN_DISC_SPECULAR: the sun's disc, its angular radius at half brightness (degrees), the
//softness of its edge (0 hard, 1 a cone from its centre to twice the radius) and its radiance
const float SUN_DISC_RADIUS = 5.0;
const float SUN_DISC_SOFTNESS = 0.05;
const float SUN_DISC_RADIANCE = 8.0;
//variants BINARY_REFINE / SECANT_REFINE: refinement steps after the linear search
const int REFINE_STEPS = 3;
//variant PLANAR_REFLECTION: scale of the reflection distortion (seed 002's "0.1 factor")
const float REFLECT_DISTORTION = 0.1;
//multiplier to enhance normal-perturbation. 0=max perturbation 1=normal perturbation
uniform float BumptexMult = 0.98839724;
//refractioncoefficient = c_air/c_water
uniform float refrCoeff = 0.7501876;
//watercolor, for modulation of refracted color
uniform vec4 waterColor = vec4(0.0, 0.060772114, 0.1613289, 1.0);
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

//color of specular highlight
uniform vec3 lightcolor;
#ifdef BOX_REFLECTION
//the dry scene (walls, sky) captured as a cube map at boxCapturePosition, stored like
//reflectionTexture (texel of direction d holds the scene in direction d*vec3(1,-1,1))
uniform samplerCube boxReflectionTexture;
//the pool's walls as an axis-aligned box, world units; boxMax.y is the walls' top
uniform vec3 boxMin;
uniform vec3 boxMax;
//where boxReflectionTexture was captured, world units
uniform vec3 boxCapturePosition;
#endif
#ifdef SSR_REFLECTION
//the scene without the water seen by this camera: colour and window-space depth (1: nothing)
uniform sampler2D sceneColor;
uniform sampler2D sceneDepth;
//depth samples of the screen-space march
#define SSR_STEPS 4
//a surface up to this fraction of the view depth in front of the ray's previous sample is hit
#define SSR_THICKNESS 0.02
#endif
#ifdef PLANAR_REFLECTION
//the scene above the water seen by the mirrored camera (seed 004)
uniform sampler2D reflection_sampler;
//Projection * ModelView of the mirrored camera (seed 004)
uniform mat4 o2v_projection_reflection;
#endif

//vectors set up by the vertex shader
//World space position of point on the water-plane
in vec3 varyingVecWorldPosition;
//vector from varyingVecWorldPosition to worldspace Camera Position
in vec3 varyingVecEye;
//vector from varyingVecWorldPosition to worldspace Light Position
in vec3 varyingVecLight;

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
    float waveHeight = texture(heightMap, vTexCoord0.xy).r;
#elif defined(TWO_NORMAL_LAYERS)
    float waveHeight = 0.5 * (texture(heightMap, vTexCoord0.xy).r
        + texture(heightMap, vTexCoord1.xy).r);
#else
    float waveHeight = 0.25 * (texture(heightMap, vTexCoord0.xy).r
        + texture(heightMap, vTexCoord1.xy).r
        + texture(heightMap, vTexCoord2.xy).r
        + texture(heightMap, vTexCoord3.xy).r);
#endif
    vec2 parallaxShift = waveHeight / max(vEye.y, 0.05) * vEye.xz;
#else
    vec2 parallaxShift = vec2(0.0);
#endif
#if defined(LEAN_NORMALS)
    //variant: the layers' mean slope over the pixel's footprint (the normal of their mean
    //height there) and the variance of the mean slope the pixel does not resolve
    vec4 vMomentsA = texture(slopeMoments, vTexCoord0.xy);
#if defined(ONE_NORMAL_LAYER)
    vec2 meanSlope = vMomentsA.xy;
    float slopeVariance = unresolvedVariance(vMomentsA);
#elif defined(TWO_NORMAL_LAYERS)
    vec4 vMomentsB = texture(slopeMoments, vTexCoord1.xy);
    vec2 meanSlope = 0.5 * (vMomentsA.xy + vMomentsB.xy);
    float slopeVariance = 0.25 * (unresolvedVariance(vMomentsA) + unresolvedVariance(vMomentsB));
#else
    vec4 vMomentsB = texture(slopeMoments, vTexCoord1.xy);
    vec4 vMomentsC = texture(slopeMoments, vTexCoord2.xy);
    vec4 vMomentsD = texture(slopeMoments, vTexCoord3.xy);
    vec2 meanSlope = 0.25 * (vMomentsA.xy + vMomentsB.xy + vMomentsC.xy + vMomentsD.xy);
    float slopeVariance = 0.0625 * (unresolvedVariance(vMomentsA) + unresolvedVariance(vMomentsB)
        + unresolvedVariance(vMomentsC) + unresolvedVariance(vMomentsD));
#endif
    vec3 vBumpTex = normalize(vec3(-meanSlope.x, 1.0, -meanSlope.y));
#elif defined(ONE_NORMAL_LAYER)
    //variant: one layer only, transform from [0,1] to [-1,1]
    vec3 vBumpTexA = vec3(texture(normalMap, vTexCoord0.xy + parallaxShift));
    vec3 vBumpTex = normalize( 2.0 * vBumpTexA - 1.0);
#elif defined(TWO_NORMAL_LAYERS)
    //variant: average the first two layers, transform from [0,1] to [-1,1]
    vec3 vBumpTexA = vec3(texture(normalMap, vTexCoord0.xy + parallaxShift));
    vec3 vBumpTexB = vec3(texture(normalMap, vTexCoord1.xy + parallaxShift));
#ifdef SLOPE_NORMALS
    vec2 meanSlope = 0.5 * (layerSlope(vBumpTexA) + layerSlope(vBumpTexB));
    vec3 vBumpTex = normalize(vec3(-meanSlope.x, 1.0, -meanSlope.y));
#else
    vec3 vBumpTex = normalize( 2.0 * (vBumpTexA+vBumpTexB) - 2.0);
#endif
#else
    //Sample normalmap at different locations
    vec3 vBumpTexA = vec3(texture(normalMap, vTexCoord0.xy + parallaxShift));
    vec3 vBumpTexB = vec3(texture(normalMap, vTexCoord1.xy + parallaxShift));
    vec3 vBumpTexC = vec3(texture(normalMap, vTexCoord2.xy + parallaxShift));
    vec3 vBumpTexD = vec3(texture(normalMap, vTexCoord3.xy + parallaxShift));

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
    vec4 depthtex = texture(worldYComponent, ( uTextureMatrix0*vec4(current_position,1)).xy);
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
        depthtex = texture(worldYComponent, ( uTextureMatrix0*vec4(current_position,1)).xy);
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
        float middle_depth = texture(worldYComponent, ( uTextureMatrix0*vec4(middle_position,1)).xy).r;
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
    vec4 vRefraction = texture(refractionTexture, ( uTextureMatrix0*vec4(current_position,1)).xy);

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

#ifndef NOREFLECTION

    // ---- [7] Reflection ----
#ifdef PLANAR_REFLECTION
    //variant: seed 004's mirrored camera read by projective texturing at the surface point,
    //offset by the projected, flattened wave normal (seed 002), as in water_baseline.frag
    vec4 vClipReflection = o2v_projection_reflection * vec4(varyingVecWorldPosition.x, 0.0, varyingVecWorldPosition.z, 1.0);
    vec2 vTextureReflection = vec2(0.5, 0.5) + 0.5 * vClipReflection.st / vClipReflection.q;
    vec3 flatNormal = vBumpTex - dot (vBumpTex, vec3(0.0, 1.0, 0.0)) * vec3(0.0, 1.0, 0.0);
    vec3 eyeNormal = uNormalMatrix * flatNormal;
    //a flat normal must not deform the image: no offset where eyeNormal.xy is 0
    vec2 reflectOffset = length(eyeNormal.xy) > 0.0 ?
        normalize (eyeNormal.xy) * length (flatNormal) * REFLECT_DISTORTION : vec2(0.0, 0.0);
    //the mirrored camera's texture is flipped in y: the offset's vertical part enters negated
    vTextureReflection += vec2(reflectOffset.x, -reflectOffset.y);
    vec4 vReflection = vec4(texture(reflection_sampler, vTextureReflection).rgb, 1.0)*reflectColor;
#else
    //Calculate reflection Vector
    R = normalize(reflect(-vEye, vBumpTexMore));
    //clamp y to 0.0001, else reflection vector would go into water
    R.y = max(R.y,0.001);
#ifdef BOX_REFLECTION
    //variant: local cube map (Lagarde and Zanuttini). The reflected ray leaves the box of the
    //pool's walls: through a wall below the walls' top it sees that wall, looked up from the
    //capture point; through the top it sees the distant sky, looked up along R itself
    vec3 boxPlane = mix(boxMin, boxMax, step(0.0, R));
    vec3 boxT = abs(boxPlane - varyingVecWorldPosition) / max(abs(R), vec3(1e-6));
    vec3 boxHit = varyingVecWorldPosition + min(boxT.x, boxT.z)*R;
    vec3 boxLookup = boxHit.y < boxMax.y ? boxHit - boxCapturePosition : R;
    vec4 vReflection = texture(boxReflectionTexture, normalize(boxLookup)*vec3(1,-1,1) )*reflectColor;
#elif defined(SSR_REFLECTION)
    //variant: screen-space reflection (engines' SSR). The ray's homogeneous points are
    //mix(ssrStart, ssrRay, u), u in [0,1] (1: its point at infinity); it leaves the plane
    //f = w+x, w-x, w+y, w-y, w+z, w-z >= 0 of the view frustum at u = f0/(f0-min(fR,0))
    vec4 ssrStart = uModelViewProjectionMatrix * vec4(varyingVecWorldPosition, 1.0);
    vec4 ssrRay = uModelViewProjectionMatrix * vec4(R, 0.0);
    vec3 ssrPlus = ssrStart.www + ssrStart.xyz;
    vec3 ssrMinus = ssrStart.www - ssrStart.xyz;
    vec3 ssrExit = min(ssrPlus / (ssrPlus - min(ssrRay.www + ssrRay.xyz, 0.0)),
        ssrMinus / (ssrMinus - min(ssrRay.www - ssrRay.xyz, 0.0)));
    vec4 ssrEnd = mix(ssrStart, ssrRay, min(min(ssrExit.x, ssrExit.y), ssrExit.z));
    //window coordinates (s, t, depth) of its start and exit: linear on the screen between them
    vec3 ssrFrom = 0.5 * ssrStart.xyz / ssrStart.w + 0.5;
    vec3 ssrTo = 0.5 * ssrEnd.xyz / ssrEnd.w + 0.5;
    vec3 ssrPrevious = ssrFrom;
    //view depths (clip w) from window coordinates: 1/(MVP^-1 (2p-1, 1)).w
    float ssrPreviousW = 1.0 / (uModelViewProjectionMatrixInverse * vec4(2.0*ssrFrom - 1.0, 1.0)).w;
    vec3 ssrHit = ssrFrom;
    bool ssrFound = false;
    //SSR_STEPS equal steps on the screen; a hit: the depth buffer holds a surface (not 1), the
    //sample is behind it, and it is at most SSR_THICKNESS of the view depth in front of the
    //previous sample (the ray passed behind it during this step)
    for (int k=1; k<=SSR_STEPS; k++)
    {
        vec3 ssrSample = mix(ssrFrom, ssrTo, float(k) / float(SSR_STEPS));
        float sceneZ = texture(sceneDepth, ssrSample.xy).r;
        float sceneW = 1.0 / (uModelViewProjectionMatrixInverse * vec4(2.0*vec3(ssrSample.xy, sceneZ) - 1.0, 1.0)).w;
        if (sceneZ < 1.0 && sceneZ <= ssrSample.z && sceneW >= ssrPreviousW * (1.0 - SSR_THICKNESS))
        {
            //refined without a fetch: where the step's depth reaches the depth found (the
            //step's start where that depth is nearer than the step)
            ssrHit = mix(ssrPrevious, ssrSample, clamp(
                (sceneZ - ssrPrevious.z) / max(ssrSample.z - ssrPrevious.z, 1e-30), 0.0, 1.0));
            ssrFound = true;
            break;
        }
        ssrPrevious = ssrSample;
        ssrPreviousW = 1.0 / (uModelViewProjectionMatrixInverse * vec4(2.0*ssrSample - 1.0, 1.0)).w;
    }
    //the scene's colour at the hit, else the sky cube map as the original reads it
    vec4 vReflection = (ssrFound ? vec4(texture(sceneColor, ssrHit.xy).rgb, 1.0)
        : texture(reflectionTexture, normalize(R)*vec3(1,-1,1) ))*reflectColor;
#else
    //Fetch from cubemap, modulate with reflectColor
    //Somehow y-component is inverted, so it is rescaled with -1.
    //probably a bug in my code.
    vec4 vReflection = texture(reflectionTexture, normalize(R)*vec3(1,-1,1) )*reflectColor;
#endif
#endif

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
    vec4 FresnelCoeffs = texture(fresnelLookup, vec2(NdotV, 0.5)) ;

    fragColor = vReflection*FresnelCoeffs.g+vRefraction*FresnelCoeffs.r;

#else
    //No Reflection
    fragColor=vRefraction;
#endif
}
