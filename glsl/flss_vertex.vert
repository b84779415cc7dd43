#version 450
// Variant `flss` evaluated per vertex (thesis §1.5.1): Algorithm 3 in the vertex stage.
#include "interface.glsl"
#include "flss.glsl"
#include "gain.glsl"

// As flss.frag: XYZ = C(ωi, ωr)·Σ_λ |P̂|²·weights(λ).
vec3 diffractionXyz(vec3 wi, vec3 wr) {
    float gainC = gainFactor(wi, wr);
    if (gainC == 0.0) {
        return vec3(0.0);
    }
    return gainC * fullSpectrumXyz(-wi - wr);
}

#include "per_vertex.glsl"
