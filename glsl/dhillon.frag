#version 450
// Variant `dhillon` (Dhillon et al. 2014): G = Σ_p I_p(u, v)·w^p, tables of the powers of w,
// one bilinear fetch per power, Horner's rule. The monomial basis is ill-conditioned in
// float32; `diffract profile` measures by how much.
#include "interface.glsl"
#include "gain.glsl"
#include "table.glsl"

layout(set = 0, binding = 1) uniform sampler2DArray gPowers;

vec3 diffractionXyz(vec3 wi, vec3 wr) {
    float gainC = gainFactor(wi, wr);
    vec3 uvw = -wi - wr;
    vec3 f;
    if (gainC == 0.0 || !tableFraction(uvw, f)) {
        return vec3(0.0);
    }
    vec2 t = nodeCentred(f.xy, tableInfo.nodes.xy);
    vec3 g = vec3(0.0);
    for (int p = TABLE_TERMS - 1; p >= 0; --p) {
        g = g * uvw.z + texture(gPowers, vec3(t, float(p))).rgb;
    }
    return gainC * g;
}

#include "shade.glsl"
