#version 450
// Thesis Algorithm 3 (FLSS fragment diffraction shader) with Algorithm 4 (texture blending)
// and the §1.4.3 colour transform. For every wavelength: lookup coordinates, the Taylor or
// Chebyshev sum over the terms of the Gaussian-windowed spectrum, |P|², CIE weights; then
// the gain factor C. The same shader draws BRDF maps (thesis §5) when OUTPUT_MODE says so.
// Output is linear (RGB, or XYZ / ρ for maps); the sRGB curve is applied on the CPU.
#include "interface.glsl"
#include "lookup.glsl"
#include "bessel.glsl"
#include "gain.glsl"
#include "colour.glsl"

layout(location = 0) in vec3 inWi;
layout(location = 1) in vec3 inWr;
layout(location = 2) in vec2 inUv;

layout(location = 0) out vec4 outColour;

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

// Lines 2–27: XYZ = C(ωi, ωr) · Σ_λ |P̂|² · weights(λ).
vec3 diffractionXyz(vec3 wi, vec3 wr) {
    float gainC = gainFactor(wi, wr);
    if (gainC == 0.0) {
        return vec3(0.0);
    }
    vec3 uvw = -wi - wr;                                             // line 3
    vec3 xyzPixelColor = vec3(0.0);
    for (int j = 0; j < LAMBDA_COUNT; ++j) {                         // line 4
        vec4 xyzWeights = getColorWeights(j);                        // line 5
        xyzPixelColor += spectralPower(uvw, xyzWeights.w * 1e-3) * xyzWeights.xyz; // line 25
    }
    return gainC * xyzPixelColor;                                    // line 27
}

vec3 safeNormalize(vec3 v) {
    float l = length(v);
    return l > 1e-20 ? v / l : vec3(0.0, 0.0, 1.0);
}

vec3 finiteOrZero(vec3 c) {
    return (any(isnan(c)) || any(isinf(c))) ? vec3(0.0) : c;
}

void main() {
    if (OUTPUT_MODE == MODE_MESH) {
        vec3 wi = safeNormalize(inWi);
        vec3 wr = safeNormalize(inWr);
        vec3 cDiffraction = xyzToLinearSrgb(diffractionXyz(wi, wr));  // line 28, eq. 1.10
        vec3 c = cDiffraction;
        if (TEXTURE_BLENDING) {
            vec3 cTexture = texture(surfaceTexture, inUv).rgb;
            vec3 h = safeNormalize(wi + wr);
            float f = schlickFresnel(clamp(dot(wr, h), 0.0, 1.0));
            c = textureBlend(cDiffraction, cTexture, f, params.lighting.z);
        }
        // Irradiance of the directional light on the surface, then the camera's exposure.
        float irradiance = max(wi.z, 0.0) * params.lighting.x;
        outColour = vec4(finiteOrZero(c * irradiance * params.lighting.y), 1.0);
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
    if (OUTPUT_MODE == MODE_MAP_XYZ) {
        outColour = vec4(finiteOrZero(diffractionXyz(wi, wr)), 1.0);
    } else {
        float rho = gainFactor(wi, wr);
        if (rho > 0.0) {
            rho *= spectralPower(-wi - wr, params.mapWi.w);
        }
        outColour = vec4(finiteOrZero(vec3(rho)), 1.0);
    }
}
