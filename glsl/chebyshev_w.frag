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
// Summed-area planes of the coefficient planes' node values ((nu + 1) × (nv + 1) texels,
// float32) for FOOTPRINT_BOX; a placeholder texel otherwise.
layout(set = 0, binding = 5) uniform sampler2DArray gSummed;

// How the table is read for the pixel's footprint (gUvFootprint): at the pixel's centre
// alone; from the level pre-filtered nearest to it (brdf::table::Levelled); or as the mean
// over the footprint's box from the summed-area planes (brdf::table::Summed).
const int FOOTPRINT_POINT = 0;
const int FOOTPRINT_LEVELS = 1;
const int FOOTPRINT_BOX = 2;
layout(constant_id = 11) const int FOOTPRINT = FOOTPRINT_POINT;

// The level of the table for the pixel's footprint (brdf::table::levels): the footprint's
// covariance in texels of the finest level is (J Jᵀ)/12 for the pixel's box (J: ∂(u, v)/
// ∂(x, y)); the level whose kernel (variance h²(4^L − 1)/6) matches its mean over
// directions, the nearest. 0 for a point (a map, a compute stage's sample).
int footprintLevel() {
    int count = int(tableInfo.atlas.z);
    vec2 h = 1.0 / (tableInfo.invExtent.xy * (tableInfo.nodes.xy - 1.0));
    vec2 dx = gUvFootprint.xy / h;
    vec2 dy = gUvFootprint.zw / h;
    float mean = (dot(dx, dx) + dot(dy, dy)) / 24.0;
#ifdef ENV_STAGE
    // The compute stages' point lights, where the box cannot be read, take the level of
    // half the footprint's width: nearer the converged picture than the full width there
    // (docs/lighting.md, footprints of the point lights).
    mean *= 0.25;
#endif
    return clamp(int(floor(0.5 * log2(1.0 + 6.0 * mean) + 0.5)), 0, count - 1);
}

// Fetch positions and pair weights of the cubic B-spline at fraction f on the n nodes of a
// level whose first texel is `at`, in normalised coordinates of the image (n + 2 texels a
// side for the level alone).
void splineTaps(vec2 f, vec2 n, vec2 at, out vec2 p0, out vec2 p1, out vec2 g0, out vec2 g1) {
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
    vec2 texels = tableInfo.atlas.xy;
    p0 = (at + i + 0.5 + w1 / g0) / texels;
    p1 = (at + i + 2.5 + w3 / g1) / texels;
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

// Σ_j c_j T_j(x) by Clenshaw's recurrence, the c_j packed as `coefficient` reads them.
vec3 clenshaw(vec4 packed[PACKED_LAYERS], float x) {
    vec3 b1 = vec3(0.0);
    vec3 b2 = vec3(0.0);
    for (int j = TABLE_TERMS - 1; j >= 1; --j) {
        vec3 b0 = coefficient(packed, j) + 2.0 * x * b1 - b2;
        b2 = b1;
        b1 = b0;
    }
    return coefficient(packed, 0) + x * b1 - b2;
}

// G at fraction f of the box from level `level` of the table: the spline in (u, v) of each
// coefficient plane, then Clenshaw in w.
vec3 seriesAt(vec3 f, int level) {
    vec4 at = tableInfo.levels[level];
    vec2 p0, p1, g0, g1;
    splineTaps(f.xy, at.xy, at.zw, p0, p1, g0, g1);
    vec4 packed[PACKED_LAYERS];
    for (int l = 0; l < PACKED_LAYERS; ++l) {
        packed[l] = layerAt(p0, p1, g0, g1, l);
    }
    return clenshaw(packed, 2.0 * f.z - 1.0);
}

// The mean of G over the box of half-widths r (in node spacings, each at least ½) about
// fraction f, the nodes held constant over their cells and G zero outside the table: four
// reads of the summed-area planes a layer, whatever the box's size.
vec3 boxAt(vec3 f, vec2 r) {
    vec2 n = tableInfo.nodes.xy;
    vec2 t = f.xy * (n - 1.0);
    // The corner at node coordinate c is summed texel c + ½, whose centre is at c + 1.
    vec2 p0 = (clamp(t - r, vec2(-0.5), n - 0.5) + 1.0) / (n + 1.0);
    vec2 p1 = (clamp(t + r, vec2(-0.5), n - 0.5) + 1.0) / (n + 1.0);
    float inv = 0.25 / (r.x * r.y);
    vec4 packed[PACKED_LAYERS];
    for (int l = 0; l < PACKED_LAYERS; ++l) {
        float z = float(l);
        packed[l] = inv * (texture(gSummed, vec3(p1.x, p1.y, z)) - texture(gSummed, vec3(p0.x, p1.y, z))
                         - texture(gSummed, vec3(p1.x, p0.y, z)) + texture(gSummed, vec3(p0.x, p0.y, z)));
    }
    return clenshaw(packed, 2.0 * f.z - 1.0);
}

// G at fraction f as the mean over the pixel's footprint: the box whose widths along u and
// v are those of a box with the footprint's variance along each (J Jᵀ/12, J = ∂(u, v)/
// ∂(x, y)), at least a node spacing (the nodes' linear interpolation, for a point). No
// branch to the spline for small footprints: on lavapipe it triples the draw's time.
vec3 footprintAt(vec3 f) {
    vec2 h = 1.0 / (tableInfo.invExtent.xy * (tableInfo.nodes.xy - 1.0));
    vec2 width = sqrt(gUvFootprint.xy * gUvFootprint.xy + gUvFootprint.zw * gUvFootprint.zw) / h;
    return boxAt(f, max(0.5 * width, vec2(0.5)));
}

vec3 diffractionXyz(vec3 wi, vec3 wr) {
    float gainC = gainFactor(wi, wr);
    vec3 f;
    if (gainC == 0.0 || !tableFraction(-wi - wr, f)) {
        return vec3(0.0);
    }
    // A map's pixels are directions: they read the table at their point. In the compute
    // stages a point light reads the box of its G-buffer footprint and a sample, which has
    // none, the spline at its point (glsl/env_common.glsl, setFootprint).
#ifdef ENV_STAGE
    bool boxed = FOOTPRINT == FOOTPRINT_BOX && gUvFootprint != vec4(0.0);
#else
    bool boxed = FOOTPRINT == FOOTPRINT_BOX && OUTPUT_MODE == MODE_MESH;
#endif
    vec3 g = boxed                           ? footprintAt(f)
           : FOOTPRINT == FOOTPRINT_LEVELS   ? seriesAt(f, footprintLevel())
                                             : seriesAt(f, 0);
    // G ≥ 0: the splines and the series in w may overshoot below zero; light cannot.
    return gainC * max(g, vec3(0.0));
}

#include "shade.glsl"
