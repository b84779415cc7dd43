#version 450
// Variant `flss` evaluated per vertex (thesis §1.5.1): Algorithm 3 in the vertex stage,
// the same BRDF as flss.frag (flss_brdf.glsl).
#include "flss_brdf.glsl"

#include "per_vertex.glsl"
