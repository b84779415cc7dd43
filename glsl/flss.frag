#version 450
// Variant `flss`: thesis Algorithm 3 (FLSS fragment diffraction shader) and the §1.4.3
// colour transform. For every wavelength: lookup coordinates, the Taylor or Chebyshev sum
// over the terms of the Gaussian-windowed spectrum, |P|², CIE weights; then the gain factor
// C (flss_brdf.glsl). main() (Algorithm 4, BRDF maps) is shared with the other variants
// (shade.glsl).
#include "flss_brdf.glsl"

#define SPECTRAL_MODE
#include "shade.glsl"
