#version 450
// Variant `chebyshev-w`: G = Σ_j c_j(u, v)·T_j(ŵ), ŵ the tabulated w range mapped to
// [−1, 1]; one bilinear fetch per coefficient, summed by Clenshaw's recurrence (MODEL §7).
#include "interface.glsl"
#include "gain.glsl"
#include "table.glsl"

layout(set = 0, binding = 1) uniform sampler2DArray gCoefficients;

vec3 coefficientAt(vec2 t, int j) {
    return texture(gCoefficients, vec3(t, float(j))).rgb;
}

vec3 diffractionXyz(vec3 wi, vec3 wr) {
    float gainC = gainFactor(wi, wr);
    vec3 f;
    if (gainC == 0.0 || !tableFraction(-wi - wr, f)) {
        return vec3(0.0);
    }
    vec2 t = nodeCentred(f.xy, tableInfo.nodes.xy);
    float x = 2.0 * f.z - 1.0;
    vec3 b1 = vec3(0.0);
    vec3 b2 = vec3(0.0);
    for (int j = TABLE_TERMS - 1; j >= 1; --j) {
        vec3 b0 = coefficientAt(t, j) + 2.0 * x * b1 - b2;
        b2 = b1;
        b1 = b0;
    }
    return gainC * (coefficientAt(t, 0) + x * b1 - b2);
}

#include "shade.glsl"
