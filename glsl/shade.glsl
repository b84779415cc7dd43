// main() of every fragment variant: thesis Algorithm 4 (texture blending) on meshes, and
// BRDF maps (thesis §5). The including variant defines
//   vec3 diffractionXyz(vec3 wi, vec3 wr)        — C(ωi, ωr)·Σ_λ |P̂|² weights (XYZ)
// and, with SPECTRAL_MODE defined,
//   float spectralPower(vec3 uvw, float lambdaUm) — |P̂|² at one wavelength.
// Output is linear (RGB, or XYZ / ρ for maps); the sRGB curve is applied on the CPU.
#ifndef SHADE_GLSL
#define SHADE_GLSL
#include "interface.glsl"
#include "gain.glsl"
#include "colour.glsl"
#include "sky.glsl"
#include "footprint_texture.glsl"

// Mesh mode: the tangent frame (T, B, N) in world space and ωr in it (diffraction.vert).
layout(location = 0) in vec3 inTangent;
layout(location = 1) in vec3 inWr;
layout(location = 2) in vec2 inUv;
layout(location = 3) in vec3 inBitangent;
layout(location = 4) in vec3 inNormal;

layout(location = 0) out vec4 outColour;

// Table variants whose table holds the light's disc (convolved into G at build time,
// brdf::table::prefilter_disc): the disc is shaded once, at its centre, with its whole
// weight. Every other variant sums the disc's directions.
layout(constant_id = 10) const bool DISC_PREFILTERED = false;

vec3 safeNormalize(vec3 v) {
    float l = length(v);
    return l > 1e-20 ? v / l : vec3(0.0, 0.0, 1.0);
}

vec3 finiteOrZero(vec3 c) {
    return (any(isnan(c)) || any(isinf(c))) ? vec3(0.0) : c;
}

void main() {
    if (OUTPUT_MODE == MODE_MESH) {
        vec3 wr = safeNormalize(inWr);
        vec3 cTexture = vec3(0.0);
        if (TEXTURE_BLENDING) {
            cTexture = params.shading.y * textureOverFootprint(surfaceTexture, inUv).rgb;
        }
        // The light's disc: Σ_k weight_k · shade(ωi_k), every direction shaded in full
        // (scene::TextureSpec::shade states the same on the CPU); one entry for a point.
        vec3 c = vec3(0.0);
        // The pixel's footprint in (u, v) at the light's centre, for a variant that reads
        // a table filtered to it (computed here, in uniform control flow).
        vec3 towardsCentre = -normalize(params.lightDirWorld.xyz);
        vec2 uvCentre = -(safeNormalize(vec3(dot(towardsCentre, inTangent),
                                             dot(towardsCentre, inBitangent),
                                             dot(towardsCentre, inNormal))) + wr).xy;
        gUvFootprint = vec4(dFdx(uvCentre), dFdy(uvCentre));
        int samples = DISC_PREFILTERED ? 1 : clamp(params.lightInfo.x, 1, MAX_DISK_SAMPLES);
        for (int k = 0; k < samples; ++k) {
            vec3 towardsLight = DISC_PREFILTERED ? -normalize(params.lightDirWorld.xyz)
                                                 : params.lightDisk[k].xyz;
            float weight = DISC_PREFILTERED ? 1.0 : params.lightDisk[k].w;
            // Algorithm 2, lines 7–8, on the interpolated frame.
            vec3 wi = safeNormalize(vec3(dot(towardsLight, inTangent),
                                         dot(towardsLight, inBitangent),
                                         dot(towardsLight, inNormal)));
            vec3 cDiffraction = xyzToLinearSrgb(diffractionXyz(wi, wr));  // line 28, eq. 1.10
            // Irradiance of this part of the light on the surface.
            float irradiance = max(wi.z, 0.0) * params.lighting.x;
            vec3 ck = cDiffraction;
            if (TEXTURE_BLENDING) {
                // t = gain·texture; Algorithm 4 lit by the sun.
                vec3 h = safeNormalize(wi + wr);
                float f = schlickFresnel(clamp(dot(wr, h), 0.0, 1.0));
                ck = textureBlend(cDiffraction, cTexture, f, params.lighting.z);
            }
            c += weight * irradiance * ck;
        }
        // Plus the scene's ambient light, a uniform sky (sky.glsl).
        if (TEXTURE_BLENDING) {
            c += uniformSky(wr, cTexture);
        }
        // Then the camera's exposure.
        outColour = vec4(finiteOrZero(c * params.lighting.y), 1.0);
        return;
    }

    // BRDF map: pixel (i, j), row j from the top, is ωr = (x, y, √(1 − x² − y²)).
    float s = params.mapInfo.x;
    float x = 2.0 * gl_FragCoord.x / s - 1.0;
    float y = 1.0 - 2.0 * gl_FragCoord.y / s;
    float r2 = x * x + y * y;
    if (r2 >= 1.0) {
        outColour = vec4(0.0, 0.0, 0.0, 1.0);
        return;
    }
    vec3 wr = vec3(x, y, sqrt(1.0 - r2));
    vec3 wi = params.mapWi.xyz;
#ifdef SPECTRAL_MODE
    if (OUTPUT_MODE == MODE_MAP_SPECTRAL) {
        float rho = gainFactor(wi, wr);
        if (rho > 0.0) {
            rho *= spectralPower(-wi - wr, params.mapWi.w);
        }
        outColour = vec4(finiteOrZero(vec3(rho)), 1.0);
        return;
    }
#endif
    vec3 c = diffractionXyz(wi, wr);
    if (OUTPUT_MODE == MODE_MAP_DISPLAY) {
        // The viewer draws the map into its sRGB swapchain, which applies the curve.
        c = xyzToLinearSrgb(c) * params.lighting.y;
    }
    outColour = vec4(finiteOrZero(c), 1.0);
}

#endif
