#version 450
// The G-buffer of a scene's environment-lit pixels (src/render/gbuffer.rs), vertex stage:
// thesis Algorithm 2's tangent frame (frame.glsl, as diffraction.vert builds it) and the
// world position, for gbuffer.frag to finish per pixel. The mesh is in world space.
#include "frame.glsl"

layout(location = 0) in vec3 inPosition;
layout(location = 1) in vec3 inNormal;
layout(location = 2) in vec4 inTangent; // w = ±1: handedness, B = w·(N × T) (mesh.rs)
layout(location = 3) in vec2 inUv;

layout(push_constant) uniform Transforms {
    mat4 model;    // M
    mat4 viewProj; // P·C⁻¹ (Vulkan clip space)
} transforms;

layout(location = 0) out vec3 outTangent;
layout(location = 1) out vec3 outBitangent;
layout(location = 2) out vec3 outNormal;
layout(location = 3) out vec3 outPosition;
layout(location = 4) out vec2 outUv;

void main() {
    vec3 t, b, n;
    tangentFrame(mat3(transforms.model), inNormal, inTangent, t, b, n);
    vec4 position = transforms.model * vec4(inPosition, 1.0);
    outTangent = t;
    outBitangent = b;
    outNormal = n;
    outPosition = position.xyz / position.w;
    // OBJ texture coordinates have v up; texture rows are stored top first.
    outUv = vec2(inUv.x, 1.0 - inUv.y);
    gl_Position = transforms.viewProj * position;
}
