// Shared by the pre-integrated variants (MODEL §7): XYZ = C(ωi, ωr)·G(u, v, w), with G
// tabulated offline in f64 over the box of (u, v, w) the scene reaches, on nodes that
// include both ends of each axis. Mirrors brdf::table on the CPU.
#ifndef TABLE_GLSL
#define TABLE_GLSL
#include "interface.glsl"

layout(set = 0, binding = 4, std140) uniform TableInfo {
    vec4 lo;        // xyz: lower corner (u0, v0, w0) of the tabulated box
    vec4 invExtent; // xyz: 1/(u1 − u0), 1/(v1 − v0), 1/(w1 − w0)
    vec4 nodes;     // x: nodes along u, y: along v, z: along w (volume slices)
    vec4 atlas;     // xy: the image's texels along u and v, z: levels (brdf::table::Levelled)
    vec4 levels[MAX_TABLE_LEVELS]; // per level: xy nodes along u and v, zw its first texel
} tableInfo;

// Position of uvw in the box as fractions in [0, 1]; false outside (the variant writes
// black there, never a clamped edge value).
bool tableFraction(vec3 uvw, out vec3 f) {
    f = (uvw - tableInfo.lo.xyz) * tableInfo.invExtent.xyz;
    return all(greaterThanEqual(f, vec3(0.0))) && all(lessThanEqual(f, vec3(1.0)));
}

// Normalised texture coordinate of fraction f on n nodes stored as n texels: node i sits
// at the centre of texel i, so both ends of the axis are exact.
vec2 nodeCentred(vec2 f, vec2 n) {
    return (f * (n - 1.0) + 0.5) / n;
}

#endif
