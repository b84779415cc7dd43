// The scene's ambient light, a uniform sky of radiance params.lighting.w, added in closed
// form (src/light/sky.rs derives and states it on the CPU): what it reflects towards ωr,
// on the picture's scale, under thesis Algorithm 4 with absolute units,
//   L·[(1 − w_d)·R(θr)/S + (π(1 + w_d) − A_α(θr))·t],   A_α = π·R0 + (1 − R0)·J(θr).
#ifndef SKY_GLSL
#define SKY_GLSL
#include "interface.glsl"

// J(cos θr) = ∫ (1 − ωr·h)⁵ cos θi dωi, linear between the table's nodes.
float fresnelTail(float cosR) {
    float x = clamp(cosR, 0.0, 1.0) * float(SKY_TAIL_NODES - 1);
    int i = min(int(floor(x)), SKY_TAIL_NODES - 2);
    float a = params.skyTail[i / 4][i % 4];
    float b = params.skyTail[(i + 1) / 4][(i + 1) % 4];
    return mix(a, b, x - float(i));
}

// The sky's light towards ωr (tangent space) off a texture of albedo t (0 without one).
vec3 uniformSky(vec3 wr, vec3 t) {
    float radiance = params.lighting.w;
    if (radiance <= 0.0) {
        return vec3(0.0);
    }
    float c = clamp(wr.z, 0.0, 1.0);
    float r0 = params.shading.x;
    float m = 1.0 - c;
    float mirror = FRESNEL ? r0 + (1.0 - r0) * m * m * m * m * m : 1.0;
    float aAlpha = PI * r0 + (1.0 - r0) * fresnelTail(c);
    float w = params.lighting.z;
    return radiance * ((1.0 - w) * mirror * params.shading.z + (PI * (1.0 + w) - aAlpha) * t);
}

#endif
