// Spectrum lookup of thesis §1.4.1 and MODEL §3: lookup coordinates (eq. 1.8), the
// Gaussian window (eq. 1.9 local coordinates) and storage decoding (eq. 1.1). Mirrors
// spectrum::{lookup_coord, windowed, TermStack::texel} on the CPU.
#ifndef LOOKUP_GLSL
#define LOOKUP_GLSL
#include "interface.glsl"

// The DFT terms (Algorithm 1): one layer per term, the cropped band only.
layout(set = 0, binding = 1) uniform sampler2DArray dftTerms;

// Eq. 1.8: fractional texel q = b + u·N·dH/λ of frequency (u/λ, v/λ), full-spectrum index.
vec2 getLookupCoords(vec2 uv, float lambdaUm) {
    vec2 n = vec2(params.spectrumSize.xy);
    vec2 b = vec2(params.spectrumSize.zw);
    return b + uv * n * params.lookup.x / lambdaUm;
}

// Gaussian window weight of a tap at signed distance d (texels) along one axis, where
// inv2s2 = 1/(2σ²) (MODEL §3: σt = N·dH/(2πσs)).
float gaussWeightOf(float d, float inv2s2) {
    return exp(-d * d * inv2s2);
}

// The spectrum is periodic: wrap a texel index into [0, n). GLSL leaves % undefined for
// negative operands, so divide non-negative values only.
int wrapIndex(int t, int n) {
    return t >= 0 ? t - n * (t / n) : t + n * ((-t + n - 1) / n);
}

// Index of full-spectrum texel t inside the stored band, or -1 outside it (zero there,
// exactly as TermStack::texel).
int bandIndex(int t, int n, int x0, int width) {
    int local = wrapIndex(t, n) - x0;
    return (local >= 0 && local < width) ? local : -1;
}

// Eq. 1.1 inverted: the stored (normalised) value of term n at band texel pos, rescaled.
vec2 rescaledFourierValueAt(ivec2 pos, int n) {
    vec2 stored = texelFetch(dftTerms, ivec3(pos, n), 0).rg;
    if (STORAGE == STORAGE_RG32F) {
        return stored;
    }
    vec4 d = params.decode[n];
    return vec2(d.x + stored.x * d.y, d.z + stored.y * d.w);
}

#endif
