// The gain factor C(ωi, ωr) of MODEL §2 with Stam's geometric term (1+ωi·ωr)²/(w² cosθi cosθr),
// the Schlick Fresnel ratio R/R0 and Stam's V-cavity shadowing S. Mirrors brdf::gain.
#ifndef GAIN_GLSL
#define GAIN_GLSL
#include "interface.glsl"

// Schlick reflectance R = R0 + (1 − R0)(1 − ωr·H)^5.
float schlickFresnel(float cosRH) {
    float r0 = params.shading.x;
    float m = 1.0 - cosRH;
    float m2 = m * m;
    return r0 + (1.0 - r0) * m2 * m2 * m;
}

// Stam's appendix: S = min(1, 2(N·H)(N·ωr)/(ωr·H), 2(N·H)(N·ωi)/(ωr·H)).
float shadowingOf(float nH, float cosI, float cosR, float cosRH) {
    if (cosRH <= 0.0) {
        return 0.0;
    }
    float k = 2.0 * nH / cosRH;
    return min(1.0, min(k * cosR, k * cosI));
}

// C(ωi, ωr); 0 below either horizon. Finite for every pair of unit vectors.
float gainFactor(vec3 wi, vec3 wr) {
    float cosI = wi.z;
    float cosR = wr.z;
    if (cosI <= 0.0 || cosR <= 0.0) {
        return 0.0;
    }
    float w = cosI + cosR;
    // 1 + ωi·ωr as |ωi + ωr|²/2 (MODEL §2, brdf::gain): no cancellation where ωi·ωr → −1
    // (grazing specular), and exact in the relative sense near backscatter.
    vec3 h = wi + wr;
    float onePlus = 0.5 * dot(h, h);
    float c = onePlus * onePlus / (w * w * cosI * cosR);
    if (FRESNEL || SHADOWING) {
        h /= length(h); // |h| ≥ w > 0 above both horizons
        float cosRH = clamp(dot(wr, h), 0.0, 1.0);
        if (FRESNEL) {
            c *= schlickFresnel(cosRH) / params.shading.x;
        }
        if (SHADOWING) {
            c *= shadowingOf(h.z, cosI, cosR, cosRH);
        }
    }
    return (isnan(c) || isinf(c)) ? 0.0 : c;
}

#endif
