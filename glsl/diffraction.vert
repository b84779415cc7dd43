#version 450
// Thesis Algorithm 2 (vertex diffraction shader): the tangent frame (N, T, B) from the
// vertex normal and tangent via the model matrix, ωr projected into it, and the clip-space
// position p = P·C⁻¹·M·p_local (eq. 1.2). ωi is projected per fragment instead (shade.glsl),
// once for each direction over the light's disc: the frame is passed on for that.
#include "interface.glsl"
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
layout(location = 1) out vec3 outWr;
layout(location = 2) out vec2 outUv;
layout(location = 3) out vec3 outBitangent;
layout(location = 4) out vec3 outNormal;

void main() {
    // Lines 2–5 (frame.glsl).
    vec3 t, b, n;
    tangentFrame(mat3(transforms.model), inNormal, inTangent, t, b, n);

    // Lines 6–10: ωr towards the eye. ωi towards the light (lines 7–8) needs one projection
    // per direction over the sun's disc: the frame goes to the fragment stage, where
    // projecting onto the interpolated frame equals interpolating per-vertex projections
    // (projection is linear in the frame), so a point light gives Algorithm 2's ωi.
    vec4 position = transforms.model * vec4(inPosition, 1.0);
    vec3 viewerDir = params.eyeWorld.xyz - position.xyz / position.w;
    outTangent = t;
    outBitangent = b;
    outNormal = n;
    // Line 10 normalises ωr per vertex; it is normalised per fragment instead, because
    // eye − position is linear in the position: interpolated unnormalised it is the exact
    // per-pixel direction on flat triangles, while normalised vectors interpolate wrongly
    // (and diffraction lobes are only ~0.005 wide in u).
    outWr = projectVectorOnTo(viewerDir, t, b, n);
    // OBJ texture coordinates have v up; texture rows are stored top first.
    outUv = vec2(inUv.x, 1.0 - inUv.y);

    // Line 11.
    gl_Position = transforms.viewProj * position;
}
