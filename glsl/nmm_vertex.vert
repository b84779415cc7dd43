#version 450
// Variant `nmm` evaluated per vertex (thesis §1.5.1).
#include "nmm.glsl"
#include "per_vertex.glsl"
