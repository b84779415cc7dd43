// main() of the pixels of a scene lit by an environment map, disc lights and point lights
// (the sun over its disc), one invocation per covered pixel of a G-buffer
// (src/render/env_scene.rs): the pixel's tangent frame, ωr in it and the texture's albedo.
// The estimator is env_common.glsl's, shared with the BRDF map (env_map.glsl); build.rs
// compiles it in place of shade.glsl into every variant's fragment file
// (`<variant>.env_scene`).
#ifndef ENV_SCENE_GLSL
#define ENV_SCENE_GLSL
#include "env_common.glsl"

// Per pixel: (T, t_r), (B, t_g), (N, t_b), (ωr in the tangent frame, key): an orthonormal
// frame in world space, the texture's linear-sRGB albedo, and as the bits of the last float
// the output pixel × 16 + the G-buffer pixel's place among the output pixel's
// supersample² (they interleave one sequence). Then, for the P.sequence.w pixels, a vec4
// of ints a pixel: the indices of its covered neighbours right, left, down and up, −1 for
// none (src/render/env_scene.rs, GBuffer::device_bytes).
layout(std430, set = 1, binding = 6) readonly buffer Pixels { vec4 gbuffer[]; };
// The G-buffer pixels this pass integrates (those whose noise is still above the target).
layout(std430, set = 1, binding = 7) readonly buffer Active { uint passPixels[]; };

// The surface of G-buffer pixel j.
Surface surfaceAt(uint j) {
    vec4 a = gbuffer[4u * j], b = gbuffer[4u * j + 1u], c = gbuffer[4u * j + 2u];
    vec4 d = gbuffer[4u * j + 3u];
    return Surface(a.xyz, b.xyz, c.xyz, d.xyz, vec3(a.w, b.w, c.w));
}

// Per G-buffer pixel, three vec4 of Out: (the added samples' linear-sRGB sum, the samples
// taken), (the sum of the squared batch sums per channel, the batches dropped for a NaN or
// an infinity), (the point lights' colour, 0). The first pass (base 0) starts them.
void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * 64u;
    if (i >= uint(P.envDims.w)) return;
    uint idx = passPixels[i];
    Surface s = surfaceAt(idx);
    uint key = floatBitsToUint(gbuffer[4u * idx + 3u].w);
    // The neighbours serve the point lights' footprints: read where the point lights are
    // evaluated (the first dispatch, or the lights' own stage).
    if (P.sequence.w > 0 && (chunk.base == 0 || chunk.count == 0)) {
        ivec4 near = floatBitsToInt(gbuffer[4u * uint(P.sequence.w) + idx]);
        for (int k = 0; k < 4; ++k) {
            gHas[k] = near[k] >= 0;
            gNear[k] = surfaceAt(gHas[k] ? uint(near[k]) : idx);
        }
    }
    if (chunk.count == 0) {
        // The point lights alone, evaluated by this variant for another's samples
        // (src/render/env.rs, EnvKernel::record): they replace the first dispatch's.
        vec3 pxyz, prgb;
        pointLights(s, pxyz, prgb);
        outSum[3u * idx + 2u] = vec4(XYZ_TO_SRGB * pxyz + prgb, 0.0);
        return;
    }
    vec3 xyz, rgb, sq;
    int closed, dropped;
    integrate(s, key >> 4, key & 15u, uint(P.sequence.x), P.cdfDims.w, xyz, rgb, sq, closed,
              dropped);
    vec3 sum = XYZ_TO_SRGB * xyz + rgb;
    if (chunk.base == 0) {
        vec3 pxyz, prgb;
        pointLights(s, pxyz, prgb);
        outSum[3u * idx] = vec4(sum, float(closed));
        outSum[3u * idx + 1u] = vec4(sq, float(dropped));
        outSum[3u * idx + 2u] = vec4(XYZ_TO_SRGB * pxyz + prgb, 0.0);
    } else {
        vec4 o = outSum[3u * idx], q = outSum[3u * idx + 1u];
        outSum[3u * idx] = vec4(o.xyz + sum, o.w + float(closed));
        outSum[3u * idx + 1u] = vec4(q.xyz + sq, q.w + float(dropped));
    }
}

#endif
