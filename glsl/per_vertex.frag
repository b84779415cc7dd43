#version 450
// Fragment stage of per-vertex evaluation (thesis §1.5.1): the diffraction colour comes
// interpolated from the vertices (per_vertex.glsl), lit over the light's disc there; texture
// blending (Algorithm 4) and exposure are applied per fragment as in shade.glsl's mesh branch.
#include "interface.glsl"
#include "gain.glsl"
#include "colour.glsl"
#include "sky.glsl"
#include "footprint_texture.glsl"

layout(location = 0) in vec3 inWi;
layout(location = 1) in vec3 inWr;
layout(location = 2) in vec2 inUv;
layout(location = 3) in vec3 inDiffraction;

layout(location = 0) out vec4 outColour;

vec3 safeNormalize(vec3 v) {
    float l = length(v);
    return l > 1e-20 ? v / l : vec3(0.0, 0.0, 1.0);
}

void main() {
    vec3 wi = safeNormalize(inWi);
    vec3 wr = safeNormalize(inWr);
    // The vertices carry the diffraction already lit (Σ over the disc of weight·cos θi·c).
    vec3 c = inDiffraction * params.lighting.x;
    if (TEXTURE_BLENDING) {
        // Algorithm 4 (colour.glsl's textureBlend), its texture part lit from the disc's
        // centre: (1 − w_d)·c_diffraction + ((1 − α) + w_d)·t, plus the uniform sky (sky.glsl).
        float irradiance = max(wi.z, 0.0) * params.lighting.x;
        vec3 cTexture = params.shading.y * textureOverFootprint(surfaceTexture, inUv).rgb;
        vec3 h = safeNormalize(wi + wr);
        float f = schlickFresnel(clamp(dot(wr, h), 0.0, 1.0));
        c = textureBlend(c, vec3(0.0), f, params.lighting.z)
          + textureBlend(vec3(0.0), cTexture, f, params.lighting.z) * irradiance
          + uniformSky(wr, cTexture);
    }
    c *= params.lighting.y;
    outColour = vec4((any(isnan(c)) || any(isinf(c))) ? vec3(0.0) : c, 1.0);
}
