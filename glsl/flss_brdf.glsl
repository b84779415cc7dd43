// Variant `flss`'s BRDF, thesis Algorithm 3 lines 2–27: XYZ = C(ωi, ωr)·Σ_λ |P̂|²·weights(λ),
// the spectrum summed by flss.glsl. Included by its fragment stage (flss.frag) and its
// per-vertex stage (flss_vertex.vert), and through flss.frag by the environment-lit
// compute stages (build.rs).
#ifndef FLSS_BRDF_GLSL
#define FLSS_BRDF_GLSL
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

#endif
