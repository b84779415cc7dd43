// Variant `nmm` (thesis §1.5.2 done right, MODEL §7): only the wavelengths whose lookup
// lands near a diffraction order of the grating, λ = d·|t|/ν for ν within ±2.5σν of an integer
// n ≥ 1 (t = u or v, d the period along that axis), 9 samples 0.625σν apart (trapezoid), each
// weighted by the Jacobian |dλ/dν| = λ²/(|t|·d) so the sum stays the spectral integral; near
// specular (the zeroth order covers every λ) the full spectrum. P̂ is FLSS's (same terms and
// taps).
// Mirrors brdf::nmm::{plan, xyz}.
// Defines diffractionXyz(); nmm.frag adds main() (shade.glsl), nmm_vertex.vert the vertex stage.
#ifndef NMM_GLSL
#define NMM_GLSL
#include "interface.glsl"
#include "flss.glsl"
#include "gain.glsl"

layout(set = 0, binding = 4, std140) uniform NmmInfo {
    vec4 period; // x: d along x, y: d along y (µm; 0: no period along that axis)
    vec4 extent; // x, y: patch size N·dH (µm)
    vec4 sigma;  // x, y: Gaussian window std σt (texels)
    vec4 lambdaRange; // x, y: shortest and longest wavelength sampled (nm; the kept ones)
} nmm;

// CIE·D65 density per nm, 1 nm apart from 380 nm (xyz).
layout(set = 0, binding = 5, std430) readonly buffer CieDensity {
    vec4 cieDensity[];
};

const int HALF_SAMPLES = 4;
const float LINE_SIGMAS = 2.5;
const float LAMBDA_MIN = 380.0;
const float LAMBDA_MAX = 780.0;

vec3 densityAt(float lambdaNm) {
    float x = lambdaNm - LAMBDA_MIN;
    int i = clamp(int(floor(x)), 0, int(LAMBDA_MAX - LAMBDA_MIN) - 1);
    float f = x - float(i);
    return mix(cieDensity[i].xyz, cieDensity[i + 1].xyz, f);
}

// Half-width of a line in ν along axis a: LINE_SIGMAS·σt·d/L.
float halfWidth(int a) {
    return LINE_SIGMAS * nmm.sigma[a] * nmm.period[a] / nmm.extent[a];
}

// Whether λ lies on a sampled line of an order along u (v-order samples there would count
// twice).
bool countedAlongU(vec2 uv, float lambdaNm) {
    float d = nmm.period.x;
    if (d <= 0.0) {
        return false;
    }
    float nu = d * abs(uv.x) * 1e3 / lambdaNm;
    float n = floor(nu + 0.5);
    return n >= 1.0 && abs(nu - n) <= halfWidth(0);
}

vec3 nmmXyz(vec3 uvw) {
    vec3 acc = vec3(0.0);
    for (int a = 0; a < 2; ++a) {
        float d = nmm.period[a];
        float t = abs(uvw[a]);
        if (d <= 0.0 || t == 0.0) {
            continue;
        }
        float delta = halfWidth(a);
        float dnu = delta / float(HALF_SAMPLES);
        float lambdaLo = nmm.lambdaRange.x;
        float lambdaHi = nmm.lambdaRange.y;
        int first = max(1, int(ceil(d * t * 1e3 / lambdaHi - delta)));
        int last = int(floor(d * t * 1e3 / lambdaLo + delta));
        for (int n = first; n <= last; ++n) {
            for (int j = -HALF_SAMPLES; j <= HALF_SAMPLES; ++j) {
                float lambda = d * t * 1e3 / (float(n) + float(j) * dnu);
                if (lambda < lambdaLo || lambda > lambdaHi) {
                    continue;
                }
                if (a == 1 && countedAlongU(uvw.xy, lambda)) {
                    continue;
                }
                float trapezoid = abs(j) == HALF_SAMPLES ? 0.5 : 1.0;
                float weight = trapezoid * dnu * lambda * lambda / (t * d * 1e3);
                acc += spectralPower(uvw, lambda * 1e-3) * densityAt(lambda) * weight;
            }
        }
    }
    return acc;
}

vec3 diffractionXyz(vec3 wi, vec3 wr) {
    float gainC = gainFactor(wi, wr);
    if (gainC == 0.0) {
        return vec3(0.0);
    }
    vec3 uvw = -wi - wr;
    // Zeroth order: within four window stds of DC at the longest wavelength.
    vec2 offset = abs(uvw.xy) * nmm.extent.xy / (LAMBDA_MAX * 1e-3);
    if (all(lessThanEqual(offset, 4.0 * nmm.sigma.xy))) {
        return gainC * fullSpectrumXyz(uvw);
    }
    return gainC * nmmXyz(uvw);
}

#endif
