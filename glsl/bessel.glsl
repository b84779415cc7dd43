// Bessel functions J_0..J_TERMS for the Jacobi–Anger (Chebyshev) expansion of MODEL §4, by
// Miller's downward recurrence: the same start index, seed, recurrence and normalisation as
// brdf::bessel::jn_all, with float-sized rescaling thresholds.
#ifndef BESSEL_GLSL
#define BESSEL_GLSL
#include "interface.glsl"

// brdf::bessel::miller_start: even index above TERMS and |a| where J is negligible.
int millerStart(float x) {
    int m = int(ceil(max(float(TERMS), x) + 20.0 + 6.0 * sqrt(x)));
    return m + (m % 2);
}

// J_0..J_TERMS of the current wavelength. A module-level array rather than an `out`
// parameter: arrays sized by specialisation constants are not reliably copied out of
// functions by every driver.
float besselJ[TERMS + 1];

// J_n(a) for n = 0..TERMS into besselJ; J_n(−a) = (−1)ⁿ J_n(a).
void besselJnAll(float a) {
    for (int n = 0; n <= TERMS; ++n) {
        besselJ[n] = 0.0;
    }
    float x = abs(a);
    if (x < 1e-4) {
        // Leading series term (x/2)ⁿ/n!: relative error ~x², below float precision here, and
        // the recurrence's 2k/x would overflow float before it could be rescaled.
        float t = 1.0;
        for (int n = 0; n <= TERMS; ++n) {
            besselJ[n] = (a < 0.0 && n % 2 == 1) ? -t : t;
            t *= 0.5 * x / float(n + 1);
        }
        return;
    }
    int start = millerStart(x);
    float jNext = 0.0;   // J_{k+1}
    float jCur = 1e-30;  // J_k, arbitrary tiny seed
    float norm = 0.0;
    for (int k = start; k >= 1; --k) {
        if (k <= TERMS) {
            besselJ[k] = jCur;
        }
        if (k % 2 == 0) {
            norm += 2.0 * jCur;
        }
        float jPrev = (2.0 * float(k) / x) * jCur - jNext;
        jNext = jCur;
        jCur = jPrev;
        if (abs(jCur) > 1e30) {
            // Only ratios matter: rescale everything accumulated so far.
            jCur *= 1e-30;
            jNext *= 1e-30;
            norm *= 1e-30;
            for (int n = 0; n <= TERMS; ++n) {
                besselJ[n] *= 1e-30;
            }
        }
    }
    besselJ[0] = jCur;
    norm += jCur;
    for (int n = 0; n <= TERMS; ++n) {
        besselJ[n] /= norm;
        if (a < 0.0 && n % 2 == 1) {
            besselJ[n] = -besselJ[n];
        }
    }
}

#endif
