#version 450
// The device build of G in float32 (devices without shaderFloat64); see table_build.glsl.
#include "table_build.glsl"
