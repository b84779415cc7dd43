#version 450
// The pixels of a scene lit by an environment map, disc lights and point lights (the sun
// over its disc), one invocation per covered pixel of a G-buffer that the CPU rasterised
// (src/render/env_scene.rs): the pixel's tangent frame, ωr in it and the texture's albedo.
// The estimator is env_common.glsl's, shared with the BRDF map (env_map.comp).
#include "env_common.glsl"

// Per pixel: (T, t_r), (B, t_g), (N, t_b), (ωr in the tangent frame, key): an orthonormal
// frame in world space, the texture's linear-sRGB albedo, and as the bits of the last float
// the output pixel × 16 + the G-buffer pixel's place among the output pixel's
// supersample² (they share one sequence, each taking the next N samples of it).
layout(std430, set = 0, binding = 7) readonly buffer Pixels { vec4 gbuffer[]; };

void main() {
    uint idx = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * 64u;
    if (idx >= uint(P.envDims.w)) return;
    vec4 a = gbuffer[4u * idx], b = gbuffer[4u * idx + 1u], c = gbuffer[4u * idx + 2u];
    vec4 d = gbuffer[4u * idx + 3u];
    Surface s = Surface(a.xyz, b.xyz, c.xyz, d.xyz, vec3(a.w, b.w, c.w));
    uint key = floatBitsToUint(d.w);
    vec3 xyz, rgb;
    integrate(s, key >> 4, (key & 15u) * uint(P.envDims.z), xyz, rgb);
    bool first = chunk.base == 0;
    outSum[2u * idx] = vec4((first ? vec3(0.0) : outSum[2u * idx].xyz) + xyz, 1.0);
    outSum[2u * idx + 1u] = vec4((first ? vec3(0.0) : outSum[2u * idx + 1u].xyz) + rgb, 1.0);
}
