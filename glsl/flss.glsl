// FLSS's per-wavelength evaluation (thesis Algorithm 3, lines 6–24): P̂(ku, kv) from the
// windowed DFT terms, and the full-spectrum sum. Shared by the variants that evaluate the
// spectrum per pixel (flss.frag, nmm.frag).
#ifndef FLSS_GLSL
#define FLSS_GLSL
#include "interface.glsl"
#include "lookup.glsl"
#include "bessel.glsl"
#include "colour.glsl"

const int TAPS = 2 * WINDOW_RADIUS + 1;

// Lines 7–24 for one wavelength: P̂(ku, kv) = Σ_n c_n · Ŵ_n(q) (MODEL §4), the windowed
// values Ŵ_n gathered over the (2R+1)² texels around floor(q) (MODEL §3).
vec2 spectralResponse(vec3 uvw, float lambdaUm) {
    vec2 q = getLookupCoords(uvw.xy, lambdaUm);                      // line 6, eq. 1.8
    ivec2 anchor = ivec2(floor(q));                                  // lines 12–13
    float k = 2.0 * PI / lambdaUm;                                   // line 8

    // The window's taps are the same for every term: band positions and Gaussian weights
    // once per wavelength (eq. 1.9 local coordinates, gaussWeightOf).
    int col[TAPS];
    int row[TAPS];
    float gx[TAPS];
    float gy[TAPS];
    for (int i = 0; i < TAPS; ++i) {
        int tx = anchor.x - WINDOW_RADIUS + i;
        int ty = anchor.y - WINDOW_RADIUS + i;
        col[i] = bandIndex(tx, params.spectrumSize.x, params.band.x, params.band.z);
        row[i] = bandIndex(ty, params.spectrumSize.y, params.band.y, params.band.w);
        gx[i] = gaussWeightOf(float(tx) - q.x, params.lookup.y);
        gy[i] = gaussWeightOf(float(ty) - q.y, params.lookup.z);
    }

    // Expansion coefficients c_n: Taylor (kw)ⁿ/n! built incrementally, or Chebyshev
    // ε_n iⁿ J_n(k·w·A) with iⁿ as a rotation of the complex plane.
    if (EXPANSION == EXPANSION_CHEBYSHEV) {
        besselJnAll(k * uvw.z * params.lookup.w);
    }
    float kw = k * uvw.z;
    float taylorScaleF = 1.0;

    vec2 P = vec2(0.0);                                              // line 7
    for (int n = 0; n <= TERMS; ++n) {                               // line 9
        vec2 fFft = vec2(0.0);                                       // line 11
        for (int j = 0; j < TAPS; ++j) {                             // line 15
            if (row[j] < 0) {
                continue;
            }
            vec2 rowSum = vec2(0.0);
            for (int i = 0; i < TAPS; ++i) {                         // line 14
                if (col[i] < 0) {
                    continue;
                }
                vec2 fftVal = rescaledFourierValueAt(ivec2(col[i], row[j]), n); // lines 17–18
                rowSum += fftVal * gx[i];                            // line 19
            }
            fFft += rowSum * gy[j];                                  // line 20
        }
        if (EXPANSION == EXPANSION_TAYLOR) {
            P += taylorScaleF * fFft;                                // lines 10, 23
            taylorScaleF *= kw / float(n + 1);
        } else {
            float c = (n == 0 ? 1.0 : 2.0) * besselJ[n];
            int r = n % 4; // iⁿ: 1, i, −1, −i
            vec2 rotated = r == 0 ? fFft
                         : r == 1 ? vec2(-fFft.y, fFft.x)
                         : r == 2 ? -fFft
                         : vec2(fFft.y, -fFft.x);
            P += c * rotated;
        }
    }
    return P;
}

// |P̂|² at one wavelength.
float spectralPower(vec3 uvw, float lambdaUm) {
    vec2 p = spectralResponse(uvw, lambdaUm);
    return dot(p, p);
}

// Lines 4–26: Σ_λ |P̂|² · weights(λ) over the wavelengths of binding 2: the colour table's,
// or only those whose weight matters when the renderer leaves the others out.
vec3 fullSpectrumXyz(vec3 uvw) {
    vec3 xyzPixelColor = vec3(0.0);
    int lambdaCount = colourWeights.length();
    for (int j = 0; j < lambdaCount; ++j) {                          // line 4
        vec4 xyzWeights = getColorWeights(j);                        // line 5
        xyzPixelColor += spectralPower(uvw, xyzWeights.w * 1e-3) * xyzWeights.xyz; // line 25
    }
    return xyzPixelColor;
}

#endif
