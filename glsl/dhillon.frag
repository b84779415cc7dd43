#version 450
// Variant `dhillon` (Dhillon et al. 2014's form): G = Σ_p I_p(u, v)·ŵ^p, tables of the
// powers of ŵ = (w − w_c)/w_h, the reachable w interval mapped onto [−1, 1] (raw powers of
// w are hopelessly conditioned on a narrow interval). One bilinear fetch per power,
// Horner's rule in ŵ. The planes are fitted from the f64 table; the build refuses a table
// whose float32 sum would miss the tolerance.
#include "interface.glsl"
#include "gain.glsl"
#include "table.glsl"

layout(set = 0, binding = 1) uniform sampler2DArray gPowers;

vec3 diffractionXyz(vec3 wi, vec3 wr) {
    float gainC = gainFactor(wi, wr);
    vec3 f;
    if (gainC == 0.0 || !tableFraction(-wi - wr, f)) {
        return vec3(0.0);
    }
    vec2 t = nodeCentred(f.xy, tableInfo.nodes.xy);
    float x = 2.0 * f.z - 1.0;
    vec3 g = vec3(0.0);
    for (int p = TABLE_TERMS - 1; p >= 0; --p) {
        g = g * x + texture(gPowers, vec3(t, float(p))).rgb;
    }
    // G ≥ 0: interpolation and rounding may overshoot below zero; light cannot.
    return gainC * max(g, vec3(0.0));
}

#include "shade.glsl"
