// Thesis Algorithm 2, lines 2–5, for every vertex stage (diffraction.vert, per_vertex.glsl):
// the tangent frame (T, B, N) of a vertex in world space, and projection into it. One
// definition, so per-pixel and per-vertex evaluation see the same frame.
#ifndef FRAME_GLSL
#define FRAME_GLSL

// projectVectorOnTo(): coordinates of v in the orthonormal frame (T, B, N).
vec3 projectVectorOnTo(vec3 v, vec3 t, vec3 b, vec3 n) {
    return vec3(dot(v, t), dot(v, b), dot(v, n));
}

vec3 safeNormalizeOr(vec3 v, vec3 fallback) {
    float l = length(v);
    return l > 1e-20 ? v / l : fallback;
}

// The frame of a vertex with `normal` and `tangent` (w = ±1: handedness) under the model
// matrix `m`. Normals transform with the inverse transpose, so non-uniform scale keeps them
// perpendicular; T is re-orthogonalised against N so the frame stays orthonormal. MODEL §1
// has B = N × T; a mirrored UV map (w = −1) mirrors the grating with the texture.
void tangentFrame(mat3 m, vec3 normal, vec4 tangent, out vec3 t, out vec3 b, out vec3 n) {
    n = safeNormalizeOr(transpose(inverse(m)) * normal, vec3(0.0, 0.0, 1.0));
    vec3 anyPerp = normalize(cross(n, abs(n.x) < 0.9 ? vec3(1.0, 0.0, 0.0) : vec3(0.0, 1.0, 0.0)));
    vec3 t0 = m * tangent.xyz;
    t = safeNormalizeOr(t0 - n * dot(n, t0), anyPerp);
    b = (tangent.w < 0.0 ? -1.0 : 1.0) * cross(n, t);
}

#endif
