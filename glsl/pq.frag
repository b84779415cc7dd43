#version 450
// Variant `pq` (thesis §1.5.3, Algorithm 5, done right): see pq.glsl.
#include "pq.glsl"
#include "shade.glsl"
