#version 450
// Variant `chebyshev-w`: G = Σ_j c_j(u, v)·T_j(ŵ), ŵ the tabulated w range mapped to
// [−1, 1], summed by Clenshaw's recurrence (MODEL §7). Each coefficient plane holds cubic
// B-spline coefficients through the (u, v) nodes (one ghost texel on each side): the
// spline is evaluated from four bilinear fetches (the weights of each pair folded into
// one fetch position), so lobes about two texels wide interpolate to O(h⁴).
#include "interface.glsl"
#include "gain.glsl"
#include "table.glsl"

layout(set = 0, binding = 1) uniform sampler2DArray gCoefficients;

// Fetch positions and pair weights of the cubic B-spline at fraction f on n nodes, in
// normalised coordinates of the n + 2 stored texels.
void splineTaps(vec2 f, vec2 n, out vec2 p0, out vec2 p1, out vec2 g0, out vec2 g1) {
    vec2 t = f * (n - 1.0);
    vec2 i = clamp(floor(t), vec2(0.0), n - 2.0);
    vec2 x = t - i;
    vec2 x2 = x * x;
    vec2 x3 = x2 * x;
    vec2 w0 = (1.0 - x) * (1.0 - x) * (1.0 - x) / 6.0;
    vec2 w1 = (3.0 * x3 - 6.0 * x2 + 4.0) / 6.0;
    vec2 w2 = (-3.0 * x3 + 3.0 * x2 + 3.0 * x + 1.0) / 6.0;
    vec2 w3 = x3 / 6.0;
    g0 = w0 + w1;
    g1 = w2 + w3;
    // c_{i−1} is stored texel i (whose centre is i + 0.5).
    p0 = (i + 0.5 + w1 / g0) / (n + 2.0);
    p1 = (i + 2.5 + w3 / g1) / (n + 2.0);
}

// The coefficient planes' XYZ are packed four values a texel over the layers: plane j's
// X, Y, Z are values 3j, 3j + 1, 3j + 2 of the flat sequence (no unused alpha to fetch).
const int PACKED_LAYERS = (3 * TABLE_TERMS + 3) / 4;

vec4 layerAt(vec2 p0, vec2 p1, vec2 g0, vec2 g1, int layer) {
    float l = float(layer);
    return g0.y * (g0.x * texture(gCoefficients, vec3(p0.x, p0.y, l))
                 + g1.x * texture(gCoefficients, vec3(p1.x, p0.y, l)))
         + g1.y * (g0.x * texture(gCoefficients, vec3(p0.x, p1.y, l))
                 + g1.x * texture(gCoefficients, vec3(p1.x, p1.y, l)));
}

vec3 coefficient(vec4 packed[PACKED_LAYERS], int j) {
    int q = 3 * j;
    return vec3(packed[q / 4][q % 4], packed[(q + 1) / 4][(q + 1) % 4],
                packed[(q + 2) / 4][(q + 2) % 4]);
}

vec3 diffractionXyz(vec3 wi, vec3 wr) {
    float gainC = gainFactor(wi, wr);
    vec3 f;
    if (gainC == 0.0 || !tableFraction(-wi - wr, f)) {
        return vec3(0.0);
    }
    vec2 p0, p1, g0, g1;
    splineTaps(f.xy, tableInfo.nodes.xy, p0, p1, g0, g1);
    vec4 packed[PACKED_LAYERS];
    for (int l = 0; l < PACKED_LAYERS; ++l) {
        packed[l] = layerAt(p0, p1, g0, g1, l);
    }
    float x = 2.0 * f.z - 1.0;
    vec3 b1 = vec3(0.0);
    vec3 b2 = vec3(0.0);
    for (int j = TABLE_TERMS - 1; j >= 1; --j) {
        vec3 b0 = coefficient(packed, j) + 2.0 * x * b1 - b2;
        b2 = b1;
        b1 = b0;
    }
    // G ≥ 0: the splines and the series in w may overshoot below zero; light cannot.
    return gainC * max(coefficient(packed, 0) + x * b1 - b2, vec3(0.0));
}

#include "shade.glsl"
