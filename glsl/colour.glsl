// Colour of thesis §1.4.2–1.4.3 and MODEL §5: CIE weights per spectral sample, XYZ → linear
// sRGB (IEC 61966-2-1; the D65 white is already in the weights) and texture blending.
#ifndef COLOUR_GLSL
#define COLOUR_GLSL
#include "interface.glsl"
#include "srgb.glsl"

// Weights of spectral sample j: xyz = CIE·D65·Δλ weight, w = λ in nm.
vec4 getColorWeights(int j) {
    return colourWeights[j];
}

// Eq. 1.10 with MODEL §5's matrix (srgb.glsl).
vec3 xyzToLinearSrgb(vec3 xyz) {
    return XYZ_TO_SRGB * xyz;
}

// Algorithm 4: c_out = (1 − w_d)·c_diffraction + (1 − α)·c_texture + w_d·c_texture,
// α = min(1, |F|) with F the Schlick reflectance.
vec3 textureBlend(vec3 cDiffraction, vec3 cTexture, float fresnelF, float wDiffuse) {
    float alpha = min(1.0, abs(fresnelF));
    vec3 diffractionDiff = (1.0 - wDiffuse) * cDiffraction;
    vec3 textSpec = (1.0 - alpha) * cTexture;
    vec3 textDiff = wDiffuse * cTexture;
    return diffractionDiff + textSpec + textDiff;
}

#endif
