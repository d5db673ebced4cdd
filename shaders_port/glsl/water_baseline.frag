#version 120
// The baseline game water shader: seeds 001-004 composed as a game would build them.
//   001 planar refraction (Refract() of the depth-buffer point, applied backwards on screen),
//   003 normal-map distortion of the scene texture with chromatic dispersion,
//   004 planar reflection from the mirrored camera read by projective texturing,
//   002 that reflection lookup offset by the projected, flattened wave normal;
// plus the depth tint, Phong highlight and Fresnel LUT of seed 000 (the seeds have none).
// Defines: FLAT_WATER (no normal map, no distortion: 001 + 004, the flat-water limit),
//          NO_PLANAR_REFRACTION (no 001: the scene texture is read at the fragment itself),
//          NO_REFRACTION (no refracted light: the water is its own colour, as 002 and 004 alone),
//          CUBE_REFLECTION (seed 000's sky cube map in place of 004's mirrored camera).
// Fixes against the documented text are listed in shaders_port/README.md.

// ---- BEGIN TUNABLE CONSTANTS (written by `study export`) ----
//travelLength==ATTENUATION_DISTANCE => fully tinted to waterColor (depth tint)
const float ATTENUATION_DISTANCE = 7.5;
//specular strength and Phong exponent
const float SPECULAR_STRENGTH = 2.0;
const float SPECULAR_EXPONENT = 256.0;
//seed 002: scale of the reflection distortion ("the 0.1 factor")
const float REFLECT_DISTORTION = 0.1;
//seed 001: 1/refractive index
uniform float refractionIndex = 0.7501876;
//seed 003: refraction strength and chromatic dispersion (texture units)
uniform float refractionStrength = 0.02;
uniform float chromaticDispersion = 0.002;
//watercolor, for the depth tint of the refracted color
uniform vec4 waterColor = vec4(0.05, 0.25, 0.3, 1.0);
//color for modulation of reflected light
uniform vec4 reflectColor = vec4(1.0, 1.0, 1.0, 1.0);
// ---- END TUNABLE CONSTANTS ----

//the scene without the water, seen by this camera: color and window-space depth
uniform sampler2D sceneColor;
uniform sampler2D sceneDepth;
#ifdef CUBE_REFLECTION
//Reflection Texture, Cubemap containing skybox (seed 000)
uniform samplerCube reflectionTexture;
#else
//the scene above the water seen by the mirrored camera (seed 004)
uniform sampler2D reflection_sampler;
#endif
//Normal pertubation map, defined in water-plane
uniform sampler2D normalMap;
//Fresnel Lookup Texture, lookup from cos(theta) -> Transm. Coeff, Refr. Coeff
uniform sampler2D fresnelLookup;

//Projection * ModelView of the mirrored camera (seed 004)
uniform mat4 o2v_projection_reflection;
//viewport size in pixels
uniform vec2 screenSize;
//worldspace camera position
uniform vec3 viewpos;
//color of specular highlight
uniform vec3 lightcolor;

//the water plane y = 0: normal and distance along it (seed 001's `surface`)
const vec4 waterPlane = vec4(0.0, 1.0, 0.0, 0.0);
//undeformed mirror normal (seed 002)
const vec3 mirrorNormal = vec3(0.0, 1.0, 0.0);

//vectors set up by the vertex shader
//World space position of point on the water-plane
varying vec3 varyingVecWorldPosition;
//vector from varyingVecWorldPosition to worldspace Camera Position
varying vec3 varyingVecEye;
//vector from varyingVecWorldPosition to worldspace Light Position
varying vec3 varyingVecLight;

#if !defined(NO_PLANAR_REFRACTION) && !defined(NO_REFRACTION)
//seed 001: the perceived position of a world position seen through the plane `surface`
vec3 Refract(vec3 position, vec4 surface, float refractionIndex)
{
    //ray origin is the camera position
    vec3 viewerPosition = viewpos;
    //ray end is the vertex's undistorted position
    vec3 vertexPosition = position;
    //get the vector from the camera to the vertex
    vec3 worldRay = vertexPosition - viewerPosition;
    //normalize it for direction
    vec3 worldRayDir = normalize(worldRay);

    //surface is a vector4 that defines a plane
    vec3 worldPlaneNormal = surface.xyz;
    //define a known position on the plane
    vec3 worldPlaneOrigin = worldPlaneNormal * surface.w;

    //get the vector result of the worldRay entering the water
    vec3 refraction = refract(worldRayDir, normalize(worldPlaneNormal), refractionIndex);

    //raycast from the vertex, backwards along the refraction vector
    float denom = dot(-worldPlaneNormal, -refraction);
    vec3 p010 = worldPlaneOrigin - vertexPosition;
    float t = dot(p010, -worldPlaneNormal) / denom;
    vec3 intersection = vertexPosition + refraction * -t;

    //get the vector from the camera to the intersection, this is the perceived position
    vec3 originToIntersection = intersection - viewerPosition;
    //starting from the camera, move along the perceived position vector by the original ray length
    return viewerPosition + normalize(originToIntersection) * length(worldRay);
}
#endif

void main (void)
{
    // ---- [1] Eye and light vectors ----
    //Renormalize interpolated varying vectors
    vec3 vEye=normalize(varyingVecEye);
    vec3 vLight = normalize(varyingVecLight);

    // ---- [2] Normal map: average four layers ----
#ifndef FLAT_WATER
    //Sample normalmap at different locations
    vec3 vBumpTexA = vec3(texture2D(normalMap, gl_TexCoord[0].xy));
    vec3 vBumpTexB = vec3(texture2D(normalMap, gl_TexCoord[1].xy));
    vec3 vBumpTexC = vec3(texture2D(normalMap, gl_TexCoord[2].xy));
    vec3 vBumpTexD = vec3(texture2D(normalMap, gl_TexCoord[3].xy));

    //Average Bump Layers, transform from [0,1] to [-1,1]
    vec3 vBumpTex = normalize( 2.0 *
        (vBumpTexA+vBumpTexB+vBumpTexC+vBumpTexD) - 4.0);
#else
    vec3 vBumpTex = mirrorNormal;
#endif

#ifndef NO_REFRACTION
    // ---- [3] Planar refraction (seed 001) ----
    //window coordinate of this fragment in [0,1]^2 (seed 003's bumpUV)
    vec2 bumpUV = vec2(gl_FragCoord.x / screenSize.x, gl_FragCoord.y / screenSize.y);
    //world position of the scene point seen here without the water, from the depth buffer
    float sceneZ = texture2D(sceneDepth, bumpUV).r;
    vec4 groundClip = gl_ModelViewProjectionMatrixInverse * vec4(2.0 * vec3(bumpUV, sceneZ) - 1.0, 1.0);
    vec3 groundPosition = groundClip.xyz / groundClip.w;
#ifndef NO_PLANAR_REFRACTION
    //where seed 001's vertex shader draws that point
    vec4 apparentClip = gl_ModelViewProjectionMatrix * vec4(Refract(groundPosition, waterPlane, refractionIndex), 1.0);
    vec2 apparentUV = vec2(0.5, 0.5) + 0.5 * apparentClip.xy / apparentClip.w;
    //the point drawn here is (to first order) the one seen where that displacement starts
    vec2 refractedUV = bumpUV - (apparentUV - bumpUV);
#else
    vec2 refractedUV = bumpUV;
#endif

    // ---- [4] Normal-map distortion and chromatic dispersion (seed 003) ----
#ifndef FLAT_WATER
    //the tangent-space bump.xy of the seed is the xz of this world-space (y up) normal
    vec2 bump = vBumpTex.xz;
    // Displace texture coordinates
    vec2 newUV = refractedUV + bump * refractionStrength;
    // Final refraction color (With chromatic dispersion)
    vec3 refractionColor = vec3(texture2D(sceneColor, newUV - chromaticDispersion).r,
        texture2D(sceneColor, newUV).g, texture2D(sceneColor, newUV - chromaticDispersion).b);
#else
    vec3 refractionColor = vec3(texture2D(sceneColor, refractedUV));
#endif
    vec4 vRefraction = vec4(refractionColor, 1.0);

    // ---- [5] Depth tint ----
    //distance the view ray travels below the water surface (depth buffer, unrefracted)
    float travelLength = length(groundPosition-varyingVecWorldPosition);
    travelLength = clamp( travelLength/ATTENUATION_DISTANCE, 0.0, 1.0);
    vRefraction=mix(vRefraction, waterColor, travelLength);
#else
    //no refracted light: the water's own colour (the depth tint's limit)
    vec4 vRefraction = waterColor;
#endif

#ifdef CUBE_REFLECTION
    // ---- [6] Sky cube-map reflection (seed 000) ----
    //Calculate reflection Vector
    vec3 R = normalize(reflect(-vEye, vBumpTex));
    //clamp y to 0.0001, else reflection vector would go into water
    R.y = max(R.y,0.001);
    //Fetch from cubemap (its y flipped as in seed 000), modulate with reflectColor
    vec4 vReflection = textureCube(reflectionTexture, normalize(R)*vec3(1,-1,1) )*reflectColor;
#else
    // ---- [6] Planar reflection (seed 004), distorted by the wave normal (seed 002) ----
    vec4 vClipReflection = o2v_projection_reflection * vec4(varyingVecWorldPosition.x, 0.0, varyingVecWorldPosition.z, 1.0);
    vec2 vDeviceReflection = vClipReflection.st / vClipReflection.q;
    vec2 vTextureReflection = vec2(0.5, 0.5) + 0.5 * vDeviceReflection;
#ifndef FLAT_WATER
    vec3 flatNormal = vBumpTex - dot (vBumpTex, mirrorNormal) * mirrorNormal;
    vec3 eyeNormal = gl_NormalMatrix * flatNormal;
    //a flat normal must not deform the image: no offset where eyeNormal.xy is 0 (normalize(0) is NaN)
    vec2 reflectOffset = length(eyeNormal.xy) > 0.0 ?
        normalize (eyeNormal.xy) * length (flatNormal) * REFLECT_DISTORTION : vec2(0.0, 0.0);
    //004's mirrored camera is flipped in y (t = 1 - gl_FragCoord.y / height): 002's offset is in
    //window coordinates, so its vertical part enters this coordinate with the opposite sign
    vTextureReflection += vec2(reflectOffset.x, -reflectOffset.y);
#endif
    vec4 reflectionTextureColor = texture2D(reflection_sampler, vTextureReflection);
    // Framebuffer reflection can have alpha > 1
    reflectionTextureColor.a = 1.0;
    vec4 vReflection = reflectionTextureColor*reflectColor;
#endif

    // ---- [7] Specular highlight ----
    //Calculate specular Reflection vector
    vec3 rLight = dot(2.0*vBumpTex,vLight)*vBumpTex-vLight;
    //evaluate phong specular reflection model, modulate with lightcolor
    vec4 specular = vec4(pow(clamp(dot(rLight, vEye),0.0,1.0),SPECULAR_EXPONENT)*lightcolor,1.0);
    vReflection+=specular*SPECULAR_STRENGTH;

    // ---- [8] Fresnel combine ----
    float NdotV = clamp( dot(vEye, vBumpTex),0.0,1.0);
    //Lookup exact Fresnel Coefficients.
    vec4 FresnelCoeffs = texture2D(fresnelLookup, vec2(NdotV, 0.5)) ;
    gl_FragColor = vReflection*FresnelCoeffs.g+vRefraction*FresnelCoeffs.r;
}
