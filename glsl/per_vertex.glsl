// main() of the per-vertex stages (thesis §1.5.1): thesis Algorithm 2's tangent frame and
// directions (as diffraction.vert), then the including variant's
//   vec3 diffractionXyz(vec3 wi, vec3 wr)
// evaluated once per vertex; per_vertex.frag interpolates the colour and blends the
// texture (Algorithm 4) per fragment. Cost scales with the vertex count, not the pixels;
// the colour between vertices is linear, so the mesh must resolve the diffraction lobes.
#ifndef PER_VERTEX_GLSL
#define PER_VERTEX_GLSL
#include "interface.glsl"
#include "colour.glsl"
#include "frame.glsl"

layout(location = 0) in vec3 inPosition;
layout(location = 1) in vec3 inNormal;
layout(location = 2) in vec4 inTangent; // w = ±1: handedness, B = w·(N × T) (mesh.rs)
layout(location = 3) in vec2 inUv;

layout(push_constant) uniform Transforms {
    mat4 model;    // M
    mat4 viewProj; // P·C⁻¹ (Vulkan clip space)
} transforms;

layout(location = 0) out vec3 outWi;
layout(location = 1) out vec3 outWr;
layout(location = 2) out vec2 outUv;
// Diffraction colour (linear sRGB) of this vertex summed over the light's disc, each
// direction weighted by its cos θi: the lit colour per unit light intensity, before exposure.
layout(location = 3) out vec3 outDiffraction;

void main() {
    // Algorithm 2 lines 2–10, exactly as diffraction.vert.
    vec3 t, b, n;
    tangentFrame(mat3(transforms.model), inNormal, inTangent, t, b, n);
    vec4 position = transforms.model * vec4(inPosition, 1.0);
    vec3 viewerDir = params.eyeWorld.xyz - position.xyz / position.w;
    vec3 lightDir = -safeNormalizeOr(params.lightDirWorld.xyz, vec3(0.0, 0.0, -1.0));
    vec3 wi = safeNormalizeOr(projectVectorOnTo(lightDir, t, b, n), vec3(0.0, 0.0, 1.0));
    vec3 wr = projectVectorOnTo(viewerDir, t, b, n);
    outWi = wi;
    outWr = wr;
    outUv = vec2(inUv.x, 1.0 - inUv.y);

    // §1.5.1: the BRDF at this vertex (the per-pixel path evaluates it per fragment), over
    // the directions of the light's disc as shade.glsl does.
    vec3 wrUnit = safeNormalizeOr(wr, vec3(0.0, 0.0, 1.0));
    vec3 c = vec3(0.0);
    int samples = clamp(params.lightInfo.x, 1, MAX_DISK_SAMPLES);
    for (int k = 0; k < samples; ++k) {
        vec3 wik = safeNormalizeOr(projectVectorOnTo(params.lightDisk[k].xyz, t, b, n),
                                   vec3(0.0, 0.0, 1.0));
        c += params.lightDisk[k].w * max(wik.z, 0.0)
           * xyzToLinearSrgb(diffractionXyz(wik, wrUnit));
    }
    outDiffraction = (any(isnan(c)) || any(isinf(c))) ? vec3(0.0) : c;

    gl_Position = transforms.viewProj * position;
}

#endif
