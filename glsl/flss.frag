#version 450
// Variant `flss`: thesis Algorithm 3 (FLSS fragment diffraction shader) and the §1.4.3
// colour transform. For every wavelength: lookup coordinates, the Taylor or Chebyshev sum
// over the terms of the Gaussian-windowed spectrum, |P|², CIE weights; then the gain factor
// C. main() (Algorithm 4, BRDF maps) is shared with the other variants (shade.glsl).
#include "interface.glsl"
#include "flss.glsl"
#include "gain.glsl"

// Lines 2–27: XYZ = C(ωi, ωr) · Σ_λ |P̂|² · weights(λ).
vec3 diffractionXyz(vec3 wi, vec3 wr) {
    float gainC = gainFactor(wi, wr);
    if (gainC == 0.0) {
        return vec3(0.0);
    }
    return gainC * fullSpectrumXyz(-wi - wr);                        // lines 3, 27
}

#define SPECTRAL_MODE
#include "shade.glsl"
