#version 450
// Variant `pq` evaluated per vertex (thesis §1.5.1).
#include "pq.glsl"
#include "per_vertex.glsl"
