// Variant `pq` (thesis §1.5.3, Algorithm 5, done right: MODEL §7): the spectrum of one
// period, interpolated from 3×3 of its DFT bins with the periodic sinc (Dirichlet kernel,
// with the phase the thesis dropped), times the periodic factor of N copies per axis. The
// two axes' factors multiply as complex numbers p + iq and the intensity scales with
// |p + iq|² = |F_x|²·|F_y|² (the thesis used √(p² + q²)). The period's bin m is the patch's
// bin M·m (a patch of M copies). Mirrors brdf::pq::{p_hat_period, power, xyz}.
// Defines diffractionXyz(); pq.frag adds main() (shade.glsl), pq_vertex.vert the vertex stage.
#ifndef PQ_GLSL
#define PQ_GLSL
#include "interface.glsl"
#include "lookup.glsl"
#include "bessel.glsl"
#include "colour.glsl"
#include "gain.glsl"

layout(set = 0, binding = 4, std140) uniform PqInfo {
    ivec4 copies;  // x, y: copies M of the period in the patch; z, w: taps per axis (1 or 3)
    vec4 period;   // x, y: period L (µm); z, w: samples per period n₁
    vec4 factor;   // x, y: copies N of the periodic factor (0: constant axis, Gaussian window);
                   // z, w: 2πσs (µm) of the coherence window
} pq;

const int PQ_TAPS = 3;

vec2 complexMul(vec2 a, vec2 b) {
    return vec2(a.x * b.x - a.y * b.y, a.x * b.y + a.y * b.x);
}

// Algorithm 5 line 2, corrected: the transform of one sampled period of n₁ samples at x bins
// from a DFT bin, e^{iπx(n₁−1)/n₁}·sin(πx)/(n₁ sin(πx/n₁)) (the thesis's sinc for large n₁).
vec2 sincWeightOf(float x, float n1) {
    float den = n1 * sin(PI * x / n1);
    float mag = abs(den) < 1e-6 ? 1.0 : sin(PI * x) / den;
    float phase = PI * x * (n1 - 1.0) / n1;
    return mag * vec2(cos(phase), sin(phase));
}

// |F/N|² of the periodic factor F = Σ_{n<N} e^{i n 2π s}: (sin(Nπf)/(N sin πf))², f = s − round(s).
// On a constant axis (N = 0) the coherence window's Gaussian, exp(−(2πσs·t/λ)²) (as FLSS).
float periodicIntensityOf(float s, float copies, float t, float twoPiSigma, float lambdaUm) {
    if (copies == 0.0) {
        float a = twoPiSigma * t / lambdaUm;
        return exp(-a * a);
    }
    float f = s - floor(s + 0.5);
    float den = copies * sin(PI * f);
    if (abs(den) < 1e-6) {
        return 1.0;
    }
    float r = sin(copies * PI * f) / den;
    return r * r;
}

// The taps along one axis: band index and complex weight of each (index −1: no tap).
void pqTaps(float s, int m, int taps, float n1, int n, int b, int x0, int width,
            out int index[PQ_TAPS], out vec2 weight[PQ_TAPS]) {
    int m0 = int(floor(s + 0.5));
    for (int i = 0; i < PQ_TAPS; ++i) {
        if (taps == 1) {
            index[i] = i == 0 ? bandIndex(b, n, x0, width) : -1;
            weight[i] = vec2(1.0, 0.0);
        } else {
            int mi = m0 - 1 + i;
            index[i] = bandIndex(b + mi * m, n, x0, width);
            weight[i] = sincWeightOf(s - float(mi), n1);
        }
    }
}

// |P̂|² of N_x × N_y copies at one wavelength: |P̂₁|²·|F_x F_y|².
float pqPower(vec3 uvw, float lambdaUm) {
    vec2 s = uvw.xy * pq.period.xy / lambdaUm;
    int col[PQ_TAPS];
    int row[PQ_TAPS];
    vec2 wx[PQ_TAPS];
    vec2 wy[PQ_TAPS];
    pqTaps(s.x, pq.copies.x, pq.copies.z, pq.period.z, params.spectrumSize.x,
           params.spectrumSize.z, params.band.x, params.band.z, col, wx);
    pqTaps(s.y, pq.copies.y, pq.copies.w, pq.period.w, params.spectrumSize.y,
           params.spectrumSize.w, params.band.y, params.band.w, row, wy);

    float k = 2.0 * PI / lambdaUm;
    if (EXPANSION == EXPANSION_CHEBYSHEV) {
        besselJnAll(k * uvw.z * params.lookup.w);
    }
    float kw = k * uvw.z;
    float taylorScaleF = 1.0;
    vec2 P = vec2(0.0);
    for (int n = 0; n <= TERMS; ++n) {
        vec2 f = vec2(0.0);
        for (int j = 0; j < PQ_TAPS; ++j) {
            if (row[j] < 0) {
                continue;
            }
            vec2 rowSum = vec2(0.0);
            for (int i = 0; i < PQ_TAPS; ++i) {
                if (col[i] < 0) {
                    continue;
                }
                rowSum += complexMul(rescaledFourierValueAt(ivec2(col[i], row[j]), n), wx[i]);
            }
            f += complexMul(rowSum, wy[j]);
        }
        if (EXPANSION == EXPANSION_TAYLOR) {
            P += taylorScaleF * f;
            taylorScaleF *= kw / float(n + 1);
        } else {
            float c = (n == 0 ? 1.0 : 2.0) * besselJ[n];
            int r = n % 4; // iⁿ: 1, i, −1, −i
            vec2 rotated = r == 0 ? f
                         : r == 1 ? vec2(-f.y, f.x)
                         : r == 2 ? -f
                         : vec2(f.y, -f.x);
            P += c * rotated;
        }
    }
    // Algorithm 5 line 3, corrected: the intensity scales with |p + iq|².
    return dot(P, P)
         * periodicIntensityOf(s.x, pq.factor.x, uvw.x, pq.factor.z, lambdaUm)
         * periodicIntensityOf(s.y, pq.factor.y, uvw.y, pq.factor.w, lambdaUm);
}

vec3 diffractionXyz(vec3 wi, vec3 wr) {
    float gainC = gainFactor(wi, wr);
    if (gainC == 0.0) {
        return vec3(0.0);
    }
    vec3 uvw = -wi - wr;
    vec3 xyz = vec3(0.0);
    // The colour table holds the wavelengths the variant keeps (leaving out drops the rest).
    int lambdaCount = colourWeights.length();
    for (int j = 0; j < lambdaCount; ++j) {
        vec4 xyzWeights = getColorWeights(j);
        xyz += pqPower(uvw, xyzWeights.w * 1e-3) * xyzWeights.xyz;
    }
    return gainC * xyz;
}

#endif
