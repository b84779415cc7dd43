#version 450
// Variant `nmm` (thesis §1.5.2 done right): see nmm.glsl.
#include "nmm.glsl"
#include "shade.glsl"
