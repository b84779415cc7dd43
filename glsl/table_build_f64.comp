#version 450
// The device build of G in float64 (needs shaderFloat64); see table_build.glsl.
#define BUILD_F64
#include "table_build.glsl"
