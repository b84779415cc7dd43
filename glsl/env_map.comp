#version 450
// A BRDF map lit by an environment map (MODEL §10), one invocation per pixel: N samples
// per pixel of L_o = ∫ L(ωi)·f_r·cos θi dωi, combining two samplers by multiple importance
// sampling (power heuristic with the samples' counts):
//  - the BRDF, every sample: (u, v) drawn from a piecewise-constant density fitted to the
//    table's G (the envelope over w), dωi = du dv / cos θi;
//  - the lights, every m-th sample: an environment pixel drawn by luminance, uniform in
//    solid angle inside it, or a disc light.
// Random numbers: the 5-dimensional R-sequence (Roberts' generalised golden ratio), with a
// per-pixel Cranley–Patterson rotation from a hash of the pixel. G is the chebyshev-w model
// of a table summed with radiance weights (brdf::env_reference): f_r/W per XYZ channel, so
// L_o,c = ∫ L_c·C·G_c du dv with the environment's RGB turned into XYZ on the CPU and
// applied channel by channel (the usual approximation: the dispersion is in G, not in the
// light). The estimator is env_common.glsl's, shared with env_scene.comp.
#include "env_common.glsl"

void main() {
    uint idx = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * 64u;
    int S = P.lightDims.w;
    if (idx >= uint(S * S)) return;
    int px = int(idx) % S, py = int(idx) / S;
    float x = 2.0 * (float(px) + 0.5) / float(S) - 1.0;
    float y = 1.0 - 2.0 * (float(py) + 0.5) / float(S);
    float r2 = x * x + y * y;
    if (r2 >= 1.0) {
        outSum[2u * idx] = vec4(0.0, 0.0, 0.0, 1.0);
        outSum[2u * idx + 1u] = vec4(0.0);
        return;
    }
    // The map's patch (MODEL §10): N = +Y, T = +X, B = N × T = −Z.
    Surface s = Surface(vec3(1.0, 0.0, 0.0), vec3(0.0, 0.0, -1.0), vec3(0.0, 1.0, 0.0),
                        vec3(x, y, sqrt(1.0 - r2)), vec3(0.0));
    // Per pixel: (the samples' XYZ sum, their number), (the point lights' XYZ, 0).
    vec3 xyz, rgb, sq;
    integrate(s, idx, 0u, 1u, chunk.count, xyz, rgb, sq);
    float n = float(chunk.base + chunk.count);
    if (chunk.base == 0) {
        vec3 pxyz, prgb;
        pointLights(s, pxyz, prgb);
        outSum[2u * idx] = vec4(xyz, n);
        outSum[2u * idx + 1u] = vec4(pxyz, 0.0);
    } else {
        outSum[2u * idx] = vec4(outSum[2u * idx].xyz + xyz, n);
    }
}
