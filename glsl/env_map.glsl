// main() of a BRDF map lit by an environment map, disc lights and point lights
// (MODEL §10), one invocation per pixel: N samples per pixel of L_o = ∫ L(ωi)·f_r·cos θi
// dωi, combining two samplers by multiple importance sampling (power heuristic with the
// samples' counts):
//  - the BRDF, every sample: (u, v) drawn from a piecewise-bilinear density fitted to the
//    table's G (the envelope over w), dωi = du dv / cos θi;
//  - the lights, every m-th sample: an environment pixel drawn by luminance, uniform in
//    solid angle inside it, or a disc light.
// Random numbers: the 5-dimensional R-sequence (Roberts' generalised golden ratio), with a
// per-pixel Cranley–Patterson rotation from a hash of the pixel. f_r is the including
// variant's diffractionXyz in radiance units, per XYZ channel, with the environment's RGB
// turned into XYZ on the CPU and applied channel by channel (the usual approximation: the
// dispersion is in G, not in the light). build.rs compiles it in place of shade.glsl into
// every variant's fragment file (`<variant>.env_map`).
#ifndef ENV_MAP_GLSL
#define ENV_MAP_GLSL
#include "env_common.glsl"

// Per pixel: (the added samples' XYZ sum, the samples taken), (the point lights' XYZ, the
// batches dropped for a NaN or an infinity).
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
    if (chunk.count == 0) {
        // The point lights alone, evaluated by this variant for another's samples
        // (src/render/env.rs, EnvKernel::record): they replace the first dispatch's.
        vec3 pxyz, prgb;
        pointLights(s, pxyz, prgb);
        outSum[2u * idx + 1u] = vec4(pxyz, outSum[2u * idx + 1u].w);
        return;
    }
    vec3 xyz, rgb, sq;
    int closed, dropped;
    // Batches of one sample: a dispatch the driver cuts short keeps every sample it took.
    integrate(s, idx, 0u, 1u, 1, xyz, rgb, sq, closed, dropped);
    if (chunk.base == 0) {
        vec3 pxyz, prgb;
        pointLights(s, pxyz, prgb);
        outSum[2u * idx] = vec4(xyz, float(closed));
        outSum[2u * idx + 1u] = vec4(pxyz, float(dropped));
    } else {
        vec4 a = outSum[2u * idx], b = outSum[2u * idx + 1u];
        outSum[2u * idx] = vec4(a.xyz + xyz, a.w + float(closed));
        outSum[2u * idx + 1u] = vec4(b.xyz, b.w + float(dropped));
    }
}

#endif
